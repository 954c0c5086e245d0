"""The machine a benchmark runs on, and how much other work ran beside it.

Wall times depend on the processor and on what else the machine does. On a 2-core machine a
2 s KP/BW run on E3 took as long beside one process busy on the other core as alone, and 1.4-1.5
times as long beside two (`python benchmarks/bench_sim.py --types KPBW --neighbours N`): other
work slows a single-process benchmark when it wants more cores than are free. The benchmark
therefore measures the cores other processes kept busy while it timed: the busy CPU time of
all cores from the kernel's /proc/stat (Linux) less this process's own CPU time, over the
wall time. Not measurable where
there is no /proc/stat, and not for a benchmark that runs worker processes of its own (their
CPU time is not this process's until they end).
"""

from __future__ import annotations

import multiprocessing
import os
import platform
import time
from pathlib import Path

OTHER_WORK_LIMIT = 0.2  # cores other processes may keep busy on average before times are suspect
_clock = time.perf_counter  # the wall clock [s] (a name of its own, for the tests)
_sleep = time.sleep


def processor() -> str:
    """The processor's model name (Linux's /proc/cpuinfo), else what the platform says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def busy_seconds(stat_cpu_line: str, ticks_per_second: float) -> float:
    """The CPU time [s] all cores have spent busy since boot, from the first ("cpu") line of
    /proc/stat: user, nice, system, irq, softirq and steal ticks (idle and iowait not counted;
    guest time is already inside user), over ``ticks_per_second``."""
    fields = stat_cpu_line.split()
    if not fields or fields[0] != "cpu":
        raise ValueError(f"not the cpu line of /proc/stat: {stat_cpu_line!r}")
    ticks = [int(x) for x in fields[1:]] + [0] * 8
    user, nice, system, _idle, _iowait, irq, softirq, steal = ticks[:8]
    return (user + nice + system + irq + softirq + steal) / ticks_per_second


def other_cores(busy: float, own: float, wall: float) -> float:
    """Cores kept busy on average by other processes over ``wall`` seconds [s] in which all
    cores were busy ``busy`` CPU seconds and this process ``own`` of them (at least 0)."""
    return max(0.0, (busy - own) / wall) if wall > 0 else 0.0


class OtherWork:
    """How many cores other processes keep busy, from its creation to :meth:`cores`."""

    def __init__(self) -> None:
        self._busy = _read_busy()
        self._own = _own_cpu()
        self._t = _clock()

    def cores(self) -> float | None:
        """Other processes' mean busy cores since creation, or None where not measurable."""
        busy = _read_busy()
        if busy is None or self._busy is None:
            return None
        return other_cores(busy - self._busy, _own_cpu() - self._own, _clock() - self._t)


def other_work_now(seconds: float = 2.0) -> float | None:
    """Cores other processes keep busy over the next ``seconds`` [s], this process idle: for a
    benchmark whose own worker processes keep it from measuring other work while it runs."""
    watch = OtherWork()
    _sleep(seconds)
    return watch.cores()


def report_other_work(other: float | None, cores: int | None) -> str:
    """The line (two with a warning) saying how many cores other processes kept busy while a
    single-process benchmark timed, warning when they took more than the ``cores`` - 1 it
    leaves free, by `OTHER_WORK_LIMIT`: then they competed for its core."""
    if other is None:
        return "other work beside the timing: not measured (no /proc/stat)"
    line = f"other work beside the timing: {other:.2f} cores busy on average"
    free = max((cores or 1) - 1, 0)
    if other > free + OTHER_WORK_LIMIT:
        line += (
            f"\nWARNING: other processes kept {other:.2f} cores busy, more than the {free} this "
            "benchmark leaves free: they took time on its core, so the wall times are slower "
            "than this machine's and not a measure against the targets; the ratios, measured "
            "alternately, count more"
        )
    return line


def busy_neighbour() -> multiprocessing.Process:
    """Start a process that keeps one core busy (a pure-Python loop: one thread) until
    terminated: other work of a known size beside a benchmark."""
    proc = multiprocessing.get_context("spawn").Process(target=_spin_forever, daemon=True)
    proc.start()
    return proc


def _spin_forever() -> None:
    """Compute a Lehmer sequence until killed: work on one core."""
    x = 1
    while True:
        x = (x * 48271) % 2147483647


def _read_busy() -> float | None:
    """All cores' busy CPU time since boot [s], or None where /proc/stat cannot be read."""
    try:
        line = Path("/proc/stat").read_text().splitlines()[0]
        return busy_seconds(line, os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError, AttributeError):
        return None


def _own_cpu() -> float:
    """This process's CPU time [s], its ended children's included."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system
