"""A small wrapper that runs one external solver and leaves none of its processes behind (Linux).

Run as a script (standard library only, so that ``python -I -S`` starts it in ~20 ms)::

    python -I -S _reaper.py PARENT_PID -- COMMAND ARG...

Why a wrapper: a solver's child that starts its own session (``setsid``, a double fork) leaves
the solver's process group, so killing the group misses it, and once its parent exits it is
reparented to init, where no walk of the process tree finds it again. The wrapper asks Linux to
make it a *child subreaper* (``prctl(PR_SET_CHILD_SUBREAPER)``, unprivileged since Linux 3.4):
every orphaned descendant is then reparented to the wrapper instead of to init, so all of the
solver's processes, escaped or not, stay in the wrapper's tree, which `descendants` reads from
``/proc/*/stat`` (parent pids). We chose this over a subreaper flag on the calling process
(a pool worker, a Dask worker with several threads or the command line itself), which would
collect the orphans of everything else that process starts, and over walking the tree of the
solver alone, which loses a double-forked daemon between two walks. cgroups would need
privileges or systemd.

The wrapper starts the command (standard streams inherited: the caller points them at files),
waits for it, and then, or when it gets SIGTERM, SIGINT or SIGHUP, or when its parent dies
(``PR_SET_PDEATHSIG`` and a check of the parent pid every 50 ms), SIGKILLs every descendant
(`kill_descendants`) and exits: with the solver's exit status, by the same signal when the
solver was killed by one, or with `START_FAILED` and a line on stderr beginning with
`START_FAILED_MARK` when the command could not be started.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import time

PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>
PR_SET_CHILD_SUBREAPER = 36
START_FAILED = 127  # the wrapper's exit status when the command could not be started
START_FAILED_MARK = "parcelfit: could not start the solver: "
_POLL_S = 0.05


def _stat(pid: int) -> tuple[int, str, int] | None:
    """(parent pid, state letter, start time [clock ticks since boot]) of ``pid``, or None."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            text = fh.read().decode("ascii", "replace")
    except OSError:
        return None
    # the command name (field 2) is in parentheses and may hold spaces and parentheses itself
    fields = text.rpartition(")")[2].split()
    try:
        return int(fields[1]), fields[0], int(fields[19])
    except (IndexError, ValueError):
        return None


def descendants(root: int) -> dict[int, int]:
    """Live (not zombie) descendants of ``root``: pid -> start time, from ``/proc/*/stat``."""
    children: dict[int, list[tuple[int, str, int]]] = {}
    try:
        names = os.listdir("/proc")
    except OSError:
        return {}
    for name in names:
        if name.isdigit():
            info = _stat(int(name))
            if info is not None:
                children.setdefault(info[0], []).append((int(name), info[1], info[2]))
    found: dict[int, int] = {}
    todo = [root]
    while todo:
        for pid, state, start in children.get(todo.pop(), ()):
            if pid not in found and pid != root:
                todo.append(pid)
                if state not in "ZX":
                    found[pid] = start
    return found


def _kill(pid: int, start: int) -> None:
    """SIGKILL ``pid`` if it is still the process that started at ``start`` (a pidfd pins the
    process, so a pid reused meanwhile by an unrelated process is never signalled)."""
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        return
    except (OSError, AttributeError):  # no pidfds (Linux < 5.3): check, then kill by pid
        info = _stat(pid)
        if info is not None and info[2] == start:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        return
    try:
        info = _stat(pid)
        if info is not None and info[2] == start:
            with contextlib.suppress(OSError):
                signal.pidfd_send_signal(fd, signal.SIGKILL)
    finally:
        os.close(fd)


def _reap() -> None:
    """Collect the exit status of every child that has ended (orphans reparented to us too)."""
    with contextlib.suppress(ChildProcessError):
        while os.waitpid(-1, os.WNOHANG)[0]:
            pass


def kill_descendants(root: int, limit_s: float = 5.0) -> list[int]:
    """SIGKILL every descendant of ``root`` until none is left (a process may fork while the
    others are being killed: its orphans come back to a subreaper ``root`` and are found on the
    next pass); reaps them when ``root`` is this process. Returns the pids still alive after
    ``limit_s`` seconds (processes in an uninterruptible sleep die only when it ends)."""
    deadline = time.monotonic() + limit_s
    while True:
        alive = descendants(root)
        if root == os.getpid():
            _reap()
        if not alive or time.monotonic() > deadline:
            return sorted(alive)
        for pid, start in alive.items():
            _kill(pid, start)
        time.sleep(0.005)


_stop: list[int] = []


def _on_signal(signum: int, _frame: object) -> None:
    _stop.append(signum)


def main(argv: list[str]) -> int:
    """Run ``argv`` = ``[PARENT_PID, "--", COMMAND, ARG...]`` (see the module docstring)."""
    parent, command = int(argv[0]), argv[2:]
    for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(sig, _on_signal)
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent:  # the caller died before the request took effect
        return 1
    try:
        # caught signals are reset to their defaults in the solver by exec; it stays in the
        # wrapper's process group (the caller's fallback kills that group)
        child = subprocess.Popen(command, stdin=subprocess.DEVNULL)
    except (OSError, ValueError) as exc:
        print(f"{START_FAILED_MARK}{exc}", file=sys.stderr, flush=True)
        return START_FAILED
    status: int | None = None
    while status is None and not _stop and os.getppid() == parent:
        # reap every child that ended: the solver, and orphans of it reparented to us
        with contextlib.suppress(ChildProcessError):
            while True:
                pid, wait_status = os.waitpid(-1, os.WNOHANG)
                if not pid:
                    break
                if pid == child.pid:
                    status = os.waitstatus_to_exitcode(wait_status)
        if status is None:
            time.sleep(_POLL_S)
    child.returncode = 0 if status is None else status  # reaped here, not by Popen
    kill_descendants(os.getpid())  # the solver too, when it is still running
    if status is None:  # stopped from outside or the caller died
        return 128 + (_stop[0] if _stop else signal.SIGTERM)
    if status < 0:  # killed by a signal: end the same way, so that the caller sees it
        with contextlib.suppress(OSError, ValueError):  # SIGKILL's action cannot be set
            signal.signal(-status, signal.SIG_DFL)
        os.kill(os.getpid(), -status)
        return 128 - status
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
