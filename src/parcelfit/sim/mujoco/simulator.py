"""The MuJoCo backend: simulate a test case and read it back like the camera would see it.

Observation (every 1/sample_rate s, default 60 Hz like the camera): the shell's top-sheet
vertices over the content footprint stand in for the AprilTag on the parcel. Their centroid is
the parcel position (x, y) [m]; the heading theta [rad] is the 2-D least-squares rotation
(Kabsch) of their rest coordinates (x_i, y_i) onto the current offsets q_i from the centroid:

    theta = atan2( sum(x_i q_iy - y_i q_ix), sum(x_i q_ix + y_i q_iy) )

(rest coordinates in the parcel frame, offsets in the rig frame, so theta is the heading in the
rig frame), which is exact for rigid motion and averages out local wrinkles otherwise.

Light barriers: a beam is interrupted when the packaging vertices' (x, y) lie on both sides of
its line with some of them over the segment; the transit time is the time between the first
interruption of LS1 and of LS2, checked every step while the parcel's centre is within its
reach of the beam's line (farther away no vertex can meet it within a step). Within the step
of the interruption the time is interpolated linearly: with s_i the signed distances [m] of the
vertices over the segment to the beam's line, the beam's margin g = min(max_i s_i, -min_i s_i)
is negative while all lie on one side and reaches 0 as the first one crosses, so the beam broke at
t_prev + dt * g_prev / (g_prev - g_now). (Counting whole steps made transit times multiples of
the step, a floor of one step on every transit difference.)

Static friction offset (mu_s_*): every step, the friction of each metal geom is set to
mu_d + offset * S, where S is the stick factor of its contacts in the step before,

    S = sum_k f_k exp(-(v_k / v_stick)^2) / sum_k f_k,

f_k the normal force and v_k the tangential slip speed of contact k with that geom (the
contact's tangential constraint velocities), v_stick = 5 mm/s: a corner of the packaging that
catches on a guide plate sticks there and raises that plate's friction, while a packaging that
slides along it keeps mu_d. For belts and rollers S uses the parcel's speed relative to the belt
under its centre (a parcel rides on a belt as a whole). MuJoCo has one Coulomb coefficient per
contact and its discrete integrator recomputes the contacts inside the step, so the switch acts
per geom with a one-step lag rather than per contact.

Status: ``unstable`` on NaN, MuJoCo's bad-acceleration warning, a speed above 20 m/s, or the
parcel falling 0.2 m below the lowest surface; ``timeout`` when the wall-clock limit passes;
``ok`` otherwise (the run ends when the centre leaves the rig's end box, some time after both
LS1 and LS2 broke, or at the rig's duration).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import Run, TestCase, Trajectory
from parcelfit.sim.crossings import crossing_diagnostics, judge_crossings, too_short_words
from parcelfit.sim.mujoco.backend import RigBackend
from parcelfit.sim.mujoco.consignment import Consignment
from parcelfit.sim.mujoco.friction import Stepper
from parcelfit.sim.mujoco.mjlog import CountedWarnings
from parcelfit.sim.mujoco.options import SceneOptions
from parcelfit.sim.mujoco.rig import Barrier, Rig, Surface
from parcelfit.sim.mujoco.scene import Scene, build_scene
from parcelfit.sim.protocol import SimResult, SimStatus

MAX_SPEED = 20.0  # m/s
FALL_DEPTH = 0.2  # m
# a beam is checked only while the parcel's centre is within its reach (the rest shell's largest
# distance from the centre) plus this much of the beam's line: more than the packaging deforms
# and moves in one step (MAX_SPEED * dt is 17 mm at 1/1200 s), so skipping farther steps never
# skips an interruption or the clear step before it, and costs nothing per step far away
BEAM_SKIP_MARGIN = 0.05  # m


@dataclass(frozen=True)
class SimOptions:
    """Run settings: scene numerics, sampling rate [Hz], wall-clock limit [s], frame recording."""

    scene: SceneOptions = field(default_factory=SceneOptions)
    sample_rate: float = 60.0
    wall_limit: float = 600.0
    record_vertices: bool = False  # keep the shell's vertex positions per sample (for animations)
    duration: float | None = None  # override the rig's duration [s]
    placement_seed: int | None = None  # draw the start pose from the rig's scatter (None: nominal)


@dataclass(frozen=True)
class Frames:
    """Per-sample vertex positions of the shell (n_samples, n_vertices, 3) [m], for animations."""

    t: np.ndarray
    vertices: np.ndarray
    triangles: np.ndarray


class _Beam:
    """A light barrier's beam, from its ends [m]: the margin of the packaging's points over it
    and the distance of a point from its line (computed on every step near it)."""

    def __init__(self, barrier: Barrier) -> None:
        self.a = np.asarray(barrier.start, dtype=float)
        self.d = np.asarray(barrier.end, dtype=float) - self.a
        self.d2 = float(self.d @ self.d)
        self.normal = np.array([-self.d[1], self.d[0]]) / math.sqrt(self.d2)

    def margin(self, xy: np.ndarray) -> float | None:
        """The beam's margin [m]: min(max s_i, -min s_i) over the signed distances s_i of the
        points ``xy`` [m] over the beam's segment to its line; >= 0 when the beam is interrupted
        (points on both sides), minus the nearest point's distance otherwise; None when no
        point is over it."""
        rel = xy - self.a
        along = (rel @ self.d) / self.d2
        over = (along >= 0) & (along <= 1)
        if not over.any():
            return None
        side = rel[over] @ self.normal
        return float(min(side.max(), -side.min()))

    def distance(self, point: np.ndarray) -> float:
        """|n . (point - a)|: the distance [m] of ``point`` [m] from the beam's (infinite) line."""
        return abs(float(self.normal @ (point - self.a)))


