"""Synthetic tracking videos with a known trajectory: for tests, benchmarks and checking a set-up.

A top-down conveyor scene (grey belt), reference tags on the belt plane and one parcel (a light
box top at height h with its tag) moving along a known path, seen by a perspective pinhole camera
(optionally tilted, with lens distortion), with motion blur (``blur_samples`` sub-frame renders
averaged over the ``exposure``, centred on the frame's time), an optional rolling shutter (image
row r is exposed around t + (r / height - 0.5) * ``readout``, rendered in ``readout_bands``
bands of rows), Gaussian sensor noise and H.264 compression (libx264 through PyAV; OpenCV's own
writer has no H.264). `straight_spin` is a fast spinning parcel path (1.6 m/s, up to 720 deg/s);
`changing_path` one whose spin, sideways speed or speed changes abruptly (onsets, stops, catches,
decelerations).

Each tag is drawn by warping OpenCV's bitmap of it (``cv2.aruco.generateImageMarker``: the black
square, data and black border) with a white quiet zone one bit wide, from its bitmap corners to
the projected corners of the square at its height (exact for an undistorted camera; lens
distortion is then applied to the whole frame by ``cv2.remap``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from parcelfit.tracking.detect import dictionary
from parcelfit.tracking.tagmap import Camera, ReferenceTag, tag_corners

Path2D = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class SyntheticScene:
    """What to render; lengths in m, angles in rad, camera in px."""

    camera: Camera
    camera_position: tuple[float, float, float]  # rig frame [m]
    tilt: float  # rotation of the camera about its own x axis [rad]
    reference_tags: tuple[ReferenceTag, ...]
    parcel_tag_id: int
    parcel_tag_size: float
    parcel_height: float
    parcel_outline: tuple[float, float]
    tag_offset: tuple[float, float] = (0.0, 0.0)
    family: str = "tag36h11"
    fps: float = 60.0
    duration: float = 2.0
    exposure: float = 1 / 500  # s
    blur_samples: int = 3
    noise_sd: float = 2.0  # grey levels
    crf: int = 18
    belt_grey: int = 90
    parcel_grey: int = 200
    hidden: tuple[tuple[float, float], ...] = ()  # time spans [s] the parcel tag is covered
    shake: float = 0.0  # sd [m] of the camera's position, drawn afresh every frame
    readout: float = 0.0  # rolling shutter: time from the first to the last row's exposure [s]
    readout_bands: int = 128  # rows rendered in this many bands, each at its own time

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """rvec, tvec (OpenCV) of the camera: looking straight down, then tilted."""
        base = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])  # x right, image y = -rig y
        c, s = math.cos(self.tilt), math.sin(self.tilt)
        tilt = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        rot = tilt @ base
        tvec = -rot @ np.asarray(self.camera_position, dtype=float)
        rvec, _ = cv2.Rodrigues(rot)
        return rvec.reshape(3), tvec


def _marker(family: str, tag_id: int, bits_px: int = 12) -> np.ndarray:
    """The tag's black square plus a one-bit white quiet zone; returns (image, black side px)."""
    d = dictionary(family)
    bits = d.markerSize + 2  # data plus the black border
    side = bits * bits_px
    img = cv2.aruco.generateImageMarker(d, tag_id, side, borderBits=1)
    return cv2.copyMakeBorder(
        img, bits_px, bits_px, bits_px, bits_px, cv2.BORDER_CONSTANT, value=255
    )


