"""Judge the MuJoCo models by what the published experiments observed (method.md section 11),
across ensembles of seeded hand placements rather than single runs.

    python scripts/ensemble_check.py                        # E3 setting 1, 20 placements per type
    python scripts/ensemble_check.py --rigs E3 E1 --placements 10 --types BW KPBW KP PB
    python scripts/ensemble_check.py --all-settings         # every speed setting of each rig
    python scripts/ensemble_check.py --rigs E1 --settings 3    # only these speed settings
    python scripts/ensemble_check.py --rigs examples/e3-variants/E3-plate-clear.yaml
    python scripts/ensemble_check.py --bulge BW=0.3 KPBW=0.45 --set zeta_MePa=0.1 --scene impratio=10
    python scripts/ensemble_check.py --rigs E2a --nose-radius 0   # square belt ends

For each rig and speed setting it simulates every consignment type at its default parameters
for the placement seeds 0..N-1 (the rig's ``start.scatter``), then prints and writes
(``--out``, default docs/research/) ``ensemble-check.md`` with the per-type statistics and the published
observations as checks:

* E3: median absolute rotation ordered BW > KP/BW > KP; BW above 90 degrees in at least a
  quarter of the placements and above 180 degrees in some; KP's median below 30 degrees; slides
  and spins both occur; Spearman's rank correlation of rotation and transit time;
* every rig and setting: PB's median transit time slowest or second slowest, by more than the
  ensemble's standard error; on E1, BW fastest.

and a figure per rig and setting (``ensemble-<rig>-<setting>.png``): the top view of every
placement's path and the heading over the travelled distance, like the published Figures 17
and 19. Runs go over all cores (``--workers``). ``--set`` changes parameters (catalogue units) for
every type, ``--bulge TYPE=FOOTPRINT`` gives a type's packaging a bulging bottom (0: a flat one)
(``--bulge-depth``, `parcelfit.sim.mujoco.shell`), ``--scene`` sets scene options,
``--nose-radius`` the radius [m] of the drums every belt and strip set of the rigs runs round at
its ends (0: square ends) in place of the rig files' own (`Rig.with_drum_ends`).
``--backend rigidbox`` judges the independent rigid-box reference instead; its
``--bottom-patch`` takes one patch for every type or one per type (``KPBW=content KP=outline``),
``--wall-outline`` likewise the outline walls and lead-ins meet (``KPBW=content``: KP/BW's rim
gives way at the plate, the others' do not).
"""

from __future__ import annotations

import argparse
import itertools
import math
import multiprocessing
import os
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim.ensemble import (
    TYPE_COLOURS,
    EnsembleSummary,
    Member,
    paired_order,
    simulate_ensemble,
    summarise,
)
from parcelfit.sim.mujoco import (
    MujocoSimulator,
    SimOptions,
    load_consignment,
    load_rig,
)
from parcelfit.sim.mujoco.options import parse_scene_options, scene_options
from parcelfit.sim.mujoco.rig import Rig
from parcelfit.sim.params import (
    BOTTOM_PATCHES,
    WALL_CONTACTS,
    WALL_DAMPINGS,
    WALL_OUTLINES,
    parameter,
    parse_assignments,
)
from parcelfit.sim.rigidbox import RigidBoxOptions, RigidBoxSimulator

TYPES = ("BW", "KPBW", "KP", "PB")


def _deg(x: float) -> float:
    return math.degrees(x)


