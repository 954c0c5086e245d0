"""The numerical settings of a scene (`SceneOptions`, not calibrated: time step [s], mesh
spacing [m], contact and friction laws, the packaging shell's degrees of freedom), their defaults
and their ``KEY=VALUE`` texts (`scene_options`)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from fractions import Fraction

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.consignment import Consignment
from parcelfit.sim.mujoco.rig import Rig
from parcelfit.sim.params import (
    BELT_FRICTION,
    CONTACT_LAWS,
    CONTACT_MAPPINGS,
    DYNAMIC_THRESHOLD,
    FRICTION_LAWS,
    MASS_LUMPINGS,
    MAX_REFINEMENT,
    MAX_TIMESTEP,
    MIN_TIMESTEP,
    ROLLER_SURFACES,
    SHELL_DIAGONALS,
    SHELL_DOFS,
    STATIC_THRESHOLD,
    STICK_SPEED,
    shell_cells,
)

PENALTY_IMPRATIO = 1e4  # the penalty law's friction stiffness (`SceneOptions.impratio`)
# MuJoCo's convex-collision tolerance around a soft content [m] (`SceneOptions.ccd_tolerance`)
SOFT_CCD_TOLERANCE = 1e-8


# default time steps [s] by shell (SceneOptions.step_for)
INTERPOLATED_SHELL_STEP = 1.0 / 2400.0
FULL_SHELL_STEP = 1.0 / 1200.0


def _check_step(step: float, what: str) -> None:
    if not MIN_TIMESTEP <= step <= MAX_TIMESTEP:
        raise ParcelfitError(
            f"{what} must lie in [{MIN_TIMESTEP:g}, {MAX_TIMESTEP:g}] s, got {step}"
        )


# the shell's mesh spacing around a rigid content where neither the scene nor the type sets one
# [m]: BW and KP/BW keep their E3 outcomes on a 22.5 mm mesh (docs/research/rim-brace/,
# docs/research/e3-contact-law/convergence/); KP takes 22.5 mm (docs/research/kp-mesh.md)
DEFAULT_SPACING = 0.03


MAX_CONTACTS_PER_PAIR = 50  # MuJoCo's mjMAXCONPAIR: contacts kept per colliding pair


@dataclass(frozen=True)
class SceneOptions:
    """Numerical settings of a scene (not calibrated): step [s], mesh spacing [m], etc."""

    # None: the default of the shell (`step_for`): 1/2400 s for an interpolated shell, where
    # transit times are converged to a few ms (at 1/1200 s E1 setting 3 came out 20-25 ms short,
    # docs/research/transit-convergence.md), 1/1200 s for the full shell around a soft content
    timestep: float | None = None
    # shell grid spacing around a rigid content [m]; None: the type's own (`mesh_spacing` of its
    # consignment file) or else DEFAULT_SPACING (`spacing_of`)
    spacing: float | None = None
    # shell grid spacing around a soft content [m]: 50 mm spins or slides every E3 placement
    # as 30 mm does (20 per setting, with the 100 mm content) at 0.7-0.88 times 40 mm's cost
    # (docs/research/pb-speed.md)
    soft_shell_spacing: float = 0.05
    # vertex spacing of a soft content [m]: 100 mm (4 x 3 x 2 vertices for the polybag's) keeps
    # every E3 placement's outcome of 60 mm (20 per setting) at three quarters of the cost; 150 mm
    # does not (docs/research/pb-speed.md)
    soft_spacing: float = 0.10
    vertex_radius: float = 0.001
    # how a contact's force follows its penetration (contact.py): "penalty" (the spring and
    # damper of the catalogue's stiffness, so that a stiffer packaging makes a shorter, harder
    # impact) or "impedance" (the law before 2026-12-01: every contact at ``contact_frequency``,
    # the stiffness setting only the static penetration)
    contact_law: str = "penalty"
    # "penalty" law only: how its per-contact stiffness meets MuJoCo's solver (contact_cap.py):
    # "vertex" (each contact's inverse mass a lone shell vertex's, every kept contact as it is:
    # an interpolated shell's flat face then realises 0.41-0.74 of the catalogue's stiffness,
    # MuJoCo keeping 50 of its contacts per pair) or "solver" (each contact's inverse mass
    # MuJoCo's own, and the contacts MuJoCo keeps of a pair at its cap weighted for those it
    # drops: a whole face pressed flat realises the catalogue's stiffness on 30 and 15 mm)
    contact_mapping: str = "vertex"
    # "impedance" law only: the contacts' own angular frequency [rad/s] (see contact.py): fixed, so that a finer time
    # step resolves the same impact instead of a faster one
    contact_frequency: float = 300.0
    # "impedance" law only. None: every contact has ``contact_frequency``. A whole-face stiffness K_ref [N/m]: a contact
    # of stiffness K gets contact_frequency * sqrt(K / K_ref), as a body on a spring does
    # (omega = sqrt(K / m)), so a stiffer contact makes a shorter impact; capped by the step as
    # before (contact.py)
    contact_frequency_stiffness: float | None = None
    solver: str = "Newton"
    # MuJoCo's iteration cap, shared by the constraint solver (Newton converges in a few) and the
    # conjugate-gradient solve of the 3-D flex's effective inertia M + h^2 K, which needs several
    # hundred on the polybag's content: at 50 every PB step was under-converged (moving E1 PB/2
    # by 12 mm and 12 ms), at 1000 none is. Rigid contents give bit-identical runs at either.
    iterations: int = 1000
    tolerance: float = 1e-7
    # MuJoCo's tolerance of its convex collision [m]; None: 1e-8 around a soft content, MuJoCo's
    # own (1e-6) around a rigid one. At 1e-6 a film vertex lying right above a content vertex
    # (the polybag's 50 mm film over its 100 mm content, at rest) is reported 0.2 mm deep in
    # it, where the geometry has them just touching; at 1e-8 none deeper than 10 um, at no
    # measurable cost (docs/research/pb-speed.md). The mailers' scenes keep MuJoCo's default, where the
    # same check finds no such error
    ccd_tolerance: float | None = None
    speed_factors: Mapping[str, float] = field(
        default_factory=dict
    )  # drive -> factor (synthetic jitter)
    # the largest in-plane (membrane) stiffness E t of the packaging shell [N/m]; None: E_Pa t_Pa
    # as given. With a cap, the shell uses the equivalent plate of the same bending stiffness
    # (`equivalent_plate`), whose stiff membrane modes no longer make the run depend on the step
    membrane_cap: float | None = None
    # MuJoCo's ratio of frictional to normal constraint impedance: at 1 a contact below its
    # friction limit still creeps (a corner held on a guide plate slid at 30-80 mm/s); larger
    # values make friction as stiff as the normal contact, the sliding limit unchanged. None:
    # 1e4 with the penalty law, whose contacts take MuJoCo's smallest impedance (at 1 their
    # friction rows are as soft: a KP/BW pushed at half its weight with mu_s 0.6 slid off at
    # once; at 100 it creeps 0.03 mm/s, at 1e3 and more it holds), 1 with the impedance law
    impratio: float | None = None
    # MuJoCo's friction cone ("elliptic" or "pyramidal") and its no-slip post-solver iterations
    # (0: off), two of the means against sliding contacts lifting off a belt (docs/research/contact-law.md)
    cone: str = "elliptic"
    noslip_iterations: int = 0
    # how MuJoCo moves the shell's vertices: "full" (each vertex its own 3 degrees of freedom) or
    # interpolated from a grid of nodes over the parcel's box, "quadratic" (3 x 3 x 3 nodes) or
    # "trilinear" (2 x 2 x 2); "auto": the consignment's own choice (`Consignment.shell`: the
    # bundled rigid-content types' trilinear over 4 x 4 x 1 cells), else quadratic around a rigid
    # content, full around a soft one
    # (a full shell loses most of a spin: spin.py, the README's "Spin")
    shell_dof: str = "auto"
    # how the shell's grid cells are split into triangles: "radiating" (mirror-symmetric, every
    # corner the tip of two triangles) or "alternating" (the mesh before 2026-11-28, whose corners
    # depend on the parity of the cell count; shell.py, "Diagonals")
    shell_diagonals: str = "radiating"
    # how the packaging's and a soft content's mass is spread over the bodies that carry it:
    # "area" (each triangle's area, or each grid cell's volume, shared by its corners, and an
    # interpolated shell's nodes weighted by how much of the film they move) or "equal"
    # (MuJoCo's own: every vertex or node the same, the model before 2026-11-28, which put the
    # packaging's moment of inertia up to 30 % and PB's content's 32 % above the lumped values;
    # lumped_mass.py, docs/research/mass-lumping.md)
    mass_lumping: str = "area"
    # an interpolated shell's grid of cells along the parcel's length, width and height (MuJoCo's
    # multi-cell flexes: the field is trilinear or quadratic within each cell, so a rim can bend
    # apart from the face it borders); None: the consignment's own (`Consignment.shell_cells`)
    # where the shell is its own choice, else one cell
    shell_cells: tuple[int, int, int] | None = None
    # braces across an interpolated shell's rim cells, as a share s of the stiffness of an ideal
    # wedge of the packaging's sheets (`rim_brace`: MuJoCo's interpolated shell is elastic on its
    # node box's faces, whose rim is a rectangle that shears freely); 0: none. Needs cells whose
    # boundaries fall on the content's ends (KP/BW: 5 x 5 x 1). None: the consignment's own
    # (`Consignment.rim_brace`) where its own shell and cells are used, else none
    rim_brace: float | None = None
    # a rigid content as n x n box tiles of one body (a diagnostic; interpolated shells only):
    # MuJoCo keeps at most 50 contacts per colliding pair (mjMAXCONPAIR), so one box rests on 50
    # of the hundreds of contacts a fine mesh offers, a subset MuJoCo picks anew each step; each
    # tile is a pair of its own. The content's stiffness and damping per contact are shared over
    # as many more contacts as the tiles could keep on the flat face (`content_contact_share`),
    # meant to keep the face as stiff as with one box (an approximation: 1.2-2.2 times stiffer
    # on KP/BW at 15-30 mm; `content_kept` matches it)
    content_tiles: int = 1
    # with content_tiles: the contacts the tiles keep, counted on the scene (a diagnostic
    # control, `scene.content_contacts`); the stiffness is then shared as if they were the
    # flat face's, so that the kept contacts together are as stiff as one box's 50 (None: the
    # flat face's estimate, `content_contact_share`)
    content_kept: int | None = None
    # friction between the packaging and belts, strips and rollers: "mujoco" (MuJoCo's own
    # contact friction) or "coulomb" (those contacts frictionless in MuJoCo and Coulomb friction
    # applied as forces at the contact points before every step, `coulomb.CoulombBelts`):
    # MuJoCo's friction lifts sliding contacts (docs/research/sliding-lift.md). The forces are explicit in
    # time: around a soft content (full shell) they need 1/2400 s (`step_for`)
    belt_friction: str = "mujoco"
    # how a flow splitter's roller units move the packaging: "linear" (a surface velocity along
    # the roller's heading everywhere on it, also on its flanks) or "turning" (an angular surface
    # velocity, as a driven roller turns: the conveying speed on top, up and down on its flanks,
    # like the belts' drums); measured in docs/research/belt-drums.md, "What it costs"
    roller_surface: str = "linear"
    # how the static friction offsets (mu_s_MePa, mu_s_BePa) fade with the slip speed v [m/s]:
    # without ``slip_speed``, fully while the contact sticks, exp(-(v / stick_speed)^2) (a few
    # mm/s: static friction only where the packaging does not slide); with it, as the velocity-
    # dependent friction law of multibody solvers' contacts: the whole offset up to stick_speed,
    # a cubic step down to none at slip_speed (e.g. stick_speed=0.1 slip_speed=1: the offset
    # acts on the slow sliding along a guide plate too)
    stick_speed: float = STICK_SPEED
    slip_speed: float | None = None
    # how the packaging's friction on belts, strips, rollers and plates is decided: "contact"
    # (each contact from its own slip: sticking contacts in MuJoCo's solver, sliding ones by hand,
    # friction.py) or "geom" (the model before 2026-12-01: MuJoCo's friction per surface, its
    # static offset switched by the parcel centre's speed on belts and by the last step's contacts
    # on plates, simulator._FrictionSwitch; with it ``belt_friction``, ``stick_speed`` and
    # ``slip_speed`` apply)
    friction: str = "contact"
    # the "contact" law's static and dynamic thresholds [m/s] (the published solver's defaults)
    static_threshold: float = STATIC_THRESHOLD
    dynamic_threshold: float = DYNAMIC_THRESHOLD
    # a time step [s] for runs on particular rigs, by rig name (e.g. {"E1": 1/4800}: the transfer
    # onto E1's fast belt converges more slowly than the rest, docs/research/transit-convergence.md); it
    # overrides ``timestep`` and the shell's default on those rigs
    rig_timesteps: Mapping[str, float] = field(default_factory=dict)
    start_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # dx [m], dy [m], dheading [deg]
    start_speed_factor: float = 1.0  # the parcel's initial speed as a fraction of its surface's
    # every mesh spacing (the packaging's, the film's, a soft content's vertices) and the time
    # step divided by this whole number, whatever set them (a scene option, the type's own, the
    # rig's): the model refined as a whole, to check that a result does not depend on its
    # discretisation (the calibration's convergence check). The shell's grid of cells, which
    # carries the packaging's bending, is the model's and stays
    refinement: int = 1

    def __post_init__(self) -> None:
        if self.timestep is not None:
            _check_step(self.timestep, "timestep")
        if not (float(self.refinement).is_integer() and 1 <= self.refinement <= MAX_REFINEMENT):
            raise ParcelfitError(
                f"refinement must be a whole number from 1 to {MAX_REFINEMENT}, got "
                f"{self.refinement}",
                fix="use 1 (the model as it is) or 2 (every mesh spacing and the step halved)",
            )
        object.__setattr__(self, "refinement", int(self.refinement))
        if not self.contact_frequency > 0:
            raise ParcelfitError(
                f"contact_frequency must be positive [rad/s], got {self.contact_frequency}"
            )
        if (
            self.contact_frequency_stiffness is not None
            and not self.contact_frequency_stiffness > 0
        ):
            raise ParcelfitError(
                "contact_frequency_stiffness must be positive [N/m] or None, got "
                f"{self.contact_frequency_stiffness}"
            )
        if self.contact_law not in CONTACT_LAWS:
            raise ParcelfitError(
                f"unknown contact_law {self.contact_law!r}", fix=f"use one of {list(CONTACT_LAWS)}"
            )
        if self.contact_mapping not in CONTACT_MAPPINGS:
            raise ParcelfitError(
                f"unknown contact_mapping {self.contact_mapping!r}",
                fix=f"use one of {list(CONTACT_MAPPINGS)}",
            )
        if self.contact_mapping == "solver" and self.contact_law != "penalty":
            raise ParcelfitError(
                "contact_mapping 'solver' maps the penalty law's stiffness, not the "
                f"{self.contact_law!r} law's",
                fix="use contact_law=penalty with it, or contact_mapping=vertex",
            )
        if self.shell_dof not in SHELL_DOFS:
            raise ParcelfitError(
                f"unknown shell_dof {self.shell_dof!r}", fix=f"use one of {list(SHELL_DOFS)}"
            )
        if self.shell_diagonals not in SHELL_DIAGONALS:
            raise ParcelfitError(
                f"unknown shell_diagonals {self.shell_diagonals!r}",
                fix=f"use one of {list(SHELL_DIAGONALS)}",
            )
        if self.shell_cells is not None:  # checked, and whole numbers (texts give floats)
            object.__setattr__(self, "shell_cells", shell_cells(self.shell_cells))
        if self.mass_lumping not in MASS_LUMPINGS:
            raise ParcelfitError(
                f"unknown mass_lumping {self.mass_lumping!r}",
                fix=f"use one of {list(MASS_LUMPINGS)}",
            )
        if self.roller_surface not in ROLLER_SURFACES:
            raise ParcelfitError(
                f"unknown roller_surface {self.roller_surface!r}",
                fix=f"use one of {list(ROLLER_SURFACES)}",
            )
        if self.belt_friction not in BELT_FRICTION:
            raise ParcelfitError(
                f"belt_friction must be mujoco or coulomb, got {self.belt_friction!r}"
            )
        for rig, step in self.rig_timesteps.items():
            _check_step(step, f"the time step for rig {rig}")
        if not self.stick_speed > 0:
            raise ParcelfitError(f"stick_speed must be positive [m/s], got {self.stick_speed}")
        if self.slip_speed is not None and not self.slip_speed > self.stick_speed:
            raise ParcelfitError(
                f"slip_speed must exceed stick_speed ({self.stick_speed} m/s) or be None, "
                f"got {self.slip_speed}"
            )
        if self.friction not in FRICTION_LAWS:
            raise ParcelfitError(f"unknown friction {self.friction!r}", fix="use contact or geom")
        if not 0 < self.static_threshold < self.dynamic_threshold:
            raise ParcelfitError(
                "the friction thresholds must satisfy 0 < static_threshold < dynamic_threshold "
                f"[m/s], got {self.static_threshold} and {self.dynamic_threshold}"
            )
        if self.friction == "contact" and self.belt_friction != "mujoco":
            raise ParcelfitError(
                "belt_friction applies to friction=geom only",
                fix="set friction=geom to use belt_friction=coulomb",
            )
        if self.cone not in ("elliptic", "pyramidal"):
            raise ParcelfitError(f"cone must be elliptic or pyramidal, got {self.cone!r}")
        if self.cone == "pyramidal" and self.friction == "contact":
            # MuJoCo builds a pyramid's rows with the friction coefficient in them before the
            # per-contact law could set it: the law would silently not act
            raise ParcelfitError(
                "the per-contact friction works with the elliptic cone only",
                fix="set cone=elliptic, or friction=geom to use the pyramidal cone",
            )
        if not (float(self.noslip_iterations).is_integer() and 0 <= self.noslip_iterations <= 1000):
            raise ParcelfitError(
                f"noslip_iterations must be a whole number from 0 to 1000, got {self.noslip_iterations}"
            )
        object.__setattr__(self, "noslip_iterations", int(self.noslip_iterations))
        if self.impratio is not None and not self.impratio >= 1:
            raise ParcelfitError(f"impratio must be at least 1, got {self.impratio}")
        if self.ccd_tolerance is not None and not self.ccd_tolerance > 0:
            raise ParcelfitError(
                f"ccd_tolerance must be positive [m] or None, got {self.ccd_tolerance}"
            )
        if not (float(self.content_tiles).is_integer() and 1 <= self.content_tiles <= 8):
            raise ParcelfitError(
                f"content_tiles must be a whole number from 1 to 8 (tiles per side of a rigid "
                f"content), got {self.content_tiles}"
            )
        object.__setattr__(self, "content_tiles", int(self.content_tiles))
        if self.content_kept is not None:
            if self.content_tiles == 1:
                raise ParcelfitError(
                    "content_kept shares the content's stiffness over its tiles' contacts; "
                    "give content_tiles above 1 with it"
                )
            most = MAX_CONTACTS_PER_PAIR * self.content_tiles**2
            if not (float(self.content_kept).is_integer() and 1 <= self.content_kept <= most):
                raise ParcelfitError(
                    f"content_kept must be a whole number of contacts from 1 to {most} (50 per "
                    f"tile), got {self.content_kept}"
                )
            object.__setattr__(self, "content_kept", int(self.content_kept))
        if self.contact_mapping == "solver" and self.content_tiles > 1:
            raise ParcelfitError(
                "content_tiles spread a rigid content's contacts over pairs to get round MuJoCo's "
                "cap, which contact_mapping 'solver' already weights for",
                fix="use content_tiles=1 with it, or contact_mapping=vertex",
            )
        if self.rim_brace is not None and not 0 <= self.rim_brace <= 10:
            raise ParcelfitError(
                f"rim_brace must lie in [0, 10] (a share of the ideal wedge), got {self.rim_brace}"
            )
        if self.membrane_cap is not None and not self.membrane_cap > 0:
            raise ParcelfitError(
                f"membrane_cap must be positive [N/m] or None, got {self.membrane_cap}"
            )
        if self.spacing is not None and not 0.003 <= self.spacing <= 0.2:
            raise ParcelfitError(
                f"mesh spacing must lie in [3, 200] mm, got {self.spacing * 1e3:g} mm"
            )
        if not 0.005 <= self.soft_shell_spacing <= 0.2:
            raise ParcelfitError(
                "film mesh spacing around a soft content must lie in [5, 200] mm, got "
                f"{self.soft_shell_spacing * 1e3:g} mm"
            )

    def impratio_for(self) -> float:
        """MuJoCo's impratio of this scene: ``impratio`` if set, else 1e4 with the penalty
        contact law and 1 with the impedance law."""
        if self.impratio is not None:
            return self.impratio
        return PENALTY_IMPRATIO if self.contact_law == "penalty" else 1.0

    def frequency_for(self, stiffness: float) -> float:
        """The angular frequency [rad/s] of a contact whose whole-face stiffness is ``stiffness``
        [N/m]: ``contact_frequency``, scaled by sqrt(stiffness / contact_frequency_stiffness)
        when that is set."""
        if self.contact_frequency_stiffness is None:
            return self.contact_frequency
        return self.contact_frequency * math.sqrt(stiffness / self.contact_frequency_stiffness)

    def shell_for(self, soft: bool, own: str | None = None) -> str:
        """The shell's degrees of freedom around a soft (True) or rigid content: ``shell_dof``
        if set, else the consignment's ``own`` choice (`Consignment.shell`), else full around
        a soft content and quadratic around a rigid one."""
        if self.shell_dof != "auto":
            return self.shell_dof
        if own is not None:
            return own
        return "full" if soft else "quadratic"

    def shell_of(self, consignment: Consignment) -> tuple[str, tuple[int, int, int]]:
        """The shell of ``consignment`` in this scene: its degrees of freedom (`shell_for`) and,
        for an interpolated shell, its grid of cells: ``shell_cells`` if set, else the type's
        own where the type's own shell is used, else one cell."""
        dof = self.shell_for(consignment.soft, consignment.shell)
        if dof == "full":
            return dof, (1, 1, 1)
        if self.shell_cells is not None:
            return dof, self.shell_cells
        if self.shell_dof == "auto" and consignment.shell is not None:
            return dof, consignment.shell_cells
        return dof, (1, 1, 1)

    def spacing_of(self, consignment: Consignment) -> float:
        """The shell's mesh spacing [m] for ``consignment``: around a soft content
        ``soft_shell_spacing``; around a rigid one ``spacing`` if set, else the type's own
        (``mesh_spacing``), else `DEFAULT_SPACING`; divided by ``refinement``."""
        if consignment.soft:
            base = self.soft_shell_spacing
        elif self.spacing is not None:
            base = self.spacing
        else:
            base = consignment.mesh_spacing or DEFAULT_SPACING
        return base / self.refinement

    def content_spacing(self) -> float:
        """The vertex spacing [m] of a soft content: ``soft_spacing`` divided by
        ``refinement``."""
        return self.soft_spacing / self.refinement

    def rim_brace_of(self, consignment: Consignment) -> float:
        """The share of an ideal wedge's stiffness the braces across the rim cells of
        ``consignment``'s shell take (`rim_brace`): ``rim_brace`` if set, else the type's own
        where its own shell and cells are used, else 0 (none)."""
        if self.rim_brace is not None:
            return self.rim_brace
        own = self.shell_dof == "auto" and consignment.shell is not None
        if own and self.shell_cells in (None, consignment.shell_cells):
            return consignment.rim_brace
        return 0.0

    def ccd_tolerance_for(self, soft: bool) -> float | None:
        """MuJoCo's convex-collision tolerance [m] for a scene with a soft (True) or rigid
        content: ``ccd_tolerance`` if set, else 1e-8 around a soft content and None (MuJoCo's
        own, 1e-6) around a rigid one."""
        if self.ccd_tolerance is not None:
            return self.ccd_tolerance
        return SOFT_CCD_TOLERANCE if soft else None

    def step_for(self, soft: bool, rig: Rig | None = None, own: str | None = None) -> float:
        """The time step [s] of a scene with a soft (True) or rigid content on ``rig``: the
        step ``rig_timesteps`` gives that rig, else ``timestep`` if given, else 1/1200 s for the
        full shell and 1/2400 s for an interpolated one (1/2400 s for the full shell too with
        Coulomb belt friction, whose explicit forces on the film's light vertices went unstable
        at 1/1200 s: E1 PB setting 1 turned 42 degrees and stalled, the simulator README's
        "Sliding"), divided by the rig's ``step_refinement``; ``own``: the consignment's shell
        (`shell_for`); every one divided by the scene's ``refinement``."""
        if rig is not None and rig.name in self.rig_timesteps:
            return self.rig_timesteps[rig.name] / self.refinement
        if self.timestep is not None:
            return self.timestep / self.refinement
        refinement = (rig.step_refinement if rig is not None else 1) * self.refinement
        if self.shell_for(soft, own) == "full" and self.belt_friction != "coulomb":
            return FULL_SHELL_STEP / refinement
        return INTERPOLATED_SHELL_STEP / refinement


