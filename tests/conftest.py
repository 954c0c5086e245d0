"""Shared helpers: small trajectories and datasets written to temporary folders."""

from __future__ import annotations

from collections.abc import Callable
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


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Start the longest tests first: with several test processes (``-n auto``) the others then
    share the rest instead of waiting for one long test at the end."""
    items.sort(key=lambda item: item.get_closest_marker("longest") is None)  # stable
