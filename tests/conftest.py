"""Shared helpers: small trajectories and datasets written to temporary folders."""

from __future__ import annotations

import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml

from parcelfit.runs import Trajectory


def line_trajectory(
    n: int = 50, vx: float = 0.6, y0: float = 0.0, turn: float = 0.0, dt: float = 1 / 60
) -> Trajectory:
    """A parcel moving along x at vx [m/s], drifting nothing, turning linearly by ``turn`` [rad]."""
    t = np.arange(n) * dt
    return Trajectory(t=t, x=vx * t, y=np.full(n, y0), theta=np.linspace(0.0, turn, n))


@pytest.fixture
def make_dataset(tmp_path: Path) -> Callable[..., Path]:
    """Write a dataset folder from {case: [(run_id, trajectory, transit)]} and return it."""

    def build(
        cases: dict[tuple[str, str, int], list[tuple[str, Trajectory, float | None]]],
        extra: dict | None = None,
    ) -> Path:
        root = tmp_path / "ds"
        (root / "runs").mkdir(parents=True, exist_ok=True)
        entries = []
        for (rig, cons, setting), runs in cases.items():
            run_docs = []
            for run_id, traj, transit in runs:
                traj.to_frame().to_csv(root / "runs" / f"{run_id}.csv", index=False)
                run_docs.append(
                    {"id": run_id, "file": f"runs/{run_id}.csv", "transit_time": transit}
                )
            entries.append(
                {"rig": rig, "consignment": cons, "speed_setting": setting, "runs": run_docs}
            )
        doc = {"name": "test", "test_cases": entries, **(extra or {})}
        (root / "dataset.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
        return root

    return build


def _sigint_ignored() -> bool | None:
    """Whether the kernel ignores SIGINT in this process (Linux's /proc; None elsewhere): also
    when a C library set it, which `signal.getsignal` does not see."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            line = next(line for line in fh if line.startswith("SigIgn:"))
    except (OSError, StopIteration):
        return None
    return bool(int(line.split()[1], 16) >> (signal.SIGINT - 1) & 1)


def _sigint_state() -> tuple[object, frozenset[int], bool | None]:
    """This thread's Ctrl-C handler, its blocked signals and whether the kernel ignores SIGINT."""
    mask = (
        signal.pthread_sigmask(signal.SIG_BLOCK, []) if hasattr(signal, "pthread_sigmask") else ()
    )
    return signal.getsignal(signal.SIGINT), frozenset(mask), _sigint_ignored()


@pytest.fixture(autouse=True)
def _ctrl_c_left_as_found() -> Iterator[None]:
    """Fail a test that leaves Ctrl-C (SIGINT) handled otherwise, ignored, or signals blocked in
    the test process: later tests there would be deaf to Ctrl-C. The state is restored for them."""
    before = _sigint_state()
    yield
    after = _sigint_state()
    if after == before:
        return
    if before[0] is not None:
        signal.signal(signal.SIGINT, before[0])  # type: ignore[arg-type]
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_SETMASK, before[1])
    pytest.fail(
        f"the test left SIGINT's handler {after[0]!r} (was {before[0]!r}), blocked signals "
        f"{sorted(map(int, after[1]))} (were {sorted(map(int, before[1]))}) and SIGINT ignored "
        f"by the kernel: {after[2]} (was {before[2]})"
    )


@pytest.fixture
def no_study_figures(monkeypatch: pytest.MonkeyPatch) -> None:
    """Calibrations in this test draw no study figures (PNG and SVG: seconds of matplotlib per
    calibration), as `Calibration(..., figures=False)` does, also for the `parcelfit calibrate`
    command run in this process: for tests of what a study stores, refuses or resumes."""
    from parcelfit.study.finish import Finish

    real = Finish.__init__

    def without_figures(self: Finish, *args: object, **kwargs: object) -> None:
        real(self, *args, **{**kwargs, "figures": False})  # type: ignore[arg-type]

    monkeypatch.setattr(Finish, "__init__", without_figures)


@pytest.fixture
def no_report_figures(monkeypatch: pytest.MonkeyPatch) -> None:
    """The report's figures are made but not drawn: each is embedded as a one-pixel PNG
    (drawing one takes about 0.4 s); for tests of the page's text. The report's own tests draw
    them."""
    import io

    from PIL import Image

    from parcelfit.report import calibration, html, page, prediction

    buf = io.BytesIO()
    Image.new("L", (1, 1)).save(buf, format="PNG")

    def placeholder(fig: object, alt: str, dpi: int = 100) -> object:
        return page.png_html(buf.getvalue(), alt)

    for module, name in (
        (page, "figure_html"),
        (calibration, "figure_html"),
        (html, "figure_html"),
        (prediction, "_figure_html"),
    ):
        monkeypatch.setattr(module, name, placeholder)


@pytest.fixture
def ctrl_c() -> Iterator[None]:
    """Ctrl-C (SIGINT) raises KeyboardInterrupt in this process during the test, and reaches the
    commands it starts, also when the test run itself was started with SIGINT ignored (a job put
    in the background by a non-interactive shell, nohup): an ignored signal stays ignored in
    every process started from there, and Python keeps it so. A handled one is reset to the
    default in a started command."""
    previous = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        if previous is not None:  # None: a handler not set from Python, which cannot be put back
            signal.signal(signal.SIGINT, previous)  # type: ignore[arg-type]


def pytest_report_header() -> str | None:
    """Say so when this test process started with Ctrl-C ignored (the `ctrl_c` fixture)."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN or _sigint_ignored():
        return "SIGINT is ignored in this process: the Ctrl-C tests enable it for themselves"
    return None


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Start the longest tests first: with several test processes (``-n auto``) the others then
    share the rest instead of waiting for one long test at the end."""
    items.sort(key=lambda item: item.get_closest_marker("longest") is None)  # stable
