"""The rigid-box reference's world and body: static primitives from a `Rig`, the parcel as one
rigid box with area-weighted contact points.

**Primitives** (world frame, SI units; each has a local frame R (columns: local axes in world), a
centre c, a material index (0 belt/roller: the BePa parameters, 1 metal: MePa) and a surface
velocity field v_s(p) = vel + spin x (p - c)):

* ``BOX`` (half extents hx, hy, hz): a belt's or strip's slab under its top face, as in the MuJoCo
  scene (top at ``surface.top``, half-thickness 0.02 m, the flat top shortened by the drum radius
  at each end; vel = speed * heading unit vector), and a wall as a thin vertical box from ``base``
  to ``base + height`` (still): met by the contact points (option ``wall_contact: points``).
* ``WALL`` (half extents as a box's): a wall met by the parcel's outline (the default,
  ``wall_contact: outline``; `parcelfit.sim.rigidbox.contact`), not by its contact points.
* ``CYLINDER`` (radius r, half-length; axis = local z): the drum a belt or strip runs round at each
  end (radius ``nose_radius``, axis across the heading at height top - r, its top level with the
  belt's), turning with the belt: spin = (speed / r) n with n the unit vector across the heading
  (to its left), so spin x (p - c) is the belt speed along the heading on top, upwards round the
  tail and downwards round the head.
* ``CAPSULE`` (radius, half-length of the segment; axis = local z): a roller unit of a flow
  splitter, lying across its heading (heading + swivel) with its top at ``surface.top``; its
  surface moves at the conveying speed along that heading everywhere ("linear", the MuJoCo
  scene's default) or turns like a driven roller ("turning": spin = (speed / radius) across).
* ``LEAD_IN`` (radius, half-height; vertical axis): a wall's rolled lead-in, met by the parcel's
  box outline analytically (`parcelfit.sim.rigidbox.contact`), not by its contact points.

**Parcel**: one rigid body, the consignment's outer box L x W x H with its total mass M. Its
inertia is the content's box (mass M - m_Pa, content size cL x cW x cH) plus the packaging as two
thin sheets L x W of m_Pa / 2 each at z = +-H/2:

    I_xx = m_c (cW^2 + cH^2) / 12 + m_Pa (W^2 / 12 + H^2 / 4)
    I_yy = m_c (cL^2 + cH^2) / 12 + m_Pa (L^2 / 12 + H^2 / 4)
    I_zz = m_c (cL^2 + cW^2) / 12 + m_Pa (L^2 + W^2) / 12

with the centre of mass at the box centre (body frame: x along L, y along W, z up).

**Contact points** (body frame, each with an area weight A_i [m^2]):

* bottom and top faces (z = -+H/2): a node grid of ceil(L / s) x ceil(W / s) cells over the face
  (spacing option s, default 10 mm), nodes on the edges and corners included, trapezoidal weights
  (a node's share of the cells around it: edge nodes half a cell, corners a quarter), so the
  weights of a face sum to its area;
* the four side faces: the same node spacing along the side (corner columns included, half
  weights), and n_z = max(3, ceil(H / s)) rows at the centres of equal height bands
  (z = -H/2 + (j + 1/2) H / n_z, weight H / n_z along the height): the faces' edges are carried by
  the bottom and top grids, so no point is counted twice when the parcel lies flat.
* the **bottom contact patch** (option): ``consignment`` (default): the consignment's bulge patch
  (its ``footprint`` times L x W, centred) where it has one, else ``rim-bending`` (below);
  ``outline``: the bottom grid covers the whole L x W face at one pressure, as if the rim were
  as rigid as the content;
  ``content``: the bottom grid covers only the content's footprint cL x cW (centred): the rim
  beyond it carries no bottom contact (a bubble mailer's flexible rim that lifts off);
  ``rim-weight``: the bottom grid covers L x W, and the weights of the nodes outside the
  content's footprint (the rim) are scaled by s so that, lying flat (every bottom point as deep),
  the rim carries only its own weight and the content's footprint the rest. A thin packaging
  cannot pass the content's weight out to its rim; the rim bears the packaging's mass over its
  area, w = m_Pa (1 - cL cW / (L W)) / M of the total, so

      s = w A_c / ((1 - w) A_r)

  with A_c and A_r the node weights' sums inside and outside the footprint (a node on the
  footprint's edge counts as inside; at least one node must lie inside).
  ``rim-bending``: the rim carries its own weight and what its bending passes on from the
  content. The packaging's sheet beyond the content's edge is a plate (bending stiffness
  D = E_Pa t_Pa^3 / (12 (1 - nu_Pa^2)) per unit width, one sheet) on the belt contact's
  foundation k_f = k_BePa / (L W) [N/m^3] (the contact law's stiffness per unit area: a
  modelling choice, the penalty contact's, not a measured softness of belt and paper), held
  flat by the content, which presses it down, and free at the outline. A plate on an elastic
  foundation whose edge is pressed down bends back up within the bending length

      lambda = (4 D / k_f)^(1/4)

  (Hetenyi's beam on an elastic foundation): its deflection beyond the content, as a share of
  the content's sink, is `strip_profile` g(b), b = d / lambda (d the distance from the
  content's footprint), which solves d^4 g / db^4 + 4 g = 0 with g(0) = 1, g'(0) = 0 and no
  moment or shear at the outline (b = the span to the outline along the same line); over a
  long span g = e^-b (cos b + sin b), whose integral is 1: a strip lambda wide at the
  content's pressure per metre of edge. The pressure is p_c on the footprint and
  q_w + (p_c - q_w) g beyond it (0 where that would pull), with q_w the rim's own weight per
  unit area (q_w A_r = w M g, w as above) and p_c from the balance of the weight. The node
  weights are these pressures averaged over each node's cell (8 x 8 points: lambda is about
  the grid's spacing, so a node's value alone would make the rim's load depend on where the
  content's edge falls between nodes). At E3's defaults (E_Pa 1000 N/mm^2, t_Pa 0.5 mm,
  k_BePa 500 N/mm) lambda is 8.4 mm for KP/BW and its rim carries 26 % of its weight (its own
  8.9 %); over the catalogue's ranges lambda runs from 2.4 to 24 mm and the share from 15 to
  45 % (`scripts/rim_bending.py`). lambda = 0 is ``rim-weight``, node for node (a lambda
  near 0 is not: it shares the footprint's edge cell by cell, ``rim-weight`` node by node, so
  the two differ by a few percentage points of the weight at 10 mm points, less on finer
  grids). The cell means sample a node's cell on the outline at points clipped onto the
  outline's edge, which weights the edge's pressure twice within those half cells (a quadrature
  detail, left as it is: it moves KP/BW's share far less than the grid's spacing does). Its
  limits:
  held flat by the content gives the rim the most (a content resting on the sheet unbonded
  lets the sheet lift off just inside its edge and passes less; not modelled); two bonded
  plies or a bubble lining would bend stiffer; and the weights are the box's contact
  stiffness and friction per point in every state, so a rim pressed at a wall or the parcel
  tilting meets the same per-area springs, not a bending sheet. Other contacts under the
  parcel (a metal plate) keep these weights: the bending length is the belt's.
  Whatever the patch, its weights are then scaled to sum to the outline's area L W, the area
  A_b by which the contact law divides the catalogue's stiffness and damping
  (`parcelfit.sim.rigidbox.contact`): lying flat on its patch the parcel has the stiffness K,
  and its sides, top and the walls it meets the same stiffness per unit area K / (L W) on every
  patch. (Until 2026-12-06 A_b was the patch's own area, so a patch smaller than the outline
  also stiffened the sides, walls and lead-ins, by L W / A_b: 4 times for BW's bulge patch.)
  The top face always covers L x W.
* the **outline the walls meet** (option ``wall_outline``; walls met by the outline and
  lead-ins only): ``outline`` (default), the packaging's L x W, as if the rim beyond the content
  were as stiff at a wall as the content; ``content``: the content's cL x cW, a rim that gives
  way entirely at a wall, so the wall meets the content through it; with ``wall_inset`` d
  [m], the packaging's outline inset by d on every side (no nearer the centre than the
  content's): a rim that has given way by d. The side points, which meet belts, drums and slabs,
  stay on the outline. (How hard E3's plate presses a rim as stiff as
  the content, against the load its rim buckles under, `rim_buckling_load`:
  `scripts/plate_force.py`.)

The points are grouped into tiles (3 x 3 bottom or top nodes, 3 columns of a side) with a
bounding sphere each, so that the contact search skips tiles far from a primitive.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.consignment import Consignment
from parcelfit.sim.mujoco.rig import Rig
from parcelfit.sim.params import BOTTOM_PATCHES, WALL_CONTACTS, WALL_OUTLINES

BOX, CYLINDER, CAPSULE, LEAD_IN, WALL = 0, 1, 2, 3, 4
KIND_NAMES = {
    BOX: "box",
    CYLINDER: "cylinder",
    CAPSULE: "capsule",
    LEAD_IN: "lead-in",
    WALL: "wall",
}
BELT, METAL = 0, 1  # material indices: the BePa and MePa parameter sets
SLAB = 0.02  # half-thickness of belt and strip slabs [m], as the MuJoCo scene's
BOTTOM, TOP, SIDE = 0, 1, 2  # point groups
ROLLER_SURFACES = ("linear", "turning")
TILE = 3  # nodes per tile edge
SUB = 8  # sub-points per axis of a node's cell where the rim's bending profile is averaged
MIN_SIDE_ROWS = 3


def _material(name: str) -> int:
    return METAL if name == "metal" else BELT  # belt and roller: the belt/packaging parameters


def rot_z(deg: float) -> np.ndarray:
    """Rotation about world z by ``deg`` degrees."""
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_across(deg: float) -> np.ndarray:
    """Rz(deg) Rx(90 deg): local z lies horizontal, across the heading ``deg`` (a drum's or a
    roller's axis)."""
    rx = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    return rot_z(deg) @ rx


@dataclass(frozen=True)
class Primitives:
    """Static primitives as arrays (see the module docstring): kind (n,), centre (n, 3), rot
    (n, 3, 3) local axes as columns, size (n, 3) (box half extents; cylinder, capsule and lead-in:
    radius, half-length, 0), material (n,), vel (n, 3) and spin (n, 3) of the surface, reach
    (n, 3): local half extents of a box around the primitive (the search's bounds), names."""

    kind: np.ndarray
    centre: np.ndarray
    rot: np.ndarray
    size: np.ndarray
    material: np.ndarray
    vel: np.ndarray
    spin: np.ndarray
    reach: np.ndarray
    names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.names)

    @staticmethod
    def of(items: list[dict]) -> Primitives:
        """Primitives from a list of dicts with the fields (see `primitive`)."""
        if not items:
            raise ParcelfitError("a rigid-box world needs at least one primitive")
        return Primitives(
            kind=np.array([it["kind"] for it in items], dtype=np.int64),
            centre=np.array([it["centre"] for it in items], dtype=float).reshape(-1, 3),
            rot=np.array([it["rot"] for it in items], dtype=float).reshape(-1, 3, 3),
            size=np.array([it["size"] for it in items], dtype=float).reshape(-1, 3),
            material=np.array([it["material"] for it in items], dtype=np.int64),
            vel=np.array([it["vel"] for it in items], dtype=float).reshape(-1, 3),
            spin=np.array([it["spin"] for it in items], dtype=float).reshape(-1, 3),
            reach=np.array([it["reach"] for it in items], dtype=float).reshape(-1, 3),
            names=tuple(it["name"] for it in items),
        )

    def subset(self, kinds: tuple[int, ...]) -> Primitives:
        """The primitives of the given ``kinds`` (e.g. (WALL, LEAD_IN)), in their order."""
        keep = np.flatnonzero(np.isin(self.kind, kinds))
        if keep.size == 0:
            raise ParcelfitError(
                f"no primitive of kind {', '.join(KIND_NAMES.get(k, str(k)) for k in kinds)}"
            )
        return Primitives(
            kind=self.kind[keep],
            centre=self.centre[keep],
            rot=self.rot[keep],
            size=self.size[keep],
            material=self.material[keep],
            vel=self.vel[keep],
            spin=self.spin[keep],
            reach=self.reach[keep],
            names=tuple(self.names[i] for i in keep),
        )

    def velocity_at(self, j: int, point: np.ndarray) -> np.ndarray:
        """The material velocity [m/s] of primitive ``j`` at world ``point`` [m]."""
        return self.vel[j] + np.cross(self.spin[j], np.asarray(point) - self.centre[j])