def _figure(rig: Rig, setting: int, members: dict[str, list[Member]], path: Path) -> None:
    rig_name = rig.name
    types = list(members)
    fig, axes = plt.subplots(
        2, len(types), figsize=(4.2 * len(types), 6.5), squeeze=False, height_ratios=(1, 1.2)
    )
    for k, cons in enumerate(types):
        top, head = axes[0][k], axes[1][k]
        for s in rig.surfaces:
            u = s.unit()
            n = np.array([-u[1], u[0]])
            c = np.array(s.centre)
            corners = [
                c + a * s.length / 2 * u + b * s.width / 2 * n
                for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1))
            ]
            top.plot(*np.array(corners).T, color="0.5", lw=0.6)
        for w in rig.walls:
            top.plot([w.start[0], w.end[0]], [w.start[1], w.end[1]], color="k", lw=2.5)
        for b in rig.barriers:
            top.plot([b.start[0], b.end[0]], [b.start[1], b.end[1]], "g--", lw=0.7)
        for m in members[cons]:
            if m.run is None:
                continue
            tr = m.run.trajectory
            top.plot(tr.x, tr.y, color=TYPE_COLOURS.get(cons, "k"), lw=0.7, alpha=0.7)
            head.plot(
                tr.x, np.degrees(np.unwrap(tr.theta)), color=TYPE_COLOURS.get(cons, "k"), lw=0.7
            )
        top.set_xlim(*rig.end.x)
        top.set_ylim(*rig.end.y)
        top.set_aspect("equal")
        top.set_title(f"{rig_name} setting {setting}: {cons}")
        top.set_xlabel("x [m]")
        top.set_ylabel("y [m]")
        head.set_xlabel("x [m]")
        head.set_ylabel("heading [deg]")
        head.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _row(cons: str, st: EnsembleSummary) -> str:
    return (
        f"| {cons} | {st.n_ok}/{st.n} | {_deg(st.rotation_median):.0f} | "
        f"{_deg(st.rotation_q25):.0f}-{_deg(st.rotation_q75):.0f} | {_deg(st.rotation_max):.0f} | "
        f"{st.share_over_90:.0%} | {st.share_over_180:.0%} | {st.spins}/{st.slides} | "
        f"{st.no_transit} | {st.transit_median:.3f} | {st.transit_sem * 1e3:.1f} | {st.rank_correlation:.2f} |"
    )


def _checks(
    rig: str, stats: dict[str, EnsembleSummary], members: dict[str, list[Member]] | None = None
) -> list[tuple[str, bool | None]]:
    """The published observations checked on ``rig``'s ensembles. The order of median rotations
    is met only where, placement by placement (``members``), each type also turns further than
    the next at more placements than less (`parcelfit.sim.ensemble.paired_order`): medians that
    differ by less than the 0.5-degree band at every placement are a tie, not an order."""
    out: list[tuple[str, bool | None]] = []
    have = set(stats)
    if rig.startswith("E3") and {"BW", "KPBW", "KP"} <= have:
        bw, kpbw, kp = stats["BW"], stats["KPBW"], stats["KP"]
        order = bw.rotation_median > kpbw.rotation_median > kp.rotation_median
        text = "median rotation BW > KP/BW > KP"
        if members is not None:
            text += ", and each type further than the next at more placements than less"
            for further, less in (("BW", "KPBW"), ("KPBW", "KP")):
                po = paired_order(members[less], members[further])
                if po.b_further <= po.a_further:
                    order = False
                    text += (
                        f" ({further} further than {less} at {po.b_further}, less at "
                        f"{po.a_further}, alike at {po.ties})"
                    )
        out.append((text, order))
        out.append(("BW > 90 degrees in at least 25 % of placements", bw.share_over_90 >= 0.25))
        out.append(("BW > 180 degrees in some placements", bw.share_over_180 > 0))
        out.append(("KP median rotation < 30 degrees", _deg(kp.rotation_median) < 30))
        spins = sum(s.spins for s in stats.values())
        slides = sum(s.slides for s in stats.values())
        out.append(("slides and spins both occur", spins > 0 and slides > 0))
    if "PB" in have and len(have) >= 3:
        order = sorted(have, key=lambda c: -stats[c].transit_median)
        pb = stats["PB"]
        rank = order.index("PB")
        margin = (
            pb.transit_median - stats[order[rank + 1]].transit_median
            if rank + 1 < len(order)
            else float("nan")
        )
        out.append(
            (
                "PB slowest or second slowest by more than its standard error "
                f"(order {' > '.join(order)})",
                rank <= 1 and margin > pb.transit_sem,
            )
        )
    if rig.startswith("E1") and "BW" in have and len(have) >= 2:
        fastest = min(have, key=lambda c: stats[c].transit_median)
        out.append((f"BW fastest on E1 (fastest: {fastest})", fastest == "BW"))
    return out


