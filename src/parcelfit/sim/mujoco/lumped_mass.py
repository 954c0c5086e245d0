"""Where a flex's mass sits: lumped by area (shell) or volume (soft content), not spread equally.

MuJoCo's ``flexcomp`` gives each body it makes (a vertex of a full shell or of a soft content,
a node of an interpolated shell) the same share of the ``mass`` attribute. On the shell's
graded mesh (narrow rim bands, a wide band over the content), on the interpolated shell's node
grid and on a soft content's grid that puts too much mass far from the parcel's centre: the
packaging's moment of inertia about the vertical came out up to 30 % above its lumped value (BW
16 % with the full shell, 25 % with the trilinear shell over 4 x 4 x 1 cells, whose 5 x 5 x 2
nodes all weighed the same; KP/BW's trilinear 30 %), and the polybag's soft content's 49 %
above a uniform box's (13 % lumped). `python scripts/mass_lumping.py` prints the table
(docs/research/mass-lumping.md).

Lumped masses
-------------
Each element hands its share of the flex's total mass M to its corners, in proportion to its
measure at rest (a triangle's area A_e over 3 corners, a tetrahedron's volume V_e over 4):

    m_v = M * sum_{e ∋ v} (A_e / 3) / sum_e A_e          (dim 2; V_e / 4 for dim 3)

This is the row-sum lumped mass of linear elements: it keeps the total mass and the centre of
mass of a uniform sheet (or solid) and its second moments to within the mesh's resolution. A
soft content is a regular grid of box cells, which MuJoCo splits into tetrahedra in one
direction only; lumping those would weight the grid's corners unequally (1 : 2 between
diagonally opposite ones), so a grid lumps its box cells instead, a cell's volume over its 8
corners: m_v proportional to the product over the three axes of half the widths of the cells
on either side.

An interpolated flex moves its vertices as x_v = sum_n W_vn x_n from its nodes n. Its nodes get
the row-sum lumping of the vertices' masses through those weights,

    m_n = sum_v W_vn m_v,

which keeps the total mass (sum_n W_vn = 1) and the centre of mass (the weights reproduce
linear fields) of the vertices' masses. W is read from MuJoCo itself: each node is moved along
its three slide joints and the vertices' response measured (the interpolation is linear in the
node positions, so a finite difference is exact to rounding). Where a node's lumped mass comes
out below a tenth of the equal share (possible with quadratic weights) the flex keeps MuJoCo's
equal shares and `lumped_masses` reports it; so does a flex with a node fixed to its frame
(MuJoCo's quadratic shell, whose 3 x 3 x 3 nodes MuJoCo itself weights 1 : 4 : 16 by the box's
volume).

The masses are set on the scene's model specification (`mujoco.MjSpec`) and the model compiled
again, so that every constant MuJoCo derives from masses (the constraints' inverse weights, the
bodies' subtree masses) follows.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from parcelfit.sim.params import MASS_LUMPINGS

# below this fraction of the equal share a node's lumped mass is taken as a sign that the
# interpolation's weights are not a partition into positive shares (quadratic fields)
MIN_SHARE = 0.1
_PROBE = 1e-3  # the node displacement of the finite difference [m]


@dataclass(frozen=True)
class FlexMasses:
    """The lumped masses [kg] of one flex's bodies, by body name, and whether they replaced
    MuJoCo's equal shares (False: the interpolation's weights gave a node too little)."""

    flex: str
    masses: dict[str, float]
    lumped: bool


def element_vertex_masses(points: np.ndarray, elements: np.ndarray, total: float) -> np.ndarray:
    """Masses [kg] of the vertices ``points`` (n x 3, m) of a mesh of ``elements`` (triangles
    or tetrahedra, k x 3 or k x 4 vertex indices) of uniform density and total mass ``total``
    [kg]: each element's area or volume shared equally among its corners."""
    points = np.asarray(points, dtype=float)
    elements = np.asarray(elements, dtype=int)
    if elements.ndim != 2 or elements.shape[1] not in (3, 4) or len(elements) == 0:
        raise ValueError(f"elements must be k x 3 or k x 4 indices, got shape {elements.shape}")
    a, b, c = (points[elements[:, i]] for i in range(3))
    if elements.shape[1] == 3:
        measure = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    else:
        d = points[elements[:, 3]]
        measure = np.abs(np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)) / 6
    if not measure.sum() > 0:
        raise ValueError("the elements have no area or volume")
    m = np.zeros(len(points))
    np.add.at(m, elements.ravel(), np.repeat(measure / elements.shape[1], elements.shape[1]))
    return m * (total / m.sum())


def grid_vertex_masses(points: np.ndarray, total: float) -> np.ndarray | None:
    """Masses [kg] of the vertices ``points`` (n x 3, m) of a regular grid of box cells (a soft
    content, MuJoCo's ``flexcomp type="grid"``) of total mass ``total`` [kg]: each vertex gets
    the product over the grid's three axes of half its neighbouring cells' widths (a cell's
    volume over its 8 corners). None if the points are not such a grid (in any orientation)."""
    points = np.asarray(points, dtype=float)
    centred = points - points.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    local = centred @ axes.T
    share = np.ones(len(points))
    cells = 1
    for d in range(3):
        # group the coordinates by level (to a micrometre), then take each level's mean
        keys, index = np.unique(np.round(local[:, d], 6), return_inverse=True)
        if len(keys) < 2:
            return None
        levels = np.bincount(index, weights=local[:, d]) / np.bincount(index)
        edges = np.diff(levels)
        width = np.zeros(len(levels))
        width[:-1] += edges / 2
        width[1:] += edges / 2
        share *= width[index]
        cells *= len(levels)
    if cells != len(points):
        return None
    return share * (total / share.sum())


