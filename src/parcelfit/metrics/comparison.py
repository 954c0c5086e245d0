"""How trajectories are prepared before two runs are compared by DTW.

Every comparison (reference selection, cost, validation) prepares trajectories the same way:

1. resample to ``rate`` [Hz] (default 60 Hz, the camera's rate). The unnormalised DTW distance
   sums local distances along the warping path, so it grows with the number of samples: real
   and simulated runs must share one rate for their distances to be comparable;
2. if ``relative``, subtract the run's initial position [m] and heading [rad] (its first sample,
   before cropping), which removes placement differences at the start guide;
3. crop to the regions of interest grown by ``margin`` [m]; the regions are tested on the
   absolute positions in the rig frame, before step 2's shift.

The x/y series is the (n, 2) array of centre positions [m]; the heading series is theta [rad].
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from parcelfit.errors import ParcelfitError
from parcelfit.runs import CaseData, Region, Trajectory, region_mask

DEFAULT_RATE_HZ = 60.0


@dataclass(frozen=True)
class Comparison:
    """Settings for preparing trajectories before DTW (see the module docstring)."""

    regions: tuple[Region, ...] = ()
    margin: float = 0.0
    relative: bool = True
    rate: float | None = DEFAULT_RATE_HZ
    window: int | None = None

    def __post_init__(self) -> None:
        if self.margin < 0:
            raise ParcelfitError(f"margin must be >= 0 m, got {self.margin}")
        if self.rate is not None and not self.rate > 0:
            raise ParcelfitError(f"rate must be a positive number of Hz, got {self.rate}")

    @classmethod
    def for_case(cls, case_data: CaseData, **overrides: object) -> Comparison:
        """The comparison using the regions and margin stored with a test case."""
        kwargs: dict[str, object] = {"regions": case_data.regions, "margin": case_data.margin}
        kwargs.update(overrides)
        return cls(**kwargs)  # type: ignore[arg-type]

    def prepare(self, trajectory: Trajectory) -> Trajectory:
        """Resample, make relative and crop one trajectory (positions [m], heading [rad])."""
        traj = trajectory.resample(self.rate) if self.rate is not None else trajectory
        mask = region_mask(traj, self.regions, self.margin)
        if self.relative:
            traj = traj.relative()
        return traj.select(mask)

    def series(
        self, trajectories: Sequence[Trajectory]
    ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Prepared x/y series ((n, 2) arrays [m]) and heading series ([rad]) of trajectories."""
        prepared = [self.prepare(t) for t in trajectories]
        return [p.xy for p in prepared], [p.theta for p in prepared]