def _paired_lines(rig: str, members: dict[str, list[Member]]) -> list[str]:
    """On E3, seed by seed, how often each type of the published order turns further than the
    next (`parcelfit.sim.ensemble.paired_order`): information beside the medians' check."""
    order = [c for c in ("BW", "KPBW", "KP") if c in members]
    if not rig.startswith("E3") or len(order) < 2:
        return []
    out = []
    for further, less in itertools.pairwise(order):
        po = paired_order(members[less], members[further])
        p = "-" if math.isnan(po.p_value) else f"{po.p_value:.2g}"
        out.append(
            f"- seed by seed, {further} turns further than {less} at {po.b_further} of "
            f"{po.n_pairs} placements, less at {po.a_further}, as far (within 0.5 degrees) at "
            f"{po.ties}; sign test p = {p}; median paired difference "
            f"{_deg(po.median_difference):+.1f} degrees"
        )
    return out


# the scene options (`SceneOptions` fields) `parcelfit simulate` has a flag for
_SIMULATE_FLAGS = {
    "timestep": "--timestep",
    "spacing": "--spacing",
    "soft_shell_spacing": "--film-spacing",
    "membrane_cap": "--membrane-cap",
    "belt_friction": "--belt-friction",
    "shell_dof": "--shell-dof",
    "shell_cells": "--shell-cells",
    "rim_brace": "--rim-brace",
    "mass_lumping": "--mass-lumping",
    "refinement": "--refinement",
}


def _reproduce_note(
    rig: str,
    setting: int,
    scene: list[str],
    set_: list[str],
    wall_limit: float,
    without_flag: list[str],
) -> str:
    """How one placement of this check is run again alone: the `parcelfit simulate` command with
    the check's parameters and scene options, or, where the check used an option that command
    has no flag for (``without_flag``, or a scene option outside `_SIMULATE_FLAGS`), which."""
    given = parse_scene_options(scene)
    missing = [*without_flag, *(f"--scene {k}" for k in given if k not in _SIMULATE_FLAGS)]
    if missing:
        return (
            "not reproducible with `parcelfit simulate` alone, which has no option for "
            + ", ".join(missing)
        )
    flags = "".join(f" --set {item}" for item in set_)
    for key, value in given.items():
        text = (
            ",".join(f"{v:g}" for v in value)
            if isinstance(value, tuple)
            else f"{value:.10g}"
            if isinstance(value, float)
            else str(value)
        )
        flags += f" {_SIMULATE_FLAGS[key]} {text}"
    if wall_limit != SimOptions.wall_limit:
        flags += f" --wall-limit {wall_limit:g}"
    return (
        f"each reproducible with `parcelfit simulate --rig {rig} --consignment TYPE "
        f"--setting {setting}{flags} --seed N`"
    )


def _per_type(
    given: list[str], types: list[str], convert: Callable[[str], Any], default: Any
) -> dict[str, Any]:
    """Each type's value of a per-type option (``--bottom-patch``, ``--wall-outline``,
    ``--wall-inset``): one value for every type, or TYPE=VALUE items (a type not named:
    ``default``), each through ``convert``; ValueError names what is wrong."""
    if len(given) == 1 and "=" not in given[0]:
        return dict.fromkeys(types, convert(given[0]))
    out = dict.fromkeys(types, default)
    for item in given:
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"{item!r}: give one value, or TYPE=VALUE for each type named")
        if name not in types:
            raise ValueError(f"{name!r} is not among --types ({' '.join(types)})")
        try:
            out[name] = convert(value)
        except ValueError as exc:
            raise ValueError(f"{exc} (for {name})") from None
    return out


