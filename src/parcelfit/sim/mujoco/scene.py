"""Building the MJCF scene of a rig and a consignment for given parameters (SI units).

Scene conventions:

* Conveying surfaces are static world geoms with a surface velocity (`surfacevel`): belts and
  strips are boxes whose top face is the conveying surface, roller units are capsules lying
  across their heading. Walls are thin static boxes. Materials select the parameters: ``belt``
  and ``roller`` use the belt/packaging ones (BePa), ``metal`` the metal/packaging ones (MePa).
* The packaging is a two-sheet flex shell (`parcelfit.sim.mujoco.shell`, elastic2d="both":
  membrane and bending) with vertex radius ``vertex_radius``; a rigid content is a free box, a
  soft content a 3-D flex grid. The content collides only with the packaging (contype bits), the
  packaging with everything. Contact properties come from the partner with the higher priority:
  surfaces (2) over the content (1) over the packaging (0), so each pair has exactly the
  parameters of the catalogue.
* Flex damping is Rayleigh stiffness-proportional: beta = 2 zeta / omega_ref, where omega_ref is
  the first bending frequency of the body treated as a free plate strip of length L,
  omega_ref = (4.730 / L)^2 sqrt(D / (rho h)), D = E h^3 / (12 (1 - nu^2)).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.consignment import Consignment
from parcelfit.sim.mujoco.contact import (
    ContactParams,
    contact_params,
    penalty_contact,
)
from parcelfit.sim.mujoco.contact_cap import map_to_solver
from parcelfit.sim.mujoco.lumped_mass import compile_model, element_vertex_masses
from parcelfit.sim.mujoco.options import MAX_CONTACTS_PER_PAIR, SceneOptions
from parcelfit.sim.mujoco.rig import Rig, Surface
from parcelfit.sim.mujoco.rim_brace import RimBrace, add_rim_braces
from parcelfit.sim.mujoco.shell import ShellMesh, pillow_shell

SLAB = 0.02  # half-thickness of belt and strip boxes [m]
CONTACT_GAP = 0.0005  # clearance between content and shell, and under the parcel at the start [m]
FREE_PLATE_BETA1 = 4.730  # first free-free beam mode, beta_1 L


@dataclass(frozen=True)
class SurfaceGeom:
    """A driven geom: name, material, world velocity of its surface on top [m/s] and the rig
    surface it belongs to. A drum (or a turning roller, `SceneOptions.roller_surface`) also has
    its world angular velocity ``spin`` [rad/s] and a point ``axis`` [m] on its axis: its
    material moves at spin x (point - axis), the belt's velocity on top, up round the tail and
    down round the head."""

    name: str
    material: str
    velocity: tuple[float, float, float]
    surface: str
    spin: tuple[float, float, float] | None = None
    axis: tuple[float, float, float] | None = None

    def velocity_at(self, points: np.ndarray) -> np.ndarray:
        """The surface's material velocity [m/s] at world ``points`` (n, 3) [m], as MuJoCo's
        ``surfacevel`` moves it: the same everywhere on a flat belt, strip or linear roller, spin x
        arm on a drum or a turning roller."""
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        if self.spin is None or self.axis is None:  # set together (`_turning`)
            return np.broadcast_to(np.asarray(self.velocity, dtype=float), pts.shape).copy()
        return np.cross(
            np.asarray(self.spin, dtype=float), pts - np.asarray(self.axis, dtype=float)
        )


@dataclass(frozen=True)
class Scene:
    """MJCF text and what the runner needs to read the simulation back."""

    xml: str
    shell: ShellMesh
    driven: tuple[SurfaceGeom, ...]
    metal_geoms: tuple[str, ...]
    start_velocity: tuple[float, float, float]
    contacts: Mapping[str, ContactParams]
    n_shell_vertices: int
    content_flex: bool
    mass_lumping: str  # how the flexes' masses are spread (`SceneOptions.mass_lumping`)
    rim_brace: RimBrace | None = None  # braces across the shell's rim cells (`rim_brace`)
    # how the contacts meet MuJoCo's solver (`SceneOptions.contact_mapping`), and the lone
    # shell vertex's inverse mass [1/kg] the contacts' solref in ``xml`` was written with
    contact_mapping: str = "vertex"
    vertex_inverse_mass: float = 0.0

    def model(self) -> mujoco.MjModel:
        """The compiled MuJoCo model of this scene, its flexes' masses lumped as the scene says
        (`parcelfit.sim.mujoco.lumped_mass.compile_model`), its rims braced if it says so, and
        with the "solver" contact mapping its packaging contacts' solref mapped with MuJoCo's
        own inverse mass (`parcelfit.sim.mujoco.contact_cap.map_to_solver`)."""
        brace = self.rim_brace
        edit = None if brace is None else lambda spec, model: add_rim_braces(spec, model, brace)
        model = compile_model(self.xml, self.mass_lumping, edit)
        if self.contact_mapping == "solver":
            map_to_solver(model, self.shell, self.vertex_inverse_mass)
        return model


def _quat(yaw_deg: float, roll_deg: float = 0.0) -> str:
    """Quaternion (w x y z) of R = Rz(yaw) Rx(roll)."""
    y, r = math.radians(yaw_deg) / 2, math.radians(roll_deg) / 2
    qz = np.array([math.cos(y), 0, 0, math.sin(y)])
    qx = np.array([math.cos(r), math.sin(r), 0, 0])
    w1, x1, y1, z1 = qz
    w2, x2, y2, z2 = qx
    q = [
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ]
    return " ".join(f"{v:.9g}" for v in q)


def _f(v: float) -> str:
    return f"{v:.9g}"


def _turning(
    speed: float, radius: float, across: np.ndarray, axis: tuple[float, float, float]
) -> tuple[str, dict[str, tuple[float, float, float]]]:
    """A cylinder or capsule turned Rz(heading) Rx(90 deg) (local z = world -across) that turns
    with its surface moving at ``speed`` [m/s] on top: its MJCF surfacevel (angular, -speed /
    radius about local z) and the `SurfaceGeom` fields for it, world spin (speed / radius) across
    [rad/s] about the point ``axis`` [m] ((speed / r) across x (0, 0, r) = speed along on top,
    up round its upstream side, down round its downstream side)."""
    w = speed / radius
    spin = (float(w * across[0]), float(w * across[1]), 0.0)
    return f"0 0 0 0 0 {_f(-w)}", {"spin": spin, "axis": axis}


def _surface_geoms(
    s: Surface,
    speed: float,
    cp: ContactParams,
    mu: float,
    condim: int = 3,
    roller_surface: str = "linear",
) -> tuple[list[str], list[SurfaceGeom]]:
    u, n = s.unit(), np.array([-s.unit()[1], s.unit()[0]])
    common = (
        f'friction="{_f(mu)} 0.005 0.0001" priority="2" solref="{cp.solref}" solimp="{cp.solimp}" '
        f'contype="1" conaffinity="1" condim="{condim}"'
    )
    xml, geoms = [], []
    r, velocity = s.nose_radius, (speed * u[0], speed * u[1], 0.0)
    for name, c, length, width in s.parts():
        # with rounded ends the flat top stops r short of each end, where the belt runs round a
        # drum of radius r whose top is level with it
        xml.append(
            f'<geom name="{name}" type="box" size="{_f(length / 2 - r)} {_f(width / 2)} {SLAB}" '
            f'pos="{_f(c[0])} {_f(c[1])} {_f(s.top - SLAB)}" quat="{_quat(s.heading)}" '
            f'surfacevel="{_f(speed)} 0 0 0 0 0" rgba="0.25 0.25 0.3 1" {common}/>'
        )
        geoms.append(SurfaceGeom(name, s.material, velocity, s.name))
        if r <= 0:
            continue
        for end, sign in (("tail", -1), ("head", 1)):
            p = c + sign * (length / 2 - r) * u
            # a cylinder across the heading that turns with the belt: speed along u on top, up
            # at the tail, down at the head. Coulomb belt friction takes the material velocity at
            # each contact point (`SurfaceGeom.velocity_at`); the static friction switch compares
            # the parcel's centre with the top velocity
            surfacevel, turns = _turning(speed, r, n, (float(p[0]), float(p[1]), s.top - r))
            xml.append(
                f'<geom name="{name}_{end}" type="cylinder" size="{_f(r)} {_f(width / 2)}" '
                f'pos="{_f(p[0])} {_f(p[1])} {_f(s.top - r)}" quat="{_quat(s.heading, 90)}" '
                f'surfacevel="{surfacevel}" rgba="0.25 0.25 0.3 1" {common}/>'
            )
            geoms.append(SurfaceGeom(f"{name}_{end}", s.material, velocity, s.name, **turns))
    if s.type == "rollers":
        rows, cols = int(s.extra["rows"]), int(s.extra["columns"])
        radius, half = s.extra["radius"], s.extra["roller_width"] / 2
        heading = s.heading + s.extra["swivel"]
        a = math.radians(heading)
        for r in range(rows):
            for c_ in range(cols):
                c = (
                    np.array(s.centre)
                    + (c_ - (cols - 1) / 2) * (s.length / cols) * u
                    + (r - (rows - 1) / 2) * (s.width / rows) * n
                )
                name = f"{s.name}_{r}_{c_}"
                # capsule axis (local z) across the roller's heading: R = Rz(heading) Rx(90 deg).
                # "linear": the surface moves along the heading everywhere; "turning": it turns
                # as a driven roller does (the conveying speed on top, up or down on its flanks)
                surfacevel, turns = f"{_f(speed)} 0 0 0 0 0", {}
                if roller_surface == "turning":
                    across = np.array([-math.sin(a), math.cos(a)])
                    axis = (float(c[0]), float(c[1]), s.top - radius)
                    surfacevel, turns = _turning(speed, radius, across, axis)
                xml.append(
                    f'<geom name="{name}" type="capsule" size="{_f(radius)} {_f(half)}" '
                    f'pos="{_f(c[0])} {_f(c[1])} {_f(s.top - radius)}" quat="{_quat(heading, 90)}" '
                    f'surfacevel="{surfacevel}" rgba="0.6 0.6 0.2 1" {common}/>'
                )
                conveying = (speed * math.cos(a), speed * math.sin(a), 0.0)
                geoms.append(SurfaceGeom(name, s.material, conveying, s.name, **turns))
    return xml, geoms


def content_contacts(model: mujoco.MjModel, data: mujoco.MjData) -> int:
    """How many of ``data``'s contacts touch the content's geoms now (one box, or its
    `SceneOptions.content_tiles`; MuJoCo keeps at most `MAX_CONTACTS_PER_PAIR` per colliding
    pair). A count, no unit."""
    geoms = np.flatnonzero(model.geom_bodyid == model.body("content").id)
    return int(np.sum(np.isin(data.contact.geom[: data.ncon], geoms).any(axis=1)))


def content_contact_share(n_face: int, tiles: int, kept: int | None = None) -> int:
    """The contacts a rigid content's face stiffness is spread over: ``n_face`` (as for the
    packaging's other faces) for one box, which MuJoCo meets on at most 50 of them; for
    ``tiles`` x ``tiles`` boxes, each a pair with its own 50, that count scaled by how many
    more contacts the tiles keep than one box, so that the kept contacts together are as stiff
    and as damped as one box's (`SceneOptions.content_tiles`). ``kept``: the contacts the tiles
    keep, counted (`SceneOptions.content_kept`); without it, the estimate if only the flat face
    touched (at most ``n_face``). That estimate is an approximation: the content touches the
    top sheet and the sides too, and on KP/BW 4 x 4 tiles keep 680 contacts (30 mm mesh) and
    800 (15 mm) where the flat face has 212 and 650: 2.2 and 1.2 times stiffer
    (docs/research/e3-contact-law/content-contacts.md). For an interpolated shell only (one box
    on a full shell keeps hundreds; `build_scene` refuses tiles there). Counts, no unit."""
    if tiles == 1:
        return n_face
    kept_one = min(MAX_CONTACTS_PER_PAIR, n_face)
    kept_tiles = kept if kept is not None else min(MAX_CONTACTS_PER_PAIR * tiles**2, n_face)
    return max(1, round(n_face * kept_tiles / kept_one))


def bending_omega(
    young: float, poisson: float, thickness: float, density: float, length: float
) -> float:
    """First free-free bending frequency [rad/s] of a plate strip (E [Pa], h [m], rho [kg/m^3], L [m])."""
    d = young * thickness**3 / (12 * (1 - poisson**2))
    return (FREE_PLATE_BETA1 / length) ** 2 * math.sqrt(d / (density * thickness))


def equivalent_plate(young: float, thickness: float, cap: float | None) -> tuple[float, float]:
    """(E [Pa], h [m]) of the plate with the bending stiffness D = E h^3 / (12 (1 - nu^2)) of
    (``young``, ``thickness``) whose membrane stiffness E h [N/m] is at most ``cap``.

    h' = h sqrt(E h / cap) and E' = E (h / h')^3 keep D and make E' h' = cap; below the cap (or
    without one) the plate is returned unchanged. The shell's mass is set separately, so only its
    elasticity changes."""
    if cap is None or young * thickness <= cap:
        return young, thickness
    h_eq = thickness * math.sqrt(young * thickness / cap)
    return young * (thickness / h_eq) ** 3, h_eq


def build_scene(
    rig: Rig,
    consignment: Consignment,
    params: Mapping[str, float],
    setting: int,
    options: SceneOptions | None = None,
) -> Scene:
    """The MJCF scene of ``rig`` at ``setting`` with ``consignment`` and SI ``params``."""
    opt = options or SceneOptions()
    if consignment.bulge is not None and consignment.soft:
        # the consignment file refuses it too; a consignment changed in code reaches this
        raise ParcelfitError(
            f"consignment {consignment.name}: a bulge needs a rigid content",
            fix="remove the bulge (a soft content's shell sags on its own)",
        )
    if consignment.soft and opt.content_tiles > 1:
        raise ParcelfitError(
            f"consignment {consignment.name}: content_tiles splits a rigid content's box; "
            "this content is soft",
            fix="use content_tiles=1 (the default)",
        )
    if opt.content_tiles > 1 and opt.shell_of(consignment)[0] == "full":
        # the share assumes one box keeps MuJoCo's 50 contacts per pair; a full shell, colliding
        # per element, keeps hundreds, and its tiles would come out several times softer
        raise ParcelfitError(
            f"consignment {consignment.name}: content_tiles works around the cap of an "
            "interpolated shell's contacts; a full shell has no such cap",
            fix="use content_tiles=1 (the default) with shell_dof=full",
        )
    p = params
    speeds = rig.drive_speeds(setting)
    L, W, _H = consignment.outer
    cL, cW, cH = consignment.content
    r = opt.vertex_radius
    half_height = cH / 2 + r + CONTACT_GAP
    soft = consignment.soft
    content_radius = r / 2 if soft else 0.0  # a soft content's vertices; a box has none
    shell = pillow_shell(
        (L, W),
        (cL, cW),
        half_height,
        opt.spacing_of(consignment),
        consignment.bulge,
        content_half_height=cH / 2,
        contact=r + content_radius,  # where a shell element touches the content
        diagonals=opt.shell_diagonals,
    )
    nv = len(shell.points)
    m_pa = p["m_Pa"]
    m_co = consignment.mass - m_pa
    if m_co <= 0:
        raise ParcelfitError(
            f"packaging mass {m_pa * 1e3:g} g leaves no mass for the content "
            f"(consignment {consignment.mass * 1e3:g} g)",
            fix="lower m_Pa",
        )
    n_face = shell.face_contacts
    # a vertex's contact is as stiff as its mass is large (README, "Contact stiffness in N/mm"):
    # the mapping takes the mean mass over the contacts of the flat bottom face, so that the
    # whole face has the stiffness asked for whatever the masses
    if opt.mass_lumping == "area":
        m_vert = element_vertex_masses(shell.points, shell.triangles, m_pa)
        m_v = float(m_vert[shell.face_contact_vertices].mean())
    else:
        m_v = m_pa / nv
    dt = opt.step_for(soft, rig, consignment.shell)

    # --- contact parameters (effective inverse mass of a flex contact: see contact.py) ------------
    def contact(
        pair: str, resting: float, other_inverse_mass: float = 0.0, shared: int = n_face
    ) -> ContactParams:
        # a flex vertex (1/m_v) against a static surface or the content (its inverse mass);
        # ``resting`` [kg]: the mass that rests on the face (the penalty law's damping);
        # ``shared``: the contacts the face's stiffness is spread over
        k = p[f"k_{pair}"]
        inverse_mass = 1 / m_v + other_inverse_mass
        if opt.contact_law == "penalty":
            return penalty_contact(k, shared, inverse_mass, p[f"zeta_{pair}"], resting, dt)
        return contact_params(
            k, shared, inverse_mass, p[f"zeta_{pair}"], dt, frequency=opt.frequency_for(k)
        )

    belt_cp = contact("BePa", consignment.mass)
    metal_cp = contact("MePa", consignment.mass)
    if soft:
        counts = [max(2, round(s / opt.content_spacing()) + 1) for s in (cL, cW)] + [2]
        m_cv = m_co / (counts[0] * counts[1] * counts[2])
        content_cp = contact("CoPa", m_co, 1 / m_cv)
    else:
        tiles = opt.content_tiles
        share = content_contact_share(n_face, tiles, opt.content_kept)
        content_cp = contact("CoPa", m_co, 1 / m_co, share)

    # --- rig ------------------------------------------------------------------------------------
    body: list[str] = []
    driven: list[SurfaceGeom] = []
    for s in rig.surfaces:
        factor = opt.speed_factors.get(s.drive, 1.0)
        cp, mu = (metal_cp, p["mu_d_MePa"]) if s.material == "metal" else (belt_cp, p["mu_d_BePa"])
        # with Coulomb belt friction MuJoCo's contacts with belts, strips and rollers are
        # frictionless (condim 1; the surfaces' priority makes their condim the contact's)
        condim = 1 if opt.belt_friction == "coulomb" and s.material != "metal" else 3
        xml, geoms = _surface_geoms(s, speeds[s.drive] * factor, cp, mu, condim, opt.roller_surface)
        body += xml
        driven += geoms
    metal = []
    for w in rig.walls:
        a, b = np.array(w.start), np.array(w.end)
        c, length = (a + b) / 2, float(np.linalg.norm(b - a))
        yaw = math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))
        cp, mu = (metal_cp, p["mu_d_MePa"]) if w.material == "metal" else (belt_cp, p["mu_d_BePa"])
        body.append(
            f'<geom name="{w.name}" type="box" size="{_f(length / 2)} {_f(w.thickness / 2)} {_f(w.height / 2)}" '
            f'pos="{_f(c[0])} {_f(c[1])} {_f(w.base + w.height / 2)}" quat="{_quat(yaw)}" '
            f'friction="{_f(mu)} 0.005 0.0001" priority="2" solref="{cp.solref}" solimp="{cp.solimp}" '
            f'contype="1" conaffinity="1" condim="3" rgba="0.7 0.7 0.75 1"/>'
        )
        if w.material == "metal":
            metal.append(w.name)
        if w.lead_in > 0:  # a rolled lead-in: a vertical cylinder at the upstream end
            name = f"{w.name}_lead_in"
            body.append(
                f'<geom name="{name}" type="cylinder" size="{_f(w.lead_in)} {_f(w.height / 2)}" '
                f'pos="{_f(a[0])} {_f(a[1])} {_f(w.base + w.height / 2)}" '
                f'friction="{_f(mu)} 0.005 0.0001" priority="2" solref="{cp.solref}" solimp="{cp.solimp}" '
                f'contype="1" conaffinity="1" condim="3" rgba="0.7 0.7 0.75 1"/>'
            )
            if w.material == "metal":
                metal.append(name)

    # --- parcel ---------------------------------------------------------------------------------
    start_surface = rig.surface(rig.start.surface)
    dx, dy, dh = opt.start_offset
    cx, cy = rig.start_centre(L, W)
    x0, y0 = cx + dx, cy + dy
    heading = rig.start.heading + dh
    zc = start_surface.top + half_height + shell.bulge_depth + r + CONTACT_GAP
    q = _quat(heading)
    v_start = (
        speeds[start_surface.drive]
        * opt.speed_factors.get(start_surface.drive, 1.0)
        * opt.start_speed_factor
    )
    u0 = start_surface.unit()
    start_velocity = (v_start * u0[0], v_start * u0[1], 0.0)

    young_pa, t_pa = equivalent_plate(p["E_Pa"], p["t_Pa"], opt.membrane_cap)
    rho_pa = m_pa / (2 * L * W * t_pa)
    beta_pa = 2 * p["zeta_Pa"] / bending_omega(young_pa, p["nu_Pa"], t_pa, rho_pa, L)
    points = " ".join(_f(v) for v in shell.points.ravel())
    shell_dof, cells = opt.shell_of(consignment)
    brace = opt.rim_brace_of(consignment)
    dof = "" if shell_dof == "full" else f' dof="{shell_dof}"'
    if cells != (1, 1, 1):
        dof += f' cellcount="{cells[0]} {cells[1]} {cells[2]}"'
    elements = " ".join(str(i) for i in shell.triangles.ravel())
    # an interpolated shell's nodes lie on a box aligned with the axes of the flexcomp's parent
    # body: a static frame turned like the parcel keeps that box aligned with the parcel
    frame_open, frame_close, place = "", "", f'pos="{_f(x0)} {_f(y0)} {_f(zc)}" quat="{q}"'
    if shell_dof != "full":
        frame_open = f'<body name="packaging_frame" {place}>'
        frame_close, place = "</body>", 'pos="0 0 0" quat="1 0 0 0"'
    body.append(
        f'{frame_open}<flexcomp name="packaging" type="direct" dim="2"{dof} {place} '
        f'radius="{_f(r)}" mass="{_f(m_pa)}" point="{points}" element="{elements}" rgba="0.85 0.75 0.55 0.8">'
        f'<contact contype="3" conaffinity="3" condim="3" selfcollide="none" priority="0"/>'
        f'<elasticity young="{_f(young_pa)}" poisson="{_f(p["nu_Pa"])}" thickness="{_f(t_pa)}" '
        f'damping="{_f(beta_pa)}" elastic2d="both"/></flexcomp>{frame_close}'
    )
    content_friction = f'friction="{_f(p["mu_CoPa"])} 0.005 0.0001"'
    if soft:
        spacing = [s / (c - 1) for s, c in zip((cL, cW, cH), counts, strict=True)]
        rho_co = m_co / (cL * cW * cH)
        beta_co = 2 * p["zeta_Co"] / bending_omega(p["E_Co"], 0.3, cH, rho_co, cL)
        body.append(
            f'<flexcomp name="content" type="grid" dim="3" count="{counts[0]} {counts[1]} {counts[2]}" '
            f'spacing="{" ".join(_f(s) for s in spacing)}" pos="{_f(x0)} {_f(y0)} {_f(zc)}" quat="{q}" '
            f'radius="{_f(content_radius)}" mass="{_f(m_co)}" rgba="0.3 0.5 0.9 1">'
            f'<contact contype="2" conaffinity="2" condim="3" selfcollide="none" priority="1" {content_friction} '
            f'solref="{content_cp.solref}" solimp="{content_cp.solimp}"/>'
            f'<elasticity young="{_f(p["E_Co"])}" poisson="0.3" damping="{_f(beta_co)}"/></flexcomp>'
        )
    else:
        # one box, or n x n tiles of it named content, content_1, ... (each its own contact pair)
        tile_geoms = []
        for i in range(tiles):
            for j in range(tiles):
                k = i * tiles + j
                name = "content" if k == 0 else f"content_{k}"
                offset = (((i + 0.5) / tiles - 0.5) * cL, ((j + 0.5) / tiles - 0.5) * cW)
                tile_geoms.append(
                    f'<geom name="{name}" type="box" pos="{_f(offset[0])} {_f(offset[1])} 0" '
                    f'size="{_f(cL / 2 / tiles)} {_f(cW / 2 / tiles)} {_f(cH / 2)}" '
                    f'mass="{_f(m_co / tiles**2)}" contype="2" conaffinity="2" condim="3" priority="1" '
                    f'{content_friction} solref="{content_cp.solref}" solimp="{content_cp.solimp}" '
                    f'rgba="0.6 0.4 0.2 1"/>'
                )
        body.append(
            f'<body name="content" pos="{_f(x0)} {_f(y0)} {_f(zc)}" quat="{q}"><freejoint name="content"/>'
            + "".join(tile_geoms)
            + "</body>"
        )

    ccd_tolerance = opt.ccd_tolerance_for(soft)
    ccd = "" if ccd_tolerance is None else f' ccd_tolerance="{_f(ccd_tolerance)}"'
    xml = f"""<mujoco model="{rig.name}-{consignment.name}">
<compiler angle="degree"/>
<option timestep="{_f(dt)}" integrator="discrete" solver="{opt.solver}" cone="{opt.cone}"
        impratio="{_f(opt.impratio_for())}" iterations="{opt.iterations}" tolerance="{_f(opt.tolerance)}"
        noslip_iterations="{opt.noslip_iterations}"{ccd}/>
<size memory="256M"/>
<visual><global offwidth="1280" offheight="720"/></visual>
<worldbody>
<light pos="1 0 3" dir="0 0 -1" directional="true"/>
{chr(10).join(body)}
</worldbody>
</mujoco>"""
    return Scene(
        xml=xml,
        shell=shell,
        driven=tuple(driven),
        metal_geoms=tuple(metal),
        start_velocity=start_velocity,
        contacts={"belt": belt_cp, "metal": metal_cp, "content": content_cp},
        n_shell_vertices=nv,
        content_flex=soft,
        mass_lumping=opt.mass_lumping,
        contact_mapping=opt.contact_mapping,
        vertex_inverse_mass=1 / m_v,
        rim_brace=None
        if brace == 0
        else RimBrace(brace, young_pa * t_pa, (cL, cW, cH), (L, W), beta_pa),
    )
