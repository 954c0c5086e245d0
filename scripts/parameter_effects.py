"""Does each parameter move the simulated response by more than the numerical noise floor?

    python scripts/parameter_effects.py                       # E3, KP/BW, setting 1
    python scripts/parameter_effects.py --placements 4 --step 0.001

For every parameter (default: the six the published first screening stage found significant on
E3 KP/BW: k_CoPa, k_MePa, mu_d_BePa, mu_d_MePa, mu_s_MePa, E_Pa) it simulates the test case at
the low and the high end of the parameter's screening range and at its default times
(1 - step) and (1 + step), every other parameter at its default. The response between two runs
a and b is measured three ways, on the rig's regions of interest with trajectories taken
relative to their start (as every comparison in parcelfit):

    DTW_xy(a, b) [m],  DTW_theta(a, b) [rad],  |T_a - T_b| [s]

* effect of p  = response(p at low, p at high), the change over the whole range;
* floor of p   = response(p (1 - step), p (1 + step)), what a 0.1 % change does: for a smooth
  model this is about 0.1 % of the effect, above that it is numerical roughness;
* noise floor  = the median of the floors over the parameters, per response measure;
* ratio        = effect / noise floor (>= 3 asked for every parameter and measure).

With ``--placements K`` each quantity is the mean over the placement seeds 0..K-1 (matched
pairs: both runs of a pair share the placement). With K >= 2 the script also measures what a
parameter does to the *ensemble* (`parcelfit.sim.ensemble.ensemble_shift`): the change of the
median rotation, the median transit time and the share of spins between the K runs at the low
and the K runs at the high end, against the same change between the runs at the default
-+step (the ensemble's noise floor, median over the parameters) and against the bootstrap
standard error of the change (how much another draw of K placements would move it). On a rig
where single placements near the spin/slide threshold change branch with any small change, this
is the response a parameter has to move. ``--scene KEY=VALUE`` sets scene options other
than the defaults (e.g. ``belt_friction=coulomb``). ``--backend rigidbox`` measures the same in
the independent rigid-box reference (`parcelfit.sim.rigidbox`, its ``--bottom-patch``), for the
parameters its world is built from (k_CoPa and the content's do not exist in it; E_Pa, t_Pa and
nu_Pa act only on its ``rim-bending`` patch, the default where the consignment has no bulge).
``--bulge FOOTPRINT`` gives the consignment a bottom bulging under its rigid content over that
share of its outline (``--bulge-depth``; 0: a flat bottom), as ``ensemble_check.py --bulge``
does, in either backend (the reference's ``consignment`` patch is then the bulge's). Writes
``docs/research/parameter-effects.md`` (``--out``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.metrics.comparison import Comparison
from parcelfit.metrics.dtw import dtw_distance
from parcelfit.runs import Run, TestCase
from parcelfit.sim.ensemble import (
    TIE_ANGLE,
    EnsembleShift,
    Member,
    ensemble_shift,
    member_of,
    paired_order,
)
from parcelfit.sim.mujoco import (
    Consignment,
    MujocoSimulator,
    SceneOptions,
    SimOptions,
    load_consignment,
    load_rig,
)
from parcelfit.sim.mujoco.consignment import BULGE_DEPTH, with_bulge
from parcelfit.sim.mujoco.options import scene_options
from parcelfit.sim.params import BOTTOM_PATCHES, CATALOGUE
from parcelfit.sim.protocol import SimStatus
from parcelfit.sim.rigidbox import RigidBoxOptions, RigidBoxSimulator
from parcelfit.sim.rigidbox.geometry import resolved_bottom_patch
from parcelfit.sim.rigidbox.simulator import PARAMETERS as REFERENCE_PARAMETERS
from parcelfit.sim.rigidbox.simulator import RIM_BENDING_PARAMETERS

PUBLISHED_E3 = ("k_CoPa", "k_MePa", "mu_d_BePa", "mu_d_MePa", "mu_s_MePa", "E_Pa")
MEASURES = ("DTW_xy [m]", "DTW_theta [rad]", "transit [s]")
ENSEMBLE_MEASURES = ("median rotation [deg]", "median transit [s]", "spin share [-]")


Job = tuple[dict[str, float], TestCase, int, SceneOptions, str, str, Consignment, float]
WALL_LIMIT = SimOptions().wall_limit  # [s] per MuJoCo run unless --wall-limit says otherwise


def _simulate(job: Job) -> Member:
    params, case, seed, scene, backend, bottom_patch, cons, wall_limit = job
    sim: MujocoSimulator | RigidBoxSimulator
    own = {cons.name: cons}
    if backend == "rigidbox":
        sim = RigidBoxSimulator(
            RigidBoxOptions(bottom_patch=bottom_patch, start_offset=scene.start_offset),
            consignments=own,
        )
    else:
        sim = MujocoSimulator(SimOptions(scene=scene, wall_limit=wall_limit), consignments=own)
    return member_of(seed, sim.with_placement(seed).run(params, case))


def _table_head(
    label: str,
    measures: tuple[str, ...],
    noise: np.ndarray | None,
    first: list[str],
    effect_suffix: str,
    last: list[str],
) -> list[str]:
    """The noise-floor line and the head of an effects table (effect and floor per measure);
    without a floor (``noise`` None) the effects alone."""
    columns = [
        *first,
        *(f"effect {m}{effect_suffix}" for m in measures),
        *(f"floor {m}" for m in measures if noise is not None),
        *last,
    ]
    floor_line = (
        []
        if noise is None
        else [
            f"**{label}**: "
            + ", ".join(f"{m} {v:.4g}" for m, v in zip(measures, noise, strict=True)),
            "",
        ]
    )
    return [*floor_line, "| " + " | ".join(columns) + " |", "|---" * len(columns) + "|"]


def _members(runs: dict[tuple[str, str, int], Member], name: str, label: str) -> list[Member]:
    return [m for (n, lab, _), m in runs.items() if (n, lab) == (name, label)]


def _shift_values(sh: EnsembleShift) -> tuple[np.ndarray, np.ndarray]:
    """(differences b - a, standard errors) in the units of ENSEMBLE_MEASURES."""
    deg = 180 / np.pi
    values = np.array([sh.rotation_median * deg, sh.transit_median, sh.spin_share])
    ses = np.array([sh.rotation_median_se * deg, sh.transit_median_se, sh.spin_share_se])
    return values, ses


def _ensemble_lines(
    runs: dict[tuple[str, str, int], Member], params: list[str], n: int, floored: bool = True
) -> list[str]:
    """The ensemble table; without floor runs (``floored`` False) effects are judged by z alone."""
    effect, se, floor = {}, {}, {}
    for name in params:
        effect[name], se[name] = _shift_values(
            ensemble_shift(_members(runs, name, "low"), _members(runs, name, "high"))
        )
        floor[name] = (
            _shift_values(
                ensemble_shift(_members(runs, name, "minus"), _members(runs, name, "plus"))
            )[0]
            if floored
            else np.full(len(ENSEMBLE_MEASURES), np.nan)
        )
    floor = {name: np.abs(v) for name, v in floor.items()}
    noise = (
        np.nanmedian(np.array(list(floor.values())), axis=0)
        if floored
        else np.full(len(ENSEMBLE_MEASURES), np.nan)
    )
    floor_words = (
        "; floor = |the same change| between the runs at the default -+step; noise floor = "
        "median of the floors. A ratio is |effect| / noise floor (inf where the floor is 0: no "
        "placement changed), z"
        if floored
        else " (no runs at the default -+step: no noise floor). z"
    )
    kinds = ("ratio", "z") if floored else ("z",)
    lines = [
        "",
        f"## The ensemble of {n} placements",
        "",
        "What each parameter does to the ensemble's statistics: effect = change from the "
        f"{n} runs at the low to the {n} runs at the high end (matched placements; high - low), "
        f"with its paired bootstrap standard error (SE){floor_words} = |effect| / SE.",
        "",
        *_table_head(
            "Ensemble noise floor",
            ENSEMBLE_MEASURES,
            noise if floored else None,
            ["parameter"],
            " (SE)",
            [f"{kind} {m}" for kind in kinds for m in ("rotation", "transit", "spins")],
        ),
    ]
    with np.errstate(divide="ignore", invalid="ignore"):
        for name in params:
            ratio = np.abs(effect[name]) / noise
            z = np.abs(effect[name]) / se[name]
            cells = [
                " | ".join(
                    f"{v:+.4g} ({e:.2g})" for v, e in zip(effect[name], se[name], strict=True)
                )
            ]
            if floored:
                cells += [
                    " | ".join(f"{v:.4g}" for v in floor[name]),
                    " | ".join(f"{v:.1f}" for v in ratio),
                ]
            cells.append(" | ".join(f"{v:.1f}" for v in z))
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        moved = {
            n_: bool(
                np.any((np.abs(effect[n_]) / noise >= 3) & (np.abs(effect[n_]) / se[n_] >= 2))
                if floored
                else np.any(np.abs(effect[n_]) / se[n_] >= 3)
            )
            for n_ in params
        }
    lines += [
        "",
        "Placement by placement (rotations closer than "
        f"{np.degrees(TIE_ANGLE):g} degree count as alike; sign test over the others):",
        "",
    ]
    for name in params:
        po = paired_order(_members(runs, name, "low"), _members(runs, name, "high"))
        lines.append(
            f"* {name}: at the high end further at {po.b_further} of {po.n_pairs} placements, "
            f"less at {po.a_further}, alike at {po.ties} (p = {po.p_value:.2g}); median paired "
            f"difference {np.degrees(po.median_difference):+.2f} degrees"
        )
    criterion = (
        ">= 3 times its floor and >= 2 standard errors" if floored else ">= 3 standard errors"
    )
    lines += [
        "",
        f"Parameters that move at least one ensemble statistic by {criterion}: "
        + (", ".join(n_ for n_ in params if moved[n_]) or "none")
        + "; not: "
        + (", ".join(n_ for n_ in params if not moved[n_]) or "none")
        + ".",
    ]
    return lines


def _response(a: Run | None, b: Run | None, cmp: Comparison) -> np.ndarray:
    if a is None or b is None:
        return np.full(3, np.nan)
    (xa, xb), (ta, tb) = cmp.series([a.trajectory, b.trajectory])
    dt = (
        abs(a.transit_time - b.transit_time)
        if a.transit_time is not None and b.transit_time is not None
        else np.nan
    )
    return np.array([dtw_distance(xa, xb), dtw_distance(ta, tb), dt])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", default="E3")
    ap.add_argument("--consignment", default="KPBW")
    ap.add_argument("--setting", type=int, default=1)
    ap.add_argument("--params", nargs="+", default=list(PUBLISHED_E3))
    ap.add_argument("--placements", type=int, default=1)
    ap.add_argument("--step", type=float, default=0.001, help="relative change for the floor")
    ap.add_argument(
        "--no-floor",
        action="store_true",
        help="skip the runs at the default -+step (half the simulations): no noise floor, "
        "the ensemble's effects judged by their standard errors alone",
    )
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument(
        "--wall-limit",
        type=float,
        default=WALL_LIMIT,
        help="wall-clock seconds after which a MuJoCo run stops as a timeout (not ok); raise it "
        "for costly scenes or a loaded machine",
    )
    ap.add_argument("--out", type=Path, default=Path("docs/research"))
    ap.add_argument("--scene", nargs="*", default=[], metavar="KEY=VALUE")
    ap.add_argument(
        "--bulge",
        type=float,
        default=None,
        metavar="FOOTPRINT",
        help="a bottom bulging below the rigid content over this share of the outline (0: flat)",
    )
    ap.add_argument("--bulge-depth", type=float, default=BULGE_DEPTH, help="[m]")
    ap.add_argument(
        "--backend",
        choices=("mujoco", "rigidbox"),
        default="mujoco",
        help="the model measured: MuJoCo's, or the independent rigid-box reference",
    )
    ap.add_argument(
        "--bottom-patch",
        choices=BOTTOM_PATCHES,
        default=None,
        help="rigidbox: where the bottom carries contact (default: the consignment's)",
    )
    args = ap.parse_args(argv)
    if args.no_floor and args.placements < 2:
        ap.error(
            "--no-floor judges each parameter by the ensemble's standard errors: give "
            "--placements 2 or more"
        )
    if args.backend == "rigidbox":
        absent = [n for n in args.params if n not in REFERENCE_PARAMETERS]
        if absent:
            ap.error(
                f"--params: {', '.join(absent)} do not exist in the rigid-box reference (it has "
                f"no packaging shell); it takes {', '.join(REFERENCE_PARAMETERS)}"
            )
        other = sorted(k.split("=", 1)[0] for k in args.scene if not k.startswith("start_offset="))
        if other:
            ap.error(
                f"--scene: the rigidbox backend takes only start_offset, not {', '.join(other)}"
            )
    elif args.bottom_patch is not None:
        ap.error("--bottom-patch is a setting of the rigid-box reference: add --backend rigidbox")
    bottom_patch = args.bottom_patch or "consignment"
    rig = load_rig(args.rig)
    cons = load_consignment(args.consignment)
    case = TestCase(args.rig, cons.name, args.setting)  # the name the simulators know it by
    if args.bulge is not None:  # 0: a flat bottom, whatever the consignment file says
        try:  # the packaging's scene checks the bulge (a rigid content, a patch inside it)
            cons = with_bulge(cons, args.bulge, args.bulge_depth)
            MujocoSimulator(consignments={cons.name: cons}).scene({}, case)
        except ParcelfitError as exc:
            ap.error(f"--bulge: {exc}")
    bending = [n for n in args.params if n in RIM_BENDING_PARAMETERS]
    if args.backend == "rigidbox" and bending:
        patch = resolved_bottom_patch(cons, bottom_patch)
        if patch != "rim-bending":
            ap.error(
                f"--params: {', '.join(bending)} act on the rigid-box reference only through its "
                f"rim's bending (--bottom-patch rim-bending, the default where the consignment "
                f"has no bulge); on {cons.name}'s {patch} patch they change nothing"
            )
    kind = cons.content_kind
    defaults = cons.parameter_values()
    spec = {p.name: p for p in CATALOGUE}
    seeds = list(range(args.placements))
    scene = scene_options(args.scene)
    jobs: dict[tuple[str, str, int], Job] = {}
    for name in args.params:
        low, high = spec[name].si_range(kind)
        d = defaults[name]
        levels = [("low", low), ("high", high)]
        if not args.no_floor:
            levels += [("minus", d * (1 - args.step)), ("plus", d * (1 + args.step))]
        for label, value in levels:
            for s in seeds:
                jobs[name, label, s] = (
                    {**defaults, name: value},
                    case,
                    s,
                    scene,
                    args.backend,
                    bottom_patch,
                    cons,
                    args.wall_limit,
                )
    t0 = time.perf_counter()
    print(f"{len(jobs)} simulations on {args.workers} processes", flush=True)
    with ProcessPoolExecutor(args.workers) as ex:
        futures = {ex.submit(_simulate, job): key for key, job in jobs.items()}
        done: dict[tuple[str, str, int], Member] = {}
        for i, fut in enumerate(as_completed(futures), 1):
            key = futures[fut]
            done[key] = member = fut.result()
            if member.status is not SimStatus.OK:  # at once: a timeout can waste hours
                name, label, seed = key
                print(
                    f"  {name} {label} placement {seed}: not ok ({member.status.value}, "
                    f"{member.wall_time:.0f} s)",
                    flush=True,
                )
            if i % max(1, len(jobs) // 20) == 0 or i == len(jobs):
                print(f"  {i}/{len(jobs)} ({time.perf_counter() - t0:.0f} s)", flush=True)
    runs = {key: done[key] for key in jobs}
    wall = time.perf_counter() - t0
    cmp = Comparison(regions=rig.regions, margin=rig.margin)
    effect, floor = {}, {}
    for name in args.params:
        effect[name] = np.nanmean(
            [_response(runs[name, "low", s].run, runs[name, "high", s].run, cmp) for s in seeds],
            axis=0,
        )
        floor[name] = (
            np.full(3, np.nan)
            if args.no_floor
            else np.nanmean(
                [
                    _response(runs[name, "minus", s].run, runs[name, "plus", s].run, cmp)
                    for s in seeds
                ],
                axis=0,
            )
        )
    noise = (
        np.full(3, np.nan)
        if args.no_floor
        else np.nanmedian(np.array(list(floor.values())), axis=0)
    )
    why = Counter(m.status.value for m in runs.values() if m.status is not SimStatus.OK)
    failed = sum(why.values())
    not_ok = f"{failed} not ok" + (
        ": " + ", ".join(f"{n} {status}" for status, n in sorted(why.items())) if failed else ""
    )
    lines = [
        "# Parameter effects" + ("" if args.no_floor else " against the numerical noise floor"),
        "",
        f"Written by `python scripts/parameter_effects.py --rig {args.rig} --consignment "
        f"{args.consignment} --setting {args.setting} --placements {args.placements} --step "
        f"{args.step:g}"
        + (" --no-floor" if args.no_floor else "")
        + (f" --params {' '.join(args.params)}" if list(args.params) != list(PUBLISHED_E3) else "")
        + (f" --scene {' '.join(args.scene)}" if args.scene else "")
        + (
            f" --bulge {args.bulge:g} --bulge-depth {args.bulge_depth:g}"
            if args.bulge is not None
            else ""
        )
        + (
            f" --backend rigidbox --bottom-patch {bottom_patch}"
            if args.backend == "rigidbox"
            else ""
        )
        + (f" --wall-limit {args.wall_limit:g}" if args.wall_limit != WALL_LIMIT else "")
        + f" --out {args.out}`: {len(runs)} simulations ({not_ok}) in {wall:.0f} s on "
        f"{args.workers} processes. Effect: the response between the runs at the two ends of "
        "the parameter's screening range"
        + (
            " (mean over the placements)."
            if args.no_floor
            else f"; floor: between the runs at the default -+{args.step:.1%}; ratio: effect / "
            "noise floor (median of the floors)."
        ),
        "",
        *_table_head(
            "Noise floor",
            MEASURES,
            None if args.no_floor else noise,
            ["parameter", "range"],
            "",
            [] if args.no_floor else ["ratio xy", "ratio theta", "ratio transit"],
        ),
    ]
    for name in args.params:
        r = spec[name].range_for(kind)
        cells = [f"{r.low:g}-{r.high:g} {spec[name].unit}", *(f"{v:.4g}" for v in effect[name])]
        if not args.no_floor:
            cells += [f"{v:.4g}" for v in floor[name]]
            cells += [f"{v:.1f}" for v in effect[name] / noise]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    if args.no_floor:
        lines += ["", "Noise floor not measured (`--no-floor`)."]
    else:
        ok = all(np.all(effect[n] / noise >= 3) for n in args.params)
        lines += ["", f"Every ratio >= 3: **{'yes' if ok else 'no'}**."]
    if len(seeds) >= 2:
        lines += _ensemble_lines(runs, args.params, len(seeds), floored=not args.no_floor)
    text = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "parameter-effects.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
