"""Make a twin dataset again, taking some consignment types' runs from an existing one.

Usage:
    python scripts/twin_regenerate.py SPEC --out DIR --reuse OLD --types PB [--workers 2]

`parcelfit synth SPEC --out DIR` with one difference: the runs of the consignment types named
by ``--types`` are not simulated but read from the dataset OLD (the same run ids), each with its
stored trajectory and transit time. Use it when a change of the twin specification cannot
change those types' runs, e.g. ``real_spacing`` (the mesh around a rigid content) for the
polybag, whose film and content meshes are settings of their own: their runs' inputs are the
same, so simulating them again would give the same runs. `synth`'s own cache of finished runs
cannot serve here, because its key is a hash of every setting, the changed one included. The
script checks only that OLD holds every run it takes; that a type's inputs did not change is
the user's claim (compare a few of its runs simulated anew, e.g. with ``--types`` left out on a
spec of one case).
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Sequence
from pathlib import Path

import parcelfit.synth as synth
from parcelfit.progress import ProgressEvent
from parcelfit.runs.dataset import load_dataset
from parcelfit.runs.run import Run

_simulate = synth._twin_run
# where to take runs from and which types, for every process: synth's worker processes start
# afresh ("spawn") and inherit the environment, and they call `_run` (this module's, by name)
_REUSE = "PARCELFIT_TWIN_REUSE"  # "FOLDER|TYPE,TYPE"
_kept: dict[str, dict[str, Run]] = {}


def _run(job: synth.TwinJob) -> tuple[Run, float]:
    """synth's run function, replaced: the stored run for a job of a reused type, else simulated."""
    folder, types = os.environ[_REUSE].split("|")
    if job.consignment.name not in types.split(","):
        return _simulate(job)
    if folder not in _kept:
        _kept[folder] = {r.id: r for c in load_dataset(folder).cases.values() for r in c.runs}
    kept = _kept[folder].get(job.run_id)
    if kept is None:
        raise SystemExit(f"{folder} has no run {job.run_id} to reuse")
    return Run(job.run_id, job.case, kept.trajectory, kept.transit_time), 0.0


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("spec", type=Path, help="the twin specification (YAML)")
    parser.add_argument("--out", type=Path, required=True, help="the new dataset's folder")
    parser.add_argument("--reuse", type=Path, required=True, help="the dataset to take runs from")
    parser.add_argument("--types", nargs="+", required=True, help="consignment types to take")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args(argv)
    load_dataset(args.reuse)  # a clear error now, not in a worker
    os.environ[_REUSE] = f"{args.reuse.resolve()}|{','.join(args.types)}"
    synth._twin_run = _run  # make_twin_dataset hands this function to its workers
    spec = synth.load_twin_spec(args.spec)
    start = time.perf_counter()

    def say(event: ProgressEvent) -> None:
        print(event.message, flush=True)

    path = spec.make(args.out, workers=args.workers, progress=say)
    print(f"wrote {path} in {(time.perf_counter() - start) / 60:.1f} min")


if __name__ == "__main__":
    main()
