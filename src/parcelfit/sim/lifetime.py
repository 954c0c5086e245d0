"""Child processes that never outlive their parent: pool workers die with the process that
started them, and an external solver runs in its own process group, killed as a whole.

- `die_with_parent` is a worker initializer. On Linux it asks the kernel to send the worker
  SIGTERM when its parent dies (``prctl(PR_SET_PDEATHSIG)`` through ctypes: no library wraps
  it in the standard library); everywhere, a daemon thread also checks once a second whether
  the parent is gone (the portable fallback). Either way the worker kills the process groups of
  the solvers it started and exits, so a SIGKILLed ``parcelfit calibrate`` leaves nothing
  running behind it.
- `run_command` runs a command without a shell, its output going to two files in its work
  folder (never to pipes: a descendant that keeps a pipe open would make the caller wait for
  it), and returns when the command itself ends or at the timeout, having killed every process
  the command started. On Linux the command runs under a small wrapper, `parcelfit.sim._reaper`
  (see there why), that is a child subreaper: descendants that started their own session
  (``setsid``, double forks) are found and killed too. Elsewhere the command's process group
  is killed, which misses such descendants.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from parcelfit.sim._reaper import START_FAILED, START_FAILED_MARK, kill_descendants

PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>
# the wrapper needs /proc and prctl: Linux
_WRAPPED = sys.platform.startswith("linux")
_REAPER = str(Path(__file__).with_name("_reaper.py"))
STDOUT_FILE = "parcelfit-solver.stdout"  # the command's output, in its work folder
STDERR_FILE = "parcelfit-solver.stderr"
_TAIL_BYTES = 64 * 1024
_STOP_GRACE_S = 1.0  # how long a wrapper gets to kill its tree before it is killed itself
_groups: set[int] = set()  # process groups of the solvers (or their wrappers) running here


def _kill_group(pgid: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        if hasattr(os, "killpg"):
            os.killpg(pgid, signal.SIGKILL)
        else:  # Windows has no process groups to signal; the solver itself is killed
            os.kill(pgid, signal.SIGTERM)


def kill_groups() -> None:
    """End every solver this process started and that is still running: on Linux SIGTERM to
    its wrapper, which SIGKILLs all of the solver's processes (and would on its own, when this
    process dies); elsewhere SIGKILL to its process group."""
    for pgid in list(_groups):
        if _WRAPPED:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pgid, signal.SIGTERM)
        else:
            _kill_group(pgid)
        _groups.discard(pgid)


def _exit_now(*_: object) -> None:
    kill_groups()
    os._exit(1)


def die_with_parent(parent_pid: int, poll: float = 1.0) -> None:
    """Worker initializer: end this process (and its solvers) when ``parent_pid`` is gone."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _exit_now)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent_pid:  # the parent died before the request took effect
        _exit_now()

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(poll)
        _exit_now()

    threading.Thread(target=watch, name="parcelfit-parent-watch", daemon=True).start()


def _tail(path: Path, limit: int = _TAIL_BYTES) -> str:
    """The last ``limit`` bytes of a log file as text ('' when it is missing)."""
    try:
        with open(path, "rb") as fh:
            fh.seek(max(0, fh.seek(0, os.SEEK_END) - limit))
            return fh.read().decode("utf-8", "replace")
    except OSError:
        return ""


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """End a command that is still running, with everything it started; reap it."""
    if proc.poll() is not None:
        return
    if _WRAPPED:
        proc.send_signal(signal.SIGTERM)  # the wrapper kills the whole tree, then exits
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(_STOP_GRACE_S)
            return
        # a wrapper that does not answer: kill its tree from here while it still holds it
        kill_descendants(proc.pid, limit_s=_STOP_GRACE_S)
    _kill_group(proc.pid)
    proc.kill()
    proc.wait()


def run_command(
    args: Sequence[str], cwd: str | Path, timeout: float
) -> subprocess.CompletedProcess[str]:
    """Run ``args`` (no shell, stdin empty) in ``cwd`` and return its exit status and the last
    64 KiB of its output, which goes to the files `STDOUT_FILE` and `STDERR_FILE` in ``cwd``.

    Returns as soon as the command itself exits, having killed any process it left behind; at
    ``timeout`` [s] kills it and all of its descendants and raises `subprocess.TimeoutExpired`
    (within ~0.1 s on Linux). Raises `OSError` when the command cannot be started. A negative
    exit status is the signal that killed the command.
    """
    cwd = Path(cwd)
    command = (
        [sys.executable, "-I", "-S", _REAPER, str(os.getpid()), "--", *args]
        if _WRAPPED
        else list(args)
    )
    with open(cwd / STDOUT_FILE, "wb") as out, open(cwd / STDERR_FILE, "wb") as err:
        proc = subprocess.Popen(
            command,
            cwd=cwd,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=err,
            start_new_session=True,  # its own process group: no Ctrl-C from the terminal
        )
    _groups.add(proc.pid)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        _stop(proc)
        raise subprocess.TimeoutExpired(
            list(args), timeout, _tail(cwd / STDOUT_FILE), _tail(cwd / STDERR_FILE)
        ) from None
    finally:
        _stop(proc)  # also on KeyboardInterrupt: nothing is left running
        _groups.discard(proc.pid)
    if not _WRAPPED:
        _kill_group(proc.pid)  # children the solver left behind die with it
    stdout, stderr = _tail(cwd / STDOUT_FILE), _tail(cwd / STDERR_FILE)
    if _WRAPPED and proc.returncode == START_FAILED and stderr.startswith(START_FAILED_MARK):
        raise OSError(stderr[len(START_FAILED_MARK) :].strip())
    return subprocess.CompletedProcess(list(args), proc.returncode, stdout, stderr)
