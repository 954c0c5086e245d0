"""How long the README's commands take: the demo (quick and full) and, optionally, the tests.

    python benchmarks/bench_setup.py [--out bench-setup] [--skip-full] [--fast-tests] [--tests]

Runs ``parcelfit demo --quick`` and ``parcelfit demo`` (each into its own folder under
``--out``, removed first so that nothing is resumed), with ``--fast-tests`` the fast subset of
the tests (``python -m pytest -m "not slow"``, as the install page gives it) and, with
``--tests``, ``bash scripts/test.sh`` as CI runs it (``CI=true``: a fresh virtual environment, the base-install
check, lint, the suite and the documentation build). Prints the machine, each command's wall
time, its exit status, the verdict line the demo ended with, and the cores other processes kept
busy just before the first and after each (`machine_load.py`; the commands' own processes keep
it from measuring others while they run), so the times quoted in the README and the getting-started
pages come from this command.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from machine_load import installed, other_work_now, processor, usable_cores

ROOT = Path(__file__).resolve().parents[1]


def timed(name: str, command: list[str], log: Path, env: dict[str, str]) -> tuple[float, int]:
    """Run ``command`` from the repository's root with its output in ``log``; print and return
    its wall time [s] and exit status."""
    t0 = time.perf_counter()
    with log.open("w") as fh:
        status = subprocess.call(command, cwd=ROOT, stdout=fh, stderr=subprocess.STDOUT, env=env)
    wall = time.perf_counter() - t0
    verdict = next(
        (
            line.strip()
            for line in reversed(log.read_text().splitlines())
            if line.startswith("verdict:")
        ),
        "",
    )
    print(
        f"{name}: {wall / 60:.1f} min, exit {status}" + (f"; {verdict}" if verdict else ""),
        flush=True,
    )
    after = other_work_now()
    if after is not None:
        print(f"  other work just after it: {after:.2f} cores busy", flush=True)
    return wall, status


def main() -> None:
    """Time the commands and print the table."""
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--out", type=Path, default=Path("bench-setup"))
    ap.add_argument("--skip-full", action="store_true", help="time the quick demo only")
    ap.add_argument(
        "--fast-tests", action="store_true", help='also time python -m pytest -m "not slow"'
    )
    ap.add_argument("--tests", action="store_true", help="also time bash scripts/test.sh")
    args = ap.parse_args()
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    other = other_work_now()
    print(
        f"processor: {processor()}, {usable_cores()} usable cores; other work just before the "
        + ("start: not measured" if other is None else f"start: {other:.2f} cores busy"),
        flush=True,
    )
    print(f"installed: {installed(('mujoco', 'numpy', 'scipy', 'scikit-learn'))}", flush=True)
    parcelfit = [sys.executable, "-m", "parcelfit"]
    env = {**os.environ, "COLUMNS": "200"}  # the commands' lines unbroken in their logs
    runs = [("parcelfit demo --quick", [*parcelfit, "demo", "--quick"], "demo-quick")]
    if not args.skip_full:
        runs.append(("parcelfit demo", [*parcelfit, "demo"], "demo"))
    failed = False
    for name, command, folder in runs:
        shutil.rmtree(out / folder, ignore_errors=True)
        _, status = timed(name, [*command, "--out", str(out / folder)], out / f"{folder}.log", env)
        failed |= status != 0
    if args.fast_tests:
        _, status = timed(
            'python -m pytest -m "not slow"',
            [sys.executable, "-m", "pytest", "-q", "-m", "not slow"],
            out / "fast-tests.log",
            env,
        )
        failed |= status != 0
    if args.tests:
        _, status = timed(
            "bash scripts/test.sh (CI=true)",
            ["bash", "scripts/test.sh"],
            out / "test.log",
            {**env, "CI": "true"},
        )
        failed |= status != 0
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
