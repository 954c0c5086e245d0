"""The "solver" contact mapping: MuJoCo's own inverse mass and its cap of 50 contacts per pair
(sim/mujoco/contact_cap.py)."""

import mujoco
import numpy as np
import pytest

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SceneOptions, SimOptions, load_consignment
from parcelfit.sim.mujoco.contact_cap import CapWeights, packaging_geoms, solver_inverse_mass
from parcelfit.sim.mujoco.friction import Stepper, observed_steps
from parcelfit.sim.mujoco.indentation import indentation_test, plate_rig
from parcelfit.sim.mujoco.options import MAX_CONTACTS_PER_PAIR
from parcelfit.sim.mujoco.scene import build_scene

pytestmark = [pytest.mark.mujoco]


def _settled(tile: float | None, mapping: str = "vertex", seconds: float = 0.15):
    """KP/BW flat on a still belt plate (``tile``: as touching tiles), its content pressed down
    with 10 N for ``seconds``: (model, data, stepper)."""
    cons = load_consignment("KPBW")
    params = cons.parameter_values()
    options = SceneOptions(contact_mapping=mapping)
    scene = build_scene(plate_rig("belt", tile), cons, params, 1, options)
    model = scene.model()
    data = mujoco.MjData(model)
    stepper = Stepper(model, data, scene, params, options)
    data.xfrc_applied[model.body("content").id, 2] = -10.0
    for _ in range(round(seconds / model.opt.timestep)):
        stepper.step()
    return model, data, stepper


def _mujoco_counts(model: mujoco.MjModel, data: mujoco.MjData) -> dict[int, int]:
    """MuJoCo's contacts of the packaging flex by the geom they touch."""
    n = data.ncon
    geom = np.asarray(data.contact.geom[:n])
    flex = np.asarray(data.contact.flex[:n])
    packaging = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    on_flex = (flex == packaging).any(axis=1)
    other = np.maximum(geom[:, 0], geom[:, 1])[on_flex]
    return {int(g): int(c) for g, c in zip(*np.unique(other, return_counts=True), strict=True)}


@pytest.mark.slow
def test_the_touching_count_is_mujocos_where_a_pair_stays_below_the_cap():
    # KP/BW's first 0.8 s on E3 at the nominal placement: it rides the strips (each below the
    # cap) and meets the guide plate; at every 20th step each box's count against MuJoCo's own
    sim = MujocoSimulator(SimOptions(duration=0.8))
    pairs: list[tuple[int, float]] = []
    weights: list[CapWeights] = []

    def observe(stepper: Stepper) -> None:
        if not weights:
            weights.append(CapWeights(stepper.model, stepper.shell))
        if round(stepper.data.time / stepper.model.opt.timestep) % 20:
            return
        model, data = stepper.model, stepper.data
        for g, count in _mujoco_counts(model, data).items():
            static_box = (
                model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX and model.geom_bodyid[g] == 0
            )
            if static_box and count < MAX_CONTACTS_PER_PAIR:
                pairs.append((count, weights[0].touching(model, data, g)))

    with observed_steps(observe):
        sim.run({}, TestCase("E3", "KPBW", 1))
    counted = np.array(pairs)
    assert len(counted) >= 20
    # MuJoCo makes one contact per triangle corner within reach of a box's face, and a few more
    # where a box's edge cuts a triangle: most counts agree exactly, all within a few contacts
    assert np.mean(counted[:, 0] == counted[:, 1]) > 0.6
    assert np.sum(counted[:, 1]) == pytest.approx(np.sum(counted[:, 0]), rel=0.05)


def test_one_plate_keeps_50_of_the_faces_contacts_and_the_count_finds_the_rest():
    model, data, stepper = _settled(tile=None)
    plate = model.geom("plate").id
    assert _mujoco_counts(model, data)[plate] == MAX_CONTACTS_PER_PAIR
    # KP/BW's flat face on its 30 mm mesh makes 212 contacts (ShellMesh.face_contacts); pressed
    # down, a few more corners of its edge band come within reach
    assert 200 <= CapWeights(model, stepper.shell).touching(model, data, plate) <= 260


