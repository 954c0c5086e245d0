import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from parcelfit import ParcelfitError
from parcelfit.cli import app
from parcelfit.runs import Trajectory, load_dataset, read_trajectory, write_trajectory
from parcelfit.sim.mujoco import load_rig
from parcelfit.tracking import (
    crossing_time,
    load_tag_map,
    read_sensor_log,
    track_all,
    track_video,
)
from parcelfit.tracking.synthetic import conveyor_scene, render_video, s_curve, scene_tag_map
from parcelfit.tracking.track import TrackOptions, fill_gaps

runner = CliRunner()
FPS = 60.0
BARRIERS = [
    {"id": "in", "from": [-0.3, -0.45], "to": [-0.3, 0.45]},
    {"id": "out", "from": [0.1, -0.45], "to": [0.1, 0.45]},
]


def tag_map_doc(scene, *, camera=True):
    return scene_tag_map(scene, camera=camera, barriers=BARRIERS)


def write_tag_map(path, scene, **kw):
    path.write_text(yaml.safe_dump(tag_map_doc(scene, **kw)))
    return path


@pytest.fixture(scope="module")
def videos(tmp_path_factory):
    """Rendered test videos: tilted camera with lens distortion, tag 2.5 cm above the belt,
    motion blur (2.2 mm travel per exposure), noise, H.264; one with camera shake and covered
    frames."""
    root = tmp_path_factory.mktemp("videos")
    scene = conveyor_scene(exposure=1 / 250, tag_offset=(0.04, -0.02))
    truth = render_video(root / "plain.mp4", scene, s_curve, seed=1)
    hard_scene = conveyor_scene(
        exposure=1 / 250,
        shake=0.002,
        hidden=((0.30, 0.33), (0.70, 0.86)),  # 2-3 frames, then 10 frames covered
        duration=1.2,
    )
    hard_truth = render_video(root / "hard.mp4", hard_scene, s_curve, seed=2)
    return {
        "root": root,
        "scene": scene,
        "truth": truth,
        "hard_scene": hard_scene,
        "hard_truth": truth_of(hard_truth),
        "plain_truth": truth_of(truth),
    }


def truth_of(doc):
    return {k: np.asarray(v) for k, v in doc.items()}


def errors(traj, truth):
    k = np.round(traj.t * FPS).astype(int)
    pos = np.hypot(traj.x - truth["x"][k], traj.y - truth["y"][k])
    head = np.abs(np.degrees(traj.theta - truth["theta"][k]))
    return pos, head


def true_crossings(scene):
    t = np.arange(0, scene.duration, 1e-4)
    x, y, th = s_curve(t)
    fine = Trajectory(t=t, x=x, y=y, theta=th)
    tm = load_tag_map_from_doc(tag_map_doc(scene))
    return {b.name: crossing_time(fine, b, scene.parcel_outline) for b in tm.barriers}


def load_tag_map_from_doc(doc, tmp=[]):  # noqa: B006 - a cache of temp folders
    import tempfile
    from pathlib import Path

    d = Path(tempfile.mkdtemp())
    tmp.append(d)
    (d / "tags.yaml").write_text(yaml.safe_dump(doc))
    return load_tag_map(d / "tags.yaml")


@pytest.mark.slow
def test_positions_headings_and_transit_time_are_accurate(videos, tmp_path):
    scene = videos["scene"]
    tm = load_tag_map(write_tag_map(tmp_path / "tags.yaml", scene))
    result = track_video(videos["root"] / "plain.mp4", tm)
    track = result.tags[scene.parcel_tag_id]
    assert track.quality["detection_rate"] == 1.0 and len(track.trajectory) == 120
    pos, head = errors(track.trajectory, videos["plain_truth"])
    assert pos.mean() <= 0.001 and pos.max() <= 0.003  # mean <= 1 mm, max <= 3 mm
    assert head.max() <= 1.0  # degrees
    crossings = true_crossings(scene)
    true_transit = crossings["out"] - crossings["in"]
    assert abs(track.transit_time - true_transit) <= 1 / FPS
    for key in ("in", "out"):
        assert abs(track.crossings[key] - crossings[key]) <= 1 / FPS
    assert result.quality["parallax_corrected"]
    assert result.quality["reference_reprojection_px"]["max"] < 1.0


@pytest.mark.slow  # renders the videos fixture
def test_without_a_camera_model_parallax_stays_and_the_report_says_so(videos, tmp_path):
    scene = videos["scene"]
    tm = load_tag_map(write_tag_map(tmp_path / "tags.yaml", scene, camera=False))
    result = track_video(videos["root"] / "plain.mp4", tm)
    assert not result.quality["parallax_corrected"]
    assert "NOT corrected" in result.quality["parallax_note"]
    pos, _ = errors(result.tags[scene.parcel_tag_id].trajectory, videos["plain_truth"])
    # a tag 2.5 cm up seen from 2 m is mapped outwards: millimetres off, not sub-millimetre
    assert pos.mean() > 0.002


@pytest.mark.slow
def test_camera_shake_and_covered_frames(videos, tmp_path):
    scene = videos["hard_scene"]
    tm = load_tag_map(write_tag_map(tmp_path / "tags.yaml", scene))
    result = track_video(videos["root"] / "hard.mp4", tm, TrackOptions(max_gap=5))
    track = result.tags[scene.parcel_tag_id]
    gaps = track.quality["gaps"]
    assert [g["interpolated"] for g in gaps] == [True, False]
    assert gaps[0]["frames"] <= 3 and gaps[1]["frames"] >= 9
    # the long gap's samples are left out, the short one's filled
    assert len(track.trajectory) == 72 - gaps[1]["frames"]
    pos, head = errors(track.trajectory, videos["hard_truth"])
    assert pos.max() <= 0.003 and head.max() <= 1.0  # the geometry follows the shaking camera
    assert result.quality["frames_without_reference_tags"] == 0


def test_fill_gaps_trims_unwraps_and_fills_only_short_gaps():
    t = np.arange(12) / 10
    x = np.array([np.nan, 0, 1, np.nan, 3, 4, np.nan, np.nan, np.nan, 8, 9, np.nan])
    theta = np.array([0, 3.1, -3.1, np.nan, -3.0, -2.9, np.nan, np.nan, np.nan, -2.5, -2.4, 0])
    traj, gaps = fill_gaps(t, x, x.copy(), theta, max_gap=2)
    assert traj.t[0] == pytest.approx(0.1) and traj.t[-1] == pytest.approx(1.0)
    assert [(g["frames"], g["interpolated"]) for g in gaps] == [(1, True), (3, False)]
    assert traj.x == pytest.approx([0, 1, 2, 3, 4, 8, 9])
    assert np.all(np.abs(np.diff(traj.theta[:5])) < 0.2)  # unwrapped across +-pi


def test_fill_gaps_flags_exactly_the_filled_samples():
    t = np.arange(12) / 10
    x = np.array([np.nan, 0, 1, np.nan, 3, 4, np.nan, np.nan, np.nan, 8, 9, np.nan])
    traj, _ = fill_gaps(t, x, x.copy(), x.copy(), max_gap=2)
    # samples t = 0.1 .. 1.0 with the long gap (0.6-0.8 s) left out; 0.3 s was filled
    assert traj.source.tolist() == ["detected"] * 2 + ["filled"] + ["detected"] * 4


