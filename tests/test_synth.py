import numpy as np
import yaml

from parcelfit.runs import TestCase, load_dataset
from parcelfit.synth import TwinSettings, make_twin_dataset


def test_twin_dataset_scatters_like_real_runs_and_keeps_the_truth(tmp_path):
    settings = TwinSettings(runs=3, real_spacing=0.05)
    path = make_twin_dataset(
        tmp_path, [TestCase("E1", "BW", 1)], {"BW": {"mu_d_BePa": 0.5}}, settings=settings, seed=4
    )
    ds = load_dataset(path)
    assert ds.synthetic and "SYNTHETIC" in ds.description
    runs = ds["E1/BW/1"].runs
    assert len(runs) == 3 and all(r.transit_time is not None for r in runs)
    starts = np.array([[r.trajectory.x[0], r.trajectory.y[0]] for r in runs])
    assert np.ptp(starts[:, 1]) > 1e-4  # placement jitter and tracking noise
    assert len({round(r.transit_time, 4) for r in runs}) == 3  # specimens and belt speeds differ
    truth = yaml.safe_load((tmp_path / "truth.yaml").read_text())
    assert truth["synthetic"] and truth["truth"]["BW"]["mu_d_BePa"] == 0.5
    assert truth["settings"]["runs"] == 3 and truth["units"]["E_Pa"] == "N/mm^2"
    again = make_twin_dataset(
        tmp_path / "again",
        [TestCase("E1", "BW", 1)],
        {"BW": {"mu_d_BePa": 0.5}},
        settings=settings,
        seed=4,
    )
    assert np.array_equal(
        load_dataset(again)["E1/BW/1"].runs[2].trajectory.xy, runs[2].trajectory.xy
    )
