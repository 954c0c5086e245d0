"""Child processes that never outlive their parent: pool workers die with the process that
started them, and an external solver runs in its own process group, killed as a whole.

- `die_with_parent` is a worker initializer. On Linux it asks the kernel to send the worker
  SIGTERM when its parent dies (``prctl(PR_SET_PDEATHSIG)`` through ctypes: no library wraps
  it in the standard library); everywhere, a daemon thread also checks once a second whether
  the parent is gone (the portable fallback). Either way the worker kills the process groups of
  the solvers it started and exits, so a SIGKILLed ``parcelfit calibrate`` leaves nothing
  running behind it.
- `run_command` runs a command without a shell in a new process group (session) and kills the
  whole group, the solver's own children included, at the timeout or when the worker dies.
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

PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>
_groups: set[int] = set()  # process groups of the solvers this process is running


def _kill_group(pgid: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        if hasattr(os, "killpg"):
            os.killpg(pgid, signal.SIGKILL)
        else:  # Windows has no process groups to signal; the solver itself is killed
            os.kill(pgid, signal.SIGTERM)


def kill_groups() -> None:
    """SIGKILL every solver process group this process started and that is still running."""
    for pgid in list(_groups):
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


def run_command(
    args: Sequence[str], cwd: str | Path, timeout: float
) -> subprocess.CompletedProcess[str]:
    """Run ``args`` (no shell) in ``cwd`` in a new process group; capture its output as text.

    At ``timeout`` [s] the whole group is killed and `subprocess.TimeoutExpired` raised.
    """
    proc = subprocess.Popen(
        list(args),
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, so its children can be killed too
    )
    _groups.add(proc.pid)
    try:
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill_group(proc.pid)
            proc.kill()
            proc.communicate()
            raise
        _kill_group(proc.pid)  # children the solver left behind die with it
    finally:
        _groups.discard(proc.pid)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return subprocess.CompletedProcess(list(args), proc.returncode, out, err)