def test_the_kept_contacts_of_a_capped_pair_are_weighted_only_with_the_solver_mapping():
    _, _, stepper = _settled(tile=None, mapping="solver")
    assert stepper.cap is not None
    diagnostics = stepper.diagnostics()
    assert diagnostics["cap_weighted"] > 0
    # the plate's pair about 212 / 50; the content's, which the top sheet touches too, more
    assert 3.5 < diagnostics["cap_largest_weight"] < 8.0
    _, _, plain = _settled(tile=None, mapping="vertex", seconds=0.0)
    assert plain.cap is None and "cap_weighted" not in plain.diagnostics()
    # MuJoCo copies a geom's solref into its contacts; the weights scale the kept ones' copies:
    # the capped plate's, not a tile's below the cap
    for tile, weighted in ((None, True), (0.04, False)):
        model, data, stepper = _settled(tile=tile, mapping="solver")
        mujoco.mj_step1(model, data)
        stepper.cap.apply(model, data)
        n = data.ncon
        geom = np.asarray(data.contact.geom[:n])[:, 0]
        on_plate = np.array([model.geom(int(g)).name.startswith("plate") for g in geom])
        ratio = np.asarray(data.contact.solref[:n])[on_plate] / model.geom_solref[geom[on_plate]]
        # each contact also scaled to its own vertex's inverse mass, about the face's (1)
        if weighted:
            assert np.median(ratio) > 3.5  # about 212 / 50
        else:
            assert 0.7 < np.median(ratio) < 1.4


def test_the_solver_mapping_rescales_only_the_packagings_pairs_by_mujocos_inverse_mass():
    cons = load_consignment("KPBW")
    params = cons.parameter_values()
    plain = build_scene(plate_rig("belt"), cons, params, 1, SceneOptions())
    mapped = build_scene(plate_rig("belt"), cons, params, 1, SceneOptions(contact_mapping="solver"))
    assert plain.xml == mapped.xml  # the scene file is the same; the compiled model differs
    m0, m1 = plain.model(), mapped.model()
    a_v = solver_inverse_mass(m1, mapped.shell)
    # an interpolated shell's contact is heavier than a lone vertex (0.42 on the 30 mm mesh)
    assert 0.3 < a_v / mapped.vertex_inverse_mass < 0.55
    plate, content = m1.geom("plate").id, m1.geom("content").id
    assert set(packaging_geoms(m1)) >= {plate, content}
    ratio = m1.geom_solref[plate] / m0.geom_solref[plate]
    assert ratio == pytest.approx([a_v / mapped.vertex_inverse_mass] * 2, rel=1e-9)
    a_co = 1 / float(m1.body("content").mass[0])
    expected = (a_v + a_co) / (mapped.vertex_inverse_mass + a_co)
    assert m1.geom_solref[content] / m0.geom_solref[content] == pytest.approx([expected] * 2)


@pytest.mark.slow
@pytest.mark.parametrize("spacing", [0.03, 0.015])
def test_the_solver_mapping_realises_the_face_stiffness_on_every_mesh(spacing):
    cons = load_consignment("KPBW")
    k = 100e3  # 100 N/mm, the low end of k_BePa's and k_CoPa's ranges
    params = {"k_BePa": k, "k_CoPa": k}
    solver = indentation_test(
        cons, params, options=SceneOptions(spacing=spacing, contact_mapping="solver"), settle=0.25
    )
    assert solver.plate == pytest.approx(k, rel=0.10)
    assert solver.content == pytest.approx(k, rel=0.10)
    # the vertex mapping's face: MuJoCo keeps 50 of the face's contacts, each stiffer than asked
    vertex = indentation_test(cons, params, options=SceneOptions(spacing=spacing), settle=0.25)
    assert vertex.plate_contacts == MAX_CONTACTS_PER_PAIR < vertex.n_face
    assert vertex.plate < 0.8 * k


def test_a_full_shell_is_not_capped_so_its_pairs_are_never_weighted():
    cons = load_consignment("KPBW")
    options = SceneOptions(shell_dof="full", contact_mapping="solver")
    scene = build_scene(plate_rig("belt"), cons, cons.parameter_values(), 1, options)
    assert CapWeights(scene.model(), scene.shell).capped is False


def test_the_solver_mapping_refuses_a_quadratic_shell():
    cons = load_consignment("KPBW")
    options = SceneOptions(shell_dof="quadratic", contact_mapping="solver")
    scene = build_scene(plate_rig("belt"), cons, cons.parameter_values(), 1, options)
    with pytest.raises(ParcelfitError, match="shell_dof=trilinear or full"):
        scene.model()


def test_the_solver_mapping_needs_the_penalty_law_and_one_content_box():
    with pytest.raises(ParcelfitError, match="maps the penalty law's stiffness"):
        SceneOptions(contact_mapping="solver", contact_law="impedance")
    with pytest.raises(ParcelfitError, match="already weights for"):
        SceneOptions(contact_mapping="solver", content_tiles=4)
    with pytest.raises(ParcelfitError, match="unknown contact_mapping"):
        SceneOptions(contact_mapping="area")
