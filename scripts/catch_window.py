"""Where does a parcel catch on E3's plate? Sweep the start across the strips, type by type.

    python scripts/catch_window.py                                  # E3 setting 1, BW KPBW KP
    python scripts/catch_window.py --types KPBW KP --range -30 30 --step 2
    python scripts/catch_window.py --set k_MePa=100 --out soft-plate

On E3 a parcel either slides along the guide plate or catches on its lead-in and swings round
(a spin). Which one happens is a threshold in the start pose, so a 20-placement ensemble
measures a share with a standard error of about 10 % and mixes geometry (where the parcel
meets the lead-in) with dynamics (whether it holds there). This sweep separates them: every
type starts at its nominal pose moved by an offset a [mm] across the strips (positive towards
the main belt's far side, the rig's ``start.scatter`` "across" direction), nothing else
changed, deterministic. Per type it reports the **catch window**, the offsets at which the net
rotation exceeds 90 degrees, and the share of the rig's across scatter (normal, its standard
deviation, cut at 2.5 sd like the placements) that falls into it: the share of spins the
across scatter alone would give. Windows of equal width at different places say the types
differ by geometry (the same catch, met at another start); windows of different width say the
dynamics differ. Writes ``catch-window.md``, ``figures/catch-window.png`` and every run's result
(``catch-window.json``: a rerun simulates only what is missing, so delete it after changing
the model) into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from scipy.stats import truncnorm

from parcelfit.atomic import write_text_atomic
from parcelfit.runs import TestCase
from parcelfit.sim.ensemble import SPIN_ANGLE, TYPE_COLOURS, rotation
from parcelfit.sim.mujoco import (
    MujocoSimulator,
    SimOptions,
    load_consignment,
    load_rig,
)
from parcelfit.sim.mujoco.options import scene_options
from parcelfit.sim.mujoco.rig import SCATTER_CUT
from parcelfit.sim.params import parameter, parse_assignments

MIN_COVERED = 0.95  # a convention's row needs this share of every type's scatter swept
RESULTS_FILE = "catch-window.json"  # every run's (rotation [rad], transit [s]); reruns resume


def _run(job: tuple[str, str, int, float, dict[str, float], list[str]]) -> tuple[float, float]:
    """(net rotation [rad], transit [s] or nan) of one start moved ``across`` [m]."""
    rig_ref, cons, setting, across, params, scene_args = job
    rig = load_rig(rig_ref)
    scene = scene_options(scene_args)
    x0, y0, h0 = scene.start_offset
    dx, dy = rig.start_shift(0.0, across)
    scene = replace(scene, start_offset=(x0 + dx, y0 + dy, h0))
    sim = MujocoSimulator(SimOptions(scene=scene), rigs={rig.name: rig})
    result = sim.run(params, TestCase(rig.name, cons, setting))
    if result.run is None:
        return float("nan"), float("nan")
    transit = result.run.transit_time
    return rotation(result.run.trajectory), float("nan") if transit is None else transit


def _key(job: tuple[str, str, int, float, dict[str, float], list[str]]) -> str:
    """The results file's key of a run: everything that decides its outcome."""
    rig_ref, cons, setting, across, params, scene_args = job
    return json.dumps(
        [rig_ref, cons, setting, round(across * 1e6), sorted(params.items()), scene_args]
    )


def _windows(offsets: np.ndarray, rotations: np.ndarray) -> list[tuple[float, float]]:
    """The runs of consecutive offsets [m] whose rotation exceeds 90 degrees, as (first, last)."""
    caught = np.abs(rotations) > SPIN_ANGLE
    out: list[tuple[float, float]] = []
    for k in np.flatnonzero(caught):
        if out and k > 0 and caught[k - 1]:
            out[-1] = (out[-1][0], float(offsets[k]))
        else:
            out.append((float(offsets[k]), float(offsets[k])))
    return out


def _scatter_share(offsets: np.ndarray, rotations: np.ndarray, sd: float) -> float:
    """The probability [-] that an across draw (normal, ``sd`` [m], cut at SCATTER_CUT sd) lands
    on a caught offset, each offset standing for the interval of half a step either side."""
    if sd <= 0:
        i = int(np.argmin(np.abs(offsets)))
        return float(abs(rotations[i]) > SPIN_ANGLE)
    mass = _scatter_mass(offsets, sd, 0.0)
    return float(np.sum(mass[np.abs(rotations) > SPIN_ANGLE]))


CONVENTIONS = {
    # how a hand lays each type, as the offset [m] of its centre from KP/BW's (the widths W):
    # centres on one spot (the bundled E3), or the right (-across, the lead-in's side) or the
    # left edges in line
    "centres on one spot": 0.0,
    "right edges in line": 0.5,
    "left edges in line": -0.5,
}