def primitive(
    name: str,
    kind: int,
    centre: np.ndarray | tuple[float, float, float],
    rot: np.ndarray,
    size: tuple[float, float, float],
    material: int,
    vel: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
    spin: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
) -> dict:
    """One primitive's fields (for `Primitives.of`); its search bounds follow from the kind."""
    a, b, c = size
    if kind in (BOX, WALL):
        reach = (a, b, c)
    elif kind in (CYLINDER, LEAD_IN):
        reach = (a, a, b)
    elif kind == CAPSULE:
        reach = (a, a, b + a)
    else:
        raise ParcelfitError(f"unknown primitive kind {kind}")
    return {
        "name": name,
        "kind": kind,
        "centre": np.asarray(centre, dtype=float),
        "rot": np.asarray(rot, dtype=float),
        "size": (float(a), float(b), float(c)),
        "material": int(material),
        "vel": np.asarray(vel, dtype=float),
        "spin": np.asarray(spin, dtype=float),
        "reach": reach,
    }


def _turning(speed: float, radius: float, across: np.ndarray) -> np.ndarray:
    """The spin [rad/s] of a drum or roller whose surface moves at ``speed`` on top: (speed /
    radius) across (across: the unit vector to the left of the heading)."""
    return (speed / radius) * np.array([across[0], across[1], 0.0])


