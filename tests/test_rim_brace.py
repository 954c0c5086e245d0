"""Braces across an interpolated shell's rim cells (sim/mujoco/rim_brace.py)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco import load_consignment
from parcelfit.sim.mujoco.indentation import plate_rig
from parcelfit.sim.mujoco.options import SceneOptions
from parcelfit.sim.mujoco.rim_brace import RimBrace, rim_braces
from parcelfit.sim.mujoco.scene import build_scene

OUTER = (0.275, 0.20)
CONTENT = (0.165, 0.125, 0.02)


def _grid(cells: tuple[int, int], half_height: float = 0.0115) -> np.ndarray:
    xs = np.linspace(-OUTER[0] / 2, OUTER[0] / 2, cells[0] + 1)
    ys = np.linspace(-OUTER[1] / 2, OUTER[1] / 2, cells[1] + 1)
    zs = (0.0, 2 * half_height)
    return np.array([(x, y, z) for x in xs for y in ys for z in zs])


def _brace(scale: float = 1.0) -> RimBrace:
    return RimBrace(scale, 5e5, CONTENT, OUTER, 1e-4)


def test_braces_give_each_rim_the_wedges_stiffness_against_a_lift_of_its_end() -> None:
    """Summed over a rim's node lines, the crossed pairs resist a lift delta of the rim's outer
    end as the wedge of the packaging's sheets does: 2 E t W h^2 / l^3, times the scale."""
    node0 = _grid((5, 5))
    braces = rim_braces(node0, _brace(0.5))
    # KP/BW over 5 x 5 x 1 cells: one rim cell at each end of the length (boundaries on the
    # content's ends), one at each side (2.5 mm of 40 over the content): 6 node lines each
    assert len(braces) == 2 * 2 * 6 * 2
    h, h_b = CONTENT[2] / 2, 0.0115
    for axis, across in ((0, OUTER[1]), (1, OUTER[0])):
        a = (OUTER[axis] - CONTENT[axis]) / 2
        c = OUTER[axis] / 5
        d = math.hypot(c, 2 * h_b)
        mine = [
            b
            for b in braces
            if abs(node0[b.nodes[0]][axis] - node0[b.nodes[1]][axis]) > 1e-9
            and node0[b.nodes[0]][axis] > 0
        ]
        assert len(mine) == 12
        for b in mine:  # a brace runs from one face of the box to the other across one cell
            p, q = node0[b.nodes[0]], node0[b.nodes[1]]
            assert abs(abs(p[axis] - q[axis]) - c) < 1e-9
            assert abs(abs(p[2] - q[2]) - 2 * h_b) < 1e-9
            assert abs(np.linalg.norm(p - q) - d) < 1e-9
        k_lift = sum(8 * b.stiffness * h_b**2 / d**2 for b in mine) / 2  # per pair: 8 k h_b^2/d^2
        wedge = 2 * 5e5 * across * h**2 / math.hypot(a, h) ** 3 * (a / c)
        assert k_lift == pytest.approx(0.5 * wedge, rel=1e-12)


def test_no_braces_at_scale_zero_and_a_clear_error_without_rim_cells() -> None:
    assert rim_braces(_grid((5, 5)), _brace(0.0)) == []
    # 4 x 4 x 1 cells: every outer cell reaches 14 mm (x) or 12.5 mm (y) over the content
    assert rim_braces(_grid((4, 4)), _brace()) == []
    cons = load_consignment("KPBW")
    params = cons.parameter_values()
    scene = build_scene(
        plate_rig("metal"), cons, params, 1, SceneOptions(shell_cells=(4, 4, 1), rim_brace=0.1)
    )
    with pytest.raises(ParcelfitError, match="beyond the content"):
        scene.model()
    with pytest.raises(ParcelfitError, match="rim_brace"):
        SceneOptions(rim_brace=-1.0)


def test_a_braced_rim_follows_the_packagings_modulus() -> None:
    """The rim of KP/BW lifted at its seam on a still plate (scripts/rim_probe.py, shortened):
    braced, its compliance falls with E_Pa nearly as a plate's (ratio 8 over 200 -> 1600
    N/mm^2); unbraced, the same cells' rim shears freely, many times as soft."""
    cons = load_consignment("KPBW")

    def compliance(e_pa: float, brace: float) -> float:
        params = cons.parameter_values(si_values={"E_Pa": e_pa})
        scene = build_scene(
            plate_rig("metal"),
            cons,
            params,
            1,
            SceneOptions(shell_cells=(5, 5, 1), rim_brace=brace),
        )
        model = scene.model()
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
        adr, n = int(model.flex_nodeadr[flex]), int(model.flex_nodenum[flex])
        bodies = model.flex_nodebodyid[adr : adr + n]
        x = model.flex_node0[adr : adr + n, 0]
        end = bodies[x > x.max() - 1e-6]
        # each load held 0.15 s: settled (held 0.3 s, both ratios the same to 1 %)
        steps = round(0.15 / model.opt.timestep)

        def lift(force: float) -> float:
            data.xfrc_applied[end, 2] = force / len(end)
            for _ in range(steps):
                mujoco.mj_step(model, data)
            return float(data.xpos[end, 2].mean())

        lift(0.0)
        z1 = lift(0.05)
        return (lift(0.15) - z1) / 0.1

    braced = compliance(2e8, 0.067) / compliance(1.6e9, 0.067)
    assert 5.0 < braced < 8.5
    assert compliance(2e8, 0.0) > 5 * compliance(2e8, 0.067)


def test_a_consignment_files_brace_applies_with_its_own_shell_only() -> None:
    cons = load_consignment("KPBW")
    braced = type(cons)(**{**cons.__dict__, "shell_cells": (5, 5, 1), "rim_brace": 0.067})
    assert SceneOptions().rim_brace_of(braced) == 0.067
    assert SceneOptions(shell_cells=(5, 5, 1)).rim_brace_of(braced) == 0.067
    assert SceneOptions(shell_cells=(4, 4, 1)).rim_brace_of(braced) == 0.0
    assert SceneOptions(shell_dof="quadratic").rim_brace_of(braced) == 0.0
    assert SceneOptions(shell_dof="full", rim_brace=0.0).rim_brace_of(braced) == 0.0
    assert SceneOptions(rim_brace=0.2).rim_brace_of(cons) == 0.2
    assert SceneOptions().rim_brace_of(cons) == 0.0  # the bundled file names none