@pytest.mark.slow  # renders a 45-frame video
def test_filled_frames_are_flagged_in_the_run_file(tmp_path):
    # the parcel tag is covered in frames 12-14 (filled, <= max_gap) and 30-38 (left out)
    scene = conveyor_scene(duration=0.75, hidden=((0.19, 0.245), (0.49, 0.64)))
    render_video(tmp_path / "gap.mp4", scene, s_curve, seed=3)
    tags = write_tag_map(tmp_path / "tags.yaml", scene)
    out = tmp_path / "out"
    result = runner.invoke(
        app,
        ["track", str(tmp_path / "gap.mp4"), "--tags", str(tags), "--out", str(out)],
    )
    assert result.exit_code == 0, result.output
    table = pd.read_csv(out / "gap-tag7.csv")
    frames = np.round(table["t"].to_numpy() * FPS).astype(int)
    assert frames.tolist() == [k for k in range(45) if not 30 <= k <= 38]
    filled = frames[table["source"].to_numpy() == "filled"]
    assert filled.tolist() == [12, 13, 14]
    assert set(table["source"]) == {"detected", "filled"}
    traj = read_trajectory(out / "gap-tag7.csv")
    assert np.flatnonzero(traj.filled).tolist() == [12, 13, 14]
    quality = json.loads((out / "gap.quality.json").read_text())["parcel_tags"]["7"]
    assert quality["interpolated_frames"] == 3 and quality["missing_frames"] == 9
    # the smoother's standard deviations: empty in exactly the filled frames, and under the
    # assumed per-frame 0.3 mm / 0.5 degrees everywhere else, largest at the ends and the gaps
    pos_sd, head_sd = traj.position_sd, traj.heading_sd
    assert np.flatnonzero(np.isnan(pos_sd)).tolist() == [12, 13, 14]
    assert np.flatnonzero(np.isnan(head_sd)).tolist() == [12, 13, 14]
    detected = ~traj.filled
    assert np.all((pos_sd[detected] > 0) & (pos_sd[detected] < 3e-4))
    assert np.all((head_sd[detected] > 0) & (head_sd[detected] < np.radians(0.5)))
    middle = np.nanmedian(pos_sd)
    for k in (0, 11, 15, 29, 30, len(traj) - 1):  # ends, next to the short and the long gap
        assert pos_sd[k] > 1.2 * middle


@pytest.mark.slow  # renders the videos fixture
def test_track_command_writes_runs_and_quality(videos, tmp_path):
    tags = write_tag_map(tmp_path / "tags.yaml", videos["scene"])
    out = tmp_path / "out"
    result = runner.invoke(
        app, ["track", str(videos["root"] / "plain.mp4"), "--tags", str(tags), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    traj = read_trajectory(out / "plain-tag7.csv")
    assert len(traj) == 120
    quality = json.loads((out / "plain.quality.json").read_text())
    assert quality["parcel_tags"]["7"]["detection_rate"] == 1.0
    assert quality["parcel_tags"]["7"]["transit_time_s"] > 0
    # no timing in the tag map: estimated from the 4 ms video's most smeared frames
    assert quality["timing"]["source"] == "estimated", quality["timing"]
    assert "camera timing not in the tag map" in " ".join(result.output.split())


@pytest.mark.slow
def test_track_all_builds_a_dataset_resumes_and_reports_bad_videos(videos, tmp_path):
    folder = tmp_path / "videos"
    folder.mkdir()
    shutil.copy(videos["root"] / "plain.mp4", folder / "E3-KPBW-1-01.mp4")
    shutil.copy(videos["root"] / "hard.mp4", folder / "E3-KPBW-1-02.mp4")
    (folder / "E3-KPBW-1-03.mp4").write_bytes(b"not a video" * 100)
    other = conveyor_scene(family="tag25h9", duration=0.2)
    render_video(folder / "E3-KPBW-1-04.mp4", other, s_curve)
    shutil.copy(videos["root"] / "plain.mp4", folder / "badname.mp4")
    tags = write_tag_map(tmp_path / "tags.yaml", videos["scene"])
    out = tmp_path / "dataset"
    result = runner.invoke(app, ["track-all", str(folder), "--tags", str(tags), "--out", str(out)])
    assert result.exit_code == 1  # some videos failed, the others are in the dataset
    summary = json.loads((out / "track-all.json").read_text())
    assert sorted(summary["done"]) == ["E3-KPBW-1-01.mp4", "E3-KPBW-1-02.mp4"]
    assert "cannot decode" in summary["failed"]["E3-KPBW-1-03.mp4"]
    assert "no reference tag" in summary["failed"]["E3-KPBW-1-04.mp4"]
    assert "RIG-CONSIGNMENT-SETTING-RUN" in summary["failed"]["badname.mp4"]
    ds = load_dataset(out)
    runs = ds["E3/KPBW/1"].runs
    assert [r.id for r in runs] == ["E3-KPBW-1-01", "E3-KPBW-1-02"]
    assert runs[0].transit_time is not None
    # a bundled rig's regions of interest and margin go with its test case
    e3 = load_rig("E3")
    assert e3.regions and ds["E3/KPBW/1"].regions == e3.regions
    assert ds["E3/KPBW/1"].margin == e3.margin
    assert summary["whole_track"] == []
    # rerun: finished videos are skipped, the dataset is the same
    summary = track_all(folder, load_tag_map(tags), out)
    assert sorted(summary["skipped"]) == ["E3-KPBW-1-01.mp4", "E3-KPBW-1-02.mp4"]
    assert not summary["done"]
    assert len(load_dataset(out)["E3/KPBW/1"].runs) == 2


@pytest.mark.slow
def test_track_all_takes_transit_times_from_the_light_barrier_logs(videos, tmp_path):
    folder = tmp_path / "videos"
    folder.mkdir()
    shutil.copy(videos["root"] / "plain.mp4", folder / "D1-KPBW-1-01.mp4")
    shutil.copy(videos["root"] / "plain.mp4", folder / "D1-KPBW-1-02.mp4")
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "D1-KPBW-1-01.csv").write_text("timestamp,sensor\n10.0,7\n10.25,3\n11.875,9\n")
    tags = write_tag_map(tmp_path / "tags.yaml", videos["scene"])
    out = tmp_path / "dataset"
    own_rig = Path(__file__).resolve().parent.parent / "examples" / "own-rig" / "D1.yaml"
    result = runner.invoke(
        app,
        [
            *("track-all", str(folder), "--tags", str(tags), "--out", str(out)),
            *("--sensor-logs", str(logs), "--sensors", "3,9", "--rig", str(own_rig)),
        ],
    )
    assert result.exit_code == 1, result.output  # the second video has no log
    summary = json.loads((out / "track-all.json").read_text())
    assert summary["done"] == ["D1-KPBW-1-01.mp4"]
    assert "no light-barrier log D1-KPBW-1-02.csv" in summary["failed"]["D1-KPBW-1-02.mp4"]
    case = load_dataset(out)["D1/KPBW/1"]
    (run,) = case.runs
    assert run.transit_time == pytest.approx(1.625, abs=1e-12)  # 11.875 - 10.25, not the video's
    # the rig file's regions of interest and margin go with its test case
    d1 = load_rig(own_rig)
    assert d1.regions and case.regions == d1.regions and case.margin == d1.margin
    # without the rig file the runs are compared over the whole track, and the summary says so
    summary = track_all(folder, load_tag_map(tags), out, sensor_logs=logs, sensors="3,9")
    assert summary["whole_track"] == ["D1"]
    assert load_dataset(out)["D1/KPBW/1"].regions == ()
    result = runner.invoke(
        app,
        [
            *("track-all", str(folder), "--tags", str(tags), "--out", str(out)),
            *("--sensor-logs", str(logs), "--sensors", "3,9"),
        ],
    )
    assert "no rig file for D1" in " ".join(result.output.split())
    with pytest.raises(ParcelfitError, match="not a folder"):
        track_all(folder, load_tag_map(tags), out, sensor_logs=tmp_path / "missing")


@pytest.mark.slow  # renders the videos fixture
def test_tag_map_errors_name_the_key(tmp_path, videos):
    path = tmp_path / "tags.yaml"
    doc = tag_map_doc(videos["scene"])
    doc["family"] = "tag36h12"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ParcelfitError, match="family") as err:
        load_tag_map(path)
    assert "tag36h11" in str(err.value) and "tags.yaml" in str(err.value)
    doc = tag_map_doc(videos["scene"])
    doc["parcel_tags"][0] = doc["parcel_tags"].pop(7)
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ParcelfitError, match="both a reference and a parcel tag"):
        load_tag_map(path)
    doc = tag_map_doc(videos["scene"])
    doc["camera"]["distortion"] = [0.1, 0.2]
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ParcelfitError, match=r"camera\.distortion"):
        load_tag_map(path)
    doc = tag_map_doc(videos["scene"])
    doc["parcel_tags"][7]["hieght"] = 0.02
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ParcelfitError, match="did you mean 'height'"):
        load_tag_map(path)


