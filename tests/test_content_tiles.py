"""SceneOptions.content_tiles: a rigid content as n x n box tiles, each its own contact pair."""

import mujoco
import numpy as np
import pytest

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco import SceneOptions, load_consignment
from parcelfit.sim.mujoco.indentation import indentation_test, plate_rig
from parcelfit.sim.mujoco.scene import build_scene, content_contact_share, content_contacts


def test_the_face_stiffness_is_shared_over_the_contacts_the_tiles_keep():
    assert content_contact_share(650, 1) == 650  # one box: as every other face
    assert content_contact_share(650, 2) == 650 * 4  # 4 pairs keep 200 contacts, not 50
    assert content_contact_share(650, 4) == 650 * 13  # 16 pairs: at most the flat face's 650
    assert content_contact_share(40, 3) == 40  # a face of fewer than 50 contacts: all kept anyway
    # counted contacts: 680 kept share as one box's 50 of a 212-contact face
    assert content_contact_share(212, 4, kept=680) == round(212 * 680 / 50)
    assert content_contact_share(212, 1, kept=680) == 212  # one box: the count plays no part


def test_counted_contacts_need_tiles_and_a_whole_count():
    with pytest.raises(ParcelfitError, match="give content_tiles above 1"):
        SceneOptions(content_kept=680)
    with pytest.raises(ParcelfitError, match="content_kept must be a whole number"):
        SceneOptions(content_tiles=4, content_kept=0)
    with pytest.raises(ParcelfitError, match=r"from 1 to 800 \(50 per tile\)"):
        SceneOptions(content_tiles=4, content_kept=801)  # more than 16 pairs can keep
    assert SceneOptions(content_tiles=4, content_kept=680.0).content_kept == 680


def test_half_the_counted_contacts_make_each_tile_contact_twice_as_stiff():
    cons = load_consignment("KPBW")

    def solref(kept: int) -> np.ndarray:
        options = SceneOptions(content_tiles=4, content_kept=kept)
        model = build_scene(plate_rig("belt"), cons, cons.parameter_values(), 1, options).model()
        geoms = np.flatnonzero(model.geom_bodyid == model.body("content").id)
        return -model.geom_solref[geoms[0]]  # direct solref: (-stiffness, -damping)

    # the penalty law: stiffness and damping per contact both follow 1 / share (share rounded)
    assert solref(340) / solref(680) == pytest.approx([2.0, 2.0], rel=2e-3)


def test_a_full_shell_refuses_tiles():
    cons = load_consignment("KPBW")
    options = SceneOptions(shell_dof="full", content_tiles=2)
    with pytest.raises(ParcelfitError, match="a full shell has no such cap"):
        build_scene(plate_rig("belt"), cons, cons.parameter_values(), 1, options)


@pytest.mark.parametrize("tiles", [0, 9, 2.5])
def test_a_tile_count_out_of_range_is_refused(tiles):
    with pytest.raises(ParcelfitError, match="content_tiles must be a whole number from 1 to 8"):
        SceneOptions(content_tiles=tiles)


def test_the_indentation_test_refuses_tiles():
    with pytest.raises(ParcelfitError, match="one content box"):
        indentation_test(load_consignment("KPBW"), options=SceneOptions(content_tiles=2))


def test_the_spin_test_and_a_soft_content_refuse_tiles():
    from parcelfit.sim.mujoco.spin import spin_test

    with pytest.raises(ParcelfitError, match="one content box"):
        spin_test(load_consignment("KPBW"), options=SceneOptions(content_tiles=2))
    pb = load_consignment("PB")
    with pytest.raises(ParcelfitError, match="content_tiles splits a rigid content"):
        build_scene(plate_rig("belt"), pb, pb.parameter_values(), 1, SceneOptions(content_tiles=2))


def _settled(tiles: int):
    cons = load_consignment("KPBW")
    options = SceneOptions(spacing=0.015, content_tiles=tiles)
    model = build_scene(plate_rig("belt"), cons, cons.parameter_values(), 1, options).model()
    data = mujoco.MjData(model)
    for _ in range(round(0.25 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    body = model.body("content").id
    geoms = np.flatnonzero(model.geom_bodyid == body)
    return model, body, len(geoms), content_contacts(model, data)


@pytest.mark.slow
@pytest.mark.mujoco
def test_tiles_keep_more_contacts_with_the_same_mass_and_inertia():
    one, b1, n1, kept1 = _settled(1)
    tiled, b4, n4, kept4 = _settled(4)
    assert (n1, n4) == (1, 16)
    assert kept1 == 50 < kept4  # MuJoCo's cap per pair binds the one box on a 15 mm mesh
    assert tiled.body_mass[b4] == pytest.approx(one.body_mass[b1])
    # principal moments (MuJoCo may order the principal axes of the tiled body otherwise)
    assert np.sort(tiled.body_inertia[b4]) == pytest.approx(np.sort(one.body_inertia[b1]), rel=1e-9)