class Renderer:
    """Renders frames of a `SyntheticScene` (grey uint8)."""

    def __init__(self, scene: SyntheticScene) -> None:
        self.scene = scene
        self.rvec, self.tvec = scene.pose()
        self.size = (scene.camera.width, scene.camera.height)
        self._k = scene.camera.matrix
        self._no_dist = np.zeros(5)
        self._markers: dict[int, np.ndarray] = {}
        base = np.full((self.size[1], self.size[0]), scene.belt_grey, np.float32)
        for tag in scene.reference_tags:
            self._draw_tag(base, tag.id, tag.corners(), 0.0)
        self._base = base
        self._distort_maps = self._maps() if np.any(scene.camera.dist) else None

    def project(self, points: np.ndarray, height: float) -> np.ndarray:
        """Ideal (undistorted) pixels of rig points (n, 2) at ``height``."""
        obj = np.column_stack([points, np.full(len(points), height)])
        img, _ = cv2.projectPoints(obj, self.rvec, self.tvec, self._k, self._no_dist)
        return img.reshape(-1, 2)

    def _draw_tag(
        self,
        frame: np.ndarray,
        tag_id: int,
        corners: np.ndarray,
        height: float,
        origin: tuple[int, int] = (0, 0),
    ) -> None:
        if tag_id not in self._markers:
            self._markers[tag_id] = _marker(self.scene.family, tag_id)
        marker = self._markers[tag_id]
        n = marker.shape[0]
        bits = dictionary(self.scene.family).markerSize + 4
        q = n / bits  # quiet zone width in marker pixels
        src = np.array([[q, q], [n - q, q], [n - q, n - q], [q, n - q]], np.float32) - 0.5
        dst = (self.project(corners, height) - origin).astype(np.float32)
        self._warp(frame, marker, src, dst)

    def _warp(self, frame: np.ndarray, image: np.ndarray, src: np.ndarray, dst: np.ndarray) -> None:
        h = cv2.getPerspectiveTransform(src, dst)
        rows, cols = image.shape[:2]
        outline = cv2.perspectiveTransform(
            np.array(
                [[[-0.5, -0.5], [cols - 0.5, -0.5], [cols - 0.5, rows - 0.5], [-0.5, rows - 0.5]]],
                np.float32,
            ),
            h,
        )[0]
        x0, y0 = np.floor(outline.min(axis=0)).astype(int) - 2
        x1, y1 = np.ceil(outline.max(axis=0)).astype(int) + 2
        x0, y0 = max(x0, 0), max(y0, 0)
        x1, y1 = min(x1, frame.shape[1]), min(y1, frame.shape[0])
        if x1 <= x0 or y1 <= y0:
            return
        shift = np.array([[1, 0, -x0], [0, 1, -y0], [0, 0, 1]], float)
        hw = shift @ h
        size = (x1 - x0, y1 - y0)
        # supersampled warp: 4x4 samples per pixel, so edges are area-averaged like a real sensor
        ss = 4
        up = np.diag([ss, ss, 1.0]) @ np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1]]) @ hw
        up = np.array([[1, 0, -0.5], [0, 1, -0.5], [0, 0, 1]]) @ up
        big = (size[0] * ss, size[1] * ss)
        warped = cv2.warpPerspective(image.astype(np.float32), up, big, flags=cv2.INTER_LINEAR)
        mask = cv2.warpPerspective(np.ones_like(image, np.float32), up, big, flags=cv2.INTER_LINEAR)
        warped = cv2.resize(warped, size, interpolation=cv2.INTER_AREA)
        mask = cv2.resize(mask, size, interpolation=cv2.INTER_AREA)
        roi = frame[y0:y1, x0:x1]
        roi[:] = roi * (1 - mask) + warped

    def _maps(self) -> tuple[np.ndarray, np.ndarray]:
        """For every distorted pixel, where it is in the ideal image (for cv2.remap)."""
        w, h = self.size
        grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).reshape(-1, 1, 2)
        cam = self.scene.camera
        ideal = cv2.undistortPoints(grid.astype(np.float32), cam.matrix, cam.dist, P=cam.matrix)
        ideal = ideal.reshape(h, w, 2)
        return ideal[..., 0].astype(np.float32), ideal[..., 1].astype(np.float32)

    def _parcel(
        self,
        frame: np.ndarray,
        x: float,
        y: float,
        theta: float,
        show_tag: bool = True,
        origin: tuple[int, int] = (0, 0),
    ) -> None:
        """Draw the parcel (and its tag) into ``frame``, a window of the image whose top-left
        pixel is ``origin`` (x, y)."""
        sc = self.scene
        length, width = sc.parcel_outline
        c, s = math.cos(theta), math.sin(theta)
        rot = np.array([[c, -s], [s, c]])
        box = np.array(
            [
                [-length / 2, width / 2],
                [length / 2, width / 2],
                [length / 2, -width / 2],
                [-length / 2, -width / 2],
            ]
        )
        top = box @ rot.T + np.array([x, y])
        pix = self.project(top, sc.parcel_height) - origin
        layer = np.zeros_like(frame)
        mask = np.zeros_like(frame)
        cv2.fillConvexPoly(
            layer, np.round(pix * 16).astype(np.int32), float(sc.parcel_grey), cv2.LINE_AA, 4
        )
        cv2.fillConvexPoly(mask, np.round(pix * 16).astype(np.int32), 1.0, cv2.LINE_AA, 4)
        frame[:] = frame * (1 - mask) + layer
        if not show_tag:
            return
        tx, ty = np.array([x, y]) + rot @ np.asarray(sc.tag_offset)
        self._draw_tag(
            frame,
            sc.parcel_tag_id,
            tag_corners(tx, ty, sc.parcel_tag_size, theta),
            sc.parcel_height,
            origin,
        )

    def _parcel_box(self, path: Path2D, t: float, span: float) -> tuple[int, int, int, int]:
        """The image window (first row, end row, first column, end column) [px] the parcel's
        box top covers within ``t`` +- ``span`` [s] (+ a 20 px margin), clipped to the image."""
        sc = self.scene
        xs, ys, _ = path(np.linspace(t - span, t + span, 9))
        r = math.hypot(*sc.parcel_outline) / 2 + 0.01
        pts = np.array(
            [
                (x + dx, y + dy)
                for x, y in zip(xs, ys, strict=True)
                for dx in (-r, r)
                for dy in (-r, r)
            ]
        )
        pix = self.project(pts, sc.parcel_height)
        w, h = self.size
        lo = np.clip(np.floor(pix.min(axis=0)) - 20, 0, [w, h]).astype(int)
        hi = np.clip(np.ceil(pix.max(axis=0)) + 21, 0, [w, h]).astype(int)
        return int(lo[1]), int(hi[1]), int(lo[0]), int(hi[0])

    def _exposed(
        self,
        path: Path2D,
        t: float,
        show_tag: bool,
        window: tuple[int, int, int, int] | None = None,
    ) -> np.ndarray:
        """The undistorted, noise-free image averaged over the exposure centred on ``t`` [s];
        only the ``window`` (first row, end row, first column, end column) when given (where
        the parcel is; a rolling shutter's band)."""
        sc = self.scene
        k = max(1, sc.blur_samples)
        times = t + (np.arange(k) + 0.5) / k * sc.exposure - sc.exposure / 2
        xs, ys, ths = path(times)
        a, b, c, d = window or (0, self._base.shape[0], 0, self._base.shape[1])
        base = self._base[a:b, c:d]
        acc = np.zeros_like(base)
        for x, y, th in zip(xs, ys, ths, strict=True):
            f = base.copy()
            self._parcel(f, float(x), float(y), float(th), show_tag, (c, a))
            acc += f
        return acc / k

    def frame(self, path: Path2D, t: float, rng: np.random.Generator) -> np.ndarray:
        """The frame at time ``t`` [s]: exposure-averaged, distorted, noisy (uint8)."""
        sc = self.scene
        if sc.shake > 0:  # the camera moved: new pose, reference tags drawn again
            moved = np.asarray(sc.camera_position) + rng.normal(0, sc.shake, 3)
            self.rvec, self.tvec = replace(sc, camera_position=tuple(moved)).pose()
            base = np.full((self.size[1], self.size[0]), sc.belt_grey, np.float32)
            for tag in sc.reference_tags:
                self._draw_tag(base, tag.id, tag.corners(), 0.0)
            self._base = base
        show_tag = not any(a <= t <= b for a, b in sc.hidden)
        if sc.readout > 0:
            h = self.size[1]
            bands = max(1, sc.readout_bands)
            edges = np.linspace(0, h, bands + 1).round().astype(int)
            img = self._base.copy()
            # only where the parcel can be during the readout is rendered
            lo, hi, c, d = self._parcel_box(path, t, sc.readout + sc.exposure)
            for a, b in itertools.pairwise(edges):
                if b <= lo or a >= hi:
                    continue
                mid_row = (a + b - 1) / 2
                tb = t + (mid_row / h - 0.5) * sc.readout
                img[a:b, c:d] = self._exposed(path, tb, show_tag, (a, b, c, d))
        else:
            img = self._base.copy()
            a, b, c, d = self._parcel_box(path, t, sc.exposure)
            img[a:b, c:d] = self._exposed(path, t, show_tag, (a, b, c, d))
        if self._distort_maps is not None:
            img = cv2.remap(img, *self._distort_maps, cv2.INTER_LINEAR, borderValue=sc.belt_grey)
        img = img + rng.normal(0, sc.noise_sd, img.shape)
        return np.clip(np.round(img), 0, 255).astype(np.uint8)