def _crossing_time(previous: tuple[float, float] | None, t_now: float, margin_now: float) -> float:
    """The time [s] the beam broke: interpolated within the step from the last uninterrupted
    (time [s], margin [m]) to ``margin_now`` >= 0 at ``t_now`` [s], else ``t_now``."""
    if previous is None:
        return t_now
    t_prev, margin_prev = previous
    if not (margin_prev < 0 <= margin_now and t_prev < t_now):
        return t_now
    return t_prev + (t_now - t_prev) * margin_prev / (margin_prev - margin_now)


class MujocoSimulator(RigBackend[SimOptions]):
    """Simulator backend on MuJoCo for bundled or user rigs and consignments (see module doc)."""

    def __init__(
        self,
        options: SimOptions | None = None,
        rigs: Mapping[str, Rig] | None = None,
        consignments: Mapping[str, Consignment] | None = None,
    ) -> None:
        super().__init__(options or SimOptions(), rigs, consignments)

    def with_speed_factors(self, factors: Mapping[str, float]) -> MujocoSimulator:
        """The same simulator with each drive's speed times its factor [-] (the scene's
        ``speed_factors``)."""
        return self.with_options(scene=replace(self.options.scene, speed_factors=dict(factors)))

    def with_refinement(self, factor: int) -> MujocoSimulator:
        """The same model refined ``factor`` times over: every mesh spacing and the time step
        divided by it (`SceneOptions.refinement`), on top of any refinement it has; its
        wall-clock limit times factor^3 (a film's vertices grow as its square, the steps as
        itself), so that a refined run is not cut short where the model's own finishes."""
        scene = self.options.scene
        return self.with_options(
            scene=replace(scene, refinement=scene.refinement * factor),
            wall_limit=self.options.wall_limit * factor**3,
        )

    def scene_options(self, rig: Rig) -> SceneOptions:
        """The scene settings of a run on ``rig``: the placement draw added to the start offset
        (the step on the rig follows from them, `SceneOptions.step_for`)."""
        opt = self.options.scene
        if self.options.placement_seed is None:
            return opt
        dx, dy, dh = rig.placement(self.options.placement_seed)
        x0, y0, h0 = opt.start_offset
        return replace(opt, start_offset=(x0 + dx, y0 + dy, h0 + dh))

    def scene(self, params: Mapping[str, float], case: TestCase) -> Scene:
        """The MJCF scene for SI ``params`` (defaults filled in) and a test case."""
        cons = self.consignment(case.consignment)
        rig = self.rig(case.rig)
        full = cons.parameter_values(si_values=params)
        return build_scene(rig, cons, full, case.speed_setting, self.scene_options(rig))

    def run(
        self, params: Mapping[str, float], case: TestCase, run_id: str | None = None
    ) -> SimResult:
        """Simulate ``case`` with SI ``params``; see the module docstring for what is measured."""
        result, _ = self.run_with_frames(params, case, run_id)
        return result

    def run_with_frames(
        self, params: Mapping[str, float], case: TestCase, run_id: str | None = None
    ) -> tuple[SimResult, Frames | None]:
        """As `run`, also returning the shell's vertex positions per sample if recorded."""
        t_wall = time.perf_counter()
        rig = self.rig(case.rig)
        cons = self.consignment(case.consignment)
        full = cons.parameter_values(si_values=params)
        scene = build_scene(rig, cons, full, case.speed_setting, self.scene_options(rig))
        with CountedWarnings() as warnings:
            try:
                model = scene.model()
            except ValueError as exc:
                return SimResult(
                    None,
                    SimStatus.FAILED,
                    time.perf_counter() - t_wall,
                    {"message": f"MuJoCo rejected the scene: {exc}"},
                ), None
            result, frames = self._simulate(model, scene, rig, full, case, run_id, t_wall)
        result.diagnostics["mujoco_warnings"] = warnings.count  # type: ignore[index]
        if warnings.first:
            result.diagnostics["first_mujoco_warning"] = warnings.first  # type: ignore[index]
        return result, frames

    def _simulate(
        self,
        model: mujoco.MjModel,
        scene: Scene,
        rig: Rig,
        params: Mapping[str, float],
        case: TestCase,
        run_id: str | None,
        t_wall: float,
    ) -> tuple[SimResult, Frames | None]:
        opt = self.options
        data = mujoco.MjData(model)
        dt = model.opt.timestep
        flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
        adr, num = model.flex_vertadr[flex], model.flex_vertnum[flex]
        points = scene.shell.points[:, :2]
        centre0 = points[scene.shell.top].mean(axis=0)
        rest = points[scene.shell.top] - centre0
        n_top = len(rest)
        reach = float(np.max(np.linalg.norm(points - centre0, axis=1))) + BEAM_SKIP_MARGIN
        beams = [_Beam(b) for b in rig.barriers]
        _set_velocity(model, data, np.asarray(scene.start_velocity))

        stepper = Stepper(model, data, scene, params, opt.scene)
        friction = (
            _FrictionSwitch(model, scene, rig, params, opt.scene.stick_speed, opt.scene.slip_speed)
            if opt.scene.friction == "geom"
            else None
        )
        duration = opt.duration if opt.duration is not None else rig.end.duration
        n_steps = round(duration / dt)
        every = max(1, round(1.0 / (opt.sample_rate * dt)))
        lowest = min(s.top for s in rig.surfaces) - FALL_DEPTH
        (x_lo, x_hi), (y_lo, y_hi) = rig.end.x, rig.end.y
        crossed: list[float | None] = [None, None]
        # each beam's last uninterrupted (time [s], margin [m]), for the crossing within a step
        clear: list[tuple[float, float] | None] = [None, None]
        samples: list[tuple[float, float, float, float]] = []
        frames: list[np.ndarray] = []
        status, message = SimStatus.OK, "reached the end of the run"
        prev_c: np.ndarray | None = None
        stop_at = n_steps
        step = 0
        while True:
            # mj_step computes positions (flexvert_xpos) before it integrates, so after a step
            # they belong to the time one step back: label them with that time
            pos_step = max(step - 1, 0)
            t_pos = pos_step * dt
            verts = data.flexvert_xpos[adr : adr + num]
            top = verts[scene.shell.top]
            c = np.add.reduce(top[:, :2], axis=0) / n_top  # the centroid, as mean() computes it
            if pos_step % every == 0 and step != 1:
                q = top[:, :2] - c
                theta = math.atan2(
                    float(np.sum(rest[:, 0] * q[:, 1] - rest[:, 1] * q[:, 0])),
                    float(np.sum(rest[:, 0] * q[:, 0] + rest[:, 1] * q[:, 1])),
                )
                samples.append((t_pos, float(c[0]), float(c[1]), theta))
                if opt.record_vertices:
                    frames.append(verts.copy())
                if (
                    not np.all(np.isfinite(verts))
                    or data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
                ):
                    status, message = (
                        SimStatus.UNSTABLE,
                        "numerical blow-up (NaN or bad acceleration)",
                    )
                    break
                if float(top[:, 2].mean()) < lowest:
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
            if step >= stop_at:
                break
            for k, beam in enumerate(beams):
                if crossed[k] is not None:  # each beam on its own: the order is checked after
                    continue
                if beam.distance(c) > reach:  # no vertex near the beam's line
                    clear[k] = None
                    continue
                margin = beam.margin(verts[:, :2])
                if margin is None:
                    clear[k] = None
                elif margin < 0:
                    clear[k] = (t_pos, margin)
                elif pos_step == 0:
                    # broken already at the start: crossed before the run, at no time it shows
                    # (as tracking leaves out a beam broken in the first frame)
                    crossed[k] = math.inf
                else:
                    crossed[k] = _crossing_time(clear[k], t_pos, margin)
                    if len(beams) == 2 and None not in crossed:  # both broken: end soon
                        stop_at = min(n_steps, step + round(rig.end.after_last_barrier / dt))
            if prev_c is not None:
                speed_vec = (c - prev_c) / dt
                if float(np.hypot(*speed_vec)) > MAX_SPEED:
                    status, message = (
                        SimStatus.UNSTABLE,
                        "energy blow-up (parcel faster than 20 m/s)",
                    )
                    break
                if friction is not None:
                    friction.update(model, data, c, speed_vec)
            prev_c = c.copy()
            stepper.step()
            step += 1
        wall = time.perf_counter() - t_wall
        judged = judge_crossings(crossed, rig.barriers)
        transit = judged.transit
        if judged.out_of_order and status is SimStatus.OK:
            status, message = SimStatus.FAILED, str(judged.note)
        diagnostics: dict[str, object] = {
            "message": message,
            "steps": step,
            "simulated_time": float(data.time),
            "steps_per_second": step / wall if wall > 0 else float("nan"),
            **crossing_diagnostics(judged),
            **stepper.diagnostics(),
            # MuJoCo flags a step whose effective-inertia (M + K for flexes) solve is singular or
            # under-converged with mjWARN_INERTIA; it prints the first only, but counts them all
            "under_converged_steps": int(data.warning[mujoco.mjtWarning.mjWARN_INERTIA].number),
        }
        run = None
        if len(samples) >= 3 and status is not SimStatus.UNSTABLE:
            arr = np.asarray(samples)
            try:
                traj = Trajectory.from_arrays(arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3])
                run = Run(
                    run_id or f"sim-{case.rig}-{case.consignment}-{case.speed_setting}",
                    case,
                    traj,
                    transit,
                )
            except ParcelfitError as exc:
                status, diagnostics["message"] = SimStatus.UNSTABLE, f"unusable trajectory: {exc}"
        if run is None and status is SimStatus.OK:
            status = SimStatus.FAILED
            diagnostics["message"] = too_short_words(message, len(samples))
        result = SimResult(run, status, wall, diagnostics)
        rec = None
        if opt.record_vertices and frames:
            rec = Frames(
                np.asarray([s[0] for s in samples[: len(frames)]]),
                np.asarray(frames),
                scene.shell.triangles,
            )
        return result, rec


