"""Braces across the rim cells of an interpolated packaging shell.

Why by hand: MuJoCo computes an interpolated shell's elasticity (``flexcomp`` with
``dof="trilinear"`` or ``"quadratic"`` and ``dim="2"``) on the boundary faces of its node box,
not on the packaging's own triangles (``mj_flexPassiveInterp`` in engine_passive.c: "2D boundary
quads (shell)"). Beyond the content that box's section across a rim is a rectangle, its top and
bottom faces and the outer end wall, open towards the content. A rectangle is a mechanism:
lifting the rim's end shears it, resisted only by the faces' bending at the cells' boundaries
and by the content's contact. The packaging's rim is a wedge instead: its top and bottom
sheets run from the content's edges to the seam and, with the content's end, form a triangle,
whose stiffness against a lift of the seam is the sheets' membrane stiffness E t. No option of
MuJoCo's flexes adds it, so each rim cell gets a pair of crossed spatial tendons (MuJoCo's own
springs) at every node line along the rim: together they give the rectangle the wedge's
stiffness against shear (docs/research/rim-stiffness.md measures both).

Formulas (a rim of length a beyond the content, half the content's height h, a strip of width b
along the rim; the node box's half-height h_b; a rim cell of length c, c = a when the cells'
boundaries lie on the content's ends):

* the wedge: a lift delta of the seam changes each sheet's length l = sqrt(a^2 + h^2) by
  -+ h delta / l; with the sheets' axial stiffness E t b / l the energy is
  2 * 1/2 (E t b / l) (h delta / l)^2, so

      K_wedge = 2 E t b h^2 / l^3                         [N/m]

* a brace pair: a diagonal of length d = sqrt(c^2 + (2 h_b)^2) changes by -+ 2 h_b delta / d
  when the cell's outer end rises by delta, so two of stiffness k give
  K_pair = 8 k h_b^2 / d^2; the rim's cells are in series, each taking a / c times the rim's
  stiffness, and

      k = s K_wedge (a / c) d^2 / (8 h_b^2)               [N/m]

  with b the node line's share of the rim's width (half a cell at either end);
* damping: stiffness-proportional, k beta with the shell's own beta (scene.py), so a brace
  damps its strain as the shell damps its own.

s (``SceneOptions.rim_brace``) scales the ideal wedge: at s = 1 its sheets neither bend near
the seam nor slide over the content's edge, and the braced rim of KP/BW is about six times as
stiff as the full shell's (each vertex its own degrees of freedom, at 1/4800 s, the reference);
s = 0 adds no brace. A rim cell is one whose cells lie beyond the content's end, or reach over
it by at most ``OVERLAP`` of their length (KP/BW's width over 5 cells: 2.5 mm of 40).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError

OVERLAP = 0.1  # the share of a rim cell's length that may lie over the content
_ROUND = 6  # decimals [m] to which the nodes' rest coordinates are grouped into grid lines


@dataclass(frozen=True)
class RimBrace:
    """What the braces of a shell follow: ``scale`` s, the packaging's membrane stiffness
    ``membrane`` E t [N/m], the content's box ``content`` (length, width, height) [m], the
    parcel's ``outer`` length and width [m] and the shell's stiffness-proportional damping
    ``beta`` [s]."""

    scale: float
    membrane: float
    content: tuple[float, float, float]
    outer: tuple[float, float]
    beta: float


@dataclass(frozen=True)
class Brace:
    """One spring: the indices of its two nodes in the flex's node list, its stiffness [N/m]."""

    nodes: tuple[int, int]
    stiffness: float


def _share(lines: np.ndarray, j: int) -> float:
    """The width [m] a node line carries: half the cells on either side of it."""
    lo = lines[j] - lines[j - 1] if j > 0 else 0.0
    hi = lines[j + 1] - lines[j] if j < len(lines) - 1 else 0.0
    return (lo + hi) / 2


