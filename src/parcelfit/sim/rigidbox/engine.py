"""The rigid box in its world, stepped by the numba integrator: `World` (body, primitives, contact
law, gravity) and `Motion` (one body's state and its integration, with optional light barriers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import Barrier
from parcelfit.sim.rigidbox import integrator as ig
from parcelfit.sim.rigidbox.geometry import Body, Primitives

GRAVITY = 9.81  # m/s^2, MuJoCo's default


@dataclass(frozen=True)
class World:
    """The parcel's body, the static primitives, the contact law (per material: K / A_b, damping
    per area, mu_d, mu_s; `contact.law_array`), the friction's static and dynamic threshold
    speeds v_s < v_d [m/s] and gravity [m/s^2]."""

    body: Body
    primitives: Primitives
    law: np.ndarray
    stick_speed: float
    slip_speed: float
    gravity: float = GRAVITY

    def __post_init__(self) -> None:
        if not 0 < self.stick_speed < self.slip_speed:
            raise ParcelfitError(
                f"the friction's threshold speeds must satisfy 0 < v_s < v_d, got "
                f"v_s = {self.stick_speed}, v_d = {self.slip_speed} m/s"
            )


def yaw_quaternion(deg: float) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of a turn by ``deg`` degrees about world z."""
    a = math.radians(deg) / 2
    return np.array([math.cos(a), 0.0, 0.0, math.sin(a)])


def _corners(half: np.ndarray) -> np.ndarray:
    return np.array(
        [[sx * half[0], sy * half[1], sz * half[2]] for sx in (-1, 1) for sy in (-1, 1)
         for sz in (-1, 1)]
    )  # fmt: skip


class Motion:
    """One run of the body in ``world`` from a pose (centre [m], unit quaternion) and velocities
    (linear [m/s], angular [rad/s], world); ``barriers``: the two light barriers to time."""

    def __init__(
        self,
        world: World,
        position: np.ndarray | tuple[float, float, float],
        quaternion: np.ndarray | tuple[float, float, float, float],
        velocity: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
        angular_velocity: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
        barriers: tuple[Barrier, Barrier] | None = None,
        after_last_barrier: float = 0.0,
    ) -> None:
        self.world = world
        b = world.body
        self.x = np.array(position, dtype=float)
        q = np.array(quaternion, dtype=float)
        self.q = q / np.linalg.norm(q)
        self.v = np.array(velocity, dtype=float)
        self.R = np.empty((3, 3))
        ig.quat_matrix(self.q, self.R)
        self.pi = b.inertia * (self.R.T @ np.asarray(angular_velocity, dtype=float))
        self.w = np.zeros(3)
        self.F = np.zeros(3)
        self.T = np.zeros(3)
        n_prim = len(world.primitives)
        self.mem_face = np.zeros((len(b.points), n_prim), dtype=np.int64)
        self.mem_step = np.full((len(b.points), n_prim), -10, dtype=np.int64)
        self.counters = np.array([0, 0, np.iinfo(np.int64).max], dtype=np.int64)
        self.corners = _corners(b.half)
        self.beam_a = np.zeros((2, 2))
        self.beam_d = np.ones((2, 2))
        self.beam_d2 = np.ones(2)
        self.beam_n = np.zeros((2, 2))
        self.crossed = np.full(2, np.inf)  # no barriers: nothing to time
        if barriers is not None:
            for k, bar in enumerate(barriers):
                a, e = np.asarray(bar.start, dtype=float), np.asarray(bar.end, dtype=float)
                d = e - a
                self.beam_a[k], self.beam_d[k], self.beam_d2[k] = a, d, float(d @ d)
                self.beam_n[k] = np.array([-d[1], d[0]]) / math.sqrt(float(d @ d))
            self.crossed[:] = np.nan
        self.clear_t = np.full(2, np.nan)
        self.clear_g = np.full(2, np.nan)
        self.after_last_barrier = after_last_barrier
        self._evaluate()

    def _args(self) -> tuple:
        b, p, world = self.world.body, self.world.primitives, self.world
        return (
            b.points, b.area, b.band, b.tile_start, b.tile_end, b.tile_centre, b.tile_radius,
            b.wall_half,
            b.row_z, b.row_h, b.radius,
            p.kind, p.centre, p.rot, p.size, p.material, p.vel, p.spin, p.reach,
            world.law, world.stick_speed, world.slip_speed, self.mem_face, self.mem_step,
        )  # fmt: skip

    def _evaluate(self) -> None:
        b = self.world.body
        ig.evaluate(
            self.x, self.q, self.v, self.pi, self.R, self.w, self.F, self.T, b.mass, b.inertia,
            self.world.gravity, *self._args(), self.counters[1],
        )  # fmt: skip

    def advance(self, dt: float, n_steps: int) -> int:
        """Integrate ``n_steps`` steps of ``dt`` [s] (fewer if the run stops: the code says why,
        `integrator.RUNNING`, ``STOPPED``, ``NOT_FINITE``, ``TOO_FAST``)."""
        b = self.world.body
        after = round(self.after_last_barrier / dt)
        return int(
            ig.advance(
                self.x, self.q, self.v, self.pi, self.R, self.w, self.F, self.T, b.mass,
                b.inertia, self.world.gravity, dt, n_steps, self.counters, *self._args(),
                self.corners, self.beam_a, self.beam_d, self.beam_d2, self.beam_n, self.crossed,
                self.clear_t, self.clear_g, after,
            )
        )  # fmt: skip

    def take_state(self, other: Motion) -> None:
        """Take ``other``'s position, orientation, velocity and angular momentum and evaluate
        this world's forces [N] and torques [N m] there (`F`, `T`): with a world of some of the
        other's primitives and no gravity, the force those primitives exert."""
        if self.world.body is not other.world.body:
            raise ParcelfitError("take_state needs the same body in both worlds")
        for mine, theirs in ((self.x, other.x), (self.q, other.q), (self.v, other.v)):
            mine[:] = theirs
        self.pi[:] = other.pi
        self._evaluate()

    @property
    def steps(self) -> int:
        """Steps taken."""
        return int(self.counters[0])

    @property
    def angular_velocity(self) -> np.ndarray:
        """World angular velocity [rad/s]."""
        return self.R @ (self.pi / self.world.body.inertia)

    @property
    def angular_momentum(self) -> np.ndarray:
        """World angular momentum about the centre [kg m^2/s]."""
        return self.R @ self.pi

    @property
    def kinetic_energy(self) -> float:
        """Translational plus rotational kinetic energy [J]."""
        b = self.world.body
        return 0.5 * b.mass * float(self.v @ self.v) + 0.5 * float(np.sum(self.pi**2 / b.inertia))

    @property
    def heading(self) -> float:
        """The heading [rad] of the body's x axis projected onto the plane."""
        return math.atan2(float(self.R[1, 0]), float(self.R[0, 0]))

    @property
    def barrier_times(self) -> tuple[float | None, float | None]:
        """When each beam broke [s] (None: not yet, or no barriers)."""
        a, b = (None if not math.isfinite(t) else float(t) for t in self.crossed)
        return a, b
