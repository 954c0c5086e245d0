"""The rigid-box reference as a `Simulator` backend: a rig and a consignment in, a run sampled
like the camera out (`parcelfit.sim.protocol`).

A run: the parcel starts on its start surface (``rig.start``: the centre `Rig.start_centre`
gives for the consignment's outline, the heading, plus the placement draw of ``placement_seed``
(`Rig.placement`) and ``start_offset``), its bottom face on the surface's top, moving with
that surface's speed (times ``speed_factors`` of its drive and ``start_speed_factor``), as the
MuJoCo scene starts it. Every 1/sample_rate s (60 Hz) the box
centre (x, y) and the heading of its x axis projected onto the plane, theta = atan2(R_yx, R_xx),
are sampled (a `Trajectory`, unwrapped). The light barriers are timed every step (the box's
footprint, `integrator`), and the run ends as the MuJoCo simulator's does: when the centre leaves
the rig's end box (checked at the samples), ``after_last_barrier`` s after both beams
broke, or after the rig's duration (``duration`` overrides it).

Status: ``unstable`` on a non-finite state, a speed above 20 m/s or the centre falling 0.2 m
below the lowest surface's top; ``timeout`` when ``wall_limit`` passes (checked at the samples);
``ok`` otherwise.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import Run, TestCase, Trajectory
from parcelfit.sim.crossings import crossing_diagnostics, judge_crossings, too_short_words
from parcelfit.sim.mujoco.backend import RigBackend
from parcelfit.sim.mujoco.consignment import Consignment
from parcelfit.sim.mujoco.rig import Rig
from parcelfit.sim.params import BOTTOM_PATCHES, WALL_CONTACTS, WALL_DAMPINGS
from parcelfit.sim.protocol import SimResult, SimStatus
from parcelfit.sim.rigidbox import integrator as ig
from parcelfit.sim.rigidbox.contact import law_array
from parcelfit.sim.rigidbox.engine import GRAVITY, Motion, World, yaw_quaternion
from parcelfit.sim.rigidbox.geometry import (
    METAL,
    ROLLER_SURFACES,
    check_walls,
    parcel_body,
    resolved_bottom_patch,
    rig_primitives,
    rim_bending_length,
)

# the parameters the reference's world is built from (`RigidBoxSimulator.world`; E_Pa, t_Pa and
# nu_Pa only on the rim-bending patch, where they set how far the rim's bending passes the
# content's load on); the others (k_CoPa, the content's stiffness, ...) belong to a shell it
# does not have
PARAMETERS = (
    "m_Pa",
    "E_Pa",
    "t_Pa",
    "nu_Pa",
    "k_BePa",
    "k_MePa",
    "zeta_BePa",
    "zeta_MePa",
    "mu_d_BePa",
    "mu_d_MePa",
    "mu_s_BePa",
    "mu_s_MePa",
)
RIM_BENDING_PARAMETERS = ("E_Pa", "t_Pa", "nu_Pa")  # read on the rim-bending patch only
FALL_DEPTH = 0.2  # m
MAX_STEP = 1e-5  # s, the largest default step
OMEGA_DT = 0.1  # the default step keeps omega_max * dt at most this
# the friction's static and dynamic threshold speeds [m/s] (RecurDyn's defaults: 1 and 1.5 mm/s)
STICK_SPEED = 0.001
SLIP_SPEED = 0.0015


@dataclass(frozen=True)
class RigidBoxOptions:
    """Numerical settings of the rigid-box reference (not calibrated).

    ``timestep`` [s] (None: the default of `step_for`), ``step_divisor`` (the default step divided
    by this whole number, to check a result's convergence in it), ``spacing`` [m] of the contact
    points,
    ``bottom_patch`` (``consignment``, ``outline``, ``content``, ``rim-weight`` or
    ``rim-bending``, `geometry`; the rim's bending from E_Pa, t_Pa, nu_Pa and k_BePa),
    the friction's static and dynamic
    threshold speeds ``stick_speed`` < ``slip_speed`` [m/s], ``speed_factors`` (drive ->
    factor), ``roller_surface`` (``linear`` or ``turning``), ``wall_contact`` (``outline``: walls
    met by the parcel's outline, or ``points``: by its contact points; `geometry`),
    ``wall_outline`` (with walls met by the outline: ``outline``, the packaging's, or
    ``content``, the content's: a rim that gives way at a wall; `geometry`), ``wall_inset`` [m]
    (with ``outline``: the outline inset by this on every side, a rim that gave way so far),
    ``wall_damping`` (``ratio``: a wall's and a lead-in's contact damped at the ratio zeta of its
    own stiffness, or ``area``: per unit area as the points; `contact`), the start's
    ``start_offset`` (dx [m], dy [m], dheading [deg]) and ``start_speed_factor``,
    ``sample_rate`` [Hz], ``wall_limit`` [s], ``duration`` [s] (None: the rig's),
    ``placement_seed`` (None: the nominal start pose), ``gravity`` [m/s^2]."""

    timestep: float | None = None
    step_divisor: int = 1
    spacing: float = 0.01
    bottom_patch: str = "consignment"
    stick_speed: float = STICK_SPEED
    slip_speed: float = SLIP_SPEED
    speed_factors: Mapping[str, float] = field(default_factory=dict)
    roller_surface: str = "linear"
    wall_contact: str = "outline"
    wall_outline: str = "outline"
    wall_inset: float = 0.0
    wall_damping: str = "ratio"
    start_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start_speed_factor: float = 1.0
    sample_rate: float = 60.0
    wall_limit: float = 600.0
    duration: float | None = None
    placement_seed: int | None = None
    gravity: float = GRAVITY

    def __post_init__(self) -> None:
        if self.timestep is not None and not 1e-7 <= self.timestep <= 1e-3:
            raise ParcelfitError(f"timestep must lie in [1e-7, 1e-3] s, got {self.timestep}")
        if not (isinstance(self.step_divisor, int) and 1 <= self.step_divisor <= 64):
            raise ParcelfitError(
                f"step_divisor must be a whole number in [1, 64], got {self.step_divisor!r}"
            )
        for key, allowed in (
            ("bottom_patch", BOTTOM_PATCHES),
            ("roller_surface", ROLLER_SURFACES),
            ("wall_contact", WALL_CONTACTS),
            ("wall_damping", WALL_DAMPINGS),
        ):
            value = getattr(self, key)
            if value not in allowed:
                raise ParcelfitError(f"unknown {key} {value!r}", fix=f"use one of {list(allowed)}")
        check_walls(self.wall_outline, self.wall_inset)
        moved = self.wall_outline != "outline" or self.wall_inset > 0
        if moved and self.wall_contact != "outline":
            raise ParcelfitError(
                f"wall_outline {self.wall_outline!r} and wall_inset {self.wall_inset:g} m move the "
                f"outline walls meet: they need wall_contact outline, got {self.wall_contact!r}",
                fix="set wall_contact: outline, or leave wall_outline at 'outline' and wall_inset 0",
            )
        if not 0 < self.stick_speed < self.slip_speed:
            raise ParcelfitError(
                f"need 0 < stick_speed < slip_speed, got {self.stick_speed}, {self.slip_speed} m/s"
            )
        if not self.sample_rate > 0:
            raise ParcelfitError(f"sample_rate must be positive [Hz], got {self.sample_rate}")

    def step_for(self, stiffness: float, mass: float) -> float:
        """The time step [s]: ``timestep`` if given, else the largest 1 / (sample_rate n) (n
        whole) with omega_max dt <= 0.1, omega_max = sqrt(stiffness / mass) (the stiffest
        whole-face contact [N/m] and the parcel's mass [kg]), and dt <= 1e-5 s; that divided by
        ``step_divisor`` (the samples still fall on steps)."""
        if self.timestep is not None:
            return self.timestep
        limit = min(MAX_STEP, OMEGA_DT / math.sqrt(stiffness / mass))
        n = math.ceil(1.0 / (self.sample_rate * limit) - 1e-9)
        return 1.0 / (self.sample_rate * n * self.step_divisor)


class RigidBoxSimulator(RigBackend[RigidBoxOptions]):
    """The rigid-box reference backend for bundled or user rigs and consignments (module doc)."""

    def __init__(
        self,
        options: RigidBoxOptions | None = None,
        rigs: Mapping[str, Rig] | None = None,
        consignments: Mapping[str, Consignment] | None = None,
    ) -> None:
        super().__init__(options or RigidBoxOptions(), rigs, consignments)

    def with_speed_factors(self, factors: Mapping[str, float]) -> RigidBoxSimulator:
        """The same reference with each drive's speed times its factor [-]."""
        return self.with_options(speed_factors=dict(factors))

    def with_refinement(self, factor: int) -> RigidBoxSimulator:
        """The same reference refined ``factor`` times over: its contact points' spacing and its
        time step divided by it, its wall-clock limit times factor^3 (points as its square,
        steps as itself)."""
        opt = self.options
        if opt.timestep is not None:
            step: dict[str, Any] = {"timestep": opt.timestep / factor}
        else:
            step = {"step_divisor": opt.step_divisor * factor}
        return self.with_options(
            spacing=opt.spacing / factor, wall_limit=opt.wall_limit * factor**3, **step
        )

    def world(self, params: Mapping[str, float], case: TestCase) -> tuple[World, float]:
        """The world of ``case`` with SI ``params`` (defaults filled in) and its time step [s]."""
        opt = self.options
        rig, cons = self.rig(case.rig), self.consignment(case.consignment)
        p = cons.parameter_values(si_values=params)
        length = 0.0
        if resolved_bottom_patch(cons, opt.bottom_patch) == "rim-bending":
            L, W, _ = cons.outer
            length = rim_bending_length(p["E_Pa"], p["t_Pa"], p["nu_Pa"], p["k_BePa"], L * W)
        body = parcel_body(
            cons, p["m_Pa"], opt.spacing, opt.bottom_patch, length, opt.wall_outline, opt.wall_inset
        )
        prims = rig_primitives(
            rig, case.speed_setting, opt.speed_factors, opt.roller_surface, opt.wall_contact
        )
        law = law_array(
            (p["k_BePa"], p["k_MePa"]),
            (p["zeta_BePa"], p["zeta_MePa"]),
            (p["mu_d_BePa"], p["mu_d_MePa"]),
            (p["mu_s_BePa"], p["mu_s_MePa"]),
            body.mass,
            body.bottom_area,
            opt.wall_damping,
        )
        stiffness = p["k_BePa"]
        if np.any(prims.material == METAL):
            stiffness = max(stiffness, p["k_MePa"])
        world = World(body, prims, law, opt.stick_speed, opt.slip_speed, opt.gravity)
        return world, opt.step_for(stiffness, body.mass)

    def start(self, rig: Rig, case: TestCase, half_height: float) -> dict[str, np.ndarray]:
        """The start pose and velocity of a run on ``rig`` (module docstring)."""
        opt = self.options
        dx, dy, dh = opt.start_offset
        if opt.placement_seed is not None:
            px, py, ph = rig.placement(opt.placement_seed)
            dx, dy, dh = dx + px, dy + py, dh + ph
        surface = rig.surface(rig.start.surface)
        speed = (
            rig.drive_speeds(case.speed_setting)[surface.drive]
            * opt.speed_factors.get(surface.drive, 1.0)
            * opt.start_speed_factor
        )
        u = surface.unit()
        outer = self.consignment(case.consignment).outer
        cx, cy = rig.start_centre(outer[0], outer[1])
        return {
            "position": np.array([cx + dx, cy + dy, surface.top + half_height]),
            "quaternion": yaw_quaternion(rig.start.heading + dh),
            "velocity": np.array([speed * u[0], speed * u[1], 0.0]),
        }

    def run(
        self, params: Mapping[str, float], case: TestCase, run_id: str | None = None
    ) -> SimResult:
        """Simulate ``case`` with SI ``params``; see the module docstring."""
        t_wall = time.perf_counter()
        opt = self.options
        rig = self.rig(case.rig)
        world, dt = self.world(params, case)
        motion = Motion(
            world,
            **self.start(rig, case, float(world.body.half[2])),
            barriers=rig.barriers,
            after_last_barrier=rig.end.after_last_barrier,
        )
        duration = opt.duration if opt.duration is not None else rig.end.duration
        n_steps = round(duration / dt)
        motion.counters[2] = n_steps  # stop at the duration at the latest
        every = max(1, round(1.0 / (opt.sample_rate * dt)))
        lowest = min(s.top for s in rig.surfaces) - FALL_DEPTH
        (x_lo, x_hi), (y_lo, y_hi) = rig.end.x, rig.end.y
        samples = [(0.0, float(motion.x[0]), float(motion.x[1]), motion.heading)]
        status, message = SimStatus.OK, "reached the end of the run"
        while True:
            code = motion.advance(dt, every)
            if code == ig.NOT_FINITE:
                status, message = SimStatus.UNSTABLE, "numerical blow-up (non-finite state)"
                break
            if code == ig.TOO_FAST:
                status, message = SimStatus.UNSTABLE, "energy blow-up (parcel faster than 20 m/s)"
                break
            step = motion.steps
            if step % every == 0:
                samples.append((step * dt, float(motion.x[0]), float(motion.x[1]), motion.heading))
            if code == ig.STOPPED:
                break
            c = motion.x
            if c[2] < lowest:
                status, message = SimStatus.UNSTABLE, "the parcel fell off the rig"
                break
            if not (x_lo <= c[0] <= x_hi and y_lo <= c[1] <= y_hi):
                message = "the parcel left the rig's end box"
                break
            if time.perf_counter() - t_wall > opt.wall_limit:
                status, message = (
                    SimStatus.TIMEOUT,
                    f"wall-clock limit of {opt.wall_limit:g} s reached",
                )
                break
        wall = time.perf_counter() - t_wall
        # each beam's time, None if never broken, inf if broken at the start (`sim.crossings`)
        judged = judge_crossings(
            [None if math.isnan(t) else float(t) for t in motion.crossed[: len(rig.barriers)]],
            rig.barriers,
        )
        transit = judged.transit
        if judged.out_of_order and status is SimStatus.OK:
            status, message = SimStatus.FAILED, str(judged.note)
        diagnostics: dict[str, object] = {
            "message": message,
            "steps": motion.steps,
            "simulated_time": motion.steps * dt,
            "timestep": dt,
            "steps_per_second": motion.steps / wall if wall > 0 else float("nan"),
            **crossing_diagnostics(judged),
            "contact_points": len(world.body.points),
        }
        run = None
        if len(samples) >= 3 and status is not SimStatus.UNSTABLE:
            arr = np.asarray(samples)
            traj = Trajectory.from_arrays(arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3])
            run = Run(
                run_id or f"rigidbox-{case.rig}-{case.consignment}-{case.speed_setting}",
                case,
                traj,
                transit,
            )
        if run is None and status is SimStatus.OK:
            status = SimStatus.FAILED
            diagnostics["message"] = too_short_words(message, len(samples))
        return SimResult(run, status, wall, diagnostics)


__all__ = ["RigidBoxOptions", "RigidBoxSimulator"]
