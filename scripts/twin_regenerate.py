"""Make a twin dataset again, taking some consignment types' runs from an existing one.

Usage:
    python scripts/twin_regenerate.py SPEC --out DIR --reuse OLD --types PB [--workers 2]
    python scripts/twin_regenerate.py SPEC --out DIR --reuse OLD --only E1/KPBW/1 [--workers 2]

`parcelfit synth SPEC --out DIR` with one difference: the runs of the consignment types named
by ``--types`` (or of every test case but those named by ``--only``) are not simulated but read
from the dataset OLD (the same run ids), each with its stored trajectory and transit time.
Every run keeps its own random stream (specimen, placement, belt speeds, tracking noise), so a
case simulated again with another setting differs from OLD's by that setting alone.

``--types``: when a change of the twin specification cannot change those types' runs, e.g.
``real_spacing`` (the mesh around a rigid content) for the polybag, whose film and content
meshes are settings of their own: their runs' inputs are the same, so simulating them again
would give the same runs. `synth`'s own cache of finished runs cannot serve here, because its
key is a hash of every setting, the changed one included. The script checks only that OLD holds
every run it takes; that a type's inputs did not change is the user's claim.
``--only``: to see how a setting moves some cases' runs (e.g. a finer ``real_spacing``) without
simulating the rest. The dataset it writes describes every run by the spec's settings (its
description and truth.yaml), though only the named cases' runs were made with them: compare it
with OLD case by case, do not use it as a dataset of its own.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from pathlib import Path

import parcelfit.synth as synth
from parcelfit.errors import ParcelfitError
from parcelfit.progress import ProgressEvent
from parcelfit.runs import TestCase
from parcelfit.runs.dataset import load_dataset
from parcelfit.runs.run import Run


def _only_labels(spec: synth.TwinSpec, types: list[str], only: list[str]) -> list[str]:
    """``types`` and ``only`` checked against the spec (each type one of its cases'
    consignments, each case one of its cases); ``only`` as the spec writes its cases. Stops
    otherwise."""
    in_spec = {c.consignment for c in spec.cases}
    for name in types:
        if name not in in_spec:
            raise SystemExit(f"--types {name!r}: no case of the spec has it ({sorted(in_spec)})")
    labels = []
    for text in only:
        try:
            case = TestCase.parse(text)
        except ParcelfitError as exc:  # its message says what is wrong
            raise SystemExit(f"--only {text!r}: {exc}") from exc
        if case not in spec.cases:
            raise SystemExit(f"--only {text!r}: not a case of the spec")
        labels.append(case.label)
    return labels


def taking(old: Path, types: list[str], only: list[str]):
    """`make_twin_dataset`'s ``taken``: OLD's run for a job of one of ``types`` (or of a case
    not in ``only``), None (simulate) for the others; stops where OLD lacks a run to take."""
    runs = {r.id: r for c in load_dataset(old).cases.values() for r in c.runs}

    def taken(job: synth.TwinJob) -> Run | None:
        if (job.consignment.name not in types) if types else (job.case.label in only):
            return None
        kept = runs.get(job.run_id)
        if kept is None:
            raise SystemExit(f"{old} has no run {job.run_id} to reuse")
        return Run(job.run_id, job.case, kept.trajectory, kept.transit_time)

    return taken


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("spec", type=Path, help="the twin specification (YAML)")
    parser.add_argument("--out", type=Path, required=True, help="the new dataset's folder (new)")
    parser.add_argument("--reuse", type=Path, required=True, help="the dataset to take runs from")
    which = parser.add_mutually_exclusive_group(required=True)
    which.add_argument("--types", nargs="+", default=[], help="consignment types to take")
    which.add_argument(
        "--only", nargs="+", default=[], help="test cases to simulate, e.g. E1/KPBW/1"
    )
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args(argv)
    if args.out.exists():
        # synth's cache of finished runs does not record which runs were taken: a folder of
        # another --types or --only would hand its taken runs on as simulated ones
        raise SystemExit(f"{args.out} exists: give a new folder")
    spec = synth.load_twin_spec(args.spec)
    only = _only_labels(spec, args.types, args.only)
    taken = taking(args.reuse, args.types, only)
    start = time.perf_counter()

    def say(event: ProgressEvent) -> None:
        print(event.message, flush=True)

    path = spec.make(args.out, workers=args.workers, progress=say, taken=taken)
    print(f"wrote {path} in {(time.perf_counter() - start) / 60:.1f} min")
    if only:
        print(
            f"note: only {', '.join(only)} follow the spec's settings; every other run is "
            f"{args.reuse}'s, whatever the dataset's description and truth.yaml say"
        )


if __name__ == "__main__":
    main()