def rig_primitives(
    rig: Rig,
    setting: int,
    speed_factors: Mapping[str, float] | None = None,
    roller_surface: str = "linear",
    wall_contact: str = "outline",
) -> Primitives:
    """The static primitives of ``rig`` at speed ``setting`` (drive speeds times
    ``speed_factors``, as the MuJoCo scene's option): see the module docstring. ``wall_contact``:
    a wall met by the parcel's outline (``outline``, `WALL`) or by its contact points
    (``points``, a `BOX`)."""
    if roller_surface not in ROLLER_SURFACES:
        raise ParcelfitError(
            f"unknown roller_surface {roller_surface!r}", fix=f"use one of {list(ROLLER_SURFACES)}"
        )
    if wall_contact not in WALL_CONTACTS:
        raise ParcelfitError(
            f"unknown wall_contact {wall_contact!r}", fix=f"use one of {list(WALL_CONTACTS)}"
        )
    speeds = rig.drive_speeds(setting)
    factors = speed_factors or {}
    items: list[dict] = []
    for s in rig.surfaces:
        speed = speeds[s.drive] * factors.get(s.drive, 1.0)
        u = s.unit()
        n = np.array([-u[1], u[0]])
        mat = _material(s.material)
        r = s.nose_radius
        vel = (speed * u[0], speed * u[1], 0.0)
        # the belt, or each strip (with its own length where the strips end on a line)
        for name, c, length, width in s.parts():
            items.append(
                primitive(
                    name,
                    BOX,
                    (c[0], c[1], s.top - SLAB),
                    rot_z(s.heading),
                    (length / 2 - r, width / 2, SLAB),
                    mat,
                    vel=vel,
                )
            )
            if r <= 0:
                continue
            for end, sign in (("tail", -1), ("head", 1)):
                p = c + sign * (length / 2 - r) * u
                items.append(
                    primitive(
                        f"{name}_{end}",
                        CYLINDER,
                        (p[0], p[1], s.top - r),
                        rot_across(s.heading),
                        (r, width / 2, 0.0),
                        mat,
                        spin=_turning(speed, r, n),
                    )
                )
        if s.type == "rollers":
            rows, cols = int(s.extra["rows"]), int(s.extra["columns"])
            radius, half = s.extra["radius"], s.extra["roller_width"] / 2
            heading = s.heading + s.extra["swivel"]
            a = math.radians(heading)
            along = np.array([math.cos(a), math.sin(a)])
            across = np.array([-math.sin(a), math.cos(a)])
            for i in range(rows):
                for j in range(cols):
                    c = (
                        np.array(s.centre)
                        + (j - (cols - 1) / 2) * (s.length / cols) * u
                        + (i - (rows - 1) / 2) * (s.width / rows) * n
                    )
                    # as the MuJoCo scene's capsule of size (radius, half): a segment of
                    # half-length ``half`` with hemispherical caps of ``radius``
                    kw: dict = {"vel": (speed * along[0], speed * along[1], 0.0)}
                    if roller_surface == "turning":
                        kw = {"spin": _turning(speed, radius, across)}
                    items.append(
                        primitive(
                            f"{s.name}_{i}_{j}",
                            CAPSULE,
                            (c[0], c[1], s.top - radius),
                            rot_across(heading),
                            (radius, half, 0.0),
                            mat,
                            **kw,
                        )
                    )
    for w in rig.walls:
        a, b = np.array(w.start), np.array(w.end)
        c, length = (a + b) / 2, float(np.linalg.norm(b - a))
        yaw = math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))
        mat = _material(w.material)
        items.append(
            primitive(
                w.name,
                WALL if wall_contact == "outline" else BOX,
                (c[0], c[1], w.base + w.height / 2),
                rot_z(yaw),
                (length / 2, w.thickness / 2, w.height / 2),
                mat,
            )
        )
        if w.lead_in > 0:
            items.append(
                primitive(
                    f"{w.name}_lead_in",
                    LEAD_IN,
                    (a[0], a[1], w.base + w.height / 2),
                    np.eye(3),
                    (w.lead_in, w.height / 2, 0.0),
                    mat,
                )
            )
    return Primitives.of(items)