def test_sensor_log_transit_time(tmp_path):
    log = tmp_path / "log.csv"
    log.write_text("timestamp,sensor\n10.0,2\n12.50,1\n13.75,2\n14.0,2\n")
    assert read_sensor_log(log, "1", "2") == pytest.approx(1.25)
    with pytest.raises(ParcelfitError, match="no event of sensor '3'"):
        read_sensor_log(log, "3", "2")
    log.write_text("time,id\n1,2\n")
    with pytest.raises(ParcelfitError, match="timestamp,sensor"):
        read_sensor_log(log, "1", "2")


@pytest.mark.slow
def test_camera_calibration_recovers_the_camera_and_tracking_stays_accurate(videos, tmp_path):
    from parcelfit.tracking.synthetic import render_checkerboard_video

    scene = videos["scene"]
    truth_cam = scene.camera
    board_video = render_checkerboard_video(tmp_path / "board.mp4", truth_cam, frames=20, seed=3)
    doc = tag_map_doc(scene, camera=False)
    tags = tmp_path / "tags.yaml"
    tags.write_text(yaml.safe_dump(doc))
    result = runner.invoke(
        app,
        [
            "camera-calibrate",
            str(board_video),
            "--tags",
            str(tags),
            "--board",
            "9x6",
            "--square",
            "0.04",
        ],
    )
    assert result.exit_code == 0, result.output
    tm = load_tag_map(tags)
    cam = tm.camera
    assert abs(cam.fx / truth_cam.fx - 1) < 0.01 and abs(cam.fy / truth_cam.fy - 1) < 0.01
    # the fitted model (principal point and k1..k3 trade off) must track as accurately
    track = track_video(videos["root"] / "plain.mp4", tm).tags[scene.parcel_tag_id]
    pos, head = errors(track.trajectory, videos["plain_truth"])
    assert pos.mean() <= 0.001 and pos.max() <= 0.003 and head.max() <= 1.0
    bad = runner.invoke(
        app, ["camera-calibrate", str(board_video), "--tags", str(tags), "--board", "7x7"]
    )
    assert bad.exit_code == 2 and "found in only" in bad.output


@pytest.mark.slow
def test_bad_tag_maps_and_videos_stop_with_exit_2(videos, tmp_path):
    video = str(videos["root"] / "plain.mp4")
    # a reference tag placed 35 cm from where it is: refused, not a trajectory 35 cm off
    doc = tag_map_doc(videos["scene"])
    doc["reference_tags"][0]["x"] += 0.35
    bad = tmp_path / "moved.yaml"
    bad.write_text(yaml.safe_dump(doc))
    result = runner.invoke(app, ["track", video, "--tags", str(bad), "--out", str(tmp_path / "a")])
    assert result.exit_code == 2 and "reprojection error" in result.output
    assert not (tmp_path / "a").exists()  # nothing written
    # a focal length of 0 px
    doc = tag_map_doc(videos["scene"])
    doc["camera"]["fx"] = 0
    bad.write_text(yaml.safe_dump(doc))
    result = runner.invoke(app, ["track", video, "--tags", str(bad), "--out", str(tmp_path / "b")])
    assert result.exit_code == 2 and "camera.fx" in result.output
    # a parcel tag that never appears
    doc = tag_map_doc(videos["scene"])
    doc["parcel_tags"][9] = doc["parcel_tags"].pop(7)
    bad.write_text(yaml.safe_dump(doc))
    result = runner.invoke(app, ["track", video, "--tags", str(bad), "--out", str(tmp_path / "c")])
    assert result.exit_code == 2 and "no parcel tag (9) was found" in result.output


@pytest.mark.slow  # the first fast test to use the rendered videos would render them
def test_timing_block_is_read_in_seconds_and_checked(videos, tmp_path):
    doc = tag_map_doc(videos["scene"])
    doc["timing"] = {"exposure_ms": 4, "readout_ms": 15}
    path = tmp_path / "tags.yaml"
    path.write_text(yaml.safe_dump(doc))
    tm = load_tag_map(path)
    assert tm.exposure == pytest.approx(0.004) and tm.readout == pytest.approx(0.015)
    doc["timing"] = {"readout_ms": -1}
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ParcelfitError, match=r"timing\.readout_ms"):
        load_tag_map(path)
    # longer than a frame interval (60 fps: 16.7 ms): refused when tracking, file and key named
    doc["timing"] = {"exposure_ms": 20}
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ParcelfitError, match=r"tags\.yaml.*timing\.exposure_ms.*frame interval"):
        track_video(videos["root"] / "plain.mp4", load_tag_map(path))


def test_rolling_shutter_renders_each_band_of_rows_at_its_own_time():
    from parcelfit.tracking.synthetic import Renderer, straight_spin

    path = straight_spin(1.6, 720)
    rs = conveyor_scene(
        320,
        180,
        readout=0.015,
        readout_bands=4,
        exposure=0.0,
        blur_samples=1,
        noise_sd=0.0,
        distortion=(0, 0, 0, 0, 0),
        tilt_deg=0.0,
    )
    gs = conveyor_scene(
        320,
        180,
        exposure=0.0,
        blur_samples=1,
        noise_sd=0.0,
        distortion=(0, 0, 0, 0, 0),
        tilt_deg=0.0,
    )
    rng = np.random.default_rng(0)
    frame = Renderer(rs).frame(path, 0.3, rng).astype(float)
    band = 45  # rows per band: the second band is exposed at 0.3 + (67 / 180 - 0.5) * 0.015 s
    at_band = Renderer(gs).frame(path, 0.3 + (67 / 180 - 0.5) * 0.015, rng).astype(float)
    at_frame = Renderer(gs).frame(path, 0.3, rng).astype(float)
    rows = slice(band, 2 * band)
    assert np.abs(frame[rows] - at_band[rows]).max() <= 1.0
    assert np.abs(frame[rows] - at_frame[rows]).max() > 50  # the parcel moved 3 mm meanwhile


