"""The machine a benchmark runs on, and whether other work took time from it.

Wall times depend on the processor and on what else the machine does. A single-process
benchmark (one simulation on one core) measures, while it times:

* **its own share of a core**: its CPU time over the wall time. A single-threaded run alone on
  a core has about 1; less means other work took time on its core (or it waited for the disk).
* **the cores other processes kept busy**: the busy CPU time of all cores from the kernel's
  /proc/stat (Linux; user, nice, system, irq, softirq and steal, so a hypervisor's stolen time
  counts as other work; in a container /proc/stat is the host's) less its own CPU time, over
  the wall time. Worker processes of its own count as other work until they have ended and
  been waited for (then they are in its children's CPU time).

It warns when its own share is below `OWN_SHARE_MIN`, or when other processes took more than
the cores it leaves free (for a single-process benchmark the cores it may run on, less one) by
`OTHER_WORK_LIMIT`.
What other work did on one 2-core machine (`python benchmarks/bench_sim.py --types KPBW
--neighbours N`, each neighbour a pure-Python loop): with one, KP/BW took 1.03 times as long
as alone; with two, 1.49 times (docs/research/pb-speed.md). A neighbour that uses memory and
caches as a simulation does was not tried.
"""

from __future__ import annotations

import multiprocessing
import os
import platform
import time
from importlib import metadata
from pathlib import Path

OTHER_WORK_LIMIT = 0.2  # cores other processes may keep busy beyond the free ones
OWN_SHARE_MIN = 0.95  # the least share of a core a single-threaded timing may have
_clock = time.perf_counter  # the wall clock [s] (a name of its own, for the tests)
_sleep = time.sleep


def processor() -> str:
    """The processor: its model name with family, model and clock (Linux's /proc/cpuinfo, first
    core), else what the platform says."""
    fields: dict[str, str] = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if not line.strip():
                break
            key, _, value = line.partition(":")
            fields.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    return describe_processor(fields) or platform.processor() or platform.machine() or "unknown"


def installed(names: tuple[str, ...]) -> str:
    """The installed versions of the packages ``names`` ("numpy 2.4.6, ..."), "not installed"
    for those that are not, with Python's: a benchmark's results can differ between installs."""
    parts = [f"Python {platform.python_version()}"]
    for name in names:
        try:
            parts.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            parts.append(f"{name} not installed")
    return ", ".join(parts)


def describe_processor(fields: dict[str, str]) -> str:
    """A processor's description from its /proc/cpuinfo fields ("" when it names no model)."""
    name = fields.get("model name", "")
    if not name:
        return ""
    detail = [
        f"{label} {fields[key]}"
        for key, label in (("cpu family", "family"), ("model", "model"))
        if key in fields
    ]
    if "cpu MHz" in fields:
        detail.append(f"{float(fields['cpu MHz']):.0f} MHz")
    return f"{name} ({', '.join(detail)})" if detail else name


def usable_cores() -> int:
    """The cores this process may run on (its affinity), else the machine's."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


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


class Watch:
    """What this process and the others did on the machine, from its creation on."""

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

    def own_share(self) -> float:
        """This process's CPU time since creation over the wall time: its share of a core."""
        wall = _clock() - self._t
        return (_own_cpu() - self._own) / wall if wall > 0 else 1.0


def other_work_now(seconds: float = 2.0) -> float | None:
    """Cores other processes keep busy over the next ``seconds`` [s], this process idle: for a
    benchmark whose own worker processes keep it from measuring other work while it runs."""
    watch = Watch()
    _sleep(seconds)
    return watch.cores()


def report_machine(what: str, own_share: float | None, other: float | None, free: int) -> str:
    """The line saying how ``what`` was timed: this process's share of a core (None: not a
    single-process timing) and the cores other processes kept busy (None: not measured), with
    a warning (a second line) when its share is below `OWN_SHARE_MIN` or the others took more
    than the ``free`` cores the timing leaves them by more than `OTHER_WORK_LIMIT`."""
    parts = []
    if own_share is not None:
        parts.append(f"this process {own_share:.2f} of a core")
    parts.append("other work not measured" if other is None else f"other work {other:.2f} cores")
    line = f"{what}: {', '.join(parts)}"
    why = []
    if own_share is not None and own_share < OWN_SHARE_MIN:
        why.append(f"this process had {own_share:.2f} of a core (less than {OWN_SHARE_MIN})")
    if other is not None and other > free + OTHER_WORK_LIMIT:
        why.append(f"other processes kept {other:.2f} cores busy, more than the {free} left free")
    if why:
        line += (
            f"\nWARNING: {'; '.join(why)}: the wall times are slower than this machine's and "
            "not a measure against the targets; ratios measured alternately count more"
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