def _number(text: str) -> float:
    return float(Fraction(text.strip()))


def parse_scene_options(items: Iterable[str]) -> dict[str, float | str | tuple[float, ...]]:
    """``KEY=VALUE`` texts (e.g. ``timestep=1/2400``, ``shell_dof=full``,
    ``start_offset=-0.0125,0.02165,0``) as `SceneOptions` keyword arguments: a value that reads
    as a number, a fraction included, becomes a float [the option's unit], comma-separated
    numbers a tuple of floats, any other value stays text."""
    out: dict[str, float | str | tuple[float, ...]] = {}
    for item in items:
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise ParcelfitError(
                f"scene option {item!r} is not KEY=VALUE", fix="write e.g. timestep=1/2400"
            )
        try:
            if "," in value:
                out[key.strip()] = tuple(_number(part) for part in value.split(","))
            else:
                out[key.strip()] = _number(value)
        except (ValueError, ZeroDivisionError):
            out[key.strip()] = value.strip()
    return out


def scene_options(items: Iterable[str]) -> SceneOptions:
    """`SceneOptions` from ``KEY=VALUE`` texts (`parse_scene_options`; units as the fields'),
    the defaults for the keys not given; an unknown key is refused with the fields' names."""
    given = parse_scene_options(items)
    unknown = sorted(set(given) - set(SceneOptions.__dataclass_fields__))
    if unknown:
        raise ParcelfitError(
            f"unknown scene option(s) {', '.join(unknown)}",
            fix=f"the keys are the fields of SceneOptions: {', '.join(SceneOptions.__dataclass_fields__)}",
        )
    return SceneOptions(**given)  # type: ignore[arg-type]