def test_exposure_renders_the_mean_of_the_sub_frames_and_the_spin_turns_at_its_rate():
    from parcelfit.tracking.synthetic import Renderer, straight_spin

    path = straight_spin(1.6, 720)
    _, _, th = path(np.array([0.0, 0.1]))
    assert np.degrees(th[1] - th[0]) == pytest.approx(72.0)
    plain = dict(noise_sd=0.0, distortion=(0, 0, 0, 0, 0), tilt_deg=0.0)
    smear = conveyor_scene(320, 180, exposure=0.008, blur_samples=4, **plain)
    sharp = conveyor_scene(320, 180, exposure=0.0, blur_samples=1, **plain)
    rng = np.random.default_rng(0)
    frame = Renderer(smear).frame(path, 0.3, rng).astype(float)
    subs = [Renderer(sharp).frame(path, 0.3 + (j + 0.5) / 4 * 0.008 - 0.004, rng) for j in range(4)]
    mean = np.mean(np.array(subs, float), axis=0)
    assert np.abs(frame - mean).max() <= 1.0  # rounding of each sub-frame
    assert np.abs(frame - subs[0]).max() > 50  # the parcel moved 9.6 mm during the exposure


@pytest.mark.slow
def test_motion_blur_and_spin_4ms(tmp_path):
    from parcelfit.tracking.synthetic import straight_spin

    path = straight_spin(1.6, 720)
    # the tag is covered in frames 21-23: the model fit must not invent it there
    scene = conveyor_scene(
        1328,
        748,
        exposure=0.004,
        blur_samples=8,
        duration=0.75,
        parcel_height=0.02,
        tag_offset=(0.05, 0.0),
        hidden=((0.34, 0.39),),
    )
    truth = truth_of(render_video(tmp_path / "spin.mp4", scene, path, seed=0))
    doc = scene_tag_map(scene, barriers=BARRIERS)
    doc["timing"] = {"exposure_ms": 4, "readout_ms": 0}
    (tmp_path / "tags.yaml").write_text(yaml.safe_dump(doc))
    result = track_video(tmp_path / "spin.mp4", load_tag_map(tmp_path / "tags.yaml"))
    track = result.tags[scene.parcel_tag_id]
    traj = track.trajectory
    assert len(traj) >= 0.95 * len(truth["t"])
    assert track.quality["frames_in_view"] == len(truth["t"])  # in view from the clip's start
    pos, head = errors(traj, truth)
    assert pos.mean() <= 0.001 and pos.max() <= 0.003 and head.max() <= 1.0
    # smeared by ~1 bit: the detected frames are fitted, and say so in the run file
    frames = np.round(traj.t * FPS).astype(int)
    assert set(frames[traj.source == "filled"]) == {21, 22, 23}
    assert (traj.source == "fitted").sum() >= 0.9 * (len(truth["t"]) - 3)
    assert track.quality["fitted_frames"] == (traj.source == "fitted").sum()
    assert track.quality["detection_rate"] == pytest.approx(42 / 45)
    # per-frame standard deviations from the fit: small where fitted, larger next to the gap
    assert np.nanmax(traj.position_sd[traj.source == "fitted"]) < 3e-4


@pytest.mark.parametrize("readout", [0.0, 0.015])
def test_smear_fit_recovers_a_spinning_tag_under_blur_and_rolling_shutter(readout):
    import math

    from parcelfit.tracking.fit import fit_smeared_tag, tag_pattern
    from parcelfit.tracking.synthetic import Renderer, straight_spin
    from parcelfit.tracking.tagmap import tag_corners

    spin = 720.0
    path = straight_spin(1.6, spin)
    scene = conveyor_scene(
        1328,
        748,
        exposure=0.008,
        blur_samples=24,
        readout=readout,
        readout_bands=48,
        parcel_height=0.02,
        tag_offset=(0.05, 0.0),
        distortion=(0, 0, 0, 0, 0),  # so that `Renderer.project` gives the frame's pixels
    )
    renderer = Renderer(scene)
    t = 0.3
    grey = renderer.frame(path, t, np.random.default_rng(1))
    x, y, th = (float(v[0]) for v in path(np.array([t])))
    c, s = math.cos(th), math.sin(th)
    w = math.radians(spin)
    truth = np.array([x + 0.05 * c, y + 0.05 * s, th])  # the tag centre and heading
    rates = np.array([1.6 - w * 0.05 * s, 0.04 + w * 0.05 * c, w])

    def corners_of(p):
        return renderer.project(tag_corners(p[0], p[1], 0.06, p[2]), 0.02)

    start = truth + np.array([0.002, -0.0015, math.radians(4)])
    px = corners_of(start)
    x0, y0 = (int(v) for v in px.min(axis=0) - 40)
    x1, y1 = (int(v) for v in px.max(axis=0) + 40)
    side = float(np.linalg.norm(px[1] - px[0]))
    steps = np.array([0.1 * 0.06 / side, 0.1 * 0.06 / side, 0.1 / (side / math.sqrt(2))])
    pattern = tag_pattern("tag36h11", 7)
    args = (grey[y0:y1, x0:x1], (x0, y0), 1, corners_of, start, steps, rates, pattern)
    fit = fit_smeared_tag(*args, 0.008, readout, 748)
    assert fit is not None and fit.rms < 0.05
    assert np.hypot(*(fit.params[:2] - truth[:2])) < 1.5e-4
    assert abs(math.degrees(fit.params[2] - truth[2])) < 0.3
    sd = np.sqrt(np.diag(fit.cov))
    assert 0 < sd[0] < 1e-4 and 0 < sd[2] < math.radians(0.2)
    if readout:  # the readout ignored: the fit lands 15 ms x 1.6 m/s x (row offset) away
        blind = fit_smeared_tag(*args, 0.008, 0.0, 748)
        assert blind is None or np.hypot(*(blind.params[:2] - truth[:2])) > 1e-3


def test_smoother_rejects_a_bad_frame_and_keeps_a_spin():
    from parcelfit.tracking.smooth import rts_smooth

    t = np.arange(60) / 60
    theta = np.radians(720) * t  # 720 deg/s
    rng = np.random.default_rng(0)
    z = theta + rng.normal(0, np.radians(0.3), 60)
    z[30] += np.radians(4)  # one bad frame
    z[40:43] = np.nan
    r = np.full(60, np.radians(0.5) ** 2)
    smoothed, sd, used, restarts = rts_smooth(z, 1 / 60, r, 1e3)
    assert not restarts
    assert used[29] and used[31] and not used[40:43].any()
    assert np.degrees(np.abs(smoothed - theta)).max() < 1.0  # the 4-degree frame: no spike
    z[30] += np.radians(20)  # a wild frame is rejected outright
    assert not rts_smooth(z, 1 / 60, r, 1e3)[2][30]
    assert np.all(sd > 0)


@pytest.mark.parametrize("change", ["onset", "stop"])
def test_smoother_restarts_the_motion_at_an_abrupt_spin_onset_or_stop(change):
    """A spin that starts (stops) within one frame: every frame after it is kept (the old gate,
    once it had rejected one frame, rejected all the rest), the track follows the kink, and a
    lone bad frame after it is still rejected."""
    from parcelfit.tracking.smooth import rts_smooth

    n, dt = 60, 1 / 60
    t = np.arange(n) * dt
    rate = np.radians(720)
    after = np.maximum(t - 0.305, 0)
    theta = rate * after if change == "onset" else rate * (t - after)
    rng = np.random.default_rng(3)
    sd = np.radians(0.1)
    z = theta + rng.normal(0, sd, n)
    z[45] += np.radians(5)  # one bad frame
    smoothed, post, used, restarts = rts_smooth(z, dt, np.full(n, sd * sd), 1e3)
    assert restarts == [19]  # between frames 18 (0.300 s) and 19 (0.317 s)
    assert used.sum() == n - 1 and not used[45]
    err = smoothed - theta
    assert np.degrees(np.abs(err)).max() < 0.4
    assert 0.3 < np.sqrt(np.mean((err / post) ** 2)) < 2  # honest sds, the kink included
    # the gate alone (no restart) loses the track from the onset on
    assert rts_smooth(z, dt, np.full(n, sd * sd), 1e3, restart_after=0)[2].sum() < 25


