"""Top views of all bundled rigs x consignment types at speed setting 1 (docs/figures/cases.png).

python scripts/figure_all_cases.py
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure
from matplotlib.patches import Polygon as MplPolygon

from parcelfit.runs import TestCase
from parcelfit.sim.mujoco import (
    MujocoSimulator,
    SimOptions,
    bundled_consignment_names,
    bundled_rig_names,
)
from parcelfit.sim.mujoco.render import _outline, draw_rig

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "cases.png"


def main() -> None:
    sim = MujocoSimulator(SimOptions(record_vertices=True))
    rigs, types = bundled_rig_names(), ["KPBW", "PB", "KP", "BW"]
    assert sorted(types) == bundled_consignment_names()
    fig = Figure(figsize=(16, 11), layout="constrained")
    axes = fig.subplots(len(rigs), len(types))
    lines = ["| case | status | wall [s] | simulated [s] | transit [s] |", "|---|---|---|---|---|"]
    for i, rig in enumerate(rigs):
        for j, cons in enumerate(types):
            case = TestCase(rig, cons, 1)
            res, frames = sim.run_with_frames({}, case)
            ax = axes[i, j]
            draw_rig(ax, sim.rig(rig))
            if res.run is not None:
                tr = res.run.trajectory
                ax.plot(tr.x, tr.y, color="#c0392b", lw=1.2)
                for k in range(0, len(frames.t), 15):
                    ax.add_patch(
                        MplPolygon(
                            _outline(frames.vertices[k]),
                            closed=True,
                            facecolor="none",
                            edgecolor="#8a6a2a",
                            lw=0.6,
                        )
                    )
                xs, ys = frames.vertices[:, :, 0], frames.vertices[:, :, 1]
                ax.set_xlim(xs.min() - 0.25, xs.max() + 0.25)
                ax.set_ylim(ys.min() - 0.25, ys.max() + 0.25)
            tt = res.run.transit_time if res.run else None
            ax.set_title(
                f"{case.label}: {res.status.value}, {res.wall_time:.0f} s wall", fontsize=9
            )
            lines.append(
                f"| {case.label} | {res.status.value} | {res.wall_time:.1f} | "
                f"{res.diagnostics.get('simulated_time', 0):.2f} | {'-' if tt is None else f'{tt:.3f}'} |"
            )
            print(lines[-1], flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT, dpi=80)
    (OUT.parent / "cases.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
