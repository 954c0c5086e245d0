"""The flexes' masses lumped by area / volume (parcelfit.sim.mujoco.lumped_mass)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import MujocoSimulator, SimOptions
from parcelfit.sim.mujoco.lumped_mass import (
    compile_model,
    element_vertex_masses,
    grid_vertex_masses,
    interpolation_weights,
    lumped_masses,
    mass_bodies,
)
from parcelfit.sim.mujoco.options import SceneOptions

from .helpers import load_file_module


def _script():
    """scripts/mass_lumping.py, whose moment of inertia the tests share."""
    return load_file_module("scripts/mass_lumping.py")


def _scene(consignment: str, **options: object):
    sim = MujocoSimulator(SimOptions(scene=SceneOptions(**options)))  # type: ignore[arg-type]
    return sim.scene({}, TestCase("E3", consignment, 1))


def _packaging(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Masses [kg] and rest positions [m] of the bodies that carry the packaging's mass."""
    bodies = mass_bodies(model, mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging"))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model.body_mass[bodies].copy(), data.xpos[bodies].copy()


def _yaw_inertia(model: mujoco.MjModel) -> float:
    """The packaging's moment of inertia [kg m^2] about the vertical through its centre of mass."""
    flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    return _script().yaw_inertia(model, mass_bodies(model, flex))


def test_triangles_share_their_area_among_their_corners() -> None:
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    m = element_vertex_masses(square, np.array([[0, 1, 2], [0, 2, 3]]), total=0.6)
    # corners 0 and 2 belong to both triangles, 1 and 3 to one
    assert m == pytest.approx([0.2, 0.1, 0.2, 0.1])


def test_a_tetrahedron_shares_its_mass_equally() -> None:
    tet = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0], [0, 0, 3]], dtype=float)
    assert element_vertex_masses(tet, np.array([[0, 1, 2, 3]]), 1.0) == pytest.approx([0.25] * 4)


def test_bad_elements_are_refused() -> None:
    with pytest.raises(ValueError, match="k x 3 or k x 4"):
        element_vertex_masses(np.zeros((3, 3)), np.array([[0, 1]]), 1.0)
    with pytest.raises(ValueError, match="no area"):
        element_vertex_masses(np.zeros((3, 3)), np.array([[0, 1, 2]]), 1.0)


def test_a_turned_grid_lumps_its_cells() -> None:
    # 3 x 2 x 2 vertices, cells 1 x 2 x 0.5 m, turned by 30 degrees about the vertical
    xs, ys, zs = np.meshgrid([0.0, 1.0, 2.0], [0.0, 2.0], [0.0, 0.5], indexing="ij")
    pts = np.stack([xs.ravel(), ys.ravel(), zs.ravel()], axis=1)
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    pts = pts @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
    m = grid_vertex_masses(pts, total=8.0)
    assert m is not None
    # the middle column's vertices stand for two half cells, the ends' for one
    expected = np.where(np.isclose(xs.ravel(), 1.0), 2.0, 1.0)
    assert m == pytest.approx(expected * 8.0 / expected.sum())
    assert grid_vertex_masses(pts[:-1], total=1.0) is None  # a vertex missing: not a grid


def test_the_full_shell_weights_its_vertices_by_area() -> None:
    scene = _scene("BW", shell_dof="full")
    equal, area = compile_model(scene.xml, "equal"), scene.model()
    m_eq, _ = _packaging(equal)
    m_area, _ = _packaging(area)
    assert np.ptp(m_eq) == 0  # MuJoCo's own: all alike
    assert m_area.sum() == pytest.approx(m_eq.sum(), rel=1e-12)
    # the mesh's triangles, at rest, shared among their corners (exactly what was set)
    tri = scene.shell.triangles
    expected = element_vertex_masses(scene.shell.points, tri, float(m_eq.sum()))
    assert m_area == pytest.approx(expected, rel=1e-6)
    # the seam's vertices border narrow rim cells: lighter than the equal share
    assert m_area[scene.shell.seam].max() < m_eq[0]