@dataclass(frozen=True)
class Body:
    """The parcel as a rigid box (see the module docstring): mass [kg], principal inertia (3,)
    [kg m^2], half extents (3,) [m], contact points (n, 3) [m, body frame], their area weights
    (n,) [m^2], groups (n,) (bottom, top, side) and height bands (n,) [m] (a side point's row
    height, 0 for the others), tiles (start, end index into the points,
    centre (3,), radius), the area A_b [m^2] that divides the contact law's stiffness (the outline's
    L W, which the bottom patch's weights sum to), the side rows' body z (m,) and height
    weights (m,) [m] (the lead-in's analytic contact is taken at these levels) and the half
    extents (3,) [m] of the outline that walls and lead-ins meet (``wall_outline``)."""

    mass: float
    inertia: np.ndarray
    half: np.ndarray
    points: np.ndarray
    area: np.ndarray
    group: np.ndarray
    band: np.ndarray
    tile_start: np.ndarray
    tile_end: np.ndarray
    tile_centre: np.ndarray
    tile_radius: np.ndarray
    bottom_area: float
    row_z: np.ndarray
    row_h: np.ndarray
    wall_half: np.ndarray

    @property
    def radius(self) -> float:
        """The half diagonal of the box [m]: no point lies farther from the centre."""
        return float(np.linalg.norm(self.half))