def rim_braces(node0: np.ndarray, brace: RimBrace) -> list[Brace]:
    """The braces of a shell whose nodes rest at ``node0`` (n, 3) [m], in the parcel's frame
    (length along x, width along y; the module docstring gives the stiffness)."""
    if brace.scale <= 0:
        return []
    grid = [np.unique(np.round(node0[:, k], _ROUND)) for k in range(3)]
    z_lo, z_hi = grid[2][0], grid[2][-1]
    h_b = (z_hi - z_lo) / 2
    h = brace.content[2] / 2
    index = {tuple(np.round(p, _ROUND)): i for i, p in enumerate(node0)}
    braces: list[Brace] = []
    for axis in (0, 1):  # the rims at the length's ends, then at the width's
        along, across = grid[axis], grid[1 - axis]
        half_c, half_o = brace.content[axis] / 2, brace.outer[axis] / 2
        a = half_o - half_c
        if a <= 0:
            continue
        l_sheet = math.hypot(a, h)
        for i in range(len(along) - 1):
            lo, hi = float(along[i]), float(along[i + 1])
            c = hi - lo
            if not (lo >= half_c - OVERLAP * c or hi <= -half_c + OVERLAP * c):
                continue
            d = math.hypot(c, 2 * h_b)
            for j, y in enumerate(across):
                k_wedge = 2 * brace.membrane * _share(across, j) * h**2 / l_sheet**3
                k = brace.scale * k_wedge * (a / c) * d**2 / (8 * h_b**2)
                for z0, z1 in ((z_lo, z_hi), (z_hi, z_lo)):
                    p0 = (lo, y, z0) if axis == 0 else (y, lo, z0)
                    p1 = (hi, y, z1) if axis == 0 else (y, hi, z1)
                    ends = (index[tuple(np.round(p0, _ROUND))], index[tuple(np.round(p1, _ROUND))])
                    braces.append(Brace(ends, k))
    return braces


def add_rim_braces(spec: mujoco.MjSpec, model: mujoco.MjModel, brace: RimBrace) -> int:
    """Add the braces of the flex "packaging" of ``model`` (compiled from ``spec``) to ``spec``
    as spatial tendons between its node bodies; returns how many. Raises when the shell is not
    interpolated or no cell lies beyond the content (the cells' boundaries must lie on or near
    the content's ends: ``shell_cells``)."""
    flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
    nodes = int(model.flex_nodenum[flex]) if flex >= 0 else 0
    if nodes == 0:
        raise ParcelfitError(
            "rim_brace needs an interpolated packaging shell",
            fix="use shell_dof trilinear or quadratic, or set rim_brace to 0",
        )
    adr = int(model.flex_nodeadr[flex])
    node0 = model.flex_node0[adr : adr + nodes].reshape(-1, 3)
    braces = rim_braces(node0, brace)
    if not braces:
        raise ParcelfitError(
            "rim_brace: no cell of the shell lies beyond the content's ends",
            fix="choose shell_cells whose boundaries fall on the content's ends "
            "(KP/BW: 5 x 5 x 1), or set rim_brace to 0",
        )
    bodies = [model.body(int(b)).name for b in model.flex_nodebodyid[adr : adr + nodes]]
    sites: dict[int, str] = {}
    for n, b in enumerate(braces):
        for node in b.nodes:
            if node not in sites:
                sites[node] = f"rim_brace_node{node}"
                spec.body(bodies[node]).add_site(name=sites[node], size=[1e-3, 0, 0])
        tendon = spec.add_tendon(
            name=f"rim_brace{n}",
            stiffness=b.stiffness,
            damping=b.stiffness * brace.beta,
            springlength=[-1, -1],  # the rest length: the nodes' distance at rest
        )
        tendon.wrap_site(sites[b.nodes[0]])
        tendon.wrap_site(sites[b.nodes[1]])
    return len(braces)
