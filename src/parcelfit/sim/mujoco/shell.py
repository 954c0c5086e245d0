"""The packaging shell: a closed two-sheet "pillow" mesh of triangles around the content.

Top and bottom sheets are rectangular grids over the packed outer footprint L x W that share
their boundary ring (the seam). Heights follow

    h(x, y) = H * min(f(x; L, c_L), f(y; W, c_W)),   f(s; L, c) = clip((L/2 - |s|) / ((L - c)/2), 0, 1)

(top at +h, bottom at -h): flat over the content footprint c_L x c_W (or a band slightly wider,
below), tapering linearly to the seam at height 0. Grid lines lie exactly on the flat band's
edges, so the shell never cuts into the content (a shell that does makes the parcel lag the
belt). The spacing of the grid is the
mesh resolution: each of the three bands (rim, content, rim) per axis is divided into the
number of cells closest to band width / spacing (at least one).

A bubble mailer's bottom may **bulge** under the content (``bulge = (d, f)``): the bottom sheet
over the content is lowered by

    b(x, y) = d * min(g(x; c_L, f L), g(y; c_W, f W)),   g(s; c, a) = clip((c/2 - |s|) / ((c - a)/2), 0, 1)

flat at depth d over a centred patch of f times the outer length and width, rising linearly to
the content's edges. The belt then carries the parcel on that patch (its `bottom_face`), so a
spin is braked by a friction torque about f times smaller than a flat face's. Grid lines lie on
the patch's edges too (five bands per axis).

**Clearance at the content's edges.** The sheets lie s = H - h_c beyond the content's faces
(h_c its half height). Where the rim is short and the content thick, the taper from the flat
band's edge down to the seam passes the content's edge closer than that: with the band ending at
the content's edge (rim R = (L - c_L)/2, g = 0) the taper's line lies

    d(g) = (g H + s (R - g)) / sqrt((R - g)^2 + H^2)

from the content's edge when the band reaches g beyond it (0.4 mm for KP's 5 mm rim around its
3 cm content, against a vertex radius of 1 mm). The shell then touches its content at rest, and
the contacts' push tensions it: the content is clamped along its ends by several times its
weight and the parcel rests on its rim. With ``content_half_height`` and ``contact`` (the distance
below which a shell element and the content touch) given, an axis whose taper would touch
(d(0) < contact) gets its flat band widened by the g at which d(g) = s, so that the taper clears
the edge as the sheets clear the faces; the grid lines then lie on the widened band's edges.
Axes that clear the content already keep their band on the content's edges.

**Diagonals.** Each grid cell is split into two triangles along one of its diagonals.
"radiating" (the default) takes, in every quadrant of the parcel, the diagonal that points away
from its centre (the one through the cell's corners at (x_i, y_j) and (x_i+1, y_j+1) where
(x_i + x_i+1)(y_j + y_j+1) > 0): the mesh is mirror-symmetric about both axes (but in a row of
cells that straddles an axis, which an odd cell count leaves and no diagonal can make symmetric),
and every corner of the seam is the tip of two triangles per sheet. "alternating" (before
2026-11-28) alternated the diagonal cell by cell, so that whether a corner of the seam was the
tip of two triangles or of one depended on the parity of the number of cells, i.e. on the mesh
spacing; a corner that is one triangle's tip folds away where the other holds. On E3 that
decided, mesh by mesh, whether a polybag meeting the guide plate's lead-in caught and spun or
slid (docs/research/pb-film-mesh-E3.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from parcelfit.errors import ParcelfitError
from parcelfit.sim.params import SHELL_DIAGONALS


def _band(a: float, b: float, spacing: float) -> np.ndarray:
    """Grid lines from a to b (b excluded), about ``spacing`` apart, at least one cell."""
    return np.linspace(a, b, max(1, round((b - a) / spacing)) + 1)[:-1]


def _axis(outer: float, inner: float, spacing: float, patch: float | None = None) -> np.ndarray:
    left = _band(-outer / 2, -inner / 2, spacing)
    if patch is None:
        mid = np.append(_band(-inner / 2, inner / 2, spacing), inner / 2)
    else:
        side = _band(-inner / 2, -patch / 2, spacing)
        centre = np.append(_band(-patch / 2, patch / 2, spacing), patch / 2)
        mid = np.concatenate([side, centre, -side[::-1]])
    return np.concatenate([left, mid, -left[::-1]])


def edge_widening(rim: float, half_height: float, clearance: float, contact: float) -> float:
    """How far [m] the flat band must reach beyond the content's edge so that the taper (from
    the band's edge at height ``half_height`` down to the seam ``rim`` beyond the content's
    edge) clears that edge by ``clearance`` [m], or 0 when the taper already lies ``contact`` [m]
    or more from it (module docstring, d(g))."""
    H, s, R = half_height, clearance, rim

    def distance(g: float) -> float:
        return (g * H + s * (R - g)) / math.hypot(R - g, H)

    if distance(0.0) >= contact:
        return 0.0
    if s >= R:
        raise ParcelfitError(
            f"the packaging's rim ({R * 1e3:g} mm beyond the content) is too short to clear the "
            f"content by {s * 1e3:g} mm",
            fix="make the outer size larger than the content by more than the clearance",
        )
    # d(g) rises from d(0) < s to d(R) = R > s (dd/dg > 0 as H > s): one root
    return float(brentq(lambda g: distance(g) - s, 0.0, R))


@dataclass(frozen=True)
class ShellMesh:
    """Vertices (n, 3) [m] in the parcel frame, triangles (m, 3), and vertex index groups."""

    points: np.ndarray
    triangles: np.ndarray
    top: np.ndarray  # top-sheet vertices over the flat band (content footprint; where a tag sits)
    bottom_face: np.ndarray  # bottom-sheet vertices over the flat band (the flat face)
    seam: np.ndarray  # boundary ring
    half_height: float  # H [m]
    bulge_depth: float  # how far the bottom's patch lies below the content's face [m]
    bottom_triangles: np.ndarray  # indices into triangles of the bottom sheet

    @property
    def face_contacts(self) -> int:
        """Contacts MuJoCo creates when the flat bottom face lies on a plane: one per corner of a
        bottom-sheet triangle that lies on the face (flex collisions are per triangle element)."""
        return len(self.face_contact_vertices)

    @property
    def face_contact_vertices(self) -> np.ndarray:
        """The vertex of each of those contacts (a vertex once per triangle it is a corner of)."""
        corners = self.triangles[self.bottom_triangles]
        return corners[np.isin(corners, self.bottom_face)]


def pillow_shell(
    outer: tuple[float, float],
    content: tuple[float, float],
    half_height: float,
    spacing: float,
    bulge: tuple[float, float] | None = None,
    *,
    content_half_height: float | None = None,
    contact: float = 0.0,
    diagonals: str = "radiating",
) -> ShellMesh:
    """Build the pillow shell for outer (L, W) and content (c_L, c_W) footprints [m], with the
    bottom bulging by depth d [m] over a patch of f times the outer size when ``bulge = (d, f)``;
    with ``content_half_height`` [m], an axis whose taper would come within ``contact`` [m] of
    the content's edge gets a flat band wide enough to clear it (module docstring).
    ``diagonals`` splits each grid cell into two triangles, "radiating" or "alternating"
    (module docstring, "Diagonals")."""
    (L, W), (cL, cW) = outer, content
    if diagonals not in SHELL_DIAGONALS:
        raise ParcelfitError(
            f"unknown shell diagonals {diagonals!r}", fix=f"use one of {list(SHELL_DIAGONALS)}"
        )
    if not (0 < cL < L and 0 < cW < W):
        raise ParcelfitError(f"content {content} must be smaller than the outer footprint {outer}")
    if spacing <= 0 or spacing > max(L, W):
        raise ParcelfitError(f"mesh spacing must be in (0, {max(L, W)}] m, got {spacing}")
    # the flat band over the content: the content's footprint, widened where the taper would
    # touch the content's edge
    bL, bW = cL, cW
    if content_half_height is not None:
        clearance = half_height - content_half_height
        bL += 2 * edge_widening((L - cL) / 2, half_height, clearance, contact)
        bW += 2 * edge_widening((W - cW) / 2, half_height, clearance, contact)
    depth, (pL, pW) = 0.0, (None, None)
    if bulge is not None:
        depth, f = bulge
        pL, pW = f * L, f * W
        if not (depth > 0 and 0 < pL < cL and 0 < pW < cW):
            raise ParcelfitError(
                f"bulge {bulge}: the depth must be positive and the patch ({pL:.3f} x {pW:.3f} m) "
                f"smaller than the content {content}"
            )
    xs, ys = _axis(L, bL, spacing, pL), _axis(W, bW, spacing, pW)
    nx, ny = len(xs), len(ys)

    def height(x: float, y: float) -> float:
        fx = np.clip((L / 2 - abs(x)) / ((L - bL) / 2), 0, 1)
        fy = np.clip((W / 2 - abs(y)) / ((W - bW) / 2), 0, 1)
        return half_height * min(fx, fy)

    def sag(x: float, y: float) -> float:  # the bulge below the content (0 without one)
        if pL is None or pW is None:
            return 0.0
        gx = np.clip((cL / 2 - abs(x)) / ((cL - pL) / 2), 0, 1)
        gy = np.clip((cW / 2 - abs(y)) / ((cW - pW) / 2), 0, 1)
        return depth * min(gx, gy)

    pts: list[list[float]] = []
    top: dict[tuple[int, int], int] = {}
    bot: dict[tuple[int, int], int] = {}
    for i, x in enumerate(xs):
        for j, y in enumerate(ys):
            top[i, j] = len(pts)
            pts.append([x, y, height(x, y)])
    for i, x in enumerate(xs):
        for j, y in enumerate(ys):
            if i in (0, nx - 1) or j in (0, ny - 1):
                bot[i, j] = top[i, j]
            else:
                bot[i, j] = len(pts)
                pts.append([x, y, -height(x, y) - sag(x, y)])
    tris: list[int] = []
    bottom_tris: list[int] = []
    for i in range(nx - 1):
        for j in range(ny - 1):
            # the cell's diagonal, the same in both sheets (module docstring, "Diagonals")
            rising = (
                (xs[i] + xs[i + 1]) * (ys[j] + ys[j + 1]) > 0
                if diagonals == "radiating"
                else (i + j) % 2 == 0
            )
            for grid, flip in ((top, False), (bot, True)):
                if flip:
                    bottom_tris += [len(tris) // 3, len(tris) // 3 + 1]
                a, b, c, d = grid[i, j], grid[i + 1, j], grid[i + 1, j + 1], grid[i, j + 1]
                # reverse the bottom's winding (outward = -z)
                quad = [a, b, c, a, c, d] if rising else [a, b, d, b, c, d]
                if flip:
                    quad = [quad[0], quad[2], quad[1], quad[3], quad[5], quad[4]]
                tris += quad
    points = np.asarray(pts)
    eps = 1e-12
    inside = [
        (i, j)
        for i in range(nx)
        for j in range(ny)
        if abs(xs[i]) <= bL / 2 + eps and abs(ys[j]) <= bW / 2 + eps
    ]
    face = (
        inside
        if pL is None or pW is None
        else [
            (i, j)
            for i in range(nx)
            for j in range(ny)
            if abs(xs[i]) <= pL / 2 + eps and abs(ys[j]) <= pW / 2 + eps
        ]
    )
    seam = sorted(
        {top[i, j] for i in range(nx) for j in range(ny) if i in (0, nx - 1) or j in (0, ny - 1)}
    )
    return ShellMesh(
        points=points,
        triangles=np.asarray(tris, dtype=int).reshape(-1, 3),
        top=np.array([top[k] for k in inside]),
        bottom_face=np.array([bot[k] for k in face]),
        seam=np.array(seam),
        half_height=half_height,
        bulge_depth=depth,
        bottom_triangles=np.array(bottom_tris),
    )