def box_inertia(
    mass: float,
    outer: tuple[float, float, float],
    content: tuple[float, float, float],
    packaging_mass: float,
) -> np.ndarray:
    """Principal moments [kg m^2] of the content box plus two packaging sheets (module doc)."""
    L, W, H = outer
    cL, cW, cH = content
    mc, mp = mass - packaging_mass, packaging_mass
    return np.array(
        [
            mc * (cW**2 + cH**2) / 12 + mp * (W**2 / 12 + H**2 / 4),
            mc * (cL**2 + cH**2) / 12 + mp * (L**2 / 12 + H**2 / 4),
            mc * (cL**2 + cW**2) / 12 + mp * (L**2 + W**2) / 12,
        ]
    )


def _axis(extent: float, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes over [-extent/2, extent/2] at most ``spacing`` apart and their trapezoidal weights."""
    n = max(1, math.ceil(extent / spacing - 1e-9))
    x = np.linspace(-extent / 2, extent / 2, n + 1)
    w = np.full(n + 1, extent / n)
    w[0] = w[-1] = extent / n / 2
    return x, w


def _tiles_of_grid(nx: int, ny: int) -> list[np.ndarray]:
    """Index blocks (row-major over an nx x ny node grid) of TILE x TILE nodes."""
    idx = np.arange(nx * ny).reshape(nx, ny)
    return [
        idx[i : i + TILE, j : j + TILE].ravel()
        for i in range(0, nx, TILE)
        for j in range(0, ny, TILE)
    ]


def resolved_bottom_patch(consignment: Consignment, bottom_patch: str) -> str:
    """The patch ``bottom_patch`` stands for on ``consignment``: ``consignment`` is ``bulge``
    (the consignment's bulge patch) where it has one, else ``rim-bending``; any other name is
    itself."""
    if bottom_patch != "consignment":
        return bottom_patch
    return "bulge" if consignment.bulge is not None else "rim-bending"


def rim_bending_length(
    young: float, thickness: float, poisson: float, stiffness: float, area: float
) -> float:
    """The bending length lambda = (4 D / k_f)^(1/4) [m] of a packaging sheet (Young's modulus
    ``young`` [Pa], ``thickness`` [m], ``poisson`` [-]; D = E t^3 / (12 (1 - nu^2)) [N m]) on
    the contact's foundation k_f = ``stiffness`` / ``area`` [N/m^3] (the whole bottom's
    stiffness K [N/m] over the outline's area L W [m^2]); see the module docstring."""
    for name, value in (("young", young), ("thickness", thickness), ("stiffness", stiffness)):
        if not (math.isfinite(value) and value > 0):
            raise ParcelfitError(f"the rim's bending needs a positive {name}, got {value!r}")
    if not 0 <= poisson < 0.5 or not (math.isfinite(area) and area > 0):
        raise ParcelfitError(
            f"the rim's bending needs 0 <= poisson < 0.5 and a positive area, got {poisson!r}, "
            f"{area!r}"
        )
    return (4.0 * plate_rigidity(young, thickness, poisson) * area / stiffness) ** 0.25


def plate_rigidity(young: float, thickness: float, poisson: float) -> float:
    """The bending stiffness D = E t^3 / (12 (1 - nu^2)) [N m] of a sheet (Young's modulus
    ``young`` [Pa], ``thickness`` [m], Poisson's ratio ``poisson`` [-])."""
    if not (math.isfinite(young) and young > 0 and math.isfinite(thickness) and thickness > 0):
        raise ParcelfitError(
            f"a sheet's bending needs a positive Young's modulus and thickness, got {young!r}, "
            f"{thickness!r}"
        )
    if not 0 <= poisson < 0.5:
        raise ParcelfitError(f"a sheet's bending needs 0 <= poisson < 0.5, got {poisson!r}")
    return young * thickness**3 / (12.0 * (1.0 - poisson**2))


def rim_buckling_load(young: float, thickness: float, poisson: float, width: float) -> float:
    """An estimate of the in-plane load per unit length of edge [N/m] under which a rim
    ``width`` [m] wide (from the content's edge to the outline) buckles, pressed evenly along
    its outline: its two plies (the packaging's top and bottom sheet), each a plate strip
    clamped at the content and free at the outline, the cantilever's Euler load in cylindrical
    bending, 2 pi^2 D / (4 b^2) (D: `plate_rigidity`). Neither bound: a content's edge that
    lets the sheet turn (a hinge) or plies meeting at an angle at a seam lower it; bonded plies
    or a bubble lining raise it; a load on a short length of edge (a corner, a lead-in) is
    resisted by the rim beside it too."""
    if not (math.isfinite(width) and width > 0):
        raise ParcelfitError(f"a rim's width must be a positive length, got {width!r} m")
    return 2.0 * math.pi**2 * plate_rigidity(young, thickness, poisson) / (4.0 * width**2)


def strip_profile(b: np.ndarray, span: np.ndarray) -> np.ndarray:
    """The deflection g(b) [-] of a strip on an elastic foundation, d^4 g / db^4 + 4 g = 0 in
    b = x / lambda, its edge b = 0 pressed down by 1 without turning (held by the content) and
    free at b = ``span`` (the outline: no moment, no shear): g(0) = 1, g'(0) = 0, the second and
    third derivatives 0 at b = span. Over a long span g = e^-b (cos b + sin b). Defined for
    0 <= b <= span (both [-], lengths over lambda); other values are refused."""
    b, span = np.broadcast_arrays(np.asarray(b, dtype=float), np.asarray(span, dtype=float))
    if not (np.all(span >= 0) and np.all(b >= 0) and np.all(b <= span * (1 + 1e-12) + 1e-12)):
        raise ParcelfitError("the strip's profile is defined for 0 <= b <= span only")
    up, down = 1.0 + 1.0j, -1.0 + 1.0j  # g = Re/Im of e^(up b) (scaled by e^-span), e^(down b)

    def rows(order: int, at: np.ndarray) -> np.ndarray:
        grow = up**order * np.exp(up * at - span)
        decay = down**order * np.exp(down * at)
        return np.stack([grow.real, grow.imag, decay.real, decay.imag], axis=-1)

    zero = np.zeros_like(span)
    system = np.stack([rows(0, zero), rows(1, zero), rows(2, span), rows(3, span)], axis=-2)
    rhs = np.broadcast_to(np.array([1.0, 0.0, 0.0, 0.0]), (*span.shape, 4))
    coef = np.linalg.solve(system, rhs[..., None])[..., 0]
    return (rows(0, b) * coef).sum(axis=-1)


def _bending_profile(
    x: np.ndarray,
    y: np.ndarray,
    outer: tuple[float, float],
    content: tuple[float, float],
    length: float,
) -> np.ndarray:
    """The rim's deflection from bending as a share of the content's sink, at points (x, y) [m]
    outside the content's footprint (``content`` cL x cW inside ``outer`` L x W):
    `strip_profile` at b = d / ``length`` (d the distance from the footprint) over the span
    from the footprint to the outline along the same line."""
    (L, W), (cL, cW) = outer, content
    dx = np.maximum(np.abs(x) - cL / 2, 0.0)
    dy = np.maximum(np.abs(y) - cW / 2, 0.0)
    d = np.hypot(dx, dy)
    # along the line from the footprint's nearest point through (x, y) the outline lies at
    # (L - cL) / 2 / cos and (W - cW) / 2 / sin of its angle, whichever is nearer
    with np.errstate(divide="ignore", invalid="ignore"):
        reach = np.minimum(
            np.where(dx > 0, (L - cL) / 2 * d / dx, np.inf),
            np.where(dy > 0, (W - cW) / 2 * d / dy, np.inf),
        )
    reach = np.maximum(np.where(np.isfinite(reach), reach, d), d)
    return strip_profile(d / length, reach / length)


def _cell_samples(
    pts: np.ndarray, half: tuple[float, float], outer: tuple[float, float], n: int
) -> tuple[np.ndarray, np.ndarray]:
    """n x n points [m] evenly over each bottom node's cell (``pts``, half widths ``half`` [m]),
    clipped to the outline ``outer`` L x W: their x and y, each (nodes, n * n), row-major over
    (x offset, y offset)."""
    (L, W), u = outer, (np.arange(n) + 0.5) / n * 2.0 - 1.0  # cell-relative offsets in (-1, 1)
    xs = np.clip(pts[:, 0, None] + half[0] * u, -L / 2, L / 2)  # (nodes, n)
    ys = np.clip(pts[:, 1, None] + half[1] * u, -W / 2, W / 2)
    return np.repeat(xs, n, axis=1), np.tile(ys, (1, n))


def _rim_weights(
    pts: np.ndarray,
    w: np.ndarray,
    consignment: Consignment,
    packaging_mass: float,
    length: float,
    spacing: float,
) -> np.ndarray:
    """Factors r_i on the bottom nodes' weights ``w`` so that, lying flat, the rim carries its
    own weight and, over the bending length ``length`` [m] (0: none), the share its bending
    passes on from the content (module docstring)."""
    L, W, _ = consignment.outer
    cL, cW, _ = consignment.content
    tol = 1e-9  # a node on the footprint's edge belongs to it
    rim = (np.abs(pts[:, 0]) > cL / 2 + tol) | (np.abs(pts[:, 1]) > cW / 2 + tol)
    if rim.all():
        raise ParcelfitError(
            f"no contact point of the {spacing * 1e3:g} mm grid lies inside the content's "
            f"footprint ({cL * 1e3:g} x {cW * 1e3:g} mm)",
            fix="use a finer spacing",
        )
    share = packaging_mass * (1.0 - cL * cW / (L * W)) / consignment.mass
    if length == 0:
        # node by node: a node inside the footprint (or on its edge) carries the content's
        # pressure, one outside the own weight's
        inside, outside = float(w[~rim].sum()), float(w[rim].sum())
        if outside == 0:
            return np.ones_like(w)
        return np.where(rim, share * inside / ((1.0 - share) * outside), 1.0)
    # cell by cell: the share of each node's cell inside the footprint, outside it, and the
    # bending profile's mean over the part outside (SUB x SUB points per cell): the bending
    # length is about the grid's spacing, and a node's point value would make the share depend
    # on where the content's edge falls between nodes
    hx, hy = (float(_axis(extent, spacing)[1][1]) / 2 for extent in (L, W))  # a cell's half
    X, Y = _cell_samples(pts, (hx, hy), (L, W), SUB)
    out = (np.abs(X) > cL / 2) | (np.abs(Y) > cW / 2)
    frac_out = out.mean(axis=1)
    a_out = float((w * frac_out).sum())
    if a_out == 0:
        return np.ones_like(w)
    g = np.zeros_like(X)
    g[out] = _bending_profile(X[out], Y[out], (L, W), (cL, cW), length)
    a_in = float((w * (1.0 - frac_out)).sum())
    passed = float((w * g.mean(axis=1)).sum())
    rho = share * (a_in + passed) / (a_out - share * (a_out - passed))
    # the pressure q_w + (p_c - q_w) g as a share of p_c; where the profile would pull the sheet
    # (g < -rho / (1 - rho)) it lifts off: no pressure, and the own weight is carried a little
    # short of exactly
    pressure = np.where(out, np.maximum(rho + (1.0 - rho) * g, 0.0), 1.0)
    return pressure.mean(axis=1)


def rim_load_share(consignment: Consignment, body: Body, beyond: float = 0.0) -> float:
    """The share [-] of ``body``'s bottom load, lying flat, that rests more than ``beyond`` [m]
    outside the content's footprint (in x or y): each bottom node's weight spread evenly over
    its grid cell (16 x 16 points)."""
    L, W, _ = consignment.outer
    cL, cW, _ = consignment.content
    bottom = body.group == BOTTOM
    pts, area = body.points[bottom], body.area[bottom]
    hx, hy = (np.diff(np.unique(pts[:, k]))[:1].sum() / 2 for k in (0, 1))  # 0: a single node
    X, Y = _cell_samples(pts, (hx, hy), (L, W), 16)
    out = ((np.abs(X) > cL / 2 + beyond) | (np.abs(Y) > cW / 2 + beyond)).mean(axis=1)
    return float((area * out).sum() / area.sum())


def check_walls(wall_outline: str, wall_inset: float) -> None:
    """Refuse an unknown ``wall_outline``, a ``wall_inset`` [m] that is not a finite length >= 0,
    and an inset of an outline other than the packaging's (`parcel_body`, `RigidBoxOptions`)."""
    if wall_outline not in WALL_OUTLINES:
        raise ParcelfitError(
            f"unknown wall_outline {wall_outline!r}", fix=f"use one of {list(WALL_OUTLINES)}"
        )
    if not (math.isfinite(wall_inset) and wall_inset >= 0):
        raise ParcelfitError(f"wall_inset must be a finite length >= 0 m, got {wall_inset!r}")
    if wall_inset > 0 and wall_outline != "outline":
        raise ParcelfitError(
            f"wall_inset insets the packaging's outline; wall_outline {wall_outline!r} has none",
            fix="set wall_outline: outline, or wall_inset: 0",
        )


def parcel_body(
    consignment: Consignment,
    packaging_mass: float,
    spacing: float = 0.01,
    bottom_patch: str = "consignment",
    bending_length: float = 0.0,
    wall_outline: str = "outline",
    wall_inset: float = 0.0,
) -> Body:
    """The rigid box of ``consignment`` with the packaging's mass ``packaging_mass`` [kg],
    contact points ``spacing`` [m] apart and the bottom contact patch ``bottom_patch``; on the
    ``rim-bending`` patch (the default where the consignment has no bulge) the rim's bending
    length ``bending_length`` [m] (`rim_bending_length`; 0: a rim that does not bend, the
    ``rim-weight`` patch); walls and lead-ins meet the packaging's or the content's outline
    (``wall_outline``), the packaging's inset by ``wall_inset`` [m] on every side (at most to
    the content's). See the module docstring."""
    if consignment.soft:
        raise ParcelfitError(
            f"consignment {consignment.name} has a soft content: the rigid-box reference "
            "represents rigid contents only",
            fix="use the MuJoCo backend for soft contents",
        )
    if bottom_patch not in BOTTOM_PATCHES:
        raise ParcelfitError(
            f"unknown bottom_patch {bottom_patch!r}", fix=f"use one of {list(BOTTOM_PATCHES)}"
        )
    check_walls(wall_outline, wall_inset)
    if not (math.isfinite(bending_length) and bending_length >= 0):
        raise ParcelfitError(
            f"the rim's bending length must be a finite length >= 0 m, got {bending_length!r}"
        )
    if not 0.001 <= spacing <= 0.1:
        raise ParcelfitError(
            f"contact point spacing must lie in [1, 100] mm, got {spacing * 1e3:g} mm"
        )
    mass = consignment.mass
    if not 0 < packaging_mass < mass:
        raise ParcelfitError(
            f"packaging mass {packaging_mass * 1e3:g} g leaves no mass for the content "
            f"(consignment {mass * 1e3:g} g)",
            fix="lower m_Pa",
        )
    L, W, H = consignment.outer
    cL, cW, _ = consignment.content
    # the content's outline is the packaging's inset as far as it goes
    inset = math.inf if wall_outline == "content" else wall_inset
    wall_half = np.array([max(L / 2 - inset, cL / 2), max(W / 2 - inset, cW / 2), H / 2])
    blocks: list[tuple[np.ndarray, np.ndarray, int, list[np.ndarray]]] = []

    def face(size: tuple[float, float], z: float, group: int) -> None:
        x, wx = _axis(size[0], spacing)
        y, wy = _axis(size[1], spacing)
        X, Y = np.meshgrid(x, y, indexing="ij")
        pts = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z)])
        blocks.append((pts, np.outer(wx, wy).ravel(), group, _tiles_of_grid(len(x), len(y))))

    patch = resolved_bottom_patch(consignment, bottom_patch)
    bottom = (L, W)
    if patch == "content":
        bottom = (cL, cW)
    elif patch == "bulge":
        footprint = consignment.bulge[1]
        bottom = (footprint * L, footprint * W)
    face(bottom, -H / 2, BOTTOM)
    pts, w, g, tiles = blocks[0]
    if patch in ("rim-weight", "rim-bending"):
        length = bending_length if patch == "rim-bending" else 0.0
        w = w * _rim_weights(pts, w, consignment, packaging_mass, length, spacing)
    # the patch carries the whole bottom's stiffness K, spread over the outline's area
    blocks[0] = (pts, w * (L * W) / w.sum(), g, tiles)
    face((L, W), H / 2, TOP)
    nz = max(MIN_SIDE_ROWS, math.ceil(H / spacing - 1e-9))
    row_z = -H / 2 + (np.arange(nz) + 0.5) * H / nz
    row_h = np.full(nz, H / nz)
    for extent, fixed, axis in ((W, L / 2, 0), (W, -L / 2, 0), (L, W / 2, 1), (L, -W / 2, 1)):
        s, ws = _axis(extent, spacing)
        S, Z = np.meshgrid(s, row_z, indexing="ij")
        pts = np.empty((S.size, 3))
        pts[:, axis] = fixed
        pts[:, 1 - axis] = S.ravel()
        pts[:, 2] = Z.ravel()
        blocks.append((pts, np.outer(ws, row_h).ravel(), SIDE, _tiles_of_grid(len(s), nz)))
    # points ordered tile by tile, so that a tile is a contiguous index range
    points, area, group = [], [], []
    starts, ends, centres, radii = [], [], [], []
    n = 0
    for pts, w, g, tiles in blocks:
        for t in tiles:
            p = pts[t]
            points.append(p)
            area.append(w[t])
            group.append(np.full(len(t), g))
            c = p.mean(axis=0)
            starts.append(n)
            ends.append(n + len(t))
            centres.append(c)
            # a side point's band reaches half a row above and below it
            reach = H / nz / 2 if g == SIDE else 0.0
            radii.append(float(np.max(np.linalg.norm(p - c, axis=1))) + reach)
            n += len(t)
    return Body(
        mass=mass,
        inertia=box_inertia(mass, consignment.outer, consignment.content, packaging_mass),
        half=np.array([L / 2, W / 2, H / 2]),
        points=np.concatenate(points),
        area=np.concatenate(area),
        group=np.concatenate(group).astype(np.int64),
        band=np.where(np.concatenate(group) == SIDE, H / nz, 0.0),
        tile_start=np.array(starts, dtype=np.int64),
        tile_end=np.array(ends, dtype=np.int64),
        tile_centre=np.array(centres),
        tile_radius=np.array(radii),
        bottom_area=float(L * W),
        row_z=row_z,
        row_h=row_h,
        wall_half=wall_half,
    )