def _choice(choices: tuple[str, ...]) -> Callable[[str], str]:
    """A converter that accepts one of ``choices``."""

    def convert(value: str) -> str:
        if value not in choices:
            raise ValueError(f"unknown value {value!r}: use one of {', '.join(choices)}")
        return value

    return convert


def _length(value: str) -> float:
    """A wall inset [m] in [0, 0.1]."""
    try:
        length = float(value)
    except ValueError:
        raise ValueError(f"{value!r} is not a length [m]") from None
    if not (math.isfinite(length) and 0 <= length <= 0.1):
        raise ValueError(f"{value!r}: give a length in [0, 0.1] m")
    return length


def _bottom_patches(given: list[str], types: list[str]) -> dict[str, str]:
    """Each type's bottom patch from ``--bottom-patch`` (a type not named: ``consignment``)."""
    return _per_type(given, types, _choice(BOTTOM_PATCHES), "consignment")


def _wall_outlines(given: list[str], types: list[str]) -> dict[str, str]:
    """Each type's wall outline from ``--wall-outline`` (a type not named: ``outline``)."""
    return _per_type(given, types, _choice(WALL_OUTLINES), "outline")


def _wall_insets(given: list[str], types: list[str]) -> dict[str, float]:
    """Each type's wall inset [m] from ``--wall-inset`` (a type not named: 0)."""
    return _per_type(given, types, _length, 0.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rigs", nargs="+", default=["E3"])
    ap.add_argument("--types", nargs="+", default=list(TYPES))
    ap.add_argument("--placements", type=int, default=20)
    which = ap.add_mutually_exclusive_group()
    which.add_argument(
        "--all-settings", action="store_true", help="every speed setting, not only 1"
    )
    which.add_argument(
        "--settings", nargs="+", type=int, default=None, help="these speed settings of every rig"
    )
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", type=Path, default=Path("docs/research"))
    ap.add_argument(
        "--wall-limit",
        type=float,
        default=SimOptions.wall_limit,
        help="wall-clock limit per run [s] (fine meshes and steps need more than the default)",
    )
    ap.add_argument(
        "--scene",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="scene options other than the defaults (e.g. impratio=10 timestep=1/2400)",
    )
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="catalogue units")
    ap.add_argument(
        "--backend",
        choices=("mujoco", "rigidbox"),
        default="mujoco",
        help="the model judged: MuJoCo's, or the independent rigid-box reference",
    )
    ap.add_argument(
        "--bottom-patch",
        nargs="+",
        default=["consignment"],
        metavar="PATCH|TYPE=PATCH",
        help="rigidbox: where the bottom carries contact, for every type or per type "
        "(KPBW=content KP=outline; a type not named: consignment): consignment (its bulge "
        "patch if it has one, else rim-bending), outline (the whole outline at one pressure), "
        "content (the content's footprint), rim-weight (the outline, its rim carrying only its "
        "own weight) or rim-bending (its own weight and what its bending passes on, from E_Pa, "
        "t_Pa, nu_Pa and k_BePa)",
    )
    ap.add_argument(
        "--reference-spacing",
        type=float,
        default=None,
        help="rigidbox: the spacing of the box's contact points [m] (default: the reference's, "
        "10 mm); halve it to check the reference's verdict is converged in it",
    )
    ap.add_argument(
        "--reference-step-divisor",
        type=int,
        default=None,
        help="rigidbox: the reference's own step divided by this whole number (2: half the "
        "step), to check its verdict is converged in it",
    )
    ap.add_argument(
        "--wall-contact",
        choices=WALL_CONTACTS,
        default=None,
        help="rigidbox: how walls meet the box (default: the reference's, its outline; points: "
        "its contact points, as before the outline contact)",
    )
    ap.add_argument(
        "--wall-outline",
        nargs="+",
        default=["outline"],
        metavar="OUTLINE|TYPE=OUTLINE",
        help="rigidbox: the outline walls and lead-ins meet, for every type or per type "
        "(KPBW=content; a type not named: outline): outline (the packaging's, a rim as stiff "
        "as the content) or content (the content's: a rim that gives way at a wall)",
    )
    ap.add_argument(
        "--wall-inset",
        nargs="+",
        default=["0"],
        metavar="LENGTH|TYPE=LENGTH",
        help="rigidbox: the packaging's outline walls meet, inset by this on every side [m], for "
        "every type or per type (KPBW=0.0084: a rim that gave way by 8.4 mm; a type not named: 0)",
    )
    ap.add_argument(
        "--wall-damping",
        choices=WALL_DAMPINGS,
        default=None,
        help="rigidbox: walls and lead-ins damped at the ratio of their contact's stiffness "
        "(default, ratio) or per unit area (area, as before)",
    )
    ap.add_argument("--bulge", nargs="*", default=[], metavar="TYPE=FOOTPRINT")
    ap.add_argument("--bulge-depth", type=float, default=0.004, help="[m]")
    ap.add_argument(
        "--nose-radius",
        type=float,
        default=None,
        help="drum radius at the ends of every belt and strip set [m] (0: square ends); "
        "default: each rig file's own",
    )
    args = ap.parse_args(argv)
    if not args.wall_limit > 0:
        ap.error(f"--wall-limit must be positive [s], got {args.wall_limit:g}")
    if args.reference_spacing is not None:
        if args.backend != "rigidbox":
            ap.error(
                "--reference-spacing sets the rigid-box reference's contact points: add --backend rigidbox"
            )
        if not 1e-3 <= args.reference_spacing <= 0.05:
            ap.error(
                f"--reference-spacing must lie in [0.001, 0.05] m, got {args.reference_spacing:g}"
            )
    for given, flag in (
        (args.wall_contact, "--wall-contact"),
        (args.wall_damping, "--wall-damping"),
        (args.reference_step_divisor, "--reference-step-divisor"),
    ):
        if given is not None and args.backend != "rigidbox":
            ap.error(f"{flag} is a setting of the rigid-box reference: add --backend rigidbox")
    if args.reference_step_divisor is not None and not 1 <= args.reference_step_divisor <= 64:
        ap.error(f"--reference-step-divisor must lie in [1, 64], got {args.reference_step_divisor}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "figures").mkdir(exist_ok=True)
    rigs = [load_rig(r) for r in args.rigs]  # bundled names or rig files
    for rig in rigs:
        missing = sorted(set(args.settings or []) - set(rig.speeds))
        if missing:
            ap.error(
                f"--settings: rig {rig.name} has no speed setting {', '.join(map(str, missing))} "
                f"(it has {', '.join(map(str, sorted(rig.speeds)))})"
            )
    if args.nose_radius is not None:
        try:
            rigs = [r.with_drum_ends(args.nose_radius) for r in rigs]
        except ParcelfitError as exc:
            ap.error(f"--nose-radius: {exc}")
    try:
        scene = scene_options(args.scene)
    except ParcelfitError as exc:
        ap.error(f"--scene: {exc}")
    bulges = {k.upper().replace("/", ""): v for k, v in parse_assignments(args.bulge).items()}
    consignments = {
        t: replace(c, bulge=(args.bulge_depth, bulges[t]) if bulges[t] > 0 else None)
        if t in bulges
        else c
        for t, c in ((t, load_consignment(t)) for t in args.types)
    }
    user = parse_assignments(args.set)
    per_type = {}
    for flag, given, parse, default in (
        ("--bottom-patch", args.bottom_patch, _bottom_patches, ["consignment"]),
        ("--wall-outline", args.wall_outline, _wall_outlines, ["outline"]),
        ("--wall-inset", args.wall_inset, _wall_insets, ["0"]),
    ):
        try:
            per_type[flag] = parse(given, args.types)
        except ValueError as exc:
            ap.error(f"{flag}: {exc}")
        if args.backend != "rigidbox" and given != default:
            ap.error(f"{flag} is a setting of the rigid-box reference: add --backend rigidbox")
    patches, walls = per_type["--bottom-patch"], per_type["--wall-outline"]
    insets = per_type["--wall-inset"]
    if any(insets[t] > 0 and walls[t] != "outline" for t in args.types):
        ap.error("--wall-inset insets the packaging's outline: not with --wall-outline content")
    if args.wall_contact == "points" and (
        set(walls.values()) != {"outline"} or any(insets.values())
    ):
        ap.error(
            "--wall-outline content and --wall-inset need walls met by the outline: drop "
            "--wall-contact points"
        )
    sim: MujocoSimulator | RigidBoxSimulator
    sim_for: dict[str, MujocoSimulator | RigidBoxSimulator] = {}
    if args.backend == "rigidbox":
        # the reference shares only the start's offset with MuJoCo's scene options
        other = sorted(k.split("=", 1)[0] for k in args.scene if not k.startswith("start_offset="))
        if other:
            ap.error(
                f"--scene: the rigidbox backend takes only start_offset, not {', '.join(other)}"
            )
        sim = RigidBoxSimulator(
            RigidBoxOptions(
                bottom_patch="consignment",
                **({} if args.reference_spacing is None else {"spacing": args.reference_spacing}),
                **({} if args.wall_contact is None else {"wall_contact": args.wall_contact}),
                **({} if args.wall_damping is None else {"wall_damping": args.wall_damping}),
                **(
                    {}
                    if args.reference_step_divisor is None
                    else {"step_divisor": args.reference_step_divisor}
                ),
                wall_limit=args.wall_limit,
                start_offset=scene.start_offset,
            ),
            rigs={r.name: r for r in rigs},
            consignments=consignments,
        )
        sim_for = {
            t: sim.with_options(
                bottom_patch=patches[t], wall_outline=walls[t], wall_inset=insets[t]
            )
            for t in args.types
        }
    else:
        sim = MujocoSimulator(
            SimOptions(scene=scene, wall_limit=args.wall_limit),
            rigs={r.name: r for r in rigs},
            consignments=consignments,
        )
    seeds = list(range(args.placements))
    lines = [
        "# Ensemble check: the models against the published observations",
        "",
        f"Written by `python scripts/ensemble_check.py --rigs {' '.join(args.rigs)} "
        f"--types {' '.join(args.types)} "
        f"--placements {args.placements}{' --all-settings' if args.all_settings else ''}"
        + (f" --settings {' '.join(map(str, args.settings))}" if args.settings else "")
        + "".join(
            f" --{k} {' '.join(v)}"
            for k, v in (("set", args.set), ("bulge", args.bulge), ("scene", args.scene))
            if v
        )
        + (f" --bulge-depth {args.bulge_depth}" if args.bulge else "")
        + (f" --nose-radius {args.nose_radius:g}" if args.nose_radius is not None else "")
        + (
            f" --backend rigidbox --bottom-patch {' '.join(args.bottom_patch)}"
            if args.backend == "rigidbox"
            else ""
        )
        + (
            f" --reference-spacing {args.reference_spacing:g}"
            if args.reference_spacing is not None
            else ""
        )
        + (f" --wall-contact {args.wall_contact}" if args.wall_contact is not None else "")
        + (
            f" --wall-outline {' '.join(args.wall_outline)}"
            if args.wall_outline != ["outline"]
            else ""
        )
        + (f" --wall-inset {' '.join(args.wall_inset)}" if args.wall_inset != ["0"] else "")
        + (f" --wall-damping {args.wall_damping}" if args.wall_damping is not None else "")
        + (
            f" --reference-step-divisor {args.reference_step_divisor}"
            if args.reference_step_divisor is not None
            else ""
        )
        + (f" --wall-limit {args.wall_limit:g}" if args.wall_limit != SimOptions.wall_limit else "")
        + "`: "
        "every consignment type at its default parameters, placement seeds "
        f"0-{args.placements - 1} (the rig's hand-placement scatter). Rotation is the net "
        "change of heading from the first to the last sample; a spin is a rotation above "
        "90 degrees. SE: standard error of the mean transit time; rho: Spearman's rank "
        "correlation of rotation and transit time.",
        "",
    ]
    # options of this check that `parcelfit simulate` cannot repeat
    without_flag = [
        flag
        for flag, used in (
            ("--backend rigidbox", args.backend == "rigidbox"),
            ("--bulge", bool(args.bulge)),
            ("--nose-radius", args.nose_radius is not None),
        )
        if used
    ]
    t0 = time.perf_counter()
    failures = 0
    # spawned workers: MuJoCo and numba are not fork-safe
    with ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("spawn")) as ex:
        for rig_arg, rig in zip(args.rigs, rigs, strict=True):
            rig_name = rig.name
            settings = (
                sorted(rig.speeds)
                if args.all_settings
                else (args.settings if args.settings else [min(rig.speeds)])
            )
            for setting in settings:
                members: dict[str, list[Member]] = {}
                for cons in args.types:
                    case = TestCase(rig_name, cons, setting)
                    params = {k: parameter(k).to_si(v) for k, v in user.items()}
                    consignments[cons].parameter_values(si_values=params)  # checks names, ranges
                    members[cons] = simulate_ensemble(
                        sim_for.get(cons, sim).with_placement, params, case, seeds, executor=ex
                    )
                    print(f"{case.label}: done ({time.perf_counter() - t0:.0f} s)", flush=True)
                stats = {c: summarise(m) for c, m in members.items()}
                fig = args.out / "figures" / f"ensemble-{rig_name}-{setting}.png"
                _figure(rig, setting, members, fig)
                lines += [
                    f"## {rig_name}, speed setting {setting}",
                    "",
                    f"![paths and headings](figures/{fig.name})",
                    "",
                    "| type | ok | median rotation [deg] | quartiles | max | > 90 deg | > 180 deg "
                    "| spins/slides | no transit | median transit [s] | SE [ms] | rho |",
                    "|---|---|---|---|---|---|---|---|---|---|---|---|",
                    *(_row(c, st) for c, st in stats.items()),
                    "",
                    "Net rotation of each placement seed 0, 1, ... [deg] ("
                    + _reproduce_note(
                        rig_arg, setting, args.scene, args.set, args.wall_limit, without_flag
                    )
                    + "):",
                    "",
                    *(
                        f"- {c}: "
                        + ", ".join(
                            f"failed ({m.status.value})"
                            if m.rotation is None
                            else f"{_deg(m.rotation):.0f}"
                            for m in ms
                        )
                        for c, ms in members.items()
                    ),
                    "",
                    "Time steps: "
                    + (
                        "the rigid-box reference's own (sim/rigidbox)"
                        if args.backend == "rigidbox"
                        else ", ".join(
                            f"{c} 1/{1 / scene.step_for(consignments[c].soft, rig, consignments[c].shell):.0f} s"
                            for c in members
                        )
                    )
                    + ".",
                    "",
                ]
                for text, ok in _checks(rig_name, stats, members):
                    mark = "met" if ok else "NOT met"
                    failures += not ok
                    lines.append(f"- {text}: **{mark}**")
                lines += _paired_lines(rig_name, members)
                lines.append("")
    lines.append(
        f"Wall time {time.perf_counter() - t0:.0f} s on {args.workers} processes "
        f"({failures} check(s) not met)."
    )
    text = "\n".join(lines) + "\n"
    (args.out / "ensemble-check.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
