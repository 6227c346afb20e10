"""Issue 13, "a viewer that explains at a glance": real sessions become real .rrd files and
MCAPs, read back. One colour per method in the rerun view, its plots and the MCAP's Foxglove
scene; the truth visible on light and dark themes; overlays and cameras in colours of their
own; a rolling detection rate that drops; the ball's crop beside each frame; the summary
panel; the default eye and axes in the blueprint."""

from __future__ import annotations

import itertools

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from rerun.chunk import RrdReader

from pslog import palette
from pslog.cli import main as pslog_main
from pslog.evaluation import evaluate
from pslog.log import SessionWriter, read_session
from pslog.log import _schemas as S
from pslog.motion import get_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate
from viewers import save_rrd
from viewers.blueprint import EYE_FOV_Y_DEG, default_eye
from viewers.panels import CROP_PX, cut

METHODS = ["typeA", "sync", "nearest", "linear"]


def _rgba(packed: int) -> tuple[int, int, int, int]:
    return tuple(int(packed) >> s & 0xFF for s in (24, 16, 8, 0))  # type: ignore[return-value]


def _static(rrd) -> dict[str, dict[str, list]]:
    """entity -> {column: first row's value} of the recording's static chunks."""
    out: dict[str, dict[str, list]] = {}
    for chunk in RrdReader(rrd).stream():
        if chunk.is_static:
            batch = chunk.to_record_batch()
            out.setdefault(chunk.entity_path, {}).update(
                {n: batch.column(n).to_pylist()[0] for n in batch.schema.names})
    return out


def _temporal(rrd, entity: str, column: str) -> list:
    return [v for chunk in RrdReader(rrd).stream()
            if not chunk.is_static and chunk.entity_path == entity
            for v in chunk.to_record_batch().column(column).to_pylist()]


def _blueprint(rrd) -> dict[str, dict[str, list]]:
    reader = RrdReader(rrd)
    out: dict[str, dict[str, list]] = {}
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        out.setdefault(chunk.entity_path, {}).update(
            {n: batch.column(n).to_pylist()[-1] for n in batch.schema.names
             if ":" in n})  # components only (not the log-time columns)
    return out


def _lab(rgb) -> np.ndarray:
    lab = cv2.cvtColor(np.array([[rgb]], np.float32) / 255.0, cv2.COLOR_RGB2LAB)[0, 0]
    return lab.astype(np.float64)  # L* 0-100, a*, b*


