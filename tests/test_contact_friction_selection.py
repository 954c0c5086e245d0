"""The per-contact friction selects a step's contacts once: `record` (after mj_step2) reuses what
`apply` (after mj_step1) selected, which holds only if mj_step2 changes neither the contacts nor
the flex's vertex positions."""

import mujoco
import numpy as np

from parcelfit.runs import TestCase

from .simhelpers import contact_law_scene


def test_the_contacts_apply_selected_are_the_ones_a_fresh_selection_finds_after_the_step():
    with contact_law_scene(TestCase("E3", "KPBW", 1)) as (model, data, friction):
        checked = 0
        for step in range(300):
            mujoco.mj_step1(model, data)
            friction.apply(model, data)
            mujoco.mj_step2(model, data)
            if step % 50 == 49:
                cached = friction._selected
                fresh = friction._select(data)
                assert cached is not None and cached[0].size > 0
                for a, b in zip(cached, fresh, strict=True):
                    assert np.array_equal(a, b)
                checked += 1
            friction.record(data)
            assert friction._selected is None  # used once, then dropped
    assert checked == 6