def render_video(
    target: str | Path, scene: SyntheticScene, path: Path2D, seed: int = 0
) -> dict[str, np.ndarray]:
    """Write an H.264 MP4 of the scene; returns the truth per frame: t [s], x, y [m], theta [rad]."""
    import av

    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    renderer = Renderer(scene)
    n = round(scene.duration * scene.fps)
    times = np.arange(n) / scene.fps
    with av.open(str(target), mode="w") as container:
        stream = container.add_stream("libx264", rate=round(scene.fps))
        stream.width, stream.height = renderer.size
        stream.pix_fmt = "yuv420p"
        stream.options = {"crf": str(scene.crf), "preset": "veryfast"}
        for t in times:
            grey = renderer.frame(path, float(t), rng)
            frame = av.VideoFrame.from_ndarray(
                cv2.cvtColor(grey, cv2.COLOR_GRAY2RGB), format="rgb24"
            )
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    x, y, th = path(times)
    return {"t": times, "x": np.asarray(x), "y": np.asarray(y), "theta": np.asarray(th)}


def conveyor_scene(
    width: int = 1280,
    height: int = 720,
    *,
    tilt_deg: float = 8.0,
    parcel_height: float = 0.025,
    distortion: tuple[float, ...] = (-0.05, 0.01, 0.0, 0.0, 0.0),
    **overrides: object,
) -> SyntheticScene:
    """A 1.6 m x 0.9 m conveyor stretch seen from 2 m, four reference tags near the corners, a
    KP/BW-sized parcel (275 x 200 mm) with a 60 mm tag; the camera scaled to ``width`` px."""
    f = width / 1.6 * 2.0 * 0.9  # the 1.6 m stretch fills ~90 % of the width at 2 m
    camera = Camera(f, f, width / 2 - 0.5, height / 2 - 0.5, tuple(distortion), width, height)
    refs = tuple(
        ReferenceTag(i, x, y, 0.08, math.radians(a))
        for i, (x, y, a) in enumerate(
            [(-0.62, 0.30, 0), (0.62, 0.30, 90), (0.62, -0.30, 180), (-0.62, -0.30, 270)]
        )
    )
    base = dict(
        camera=camera,
        camera_position=(0.0, 2.0 * math.tan(math.radians(tilt_deg)), 2.0),
        tilt=math.radians(tilt_deg),
        reference_tags=refs,
        parcel_tag_id=7,
        parcel_tag_size=0.06,
        parcel_height=parcel_height,
        parcel_outline=(0.275, 0.20),
    )
    base.update(overrides)
    return SyntheticScene(**base)  # type: ignore[arg-type]