def _luminance(rgb) -> float:
    """WCAG 2 relative luminance of an sRGB colour."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    c = np.where(c <= 0.03928, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return float(0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2])


def _contrast(a, b) -> float:
    hi, lo = sorted((_luminance(a), _luminance(b)), reverse=True)
    return (hi + 0.05) / (lo + 0.05)


@pytest.fixture(scope="module")
def fused(tmp_path_factory):
    """A simulated throw with missed detections, fused with four methods by the CLI."""
    folder = tmp_path_factory.mktemp("glance")
    session, fused = folder / "s.mcap", folder / "fused.mcap"
    assert pslog_main(["simulate", "--rig", "paper3", "--timing", "typeB", "--motion", "throw",
                       "--duration", "1.2", "--noise-px", "0.3", "--miss-rate", "0.15",
                       "--seed", "4", "-o", str(session)]) == 0
    args = ["fuse", str(session), "-o", str(fused)]
    for m in METHODS:
        args += ["--method", m]
    assert pslog_main(args) == 0
    rrd = folder / "fused.rrd"
    save_rrd([fused], rrd)
    return fused, rrd


def test_one_colour_per_method_in_the_view_its_plots_and_the_mcap_scene(fused):
    path, rrd = fused
    static = _static(rrd)
    scene: dict[str, set] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            if channel.topic.endswith("/scene"):
                update = S.SceneUpdate.FromString(message.data)
                for e in update.entities:
                    for s in e.spheres:
                        scene.setdefault(channel.topic, set()).add(
                            (round(s.color.r * 255), round(s.color.g * 255),
                             round(s.color.b * 255)))
    seen = set()
    for m in METHODS:
        want = palette.METHOD_COLORS[m]
        assert _rgba(static[f"/world/tracks/{m}"]["Points3D:colors"][0])[:3] == want
        assert _rgba(static[f"/world/tracks/{m}/trail"]["LineStrips3D:colors"][0])[:3] == want
        assert _rgba(static[f"/plots/error_mm/{m}"]["SeriesLines:colors"][0])[:3] == want
        assert scene[S.track_scene_topic(m)] == {want}, m
        seen.add(want)
    assert len(seen) == len(METHODS)
    legend = static["/legend"]["TextDocument:text"][0]
    for m in METHODS:
        assert f"{m} {palette.color_name(palette.METHOD_COLORS[m])}" in legend


def test_an_unknown_method_has_the_same_colour_in_the_view_and_the_mcap(tmp_path):
    """A track whose name is no fusion method (an imported one) gets a colour by its name's
    hash: the rerun view and the MCAP agree without sharing any state."""
    from pslog.records import Track

    rig = builtin_rig("paper3")
    path = tmp_path / "s.mcap"
    det, truth = simulate(rig, get_motion("throw"), 0.3, SimulationOptions(seed=1))
    t = truth.time_ns[::4]
    with SessionWriter(path, rig) as w:
        w.add_detections(det)
        w.add_track(Track("mocap", t, truth.at(t), np.zeros(len(t), np.int32)))
    rrd = tmp_path / "s.rrd"
    save_rrd([path], rrd, methods="mocap", frames="none")
    want = palette.method_color("mocap")
    assert _rgba(_static(rrd)["/world/tracks/mocap"]["Points3D:colors"][0])[:3] == want
    with open(path, "rb") as f:
        for _, _c, message in make_reader(f).iter_messages(
                topics=[S.track_scene_topic("mocap")]):
            c = S.SceneUpdate.FromString(message.data).entities[0].spheres[0].color
            assert (round(c.r * 255), round(c.g * 255), round(c.b * 255)) == want


def test_the_palette_keeps_its_families_apart_and_the_truth_visible_on_both_themes(fused):
    _, rrd = fused
    truth = _rgba(_static(rrd)["/world/truth"]["Points3D:colors"][0])[:3]
    assert truth == palette.TRUTH_COLOR
    # rerun's light theme is near white, its dark theme near black: the truth must stand out
    # on both (WCAG's 3:1 for graphics), which a white (or black) truth cannot
    for background in ((255, 255, 255), (240, 240, 240), (0, 0, 0), (20, 20, 20)):
        assert _contrast(truth, background) >= 3.0, background
    methods = list(palette.METHOD_COLORS.values()) + list(palette.EXTRA_METHOD_COLORS)
    cameras = list(palette.CAMERA_COLORS)
    others = [palette.TRUTH_COLOR, palette.REJECTED_COLOR, palette.CONSTRUCTION_COLOR,
              palette.SNAP_COLOR]
    every = methods + cameras + others
    assert len(set(every)) == len(every)
    for a, b in itertools.combinations(every, 2):  # ΔE*76, a clear difference
        assert np.linalg.norm(_lab(a) - _lab(b)) >= 20.0, (a, b)
    for a, b in itertools.product(methods, cameras):
        assert np.linalg.norm(_lab(a) - _lab(b)) >= 25.0, (a, b)
    # each colour has a name in the legend
    assert all(palette.color_name(c) != "rgb({}, {}, {})".format(*c) for c in every)


def test_construction_overlays_have_their_own_colours_and_hidden_labels(fused):
    _, rrd = fused
    static = _static(rrd)
    assert static["/world/typeA/past"]["Points3D:show_labels"] == [False]
    assert static["/world/typeA/predicted"]["Points3D:show_labels"] == [False]
    assert static["/world/cameras/cam1/image/typeA/interpolated"][
        "Points2D:show_labels"] == [False]
    colours = {
        "/world/typeA/predicted": ("Points3D:colors", palette.CONSTRUCTION_COLOR),
        "/world/typeA/correction": ("LineStrips3D:colors", palette.SNAP_COLOR),
        "/world/cameras/cam2/image/typeA/snap": ("LineStrips2D:colors", palette.SNAP_COLOR),
        "/world/cameras/cam2/image/typeA/bracket": ("LineStrips2D:colors",
                                                    palette.CONSTRUCTION_COLOR)}
    for entity, (column, want) in colours.items():
        rows = [r for r in _temporal(rrd, entity, column) if r]
        assert rows, entity
        assert {_rgba(v)[:3] for r in rows for v in r} == {want}, entity
    assert not set(palette.METHOD_COLORS.values()) & {palette.CONSTRUCTION_COLOR,
                                                      palette.SNAP_COLOR}


def test_detection_rate_is_a_rolling_rate_that_drops(fused):
    path, rrd = fused
    s = read_session(path)
    det = s.detections
    rows = np.flatnonzero(det.frame_camera == 0)
    detected = det.candidates_per_frame()[rows] > 0
    assert not detected.all(), "the session must miss some detections"
    rate = np.array(_temporal(rrd, "/plots/detection_rate/cam1", "Scalars:scalars")).ravel()
    assert len(rate) == len(rows)
    assert rate.min() < 100.0 and rate.max() == 100.0
    # over the last 0.5 s: 15 frames at 30 fps
    window = round(0.5 * s.rig.cameras[0].fps)
    expected = [100.0 * detected[max(0, i + 1 - window):i + 1].mean()
                for i in range(len(rows))]
    np.testing.assert_allclose(rate, expected)
    axes = [v for v in _blueprint(rrd).values() if "ScalarAxis:range" in v]
    assert [a["ScalarAxis:range"] for a in axes] == [[[0.0, 105.0]]]


def test_each_camera_has_a_crop_of_the_ball(tmp_path):
    """With frames: a CROP_PX square crop per frame, centred on the frame's detection, and
    its 2D view beside the camera's view in the blueprint."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det, truth = simulate(rig, get_motion("throw"), 0.4, SimulationOptions(seed=2))
    path = tmp_path / "s.mcap"
    offsets = np.concatenate([[0], np.cumsum(det.candidates_per_frame())])
    frames = {}
    with SessionWriter(path, rig, timing="typeA") as w:
        for i in range(det.n_frames):
            cam, k = int(det.frame_camera[i]), int(det.frame_index[i])
            uv = det.cand_uv[offsets[i]:offsets[i + 1]]
            image = np.full((rig.cameras[cam].height, rig.cameras[cam].width, 3), 40, np.uint8)
            for u, v in uv:  # a bright 9 px square where the ball is
                cv2.rectangle(image, (round(u) - 4, round(v) - 4), (round(u) + 4, round(v) + 4),
                              (255, 255, 255), -1)
            ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])
            assert ok
            w.add_frame(cam, k, int(det.frame_time_ns[i]), uv=uv, image=jpeg.tobytes())
            frames[(cam, k)] = len(uv)
        w.add_truth(truth)
    rrd = tmp_path / "s.rrd"
    save_rrd([path], rrd)
    for c, name in enumerate(rig.names):
        blobs = _temporal(rrd, f"/crops/{name}", "EncodedImage:blob")
        assert len(blobs) == sum(1 for (cam, _), n in frames.items() if cam == c and n)
        for blob in blobs[::5]:
            crop = cv2.imdecode(np.frombuffer(bytes(blob[0]), np.uint8), cv2.IMREAD_GRAYSCALE)
            assert crop.shape == (CROP_PX, CROP_PX)
            centre = crop[CROP_PX // 2 - 2:CROP_PX // 2 + 3, CROP_PX // 2 - 2:CROP_PX // 2 + 3]
            assert centre.mean() > 200 and np.median(crop) < 80  # the ball, in the middle
        boxes = _temporal(rrd, f"/crops/{name}/detection", "Boxes2D:centers")
        assert len(boxes) == len(blobs) and all(len(b) == 1 for b in boxes)
    origins = {v.get("ViewBlueprint:space_origin", [None])[0]
               for v in _blueprint(rrd).values()}
    assert {f"/crops/{n}" for n in rig.names} <= origins | {None}
    assert all(f"/crops/{n}" in origins for n in rig.names), origins


def test_cut_pads_at_the_frame_border():
    frame = np.arange(20 * 30 * 3, dtype=np.uint8).reshape(20, 30, 3)
    crop, uv = cut(frame, np.array([1.2, 18.7]), 8)
    assert crop.shape == (8, 8, 3)
    np.testing.assert_allclose(uv, [1.2 + 3, 18.7 - 15])
    assert (crop[:, :3] == 0).all() and (crop[-3:] == 0).all()  # outside the frame: black
    np.testing.assert_array_equal(crop[:5, 3:], frame[15:20, 0:5])


def test_summary_panel_holds_accuracy_and_camera_clocks(fused):
    path, rrd = fused
    text = _static(rrd)["/summary"]["TextDocument:text"][0]
    s = read_session(path)
    assert "**Accuracy**" in text and "**Camera clocks**" in text
    for m in METHODS:
        a = evaluate(s.tracks[m], s.truth)
        assert (f"| {m} | {a.n_points} | {a.rate_hz:.1f} | {a.median_mm:.1f} | "
                f"{a.p95_mm:.1f} | {a.rms_mm:.1f} | {a.max_mm:.1f} |") in text
    for cam in s.rig.cameras:
        assert f"| {cam.name} | 30 | {cam.offset * 1e3:.3f} |" in text
    # the clocks as the 'timing' document holds them (σ from pslog sync: tests/test_view.py)
    assert _static(rrd)["/timing"]["TextDocument:text"][0] in text
    views = {v.get("ViewBlueprint:space_origin", [None])[0] for v in _blueprint(rrd).values()}
    assert "/summary" in views


def test_summary_without_truth_says_so(tmp_path):
    rig = builtin_rig("paper3")
    det, _ = simulate(rig, get_motion("throw"), 0.3, SimulationOptions(seed=1))
    path = tmp_path / "s.mcap"
    with SessionWriter(path, rig) as w:
        w.add_detections(det)
    rrd = tmp_path / "s.rrd"
    save_rrd([path], rrd, frames="none")
    assert "no ground truth" in _static(rrd)["/summary"]["TextDocument:text"][0]


def test_default_eye_frames_the_trajectory_and_its_floor(fused):
    """The eye of the blueprint sees the whole trajectory and its floor inside the view
    (rerun's 55° vertical field of view, a 4:3 view), filling a good part of it, and is
    not framed on the far cameras."""
    path, rrd = fused
    s = read_session(path)
    eye = next(v for v in _blueprint(rrd).values() if "EyeControls3D:position" in v)
    pos = np.array(eye["EyeControls3D:position"][0])
    target = np.array(eye["EyeControls3D:look_target"][0])
    centers = np.array([c.center_world for c in s.rig.cameras])
    expected = default_eye(centers, s.truth.position_world)
    assert expected is not None
    forward = (target - pos) / np.linalg.norm(target - pos)
    right = np.cross(forward, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    ty = np.tan(np.radians(EYE_FOV_Y_DEG / 2))
    tx = ty * 4 / 3
    points = s.truth.position_world
    floor = points * [1, 1, 0]
    scene = np.concatenate([points, floor])
    d = scene - pos
    z = d @ forward
    x, y = (d @ right) / z / tx, (d @ up) / z / ty
    assert np.all(z > 0)
    assert np.abs(x).max() <= 1.0 and np.abs(y).max() <= 1.0  # all inside
    assert np.ptp(x) > 1.0 or np.ptp(y) > 1.0  # and large: over half the width or height
    assert pos[2] > target[2]  # from above


def test_the_live_view_has_no_crop_or_summary_views(tmp_path):
    """The live view shows neither crops nor the summary (a live run has no frames to cut
    nor truth): its blueprint leaves those views out rather than showing them empty."""
    import rerun as rr

    from viewers.blueprint import build_blueprint

    for recorded in (True, False):
        path = tmp_path / f"bp-{recorded}.rrd"
        rec = rr.RecordingStream("pslog-test")
        rec.save(path)
        rec.send_blueprint(build_blueprint(["cam1", "cam2"], ["typeA"], has_truth=False,
                                           quality={}, recorded=recorded))
        rec.flush()
        rec.disconnect()
        origins = {v.get("ViewBlueprint:space_origin", [None])[0]
                   for v in _blueprint(path).values()}
        assert ("/crops/cam1" in origins) is recorded
        assert ("/summary" in origins) is recorded
        assert "/legend" in origins and "/world/cameras/cam2/image" in origins


def test_detection_rate_counts_the_ball_not_a_static_distractor(tmp_path):
    """A second orange object in view is a candidate in every frame: counting frames with a
    candidate, the rate read 100 % though the ball was missed in half the frames (session
    34's walkthrough). The plot counts the frames with a candidate off every static spot
    (pslog info's "moving" rate): the ball's, against the simulation's ball labels, and the
    legend names the spot left out."""
    session = tmp_path / "d.mcap"
    assert pslog_main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                       "--miss-rate", "0.5", "--distractor", "cam1=0.5,0.3,0.1",
                       "--noise-px", "0.5", "--seed", "3", "-o", str(session)]) == 0
    s = read_session(session)
    det, ball = s.detections, s.ball_truth
    rows = np.flatnonzero(det.frame_camera == 0)
    assert (det.candidates_per_frame()[rows] > 0).all()  # the distractor: in every frame
    # the frames the ball was detected in (its labels: a frame of its own per detection)
    seen = np.isin(det.frame_index[rows], ball.frame_index[ball.frame_camera == 0])
    assert 0.3 < seen.mean() < 0.7
    rrd = tmp_path / "d.rrd"
    save_rrd([session], rrd, methods="nearest")
    rate = np.array(_temporal(rrd, "/plots/detection_rate/cam1", "Scalars:scalars")).ravel()
    window = round(0.5 * s.rig.cameras[0].fps)
    expected = np.array([100.0 * seen[max(0, i + 1 - window):i + 1].mean()
                         for i in range(len(rows))])
    assert len(rate) == len(rows) and rate.min() < 70.0
    np.testing.assert_allclose(rate, expected)
    legend = _static(rrd)["/legend"]["TextDocument:text"][0]
    cam = s.rig.cameras[0]
    u, v = cam.project(np.array([[0.5, 0.3, 0.1]]))[0][0]
    assert f"left out: cam1 at ({u:.0f}, {v:.0f}) px" in legend, legend
    views = [v for v in _blueprint(rrd).values()
             if v.get("ViewBlueprint:space_origin") == ["/plots/detection_rate"]]
    assert [v["ViewBlueprint:display_name"] for v in views] == [
        ["ball detection rate (%, last 0.5 s)"]]