def add_rigid_velocity(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    linear: np.ndarray,
    w: float = 0.0,
    centre: np.ndarray | None = None,
) -> None:
    """Add the rigid velocity ``linear + w e_z x (x - centre)`` [m/s, rad/s, m] to every free
    and slide joint (content, shell vertices or nodes); positions must be computed."""
    spin = np.array([0.0, 0.0, w])
    c = np.zeros(3) if centre is None else centre
    for j in range(model.njnt):
        a = model.jnt_dofadr[j]
        body = model.jnt_bodyid[j]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            data.qvel[a : a + 3] += linear + np.cross(spin, data.xpos[body] - c)
            data.qvel[a + 3 : a + 6] += data.xmat[body].reshape(3, 3).T @ spin
        elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE:
            v = linear + np.cross(spin, data.xpos[body] - c)
            data.qvel[a] += float(np.dot(data.xaxis[j], v))
    mujoco.mj_forward(model, data)


def _set_velocity(model: mujoco.MjModel, data: mujoco.MjData, v: np.ndarray) -> None:
    """Give every degree of freedom (at rest) the world velocity ``v`` [m/s]."""
    mujoco.mj_forward(model, data)
    add_rigid_velocity(model, data, v)


class _FrictionSwitch:
    """Raise a surface's friction by the static offset while the packaging sticks to it."""

    def __init__(
        self,
        model: mujoco.MjModel,
        scene: Scene,
        rig: Rig,
        params: Mapping[str, float],
        stick_speed: float,
        slip_speed: float | None,
    ) -> None:
        self.stick_speed, self.slip_speed = stick_speed, slip_speed
        metal_ids = np.array([model.geom(n).id for n in scene.metal_geoms], dtype=int)
        self.metal = (
            (metal_ids, params["mu_d_MePa"], params["mu_s_MePa"])
            if params["mu_s_MePa"] > 0 and metal_ids.size
            else None
        )
        self.belts: list[tuple[int, np.ndarray, Surface]] = []
        if params["mu_s_BePa"] > 0:
            self.belts = [
                (model.geom(g.name).id, np.asarray(g.velocity[:2]), rig.surface(g.surface))
                for g in scene.driven
                if g.material != "metal"
            ]
        self.belt_area = _Rectangles([surface for _, _, surface in self.belts])
        self.mu_belt = (params["mu_d_BePa"], params["mu_s_BePa"])

    def _stick(self, slip: np.ndarray | float) -> np.ndarray | float:
        """The share of the static offset at slip speed ``slip`` [m/s]: without a slip speed 1
        while the contact sticks, falling to 0 above a few stick speeds (Gaussian); with one, 1
        up to the stick speed, then a cubic step (3 u^2 - 2 u^3 falling) to 0 at the slip
        speed."""
        v = np.asarray(slip)
        if self.slip_speed is None:
            return np.exp(-((v / self.stick_speed) ** 2))
        u = np.clip((v - self.stick_speed) / (self.slip_speed - self.stick_speed), 0.0, 1.0)
        return 1.0 - u * u * (3.0 - 2.0 * u)

    def update(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        centre: np.ndarray,
        velocity: np.ndarray,
    ) -> None:
        """Set the friction of the switched geoms from the last step's contacts (walls) and the
        parcel's centre [m] and velocity [m/s] (belts)."""
        if self.metal is not None:
            ids, mu_d, offset = self.metal
            n = data.ncon
            geoms = data.contact.geom[:n]
            for gid in ids:
                on = np.flatnonzero((geoms[:, 0] == gid) | (geoms[:, 1] == gid))
                stick = 0.0
                if on.size:
                    adr = data.contact.efc_address[on]
                    valid = adr >= 0
                    adr = adr[valid]
                    if adr.size:
                        force = np.maximum(data.efc_force[adr], 0.0)
                        slip = np.hypot(data.efc_vel[adr + 1], data.efc_vel[adr + 2])
                        total = float(force.sum())
                        if total > 0:
                            stick = float(np.sum(force * self._stick(slip)) / total)
                model.geom_friction[gid, 0] = mu_d + offset * stick
        if not self.belts:
            return
        mu_d, offset = self.mu_belt
        inside = self.belt_area.contain(centre)
        for (gid, v_surface, _), over in zip(self.belts, inside, strict=True):
            stick = float(self._stick(float(np.hypot(*(velocity - v_surface))))) if over else 0.0
            model.geom_friction[gid, 0] = mu_d + offset * stick


class _Rectangles:
    """The rectangles of some surfaces, to test which lie under a point. It runs on every step,
    so each rectangle is kept as plain floats (a few surfaces: scalar arithmetic is faster than
    building arrays)."""

    def __init__(self, surfaces: list[Surface]) -> None:
        self.rects = [
            (*map(float, s.centre), *map(float, s.unit()), s.length / 2, s.width / 2)
            for s in surfaces
        ]

    def contain(self, point: np.ndarray) -> list[bool]:
        """Which rectangles (in order) ``point`` [m] lies over, edges included."""
        px, py = float(point[0]), float(point[1])
        out = []
        for cx, cy, ux, uy, half_length, half_width in self.rects:
            rx, ry = px - cx, py - cy
            out.append(
                abs(rx * ux + ry * uy) <= half_length and abs(ry * ux - rx * uy) <= half_width
            )
        return out


__all__ = ["Frames", "MujocoSimulator", "SimOptions"]
