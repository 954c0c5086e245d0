"""scripts/rim_probe.py: the content's sink into its packaging follows k_CoPa."""

import pytest

from parcelfit.sim.mujoco import SceneOptions

from .helpers import load_file_module

rim_probe = load_file_module("scripts/rim_probe.py")


@pytest.mark.slow
@pytest.mark.mujoco
def test_a_stiffer_content_contact_lets_the_content_sink_less():
    def probe(k_copa: float):
        return rim_probe.compliance(
            "content", "KPBW", "k_CoPa", k_copa, SceneOptions(), (10.0, 20.0), 0.15, 0.05
        )

    soft, stiff = probe(100.0), probe(1000.0)
    # the content presses into its packaging: a positive sink, less at the stiffer contact
    assert soft.compliance > 2 * stiff.compliance > 0
    assert soft.travel > stiff.travel > 0
    assert 0 <= stiff.jitter < stiff.travel
    assert 0 < soft.contacts <= 50  # MuJoCo's cap per colliding pair
