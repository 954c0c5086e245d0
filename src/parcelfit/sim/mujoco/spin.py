"""Virtual spin and slide tests: does a parcel model keep and lose its spin and its speed as a
body should?

A parcel that a guide plate sets spinning turns until friction under it has taken its spin
away. Two checks on a parcel at rest on a still plate of belt material (default parameters):

**Free spin** (gravity off, the parcel lifted clear of the plate): the parcel is given the rigid
angular velocity w0 about the vertical through its content's centre (every vertex and node
v = w0 x r). No force acts on it, so its angular momentum must stay: the check reports the
fraction of w0 its content still has after ``duration`` seconds (1 for a faithful model).

**Spin-down on the plate** (gravity on): the same kick, and the parcel turns until the belt's
friction has stopped it. For a rigid body with Coulomb friction and the contact forces f_i at
distances r_i from the centre that the model itself carries at rest, the turn is

    theta = I_z w0^2 / (2 mu sum_i f_i r_i)

(I_z: the parcel's moment of inertia about the vertical through its centre, mu: the belt
friction coefficient). The check reports the model's turn beside this estimate.

**Slide on the plate** (gravity on): the parcel is given the horizontal speed v0 and slides
until the plate's friction stops it. A body with Coulomb friction slides

    s = v0^2 / (2 mu g)

and keeps touching the plate all the way. The check reports the model's slide (the shell's mean
displacement) beside this estimate, and the share of steps of the slide in which the shell
touches the plate nowhere: MuJoCo's convex contact model lifts a contact that slides (its
documented "motion in the normal direction" at the onset of slip), so a sliding parcel hops
(docs/research/sliding-lift.md).

Measured with these checks (docs/research/spin-check.md): the packaging shell with a degree of freedom per
vertex (`SceneOptions.shell_dof` "full") loses most of its spin in free flight at the default
time step, which brakes every spin the plate starts; a shell whose vertices follow a quadratic
field over its box ("quadratic") keeps it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import mujoco
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.sim.mujoco.consignment import Consignment
from parcelfit.sim.mujoco.friction import Stepper
from parcelfit.sim.mujoco.indentation import plate_geoms, plate_rig
from parcelfit.sim.mujoco.mjlog import CountedWarnings
from parcelfit.sim.mujoco.options import SceneOptions
from parcelfit.sim.mujoco.scene import build_scene
from parcelfit.sim.mujoco.simulator import add_rigid_velocity


@dataclass(frozen=True)
class SpinTest:
    """Outcome of one spin test: the kick w0 [rad/s], the content's angular velocity left at the
    end [rad/s] and its fraction of w0, the turn [rad] and the time it took [s], and for the
    spin-down (None in free flight) the rigid Coulomb estimate of the turn [rad], the lever
    [m] (the mean distance of the plate's contacts from the content's centre at rest, weighted
    by their normal forces: sum f r / sum f), how many contacts the plate had then, and the
    sum of the normal forces between the packaging and the content at rest [N] beside the
    content's weight [N] (about equal where the shell only carries it; more where it clamps
    it)."""

    w0: float
    w_end: float
    retained: float
    turn: float
    time: float
    coulomb_turn: float | None
    lever: float | None = None
    plate_contacts: int | None = None
    content_load: float | None = None
    content_weight: float | None = None


def _yaw(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def spin_test(
    consignment: Consignment,
    *,
    w0: float = 10.0,
    free: bool = False,
    duration: float = 0.1,
    params: Mapping[str, float] | None = None,
    options: SceneOptions | None = None,
    settle: float = 0.3,
    plate_tile: float | None = None,
) -> SpinTest:
    """Kick the parcel (settled ``settle`` s on a still belt-material plate) with w0 [rad/s]
    about the vertical and follow its content: in free flight (``free``: gravity off, lifted at
    0.3 m/s) for ``duration`` s, else until it stops turning (at most 2 s). SI ``params``
    override the defaults. ``plate_tile`` [m] builds the plate of square tiles of about that
    side (`indentation.plate_rig`): physically the same plate, numerically more contact pairs."""
    if consignment.soft:
        raise ParcelfitError("the spin test needs a rigid content (it follows the content body)")
    if options is not None and options.content_tiles > 1:
        raise ParcelfitError(
            "the spin test reads the contacts and inertia of one content box",
            fix="use content_tiles=1 (the default)",
        )
    with CountedWarnings():  # MuJoCo's per-step notes (e.g. on interpolated shells) counted
        return _spin_test(consignment, w0, free, duration, params, options, settle, plate_tile)


@dataclass(frozen=True)
class SlideTest:
    """Outcome of one slide test: the kick v0 [m/s], the model's slide [m] and the Coulomb
    slide v0^2 / (2 mu g) [m], the time it took [s], and the share of the sliding steps in which
    the shell touched the plate nowhere."""

    v0: float
    slide: float
    coulomb_slide: float
    time: float
    no_contact: float


def _settled(
    consignment: Consignment,
    params: Mapping[str, float] | None,
    options: SceneOptions | None,
    settle: float,
    plate_tile: float | None = None,
) -> tuple[mujoco.MjModel, mujoco.MjData, dict[str, float], Callable[[], None]]:
    """The parcel settled ``settle`` s on a still belt-material plate (of tiles about
    ``plate_tile`` [m] wide if given), the SI parameters and the step function (MuJoCo's step,
    after the Coulomb belt friction where the scene has it)."""
    full = consignment.parameter_values(si_values=dict(params or {}))
    scene = build_scene(plate_rig("belt", plate_tile), consignment, full, 1, options)
    model = scene.model()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    step = Stepper(model, data, scene, full, options or SceneOptions()).step

    for _ in range(round(settle / model.opt.timestep)):
        step()
    return model, data, full, step


def slide_test(
    consignment: Consignment,
    *,
    v0: float = 1.0,
    params: Mapping[str, float] | None = None,
    options: SceneOptions | None = None,
    settle: float = 0.3,
) -> SlideTest:
    """Kick the parcel (settled ``settle`` s on a still belt-material plate) to v0 [m/s] along
    the plate and follow it until it stops (at most 2 s): its slide [m] beside v0^2 / (2 mu g),
    and the share of sliding steps without any contact with the plate. SI ``params`` override
    the defaults."""
    if not v0 > 0:
        raise ParcelfitError(f"the slide test needs a positive speed [m/s], got {v0}")
    with CountedWarnings():
        model, data, full, step = _settled(consignment, params, options, settle)
        plate = np.array(plate_geoms(model))
        flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "packaging")
        verts = slice(model.flex_vertadr[flex], model.flex_vertadr[flex] + model.flex_vertnum[flex])
        x0 = float(data.flexvert_xpos[verts, 0].mean())
        add_rigid_velocity(model, data, np.array([v0, 0.0, 0.0]))
        dt = model.opt.timestep
        prev, t, sliding, lifted = x0, 0.0, 0, 0
        while t < 2.0:
            step()
            t += dt
            x = float(data.flexvert_xpos[verts, 0].mean())
            # positions lag the step by one (simulator.py), so the first step shows no motion
            if t > 2 * dt and (x - prev) / dt < 0.01 * v0:  # stopped (1 % of the kick)
                break
            prev = x
            sliding += 1
            geoms = data.contact.geom[: data.ncon]
            lifted += not bool(np.isin(geoms, plate).any())
    mu = full["mu_d_BePa"]
    coulomb = v0**2 / (2 * mu * float(np.linalg.norm(model.opt.gravity)))
    return SlideTest(v0, x - x0, coulomb, t, lifted / max(sliding, 1))


def _spin_test(
    consignment: Consignment,
    w0: float,
    free: bool,
    duration: float,
    params: Mapping[str, float] | None,
    options: SceneOptions | None,
    settle: float,
    plate_tile: float | None,
) -> SpinTest:
    model, data, _, step = _settled(consignment, params, options, settle, plate_tile)
    content = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "content")
    centre = data.xpos[content].copy()
    coulomb = lever = content_load = weight = None
    n_plate = None
    if not free:
        belt = plate_geoms(model)
        content_geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "content")
        mu = float(model.geom_friction[belt[0], 0])
        moment = load = content_load = 0.0
        weight = float(model.body_mass[content] * np.linalg.norm(model.opt.gravity))
        n_plate = 0
        for i in range(data.ncon):
            geoms = data.contact[i].geom
            f = np.zeros(6)
            mujoco.mj_contactForce(model, data, i, f)
            if geoms[0] in belt or geoms[1] in belt:
                moment += f[0] * float(np.hypot(*(data.contact[i].pos - centre)[:2]))
                load += f[0]
                n_plate += 1
            elif content_geom in geoms:
                content_load += f[0]
        lever = moment / load if load > 0 else None
        inertia = model.body_inertia[content] @ (data.xmat[content].reshape(3, 3)[2] ** 2)
        for b in range(1, model.nbody):
            if b != content:
                inertia += model.body_mass[b] * float(np.sum((data.xpos[b] - centre)[:2] ** 2))
        coulomb = inertia * w0**2 / (2 * mu * moment) if moment > 0 else None
    else:
        model.opt.gravity[:] = 0.0
    add_rigid_velocity(model, data, np.array([0.0, 0.0, 0.3 if free else 0.0]), w0, centre)
    prev = _yaw(data.xquat[content])
    turn, t = 0.0, 0.0
    end = duration if free else 2.0
    while t < end:
        step()
        t += model.opt.timestep
        yaw = _yaw(data.xquat[content])
        turn += (yaw - prev + math.pi) % (2 * math.pi) - math.pi
        prev = yaw
        if not free and t > 0.01 and abs(data.cvel[content][2]) < 0.01:
            break
    w_end = float(data.cvel[content][2])
    return SpinTest(w0, w_end, w_end / w0, turn, t, coulomb, lever, n_plate, content_load, weight)


__all__ = ["SlideTest", "SpinTest", "slide_test", "spin_test"]