def test_interpolated_nodes_carry_the_vertices_they_move() -> None:
    scene = _scene("BW")  # the type's own shell: trilinear over 4 x 4 x 1 cells
    model = mujoco.MjModel.from_xml_string(scene.xml)
    f = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    w = interpolation_weights(model, f)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    nodes = model.flex_nodebodyid[
        model.flex_nodeadr[f] : model.flex_nodeadr[f] + model.flex_nodenum[f]
    ]
    verts = data.flexvert_xpos[
        model.flex_vertadr[f] : model.flex_vertadr[f] + model.flex_vertnum[f]
    ]
    assert w.sum(axis=1) == pytest.approx(1.0, abs=1e-9)
    assert w @ data.xpos[nodes] == pytest.approx(verts, abs=1e-9)
    (flex,) = [x for x in lumped_masses(model) if x.flex == "packaging"]
    assert flex.lumped
    m_nodes = np.array(list(flex.masses.values()))
    m_verts = element_vertex_masses(verts, scene.shell.triangles, float(m_nodes.sum()))
    # the same total mass and centre of mass as the film's vertices
    assert m_nodes.sum() == pytest.approx(m_verts.sum(), rel=1e-12)
    assert m_nodes @ data.xpos[nodes] / m_nodes.sum() == pytest.approx(
        m_verts @ verts / m_verts.sum(), abs=1e-9
    )


def test_area_lumping_brings_both_shells_inertia_together() -> None:
    full_eq = _yaw_inertia(compile_model(_scene("BW", shell_dof="full").xml, "equal"))
    full = _yaw_inertia(_scene("BW", shell_dof="full").model())
    tri_eq = _yaw_inertia(compile_model(_scene("BW").xml, "equal"))
    tri = _yaw_inertia(_scene("BW").model())
    # measured 2026-11-28: full 133 -> 115, trilinear 157 -> 125 (1e-6 kg m^2)
    assert tri_eq > 1.2 * tri and full_eq > 1.1 * full
    assert tri == pytest.approx(full, rel=0.12)


def test_the_soft_content_is_lumped_as_a_grid() -> None:
    model = _scene("PB").model()
    f = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "content")
    a, n = model.flex_vertadr[f], model.flex_vertnum[f]
    masses = model.body_mass[model.flex_vertbodyid[a : a + n]]
    # corners stand for one cell corner, interior vertices of a face for four
    assert masses.max() / masses.min() == pytest.approx(4.0)
    assert masses.sum() == pytest.approx(0.17)


def test_the_quadratic_shell_keeps_mujocos_own_masses() -> None:
    scene = _scene("KP", shell_dof="quadratic")
    model = mujoco.MjModel.from_xml_string(scene.xml)
    (flex,) = [x for x in lumped_masses(model) if x.flex == "packaging"]
    assert not flex.lumped
    assert scene.model().body_mass == pytest.approx(model.body_mass)


def test_an_unknown_lumping_is_refused() -> None:
    with pytest.raises(ParcelfitError, match="mass_lumping"):
        SceneOptions(mass_lumping="volume")
    with pytest.raises(ValueError, match="unknown mass lumping"):
        compile_model("<mujoco/>", "volume")


def test_the_lumping_from_a_study_file_and_the_simulate_command(tmp_path) -> None:
    """``mass_lumping`` in a study's simulator section and `parcelfit simulate --mass-lumping`
    reach the scene; leaving it out keeps lumped masses."""
    from typer.testing import CliRunner

    from parcelfit.cli import app
    from parcelfit.sim.factory import SimulatorSection, make_simulator

    def sim(**given: str):
        section = SimulatorSection(backend="mujoco", rig="E3", consignment="BW", **given)
        return make_simulator(section.to_config(tmp_path))

    case = TestCase("E3", "BW", 1)
    lumped = sim().scene({}, case).model()  # type: ignore[attr-defined]
    equal = sim(mass_lumping="equal").scene({}, case).model()  # type: ignore[attr-defined]
    assert np.ptp(_packaging(equal)[0]) == 0 and np.ptp(_packaging(lumped)[0]) > 0
    out = tmp_path / "run.csv"
    runner = CliRunner()
    args = ["simulate", "--rig", "E3", "--consignment", "BW", "--out", str(out)]
    bad = runner.invoke(app, [*args, "--mass-lumping", "volume"])
    assert bad.exit_code != 0 and "mass_lumping" in bad.output