@pytest.mark.slow  # renders a 30-frame video
def test_an_abrupt_spin_onset_keeps_every_frame_and_the_report_counts_match_the_run_file(
    tmp_path, monkeypatch
):
    """Issue 56: a parcel caught on a guide plate starts spinning at 720 deg/s within one frame
    (8 ms exposure): the smoother used to discard every frame after the onset."""
    from parcelfit.tracking.synthetic import changing_path

    path = changing_path(spin_deg_s=(0.0, 720.0), spin_change_s=0.255)
    scene = conveyor_scene(
        1328,
        748,
        exposure=0.008,
        blur_samples=20,
        duration=0.5,
        parcel_height=0.02,
        tag_offset=(0.05, 0.0),
    )
    truth = truth_of(render_video(tmp_path / "onset.mp4", scene, path, seed=4))
    doc = scene_tag_map(scene, barriers=BARRIERS)
    doc["timing"] = {"exposure_ms": 8, "readout_ms": 0}
    tags = tmp_path / "tags.yaml"
    tags.write_text(yaml.safe_dump(doc))
    out = tmp_path / "out"
    result = runner.invoke(
        app, ["track", str(tmp_path / "onset.mp4"), "--tags", str(tags), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    traj = read_trajectory(out / "onset-tag7.csv")
    measured = ~traj.filled
    assert measured.sum() >= 0.95 * len(truth["t"])
    pos, head = errors(traj, truth)
    assert pos.mean() <= 0.001 and pos.max() <= 0.003 and head.max() <= 1.0
    dh = np.radians(head[measured]) / traj.heading_sd[measured]
    assert np.sqrt(np.mean(dh**2)) <= 2  # the stated heading sds are honest at the onset
    quality = json.loads((out / "onset.quality.json").read_text())["parcel_tags"]["7"]
    assert quality["motion_restarts_s"]  # the onset was seen as a change of motion
    assert_report_counts_match_run_file(quality, traj)
    assert "discarded" not in result.output  # nothing discarded: no warning
    # the old gate (no restart) discards the frames after the onset: the command warns, and
    # the report's counts still are the run file's
    import functools

    from parcelfit.tracking import track as track_module

    old_gate = functools.partial(track_module.smooth_track, restart_after=0)
    monkeypatch.setattr(track_module, "smooth_track", old_gate)
    result = runner.invoke(
        app, ["track", str(tmp_path / "onset.mp4"), "--tags", str(tags), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    quality = json.loads((out / "onset.quality.json").read_text())["parcel_tags"]["7"]
    assert quality["discarded_by_smoother"] >= 5 and not quality["motion_restarts_s"]
    assert f"the smoother discarded {quality['discarded_by_smoother']} of" in " ".join(
        result.output.split()
    )
    assert_report_counts_match_run_file(quality, read_trajectory(out / "onset-tag7.csv"))
    monkeypatch.undo()
    # without timing in the tag map: estimated from the fit's residual, and as accurate
    del doc["timing"]
    tags.write_text(yaml.safe_dump(doc))
    result = runner.invoke(
        app, ["track", str(tmp_path / "onset.mp4"), "--tags", str(tags), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "camera timing not in the tag map: estimated exposure" in " ".join(result.output.split())
    report = json.loads((out / "onset.quality.json").read_text())
    assert report["timing"]["source"] == "estimated"
    assert abs(report["timing"]["exposure_ms"] - 8) <= 1 and report["timing"]["readout_ms"] <= 2
    traj = read_trajectory(out / "onset-tag7.csv")
    assert (~traj.filled).sum() >= 0.95 * len(truth["t"])
    pos, head = errors(traj, truth)
    assert pos.mean() <= 0.001 and pos.max() <= 0.003 and head.max() <= 1.0
    assert_report_counts_match_run_file(report["parcel_tags"]["7"], traj)


def assert_report_counts_match_run_file(quality, traj):
    """The quality report's counts are those of the run file's ``source`` column."""
    source = np.asarray(traj.source)
    assert quality["measured_frames"] == int((source != "filled").sum())
    assert quality["detected_frames"] == int((source == "detected").sum())
    assert quality["fitted_frames"] == int((source == "fitted").sum())
    assert quality["interpolated_frames"] == int((source == "filled").sum())
    assert quality["detection_rate"] == pytest.approx(
        quality["measured_frames"] / quality["frames_in_view"]
    )
    # the stated sds: the report's medians are the run file's, lambda never narrows a fit
    assert quality["position_sd_median"] == pytest.approx(np.nanmedian(traj.position_sd), rel=1e-6)
    assert quality["heading_sd_median"] == pytest.approx(np.nanmedian(traj.heading_sd), rel=1e-6)
    assert all(v >= 1.0 for v in quality["fit_variance_scale"])


def test_smoother_weighs_each_frame_by_its_own_standard_deviation():
    from parcelfit.tracking.track import smooth_track

    n = 45
    t = np.arange(n) / 60
    truth = np.column_stack([-0.6 + 1.6 * t, -0.03 + 0.04 * t, np.radians(720) * t])
    rng = np.random.default_rng(2)
    arr = truth + rng.normal(0, 1, (n, 3)) * [5e-5, 5e-5, np.radians(0.05)]
    arr[20, 2] += np.radians(4)  # a bad frame that says it is unsure (a smeared detection)
    arr[20, 0] += 0.002
    sd = np.tile([1e-4, np.radians(0.1)], (n, 1))  # fitted frames
    sd[20] = [3 * 3e-4, 3 * np.radians(0.5)]
    out, rejected, post, _ = smooth_track(arr, 1 / 60, sd)
    assert rejected == 0
    assert np.degrees(abs(out[20, 2] - truth[20, 2])) < 0.2  # the 4-degree frame: no spike
    assert abs(out[20, 0] - truth[20, 0]) < 2e-4
    # with the same sd in every frame (the old smoother) the spike stays about a degree
    same, _, _, _ = smooth_track(arr, 1 / 60)
    assert np.degrees(abs(same[20, 2] - truth[20, 2])) > 0.5
    # the posterior sds follow the measurement sds: tighter than one fitted frame in the middle
    assert np.all(post[10:35, 0] < 1e-4) and np.all(post[:, 1] > 0)


def test_smoother_standard_deviation_is_the_gaussian_posterior():
    """The RTS smoother's sd (written to the run files) equals the posterior sd of the same
    Gaussian model solved at once: prior, constant-acceleration steps, measurements."""
    from parcelfit.tracking.smooth import rts_smooth

    n, dt, q, r = 24, 1 / 60, 10.0, 9e-8
    z = 0.5 * np.arange(n) * dt + np.random.default_rng(1).normal(0, 3e-4, n)
    z[9:12] = np.nan
    _, sd, _, _ = rts_smooth(z, dt, np.full(n, r), q)
    f = np.array([[1, dt, dt * dt / 2], [0, 1, dt], [0, 0, 1]])
    qm = q * np.array(
        [
            [dt**5 / 20, dt**4 / 8, dt**3 / 6],
            [dt**4 / 8, dt**3 / 3, dt**2 / 2],
            [dt**3 / 6, dt**2 / 2, dt],
        ]
    )
    info = np.zeros((3 * n, 3 * n))  # the posterior information matrix of all states
    info[:3, :3] = np.linalg.inv(np.diag([r, 1e2, 1e4]))  # the smoother's prior
    qi = np.linalg.inv(qm)
    for k in range(1, n):
        a, b = slice(3 * k - 3, 3 * k), slice(3 * k, 3 * k + 3)
        info[a, a] += f.T @ qi @ f
        info[b, b] += qi
        info[a, b] -= f.T @ qi
        info[b, a] -= qi @ f
    for k in np.flatnonzero(np.isfinite(z)):
        info[3 * k, 3 * k] += 1 / r
    posterior_sd = np.sqrt(np.diag(np.linalg.inv(info))[0::3])
    assert sd == pytest.approx(posterior_sd, rel=1e-6)


def _write_avi(path, width, height, frames, fps=30.0):
    """A Motion-JPEG AVI (OpenCV's own encoder, present in every build) of grey frames."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (width, height))
    assert writer.isOpened()
    for k in range(frames):
        writer.write(np.full((height, width, 3), 40 * k % 256, np.uint8))
    writer.release()
    return path


@pytest.mark.parametrize(
    ("name", "make", "message"),
    [
        ("one.avi", lambda p: _write_avi(p, 1, 1, 5), "frames are 1 x 1 px, too small"),
        ("two.avi", lambda p: _write_avi(p, 2, 2, 5), "frames are 2 x 2 px, too small"),
        ("line.avi", lambda p: _write_avi(p, 1, 500, 5), "frames are 1 x 500 px, too small"),
        ("small.avi", lambda p: _write_avi(p, 40, 14, 5), "frames are 40 x 14 px, too small"),
        ("empty.avi", lambda p: _write_avi(p, 64, 48, 0), "no frame that can be decoded"),
        ("slow.avi", lambda p: _write_avi(p, 64, 48, 3, fps=1.0), "frame rate of 1 fps"),
        ("junk.mp4", lambda p: p.write_bytes(b"not a video" * 100), "cannot decode this video"),
        ("zero.mp4", lambda p: p.write_bytes(b""), "cannot decode this video"),
        ("folder.mp4", lambda p: p.mkdir(), "not a video file"),
    ],
)
def test_degenerate_videos_stop_with_one_line_naming_the_file(tmp_path, name, make, message):
    tags = tmp_path / "tags.yaml"
    tags.write_text(yaml.safe_dump(scene_tag_map(conveyor_scene(), camera=False)))
    video = tmp_path / name
    make(video)
    result = runner.invoke(app, ["track", str(video), "--tags", str(tags), "--out", str(tmp_path)])
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit)  # no traceback
    assert str(video) in result.output and message in result.output
    calib = runner.invoke(app, ["camera-calibrate", str(video), "--tags", str(tmp_path / "c.yaml")])
    if name != "slow.avi":  # the board finder does not care about the frame rate
        assert calib.exit_code == 2 and message in calib.output, calib.output


def test_a_truncated_mp4_gives_parcelfit_s_error_and_no_decoder_noise(tmp_path):
    """A recording cut short (its index, the moov atom, lost) made FFmpeg print its own
    messages on the terminal beside parcelfit's; now only parcelfit's, which names the file.
    In a process of its own: OpenCV reads FFmpeg's log level once per process."""
    import os
    import subprocess
    import sys

    sample = Path(__file__).resolve().parents[1] / "examples" / "tracking" / "D1-envelope-1-01.mp4"
    video = tmp_path / "cut.mp4"
    data = sample.read_bytes()
    video.write_bytes(data[: len(data) // 2])
    tags = tmp_path / "tags.yaml"
    tags.write_text(yaml.safe_dump(scene_tag_map(conveyor_scene(), camera=False)))
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    env["COLUMNS"] = "200"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "parcelfit",
            "track",
            str(video),
            "--tags",
            str(tags),
            "--out",
            str(tmp_path / "tracks"),
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2, done.stdout + done.stderr
    assert "cannot decode this video" in done.stdout + done.stderr
    assert str(video) in (done.stdout + done.stderr).replace("\n", "")
    assert "moov" not in done.stdout + done.stderr


def test_a_video_damaged_in_its_middle_says_the_decoder_stopped_early(tmp_path):
    """With FFmpeg's own messages quiet, a file whose middle is damaged ended 'done' with the
    frames before the damage alone; now track says how many of the stated frames it decoded."""
    sample = Path(__file__).resolve().parents[1] / "examples" / "tracking" / "D1-envelope-1-01.mp4"
    data = sample.read_bytes()
    a, b = len(data) // 3, len(data) // 3 + len(data) // 6
    video = tmp_path / "mid.mp4"
    video.write_bytes(data[:a] + bytes(b - a) + data[b:])
    tags = sample.parent / "tags.yaml"
    result = runner.invoke(
        app, ["track", str(video), "--tags", str(tags), "--out", str(tmp_path / "t")]
    )
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    quality = json.loads((tmp_path / "t" / "mid.quality.json").read_text())
    frames = quality["frames"]
    assert quality["frames_in_container"] == 60 and frames < 58
    assert f"decoded {frames} of the 60 frames the video states" in said
    whole = runner.invoke(
        app, ["track", str(sample), "--tags", str(tags), "--out", str(tmp_path / "w")]
    )
    assert whole.exit_code == 0 and "frames the video states" not in whole.output


def test_only_an_exact_frame_count_judges_the_decoder(tmp_path):
    """MP4 states its frames exactly; Matroska does not (OpenCV then estimates a count from the
    duration, an audio track's included, which made an intact file look damaged)."""
    import av

    from parcelfit.tracking.video import stated_frames

    sample = Path(__file__).resolve().parents[1] / "examples" / "tracking" / "D1-envelope-1-01.mp4"
    assert stated_frames(sample) == 60
    mkv = tmp_path / "copy.mkv"
    with av.open(str(sample)) as src, av.open(str(mkv), "w") as dst:
        stream = dst.add_stream_from_template(src.streams.video[0])
        for packet in src.demux(src.streams.video[0]):
            if packet.dts is not None:
                packet.stream = stream
                dst.mux(packet)
    assert stated_frames(mkv) is None
    assert stated_frames(mkv.with_name("missing.mp4")) is None


def test_the_detector_finds_nothing_in_frames_too_small_for_a_tag():
    from parcelfit.tracking.detect import TagDetector

    for shape in ((1, 1), (3, 3), (7, 200), (200, 7)):
        detector = TagDetector()
        for _ in range(3):  # the first frame is searched at shrink factors 1, 2 and 4
            assert detector.detect(np.zeros(shape, np.uint8)) == {}
    with pytest.raises(ParcelfitError, match="8-bit frame"):
        TagDetector().detect(np.zeros((32, 32), np.float32))


def test_fit_covariance_counts_correlated_pixel_noise():
    """The fit's covariance is cluster-robust: noise shared by blocks of pixels (compression
    blocks) widens it, where the independent-pixel covariance would not notice."""
    import math

    from parcelfit.tracking.fit import fit_smeared_tag, tag_pattern
    from parcelfit.tracking.synthetic import Renderer, straight_spin
    from parcelfit.tracking.tagmap import tag_corners

    path = straight_spin(1.6, 360.0)
    scene = conveyor_scene(
        1328,
        748,
        exposure=0.004,
        blur_samples=12,
        parcel_height=0.02,
        tag_offset=(0.05, 0.0),
        distortion=(0, 0, 0, 0, 0),
    )
    renderer = Renderer(scene)
    grey = renderer.frame(path, 0.3, np.random.default_rng(1)).astype(float)
    x, y, th = (float(v[0]) for v in path(np.array([0.3])))
    w = math.radians(360.0)
    truth = np.array([x + 0.05 * math.cos(th), y + 0.05 * math.sin(th), th])
    rates = np.array([1.6 - w * 0.05 * math.sin(th), 0.04 + w * 0.05 * math.cos(th), w])

    def corners_of(p):
        return renderer.project(tag_corners(p[0], p[1], 0.06, p[2]), 0.02)

    px = corners_of(truth)
    x0, y0 = (int(v) for v in px.min(axis=0) - 40)
    x1, y1 = (int(v) for v in px.max(axis=0) + 40)
    side = float(np.linalg.norm(px[1] - px[0]))
    steps = np.array([0.1 * 0.06 / side, 0.1 * 0.06 / side, 0.1 / (side / math.sqrt(2))])
    pattern = tag_pattern("tag36h11", 7)
    sds = {}
    for blocks in (False, True):
        patch = grey[y0:y1, x0:x1].copy()
        if blocks:  # 8 x 8 px blocks each offset by its own grey level, sd 8
            rng = np.random.default_rng(3)
            offsets = rng.normal(0, 8, (patch.shape[0] // 8 + 1, patch.shape[1] // 8 + 1))
            patch += np.kron(offsets, np.ones((8, 8)))[: patch.shape[0], : patch.shape[1]]
        patch = np.clip(patch, 0, 255).astype(np.uint8)
        fit = fit_smeared_tag(
            patch, (x0, y0), 1, corners_of, truth, steps, rates, pattern, 0.004, 0.0, 748
        )
        assert fit is not None
        sds[blocks] = (math.sqrt(fit.cov[0, 0]), math.sqrt(fit.cov_iid[0, 0]))
    robust_ratio = sds[True][0] / sds[False][0]
    iid_ratio = sds[True][1] / sds[False][1]
    assert robust_ratio > 1.5 * iid_ratio


def _noisy_track(n=45, spin_deg_s=720.0, sd=(5e-5, 5e-4)):
    t = np.arange(n) / 60
    truth = np.column_stack([-0.6 + 1.6 * t, -0.03 + 0.04 * t, np.radians(spin_deg_s) * t])
    rng = np.random.default_rng(5)
    return t, truth, truth + rng.normal(0, 1, (n, 3)) * [sd[0], sd[0], sd[1]]


def _smooth_fitted(arr, fit_sd, reach=None, rates=None, timing_lag=None):
    from parcelfit.tracking.track import smooth_scaled

    n = len(arr)
    base = np.full((n, 2), 1e-14)
    fit_var = np.tile(np.square(fit_sd), (n, 1))
    return smooth_scaled(
        arr,
        1 / 60,
        base,
        fit_var,
        np.full((n, 3), np.nan) if rates is None else rates,
        np.zeros(n) if reach is None else reach,
        np.zeros(n) if timing_lag is None else timing_lag,
    )


def test_fits_that_state_too_small_sds_are_widened_never_narrowed():
    """lambda >= 1: fits whose sds are 3 times too small are widened until error / sd is
    honest (the smoother's own jerk absorbs part of the noise, so lambda stays under 9);
    honest fits and fits whose sds are 3 times too large keep theirs (lambda 1)."""
    from parcelfit.tracking.track import smooth_track

    _, truth, arr = _noisy_track()
    honest = np.array([5e-5, 5e-4])
    for factor in (1 / 3, 1.0, 3.0):
        out, gated, sd, _, scale = _smooth_fitted(arr, factor * honest)
        assert gated == 0
        if factor < 1:
            assert all(3.0 <= v <= 9.0 for v in scale), scale
            pos = np.hypot(*(out[:, :2] - truth[:, :2]).T) / (np.sqrt(2) * sd[:, 0])
            head = np.abs(out[:, 2] - truth[:, 2]) / sd[:, 1]
            for z in (pos, head):
                assert 0.5 <= np.sqrt(np.mean(z**2)) <= 2
            # without lambda the same fits' sds are over 2 times too small
            plain = smooth_track(arr, 1 / 60, np.tile(factor * honest, (len(arr), 1)))[2]
            assert np.sqrt(np.mean((np.abs(out[:, 2] - truth[:, 2]) / plain[:, 1]) ** 2)) > 2
        else:
            assert scale == [1.0, 1.0]


def test_fitted_sds_grow_with_the_motion_rates_and_the_timing_uncertainty():
    """A fit sees the tag at its centre row's time and moves it to the frame time with its
    motion model's rates: where those rates miss the smoothed ones, or the readout is unsure,
    the sd grows with the rate; with no lag nothing is added."""
    n = 45
    honest = np.array([5e-5, 5e-4])
    heading_sd = {}
    for spin in (0.0, 720.0):
        _, _, arr = _noisy_track(n, spin)
        base = _smooth_fitted(arr, honest)[2]
        unsure = _smooth_fitted(arr, honest, timing_lag=np.full(n, 0.2 * 5e-4))[2]
        heading_sd[spin] = unsure[:, 1].mean()
        assert np.all(unsure >= base * (1 - 1e-9))
        # the timing's share: the smoothed rate times the lag's uncertainty, in quadrature
        w = np.radians(spin)
        assert unsure[n // 2, 1] == pytest.approx(
            np.hypot(base[n // 2, 1], w * 0.2 * 5e-4), rel=0.05
        )
    assert heading_sd[720.0] > 2 * heading_sd[0.0]
    # a motion model whose turn rate misses the track's by 200 deg/s in frames 20-24, seen
    # 3 ms from the frame time: those frames count less and their sds grow
    _, _, arr = _noisy_track(n, 720.0)
    rates = np.tile([1.6, 0.04, np.radians(720.0)], (n, 1))
    rates[20:25, 2] += np.radians(200)
    reach = np.full(n, 0.003)
    plain = _smooth_fitted(arr, honest, reach=reach, rates=np.tile(rates[0], (n, 1)))[2]
    missed = _smooth_fitted(arr, honest, reach=reach, rates=rates)[2]
    assert np.all(missed[20:25, 1] > 1.5 * plain[20:25, 1])
    assert missed[5, 1] == pytest.approx(plain[5, 1], rel=0.05)


def test_timing_uncertainty_is_half_the_estimate_grid_or_the_camera_figure():
    from parcelfit.tracking.smear import timing_uncertainty

    assert timing_uncertainty(0.008, 0.015, 60.0, True) == pytest.approx((1 / 3840, 1 / 1920))
    exposure_sd, readout_sd = timing_uncertainty(0.008, 0.015, 60.0, False)
    assert readout_sd > exposure_sd > timing_uncertainty(0.0, 0.0, 60.0, False)[0] > 0


def test_a_rig_name_with_a_dash_is_read_when_the_rig_is_known():
    from parcelfit.runs import TestCase
    from parcelfit.tracking.batch import case_of

    video = Path("E3-far-plate-KPBW-2-07.mp4")
    known = ("E1", "E3", "E3-far", "E3-far-plate")
    assert case_of(video, known) == (TestCase("E3-far-plate", "KPBW", 2), video.stem)
    assert case_of(Path("E3-far-KP-1-01.mp4"), known)[0] == TestCase("E3-far", "KP", 1)
    assert case_of(Path("E3-KPBW-1-07.mp4"), known)[0] == TestCase("E3", "KPBW", 1)
    assert case_of("E3-KP.BW-1-07", known)[0] == TestCase("E3", "KP.BW", 1)  # a stem as it is
    with pytest.raises(ParcelfitError, match="read only for a known rig"):
        case_of(video)  # without the rig's name the dash splits it
    with pytest.raises(ParcelfitError, match="after the rig E3-far-plate give CONSIGNMENT"):
        case_of(Path("E3-far-plate-KPBW-x-07.mp4"), known)
    # rig E3-far, consignment 2, setting 1 or rig E3, consignment far, setting 2, run 1-07
    with pytest.raises(ParcelfitError, match="reads as more than one test case"):
        case_of(Path("E3-far-2-1-07.mp4"), known)


def test_a_run_tracked_under_a_rig_no_longer_given_is_reported_and_the_rest_go_on(tmp_path):
    folder, out = tmp_path / "videos", tmp_path / "out"
    folder.mkdir()
    tracks = out / "tracks"
    tracks.mkdir(parents=True)
    t = np.linspace(0.0, 1.0, 11)
    trajectory = Trajectory(t, 0.5 * t, np.zeros_like(t), np.zeros_like(t))
    for stem in ("E3-far-KPBW-1-07", "E3-KPBW-1-01"):
        (folder / f"{stem}.mp4").write_bytes(b"")  # tracked before: skipped, not opened
        write_trajectory(trajectory, tracks / f"{stem}-tag1.csv")
        entry = {"file": f"{stem}-tag1.csv", "measured_frames": 11, "transit_time_s": 1.0}
        quality = {"parcel_tags": {"1": entry}}
        (tracks / f"{stem}.quality.json").write_text(json.dumps(quality), encoding="utf-8")
    tags = load_tag_map(Path(__file__).parents[1] / "examples" / "tracking" / "tags.yaml")
    rigs = {"E3": ((), 0.0), "E3-far": ((), 0.0)}
    summary = track_all(folder, tags, out, regions=rigs)  # with the rig: both runs read
    assert summary["failed"] == {}
    assert {c.rig for c in load_dataset(out).cases} == {"E3", "E3-far"}
    summary = track_all(folder, tags, out, regions={"E3": ((), 0.0)})  # without it
    assert list(summary["failed"]) == ["E3-far-KPBW-1-07.quality.json"]
    assert [c.rig for c in load_dataset(out).cases] == ["E3"]


def test_barriers_listed_out_of_order_give_no_transit_time_and_say_so(videos, tmp_path):
    """The tag map's barriers swapped: the last breaks before the first; the transit time is
    left out (it was negative, which no run file takes) and track says why."""
    doc = scene_tag_map(videos["scene"], barriers=BARRIERS[::-1])
    tags = tmp_path / "tags.yaml"
    tags.write_text(yaml.safe_dump(doc))
    result = runner.invoke(
        app,
        ["track", str(videos["root"] / "plain.mp4"), "--tags", str(tags), "--out", str(tmp_path)],
    )
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    assert "the last light barrier broke before the first: the tag map lists light_barriers" in said
    quality = json.loads((tmp_path / "plain.quality.json").read_text())
    tag = quality["parcel_tags"][str(videos["scene"].parcel_tag_id)]
    assert tag["barriers_out_of_order"] is True and tag["transit_time_s"] is None
    assert all(t is not None for t in tag["crossings_s"].values())


def test_a_beam_broken_already_at_the_first_sample_has_no_crossing_time():
    # a parcel 0.2 m long moving at 1 m/s along x, a beam across x = 0
    from parcelfit.runs import Barrier
    from parcelfit.tracking.barriers import broken_at_start

    beam = Barrier("LS1", (0.0, -0.5), (0.0, 0.5))
    t = np.arange(0.0, 0.5, 1 / 60)
    outline = (0.2, 0.1)
    before = Trajectory(t, -0.3 + t, np.zeros_like(t), np.zeros_like(t))
    # the leading edge (centre + 0.1 m) reaches the beam at t = 0.2 s
    assert crossing_time(before, beam, outline) == pytest.approx(0.2, abs=1e-9)
    assert not broken_at_start(before, beam, outline)
    # the same motion seen from t = 0.25 s: the beam was broken before the first sample
    late = Trajectory(t, -0.05 + t, np.zeros_like(t), np.zeros_like(t))
    assert broken_at_start(late, beam, outline)
    assert crossing_time(late, beam, outline) is None  # not t[0], which would shorten a transit


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_a_beam_passed_before_the_first_sample_is_told_from_one_not_reached(direction):
    """A parcel moving along x (either way: the barriers' order says which side is beyond) seen
    only after it passed LS1 wholly: LS1 named as passed; LS2 ahead of it is not; a parcel that
    never reached LS2 does not name LS2 either."""
    from parcelfit.runs import Barrier
    from parcelfit.tracking.barriers import passed_at_start

    ls1 = Barrier("LS1", (0.0, -0.5), (0.0, 0.5))
    ls2 = Barrier("LS2", (direction * 1.0, 0.5), (direction * 1.0, -0.5))
    t = np.arange(0.0, 0.9, 1 / 60)
    outline = (0.2, 0.1)
    zero = np.zeros_like(t)
    past = Trajectory(t, direction * (0.3 + t), zero, zero)  # the trailing edge 0.2 m past LS1
    assert passed_at_start(past, [ls1, ls2], outline) == ["LS1"]
    assert crossing_time(past, ls2, outline) is not None
    before = Trajectory(t, direction * (-0.3 + t), zero, zero)  # breaks LS1, never LS2
    assert passed_at_start(before, [ls1, ls2], outline) == []
    assert passed_at_start(past, [ls1], outline) == []  # one barrier: no side is beyond
    aside = Trajectory(t, direction * (0.3 + t), zero + 0.8, zero)  # beyond its line, not its beam
    assert passed_at_start(aside, [ls1, ls2], outline) == []
    # wholly beyond the last barrier at the start: passed as well
    gone = Trajectory(t, direction * (1.3 + t), zero, zero)
    assert passed_at_start(gone, [ls1, ls2], outline) == ["LS1", "LS2"]


@pytest.mark.slow
def test_the_sample_video_starts_across_ls1_and_track_says_so(tmp_path):
    root = Path(__file__).parents[1] / "examples" / "tracking"
    video, tags = root / "D1-envelope-1-01.mp4", root / "tags.yaml"
    result = runner.invoke(
        app, ["track", str(video), "--tags", str(tags), "--out", str(tmp_path / "t")]
    )
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    assert "tag 7: LS1 already broken or passed in the first frame with the tag" in said
    quality = json.loads((tmp_path / "t" / "D1-envelope-1-01.quality.json").read_text())
    tag = quality["parcel_tags"]["7"]
    assert tag["barriers_broken_at_start"] == ["LS1"] and tag["transit_time_s"] is None
    assert tag["barriers_passed_at_start"] == []
    # with a light-barrier log the transit time is the log's, and nothing is said of LS1
    log = tmp_path / "log.csv"
    log.write_text("timestamp,sensor\n0.5,LS1\n1.6,LS2\n")
    logged = runner.invoke(
        app,
        [
            "track",
            str(video),
            "--tags",
            str(tags),
            "--out",
            str(tmp_path / "l"),
            "--sensor-log",
            str(log),
            "--sensors",
            "LS1,LS2",
        ],
    )
    assert logged.exit_code == 0, logged.output
    assert "already broken" not in logged.output
    doc = json.loads((tmp_path / "l" / "D1-envelope-1-01.quality.json").read_text())
    assert doc["parcel_tags"]["7"]["transit_time_s"] == pytest.approx(1.1)