def s_curve(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A parcel path: 0.55 m/s along x from -0.55 m, drifting across and turning by ~35 deg."""
    t = np.asarray(t, dtype=float)
    x = -0.55 + 0.55 * t
    y = 0.12 * np.sin(1.4 * t) - 0.05
    theta = math.radians(10) + math.radians(35) * np.sin(0.9 * t)
    return x, y, theta


def straight_spin(speed: float = 1.6, spin_deg_s: float = 720.0, start: float = -0.62) -> Path2D:
    """A parcel path: ``speed`` [m/s] along x from ``start`` [m], 30 mm across, spinning at
    ``spin_deg_s`` [deg/s] (a fast conveyor transfer)."""

    def path(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        x = start + speed * t
        y = -0.03 + 0.04 * t
        theta = math.radians(15) + math.radians(spin_deg_s) * t
        return x, y, theta

    return path


def changing_path(
    speed: float = 1.6,
    start: float = -0.62,
    *,
    spin_deg_s: tuple[float, float] = (0.0, 0.0),
    spin_change_s: float = math.inf,
    sideways: tuple[float, float] = (0.04, 0.04),
    sideways_change_s: float = math.inf,
    decel: float = 0.0,
    decel_from_s: float = math.inf,
) -> Path2D:
    """A parcel path whose motion changes abruptly (within no time at all), for the smoother:
    ``speed`` [m/s] along x from ``start`` [m], 30 mm across; the spin [deg/s] jumps from
    ``spin_deg_s[0]`` to ``spin_deg_s[1]`` at ``spin_change_s`` [s] (an onset when the first is
    0, a stop when the second is), the sideways speed [m/s] from ``sideways[0]`` to
    ``sideways[1]`` at ``sideways_change_s`` (a catch on a guide plate: to 0), and from
    ``decel_from_s`` the parcel slows along x at ``decel`` [m/s^2] until it stands."""
    w0, w1 = (math.radians(w) for w in spin_deg_s)
    v0, v1 = sideways
    stop = speed / decel if decel > 0 else math.inf

    def path(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        tau = np.clip(t - decel_from_s, 0.0, stop)
        x = start + speed * np.minimum(t, decel_from_s) + speed * tau - 0.5 * decel * tau * tau
        y = -0.03 + v0 * t + (v1 - v0) * np.maximum(t - sideways_change_s, 0.0)
        theta = math.radians(15) + w0 * t + (w1 - w0) * np.maximum(t - spin_change_s, 0.0)
        return x, y, theta

    return path


def render_checkerboard_video(
    target: str | Path,
    camera: Camera,
    board: tuple[int, int] = (9, 6),
    square: float = 0.04,
    frames: int = 24,
    seed: int = 0,
    fps: float = 10.0,
) -> Path:
    """An H.264 video of a checkerboard (``board`` inner corners, ``square`` [m]) held at varied
    poses 1.5-2.3 m in front of ``camera`` (with its distortion), for camera calibration tests."""
    import av

    rng = np.random.default_rng(seed)
    cols, rows = board
    px = 40
    img = np.full(((rows + 3) * px, (cols + 3) * px), 255, np.uint8)
    for r in range(rows + 1):
        for c in range(cols + 1):
            if (r + c) % 2 == 0:
                img[(r + 1) * px : (r + 2) * px, (c + 1) * px : (c + 2) * px] = 0
    # board image pixel (u, v) <-> board plane point ((u + 0.5) / px - 1) * square, same for v
    w_m, h_m = (cols + 3) * square, (rows + 3) * square
    src = np.array(
        [
            [-0.5, -0.5],
            [img.shape[1] - 0.5, -0.5],
            [img.shape[1] - 0.5, img.shape[0] - 0.5],
            [-0.5, img.shape[0] - 0.5],
        ],
        np.float32,
    )
    plane = np.array([[0, 0], [w_m, 0], [w_m, h_m], [0, h_m]]) - np.array([w_m, h_m]) / 2
    scene = SyntheticScene(camera, (0, 0, 1), 0.0, (), 0, 0.01, 0.0, (0.01, 0.01), noise_sd=1.5)
    renderer = Renderer(scene)
    target = Path(target)
    with av.open(str(target), mode="w") as container:
        stream = container.add_stream("libx264", rate=round(fps))
        stream.width, stream.height = camera.width, camera.height
        stream.pix_fmt = "yuv420p"
        stream.options = {"crf": "16", "preset": "veryfast"}
        for _ in range(frames):
            rvec = np.array(
                [rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)]
            )
            z = rng.uniform(1.5, 2.3)
            tvec = np.array([rng.uniform(-0.25, 0.25) * z, rng.uniform(-0.12, 0.12) * z, z])
            obj = np.column_stack([plane, np.zeros(4)])
            dst, _ = cv2.projectPoints(obj, rvec, tvec, camera.matrix, np.zeros(5))
            frame = np.full((camera.height, camera.width), 120, np.float32)
            renderer._warp(frame, img, src, dst.reshape(4, 2).astype(np.float32))
            if renderer._distort_maps is not None:
                frame = cv2.remap(frame, *renderer._distort_maps, cv2.INTER_LINEAR, borderValue=120)
            frame = np.clip(np.round(frame + rng.normal(0, 1.5, frame.shape)), 0, 255).astype(
                np.uint8
            )
            vf = av.VideoFrame.from_ndarray(cv2.cvtColor(frame, cv2.COLOR_GRAY2RGB), format="rgb24")
            for packet in stream.encode(vf):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return target


def scene_tag_map(
    scene: SyntheticScene, *, camera: bool = True, barriers: list[dict] | None = None
) -> dict:
    """The tag map document (as YAML would hold it) that describes ``scene``: its reference
    tags, its parcel tag, the true camera (unless ``camera`` is False) and ``barriers``."""
    doc: dict = {
        "family": scene.family,
        "reference_tags": {
            t.id: {"x": t.x, "y": t.y, "size": t.size, "angle": math.degrees(t.angle)}
            for t in scene.reference_tags
        },
        "parcel_tags": {
            scene.parcel_tag_id: {
                "size": scene.parcel_tag_size,
                "height": scene.parcel_height,
                "offset": list(scene.tag_offset),
                "outline": list(scene.parcel_outline),
            }
        },
    }
    if camera:
        cam = scene.camera
        doc["camera"] = {
            "fx": cam.fx,
            "fy": cam.fy,
            "cx": cam.cx,
            "cy": cam.cy,
            "distortion": list(cam.distortion),
            "width": cam.width,
            "height": cam.height,
        }
    if barriers:
        doc["light_barriers"] = barriers
    return doc