def _scatter_mass(offsets: np.ndarray, sd: float, shift: float) -> np.ndarray:
    """The probability [-] of each swept offset (half a step either side) for an across draw
    (normal, ``sd`` [m], cut at SCATTER_CUT sd) about ``shift`` [m]; what falls outside the
    sweep is left out (the masses then sum to less than 1)."""
    step = float(offsets[1] - offsets[0])
    dist = truncnorm(-SCATTER_CUT, SCATTER_CUT, loc=shift, scale=sd)
    return dist.cdf(offsets + step / 2) - dist.cdf(offsets - step / 2)


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The median of ``values`` drawn with probabilities ``weights`` (normalised here)."""
    order = np.argsort(values)
    cum = np.cumsum(weights[order]) / np.sum(weights)
    return float(values[order][np.searchsorted(cum, 0.5)])


def _conventions(
    offsets: np.ndarray,
    rot: dict[str, np.ndarray],
    widths: dict[str, float],
    sd: float,
    shifts: np.ndarray,
) -> list[str]:
    """Markdown: for each placement convention and common shift [m] of the start across, the
    median |rotation| [deg] per type under the across scatter and which E3 checks hold."""
    lines = [
        "| convention | shift [mm] | median rotation BW / KP/BW / KP [deg] | BW > 90 deg | "
        "BW > KP/BW > KP | KP < 30 deg | scatter inside the sweep |",
        "|---|---|---|---|---|---|---|",
    ]
    holds: dict[str, list[float]] = {}
    for name, factor in CONVENTIONS.items():
        holds[name] = []
        for shift in shifts:
            med, share90, covered = {}, 0.0, 1.0
            for cons in ("BW", "KPBW", "KP"):
                centre = shift + factor * (widths[cons] - widths["KPBW"])
                mass = _scatter_mass(offsets, sd, centre)
                covered = min(covered, float(mass.sum()))
                deg = np.degrees(np.abs(rot[cons]))
                med[cons] = _weighted_median(deg, mass)
                if cons == "BW":
                    share90 = float(mass[deg > 90].sum() / mass.sum())
            if covered < MIN_COVERED:
                continue
            order = med["BW"] > med["KPBW"] > med["KP"]
            ok = order and share90 >= 0.25 and med["KP"] < 30
            if ok:
                holds[name].append(float(shift))
            if round(shift * 1000) % 9 == 0:  # every 9 mm in the table
                lines.append(
                    f"| {name} | {shift * 1e3:+.0f} | {med['BW']:.0f} / {med['KPBW']:.0f} / "
                    f"{med['KP']:.0f} | {share90:.0%} | {'yes' if order else 'no'} | "
                    f"{'yes' if med['KP'] < 30 else 'no'} | {covered:.0%} |"
                )
    lines.append("")
    for name, ok in holds.items():
        where = ", ".join(f"{x * 1e3:+.0f}" for x in ok) if ok else "none"
        lines.append(
            f"- {name}: all three checks hold at shifts [mm] {where} (shifts with at least "
            f"{MIN_COVERED:.0%} of every type's scatter inside the sweep)"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", default="E3", help="bundled rig name or rig file")
    ap.add_argument("--types", nargs="+", default=["BW", "KPBW", "KP"])
    ap.add_argument("--setting", type=int, default=1)
    ap.add_argument("--range", nargs=2, type=float, default=(-36.0, 36.0), metavar=("LO", "HI"))
    ap.add_argument("--step", type=float, default=3.0, help="[mm]")
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="catalogue units")
    ap.add_argument("--scene", nargs="*", default=[], metavar="KEY=VALUE")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", type=Path, default=Path("docs/research"))
    args = ap.parse_args(argv)
    if args.step <= 0 or args.range[1] <= args.range[0]:
        ap.error("--range needs LO < HI and --step a positive number of mm")
    rig = load_rig(args.rig)
    params = {k: parameter(k).to_si(v) for k, v in parse_assignments(args.set).items()}
    n = math.floor((args.range[1] - args.range[0]) / args.step + 1e-9) + 1
    offsets = (args.range[0] + args.step * np.arange(n)) / 1000.0
    jobs = [
        (args.rig, cons, args.setting, float(a), params, list(args.scene))
        for cons in args.types
        for a in offsets
    ]
    args.out.mkdir(parents=True, exist_ok=True)
    store = args.out / RESULTS_FILE
    saved = json.loads(store.read_text()) if store.exists() else {}
    done: dict[str, list[float]] = saved.get("runs", {})
    wall_before = float(saved.get("wall_seconds", 0.0))  # of the calls that simulated the runs
    todo = [job for job in jobs if _key(job) not in done]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        for k, (job, res) in enumerate(zip(todo, pool.map(_run, todo), strict=True), 1):
            done[_key(job)] = list(res)
            wall = wall_before + time.perf_counter() - t0
            # a crash loses no finished run
            write_text_atomic(store, json.dumps({"runs": done, "wall_seconds": wall}, indent=0))
            if k % 10 == 0 or k == len(todo):
                print(f"  {k}/{len(todo)} runs ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    wall = wall_before + (time.perf_counter() - t0 if todo else 0.0)
    results = [tuple(done[_key(job)]) for job in jobs]
    rot = np.array([r[0] for r in results]).reshape(len(args.types), n)
    transit = np.array([r[1] for r in results]).reshape(len(args.types), n)
    sd_across = rig.start.scatter[1]

    (args.out / "figures").mkdir(exist_ok=True)
    fig, (ax_r, ax_t) = plt.subplots(2, 1, figsize=(7.5, 6.5), sharex=True)
    for i, cons in enumerate(args.types):
        colour = TYPE_COLOURS.get(cons)
        ax_r.plot(offsets * 1e3, np.degrees(np.abs(rot[i])), "o-", ms=3, color=colour, label=cons)
        ax_t.plot(offsets * 1e3, transit[i], "o-", ms=3, color=colour, label=cons)
    ax_r.axhline(90, color="0.4", lw=0.8, ls="--")
    for ax in (ax_r, ax_t):
        ax.axvspan(-sd_across * 1e3, sd_across * 1e3, color="0.9", zorder=0)
        ax.grid(alpha=0.3)
    ax_r.set_ylabel("net rotation [deg]")
    ax_t.set_ylabel("transit time [s]")
    ax_t.set_xlabel("start moved across the strips [mm] (grey: +-1 sd of the placement scatter)")
    ax_r.legend()
    ax_r.set_title(f"{rig.name} setting {args.setting}: catch window by start offset")
    fig.tight_layout()
    fig.savefig(args.out / "figures" / "catch-window.png", dpi=90)
    plt.close(fig)

    command = (
        f"python scripts/catch_window.py --rig {args.rig} --types {' '.join(args.types)} "
        f"--setting {args.setting} --range {args.range[0]:g} {args.range[1]:g} --step {args.step:g}"
        + (f" --set {' '.join(args.set)}" if args.set else "")
        + (f" --scene {' '.join(args.scene)}" if args.scene else "")
    )
    lines = [
        f"# Catch window on {rig.name}, speed setting {args.setting}",
        "",
        f"Written by `{command}` ({len(jobs)} runs, {wall:.0f} s on {args.workers} processes): "
        "each type from its nominal start moved across the strips by the offset (positive "
        "towards the main belt's far side), default parameters"
        + (f" except {', '.join(args.set)}" if args.set else "")
        + ". A catch: net rotation above 90 degrees. Share of the scatter: the probability that "
        f"the rig's across scatter (sd {sd_across * 1e3:g} mm, cut at {SCATTER_CUT:g} sd) lands "
        "on a caught offset, the along and heading scatter left out.",
        "",
        "![rotation and transit by start offset](figures/catch-window.png)",
        "",
        "| type | caught offsets [mm] | caught width [mm] | share of the across scatter | "
        "rotation at 0 [deg] | runs without a transit time |",
        "|---|---|---|---|---|---|",
    ]
    step = float(offsets[1] - offsets[0]) if n > 1 else 0.0
    i0 = int(np.argmin(np.abs(offsets)))
    at_zero = bool(abs(offsets[i0]) < 1e-9)
    for i, cons in enumerate(args.types):
        wins = _windows(offsets, rot[i])
        span = ", ".join(f"{a * 1e3:+.0f} to {b * 1e3:+.0f}" for a, b in wins) or "none"
        width = f"{sum(b - a + step for a, b in wins) * 1e3:.0f}"
        share = _scatter_share(offsets, rot[i], sd_across)
        nominal = f"{math.degrees(abs(rot[i, i0])):.0f}" if at_zero else "-"
        missing = int(np.sum(~np.isfinite(transit[i])))
        lines.append(f"| {cons} | {span} | {width} | {share:.0%} | {nominal} | {missing} |")
    lines += [
        "",
        "Net rotation [deg] at each offset "
        + ", ".join(f"{a * 1e3:+.0f}" for a in offsets)
        + " mm:",
        "",
    ]
    for i, cons in enumerate(args.types):
        lines.append(f"- {cons}: " + ", ".join(f"{math.degrees(abs(r)):.0f}" for r in rot[i]))
    if {"BW", "KPBW", "KP"} <= set(args.types):
        widths = {c: load_consignment(c).outer[1] for c in ("BW", "KPBW", "KP")}
        shifts = offsets[np.abs(offsets) <= 0.06 + 1e-9]
        rows = {c: rot[args.types.index(c)] for c in ("BW", "KPBW", "KP")}
        lines += [
            "",
            "## What a placement convention would give",
            "",
            "The swept rotations, read as a function of where each type starts, give the E3 "
            "checks of issue 11 for any way of laying the parcels: every type's start moved by a "
            "common shift across, and by half its width's difference from KP/BW's where an edge "
            "is put in line. Medians over the across scatter only (the along and heading "
            "scatter, which the 20-placement ensembles add, are left out).",
            "",
            *_conventions(offsets, rows, widths, sd_across, shifts),
        ]
    text = "\n".join(lines) + "\n"
    (args.out / "catch-window.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
