"""Convergence of the *ensemble* outcome against mesh spacing and time step (issue: a corner
catch or a spin must be a converged physical outcome, not a mesh artefact).

    python scripts/ensemble_convergence.py                       # E3/1, KPBW BW KP, 20 placements
    python scripts/ensemble_convergence.py --types KPBW --placements 10 \
        --configs 30:600 20:600 15:1200
    python scripts/ensemble_convergence.py --rig E3
    python scripts/ensemble_convergence.py --types PB --configs 50:1200:100:tolerance=1e-6 \
        50:1200:100

For every numerical configuration (shell mesh spacing [mm] : steps per second; the spacing of
the packaging around a rigid content and of the polybag's film alike; optionally a soft
content's vertex spacing [mm] and other scene options as KEY=VALUE) it simulates
each consignment type at its default parameters for the placement seeds 0..N-1 (the rig's
``start.scatter``) and reports the ensemble statistics the published observations are judged by:
median absolute rotation, share of spins (> 90 degrees), median transit time, and, paired by
placement against the finest configuration (the reference, listed last), the median absolute
difference of each run's rotation [deg] and transit time [ms] and the share of placements whose
outcome (spin/slide) differs. Wall time per run is measured on one core per worker.

Writes ``ensemble-convergence-<rig>.md`` into ``--out`` (default docs/research/) after every type.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parcelfit.runs import TestCase
from parcelfit.sim.ensemble import Member, simulate_ensemble, summarise
from parcelfit.sim.mujoco import MujocoSimulator, load_rig
from parcelfit.sim.mujoco.options import SceneOptions, parse_scene_options
from parcelfit.sim.mujoco.simulator import SimOptions

DEFAULT_CONFIGS = ("40:600", "30:600", "20:600", "30:1200", "15:600", "15:1200")


@dataclass(frozen=True)
class Config:
    """Shell mesh spacing [m], time step [s] and, if given, a soft content's vertex spacing [m]
    (None: the default, `SceneOptions.soft_spacing`)."""

    spacing: float
    timestep: float
    content_spacing: float | None = None
    scene: tuple[str, ...] = ()  # other scene options, KEY=VALUE (e.g. tolerance=1e-6)

    @classmethod
    def parse(cls, text: str) -> Config:
        parts = text.split(":")
        scene = tuple(p for p in parts if "=" in p)
        parts = [p for p in parts if "=" not in p]
        if len(parts) not in (2, 3):
            raise ValueError(
                f"{text!r}: expected spacing_mm:steps_per_second[:content_spacing_mm][:KEY=VALUE]"
            )
        content = float(parts[2]) / 1e3 if len(parts) == 3 else None
        return cls(float(parts[0]) / 1e3, 1.0 / float(parts[1]), content, scene)

    @property
    def label(self) -> str:
        text = f"{self.spacing * 1e3:g} mm, 1/{round(1 / self.timestep)} s"
        if self.content_spacing is not None:
            text += f", content {self.content_spacing * 1e3:g} mm"
        if self.scene:
            text += ", " + ", ".join(self.scene)
        return text


class _Factory:
    """Picklable ``seed -> simulator`` for one numerical configuration and rig."""

    def __init__(self, config: Config, rig_arg: str) -> None:
        self.config, self.rig_arg = config, rig_arg

    def __call__(self, seed: int) -> MujocoSimulator:
        rig = load_rig(self.rig_arg)
        # the spacing is the shell's around either content: the film of a soft one too
        scene = SceneOptions(
            timestep=self.config.timestep,
            spacing=self.config.spacing,
            soft_shell_spacing=self.config.spacing,
            soft_spacing=self.config.content_spacing or SceneOptions.soft_spacing,
            **parse_scene_options(self.config.scene),  # type: ignore[arg-type]
        )
        sim = MujocoSimulator(SimOptions(scene=scene), rigs={rig.name: rig})
        return sim.with_placement(seed)


def _outcomes(members: list[Member]) -> dict[int, Member]:
    return {m.seed: m for m in members}


def _write(args, rig, configs, results, walls, types_done) -> None:
    """Write (and print) the table for the types finished so far."""
    ref = len(configs) - 1
    lines = [
        "# Ensemble convergence: mesh spacing and time step",
        "",
        f"Measured with `python scripts/ensemble_convergence.py --rig {args.rig} --setting "
        f"{args.setting} --types {' '.join(args.types)} --placements {args.placements} "
        f"--configs {' '.join(args.configs)}` ({args.workers} workers on a 2-core machine; wall "
        "times are per run and include the other worker's load).",
        "",
        f"Rig {rig.name}, speed setting {args.setting}, default parameters, placement seeds "
        f"0..{args.placements - 1}. The reference is the last configuration "
        f"({configs[ref].label}). Paired columns compare each placement with the same placement "
        "at the reference: median |delta rotation|, median |delta T| and the share of "
        "placements whose outcome (spin > 90 degrees / slide) differs.",
        "",
        "| type | mesh, step | median rotation [deg] | spins | median T [ms] | "
        "paired |d rot| [deg] | paired |d T| [ms] | paired d T [ms] | outcome differs | s/run |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    per_seed: list[str] = []
    for cons in types_done:
        reference = _outcomes(results[cons, ref])
        for k, cfg in enumerate(configs):
            members = results[cons, k]
            s = summarise(members)
            d_rot, d_t, differs, both = [], [], 0, 0
            for m in members:
                r = reference.get(m.seed)
                if r is None or m.rotation is None or r.rotation is None:
                    continue
                both += 1
                d_rot.append(abs(math.degrees(m.rotation - r.rotation)))
                if m.transit_time is not None and r.transit_time is not None:
                    d_t.append((m.transit_time - r.transit_time) * 1e3)
                differs += m.outcome != r.outcome
            paired = (
                ("-", "-", "-", "-")
                if k == ref
                else (
                    f"{np.median(d_rot):.1f}" if d_rot else "n/a",
                    f"{np.median(np.abs(d_t)):.1f}" if d_t else "n/a",
                    f"{np.median(d_t):+.1f}" if d_t else "n/a",
                    f"{differs}/{both}",
                )
            )
            lines.append(
                f"| {cons} | {cfg.label} | {math.degrees(s.rotation_median):.1f} "
                f"({math.degrees(s.rotation_q25):.0f}-{math.degrees(s.rotation_q75):.0f}) | "
                f"{s.spins}/{s.n} | {s.transit_median * 1e3:.1f} | {paired[0]} | {paired[1]} | "
                f"{paired[2]} | {paired[3]} | {walls[cons, k]:.1f} |"
            )
            by_seed = sorted(members, key=lambda m: m.seed)
            rot = ", ".join(
                "-" if m.rotation is None else f"{math.degrees(m.rotation):.0f}" for m in by_seed
            )
            tt = ", ".join(
                "-" if m.transit_time is None else f"{m.transit_time:.3f}" for m in by_seed
            )
            per_seed.append(f"| {cons} | {cfg.label} | {rot} | {tt} |")
    lines += [
        "",
        "Each placement (seeds in order): net rotation [deg] and transit time [s].",
        "",
        "| type | mesh, step | rotations | transit times |",
        "|---|---|---|---|",
        *per_seed,
    ]
    args.out.mkdir(parents=True, exist_ok=True)
    target = args.out / f"ensemble-convergence-{Path(args.rig).stem}.md"
    target.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"written: {target} ({len(types_done)} of {len(args.types)} types)", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rig", default="E3", help="bundled rig name or a rig YAML file")
    ap.add_argument("--setting", type=int, default=1)
    ap.add_argument("--types", nargs="+", default=["KPBW", "BW", "KP"])
    ap.add_argument("--placements", type=int, default=20)
    ap.add_argument(
        "--configs",
        nargs="+",
        default=list(DEFAULT_CONFIGS),
        help="spacing_mm:steps_per_second[:content_spacing_mm] (the last: a soft content's "
        "vertex spacing), finest (the reference) last",
    )
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", type=Path, default=Path("docs/research"))
    args = ap.parse_args(argv)

    rig = load_rig(args.rig)
    try:
        configs = [Config.parse(c) for c in args.configs]
    except ValueError as exc:
        ap.error(f"--configs: {exc}")
    seeds = list(range(args.placements))
    results: dict[tuple[str, int], list[Member]] = {}
    walls: dict[tuple[str, int], float] = {}
    started = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        for cons in args.types:
            for k, cfg in enumerate(configs):
                factory = _Factory(cfg, args.rig)
                params = factory(0).consignment(cons).parameter_values()
                case = TestCase(rig.name, cons, args.setting)
                members = simulate_ensemble(factory, params, case, seeds, executor=pool)
                results[cons, k] = members
                walls[cons, k] = float(np.median([m.wall_time for m in members]))
                s = summarise(members)
                print(
                    f"{cons:5s} {cfg.label:18s} median rot {math.degrees(s.rotation_median):6.1f} deg"
                    f"  spins {s.spins:2d}/{s.n}  median T {s.transit_median * 1e3:7.1f} ms"
                    f"  {walls[cons, k]:5.1f} s/run  ({time.perf_counter() - started:5.0f} s)",
                    flush=True,
                )
            _write(args, rig, configs, results, walls, args.types[: args.types.index(cons) + 1])

    return 0


if __name__ == "__main__":
    sys.exit(main())