def interpolation_weights(model: mujoco.MjModel, flex: int) -> np.ndarray:
    """The weights W (vertices x nodes) with which interpolated flex ``flex`` places its
    vertices from its nodes, x_v = sum_n W_vn x_n, measured on ``model`` at its rest pose."""
    data = mujoco.MjData(model)
    mujoco.mj_fwdPosition(model, data)
    vadr, vnum = model.flex_vertadr[flex], model.flex_vertnum[flex]
    nadr, nnum = model.flex_nodeadr[flex], model.flex_nodenum[flex]
    base = data.flexvert_xpos[vadr : vadr + vnum].copy()
    weights = np.zeros((vnum, nnum))
    for n in range(nnum):
        body = model.flex_nodebodyid[nadr + n]
        jnt = model.body_jntadr[body]
        if model.body_jntnum[body] < 1 or model.jnt_type[jnt] != mujoco.mjtJoint.mjJNT_SLIDE:
            raise ValueError(f"node body {model.body(body).name} has no slide joint to probe")
        q = model.jnt_qposadr[jnt]
        axis = data.xaxis[jnt].copy()  # the joint's direction in the world
        data.qpos[q] += _PROBE
        mujoco.mj_fwdPosition(model, data)
        moved = data.flexvert_xpos[vadr : vadr + vnum] - base
        weights[:, n] = moved @ axis / _PROBE
        data.qpos[q] -= _PROBE
    mujoco.mj_fwdPosition(model, data)
    return weights


def is_interpolated(model: mujoco.MjModel, flex: int) -> bool:
    """Whether flex ``flex`` moves its vertices from nodes (no vertex bodies of its own)."""
    return bool(
        model.flex_nodenum[flex] > 0 and model.flex_vertbodyid[model.flex_vertadr[flex]] < 0
    )


def flex_elements(model: mujoco.MjModel, flex: int) -> np.ndarray:
    """The elements of flex ``flex`` (k x (dim + 1) vertex indices within the flex)."""
    dim, num = int(model.flex_dim[flex]), int(model.flex_elemnum[flex])
    adr = int(model.flex_elemdataadr[flex])
    return np.asarray(model.flex_elem[adr : adr + num * (dim + 1)]).reshape(num, dim + 1)


def mass_bodies(model: mujoco.MjModel, flex: int) -> np.ndarray:
    """The bodies that carry flex ``flex``'s mass: its nodes if it is interpolated (its
    vertices then have no bodies of their own), else its vertices' bodies."""
    if is_interpolated(model, flex):
        nadr = model.flex_nodeadr[flex]
        return model.flex_nodebodyid[nadr : nadr + model.flex_nodenum[flex]]
    vadr = model.flex_vertadr[flex]
    return model.flex_vertbodyid[vadr : vadr + model.flex_vertnum[flex]]


def lumped_masses(model: mujoco.MjModel) -> list[FlexMasses]:
    """The lumped masses (module docstring) of every flex of ``model`` whose bodies carry its
    mass, computed from the model's rest pose and its flexes' total masses."""
    data = mujoco.MjData(model)
    mujoco.mj_fwdPosition(model, data)
    out = []
    for f in range(model.nflex):
        dim = int(model.flex_dim[f])
        if dim < 2:
            continue
        vadr, vnum = model.flex_vertadr[f], model.flex_vertnum[f]
        elements = flex_elements(model, f)
        points = data.flexvert_xpos[vadr : vadr + vnum]
        interpolated = is_interpolated(model, f)
        bodies = mass_bodies(model, f)
        total = float(model.body_mass[bodies].sum())
        grid = grid_vertex_masses(points, total) if dim == 3 else None
        m_v = grid if grid is not None else element_vertex_masses(points, elements, total)
        masses, lumped = m_v, True
        if interpolated:
            try:
                masses = interpolation_weights(model, f).T @ m_v
            except ValueError:  # a node fixed to its frame (MuJoCo's quadratic shell)
                lumped = False
        lumped = lumped and bool(np.all(masses >= MIN_SHARE * total / len(bodies)))
        names = [model.body(int(b)).name for b in bodies]
        values = masses if lumped else model.body_mass[bodies]
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_FLEX, f) or str(f)
        out.append(FlexMasses(name, dict(zip(names, map(float, values), strict=True)), lumped))
    return out


def compile_model(
    xml: str,
    lumping: str = "area",
    edit: Callable[[mujoco.MjSpec, mujoco.MjModel], object] | None = None,
) -> mujoco.MjModel:
    """The MuJoCo model of scene ``xml``, its flexes' masses lumped as ``lumping`` says:
    "area" (module docstring) or "equal" (MuJoCo's own equal shares); ``edit(spec, model)``, if
    given, changes the specification before it is compiled again (``model``: as first compiled)."""
    if lumping not in MASS_LUMPINGS:
        raise ValueError(f"unknown mass lumping {lumping!r}: use one of {list(MASS_LUMPINGS)}")
    model = mujoco.MjModel.from_xml_string(xml)
    flexes = [] if lumping == "equal" or model.nflex == 0 else lumped_masses(model)
    flexes = [flex for flex in flexes if flex.lumped]
    if not flexes and edit is None:
        return model
    spec = mujoco.MjSpec.from_string(xml)
    if edit is not None:
        edit(spec, model)
    for flex in flexes:
        for name, mass in flex.masses.items():
            body = spec.body(name)
            # a vertex or node body's inertia is a tiny sphere's: keep its radius
            body.inertia = body.inertia * (mass / body.mass)
            body.mass = mass
    return spec.compile()
