"""Top views of a rig and a simulated parcel (matplotlib; no OpenGL needed).

`draw_rig` draws surfaces (with arrows for their motion), walls and light barriers;
`animate_run` writes a GIF (Pillow) or MP4 (ffmpeg, if installed) of the shell's outline over
time; `snapshot` draws the shell at chosen sample indices; `render_key_frames` simulates a run
once more with the vertices recorded and draws its key frames (and optionally an animation).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Polygon as MplPolygon
from matplotlib.patches import Rectangle

from parcelfit.errors import ParcelfitError
from parcelfit.runs import TestCase
from parcelfit.sim.mujoco.rig import Rig
from parcelfit.sim.mujoco.simulator import Frames, MujocoSimulator

_COLOURS = {"belt": "#5a5f6e", "roller": "#a0a040", "metal": "#9aa0aa"}


def _rect(
    ax: Axes, centre: np.ndarray, length: float, width: float, heading: float, colour: str
) -> None:
    a = math.radians(heading)
    u, n = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    corner = centre - u * length / 2 - n * width / 2
    ax.add_patch(
        Rectangle(
            tuple(corner),
            length,
            width,
            angle=heading,
            rotation_point="xy",
            facecolor=colour,
            edgecolor="none",
            alpha=0.45,
        )
    )


def draw_rig(ax: Axes, rig: Rig) -> None:
    """Draw the rig's surfaces, walls and light barriers into ``ax`` (metres)."""
    for s in rig.surfaces:
        u, n = s.unit(), np.array([-s.unit()[1], s.unit()[0]])
        c = np.asarray(s.centre)
        colour = _COLOURS.get(s.material, "grey")
        if s.type == "strips":
            for _name, centre, length, width in s.parts():
                _rect(ax, centre, length, width, s.heading, colour)
        elif s.type == "rollers":
            rows, cols = int(s.extra["rows"]), int(s.extra["columns"])
            h = s.heading + s.extra["swivel"]
            for r in range(rows):
                for col in range(cols):
                    p = (
                        c
                        + (col - (cols - 1) / 2) * (s.length / cols) * u
                        + (r - (rows - 1) / 2) * (s.width / rows) * n
                    )
                    _rect(ax, p, 2 * s.extra["radius"], s.extra["roller_width"], h, colour)
        else:
            _rect(ax, c, s.length, s.width, s.heading, colour)
        ax.annotate(
            "",
            xy=tuple(c + 0.12 * u),
            xytext=tuple(c - 0.12 * u),
            arrowprops={"arrowstyle": "->", "color": "white", "lw": 1.5},
        )
    for w in rig.walls:
        ax.plot([w.start[0], w.end[0]], [w.start[1], w.end[1]], color="#333333", lw=2.5)
    for b in rig.barriers:
        ax.plot([b.start[0], b.end[0]], [b.start[1], b.end[1]], color="red", lw=1, ls="--")
        ax.text(b.end[0], b.end[1], b.name, color="red", fontsize=7)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def _outline(vertices: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise) of the vertices' (x, y) [m] (Andrew's monotone chain)."""
    from scipy.spatial import ConvexHull

    xy = vertices[:, :2]
    return xy[ConvexHull(xy).vertices]


def snapshot(rig: Rig, frames: Frames, indices: Sequence[int], title: str = "") -> Figure:
    """Top view with the parcel's outline at the given sample indices."""
    fig = Figure(figsize=(9, 5), layout="constrained")
    ax = fig.subplots()
    draw_rig(ax, rig)
    for k, i in enumerate(indices):
        hull = _outline(frames.vertices[i])
        ax.add_patch(
            MplPolygon(
                hull,
                closed=True,
                facecolor="#d9b77e",
                edgecolor="#8a6a2a",
                alpha=0.3 + 0.7 * (k + 1) / len(indices),
            )
        )
        ax.text(*hull.mean(axis=0), f"{frames.t[i]:.2f}s", fontsize=6, ha="center")
    ax.autoscale_view()
    ax.set_title(title)
    return fig


def check_video_path(path: str | Path) -> None:
    """Refuse an animation file name whose suffix is not .gif or .mp4 (before any work)."""
    path = Path(path)
    if path.suffix.lower() not in (".gif", ".mp4"):
        raise ParcelfitError(
            f"unknown video type {path.suffix!r}", file=path, fix="use .gif or .mp4"
        )


def animate_run(rig: Rig, frames: Frames, path: str | Path, title: str = "", fps: int = 20) -> Path:
    """Write an animation of the parcel's top view to ``path`` (.gif, or .mp4 with ffmpeg)."""
    from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter

    path = Path(path)
    check_video_path(path)
    fig = Figure(figsize=(8, 4.5), dpi=100, layout="constrained")
    ax = fig.subplots()
    draw_rig(ax, rig)
    allxy = frames.vertices[:, :, :2].reshape(-1, 2)
    ax.set_xlim(allxy[:, 0].min() - 0.3, allxy[:, 0].max() + 0.3)
    ax.set_ylim(allxy[:, 1].min() - 0.3, allxy[:, 1].max() + 0.3)
    patch = MplPolygon(
        _outline(frames.vertices[0]), closed=True, facecolor="#d9b77e", edgecolor="#8a6a2a"
    )
    ax.add_patch(patch)
    label = ax.set_title(title)
    step = max(1, round(len(frames.t) / (fps * frames.t[-1]))) if frames.t[-1] > 0 else 1
    idx = list(range(0, len(frames.t), step))

    def update(i: int) -> tuple:
        patch.set_xy(_outline(frames.vertices[i]))
        label.set_text(f"{title}  t = {frames.t[i]:.2f} s")
        return patch, label

    anim = FuncAnimation(fig, update, frames=idx, blit=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        anim.save(path, writer=PillowWriter(fps=fps))
    else:
        try:
            anim.save(path, writer=FFMpegWriter(fps=fps))
        except (FileNotFoundError, RuntimeError) as exc:
            raise ParcelfitError(
                "writing MP4 needs ffmpeg on the PATH", fix="install ffmpeg or write a .gif"
            ) from exc
    return path


def key_frame_indices(n_samples: int, count: int = 6) -> list[int]:
    """``count`` sample indices spread evenly over a run of ``n_samples`` samples."""
    if n_samples <= 0:
        return []
    spread = np.linspace(0, n_samples - 1, min(count, n_samples)).round().astype(int)
    return sorted({int(i) for i in spread})


@dataclass(frozen=True)
class KeyFrames:
    """A run drawn at a few instants: the recording run's status ('ok' or why it ended), the
    figure (None unless the run succeeded) and the animation written (None if not asked)."""

    status: str
    figure: Figure | None
    animation: Path | None = None


def render_key_frames(
    simulator: MujocoSimulator,
    params: Mapping[str, float],
    case: TestCase,
    *,
    count: int = 7,
    animation: str | Path | None = None,
) -> KeyFrames:
    """Simulate ``case`` with SI ``params`` once more, recording the shell's vertices, and draw
    ``count`` key frames (and, with ``animation`` a .gif or .mp4 path, write an animation)."""
    recorder = simulator.with_options(record_vertices=True)
    result, frames = recorder.run_with_frames(dict(params), case, run_id="key-frames")
    if frames is None or not result.ok:
        return KeyFrames(result.status.value, None)
    rig = recorder.rig(case.rig)
    idx = key_frame_indices(len(frames.t), count)
    fig = snapshot(rig, frames, idx, f"{case.label}, calibrated parameters")
    gif = None
    if animation is not None:
        gif = animate_run(rig, frames, animation, f"{case.label} (calibrated)")
    return KeyFrames(result.status.value, fig, gif)
