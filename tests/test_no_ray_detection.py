"""Session 27: a detection without a ray is a missing detection, for ``nearest`` and
``typeA`` (issue 10).

A detection whose pixel has no ray (NaN, far beyond the image, or beyond a strong lens's
fold-over: ``prepare`` gives it NaN undistorted pixels and ray) changed what the other
detections made: ``nearest`` made a point at its time from the other cameras' latest
detections, took it as its camera's latest detection (an unused slot, where the session
without it takes the camera's previous one), and its NaN pixel entered the image speed, the
noise's residuals and the breaks of the slots after it (positions up to 57 mm and ``std_m``
up to 0.48 m different on the session below); ``typeA`` lost the points it was a bracket
of (358 against 359 points) and moved others (26 mm). Both now fuse the session without
those detections (``_prepare.rays_only``; the stream's ``MeasuredNoiseStream`` leaves them
out too): the same bits as the session with the rows deleted. So do ``sync``, ``typeB`` and
``linear`` (``stereo.rays_only_shared``): a partner without a ray left typeB / linear's
detection at its instant without a prediction, and could start a ``sync`` group.

Checked on real files through ``pslog fuse`` (as ``test_first_row_no_ray.py`` does for
``sync``, ``typeB``, ``linear`` and ``smooth``), and on the stream pushed a detection at a
time.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_stream_type_a import assert_same, pushed_one_by_one

from pslog import Rig, SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import FusionOptions, fuse
from pslog.fusion._prepare import prepare
from pslog.fusion.stream import StreamFuser
from pslog.log import SessionWriter, read_session
from pslog.records import NS, Detections, Observations, Track
from pslog.timing import observations as timed_observations

METHODS = ("nearest", "typeA")
#: A barrel lens that folds over inside the image: ``r (1 - 0.5 r²)`` peaks at r = 0.816
#: (normalised), 326 px from the centre at paper3's 600 px focal length; the corners are
#: 400 px out: their pixels have no ray.
FOLDING = (-0.5, 0.0, 0.0, 0.0, 0.0)


def _session(lens: bool = False, timing: str = "typeA"):
    """(rig, observations) of a 6 s paper3 rally at 0.5 px of noise with misses, drops and
    jitter, its times from 2 s on (typeA timing, or ``timing``)."""
    rig = apply_timing(builtin_rig("paper3"), timing)
    if lens:
        rig = Rig(tuple(c.replace(dist=np.array(FOLDING)) for c in rig.cameras), rig.name)
    det, _ = simulate(rig, get_motion("rally"), 6.0,
                      SimulationOptions(noise_px=0.5, miss_rate=0.2, drop_rate=0.05,
                                        jitter_s=2e-4, seed=1))
    obs = timed_observations(det, rig)
    return rig, Observations(obs.time_ns - obs.time_ns[0] + 2 * NS, obs.camera, obs.uv,
                             obs.frame_index)


def _damaged(obs: Observations, rows: list[int], value) -> tuple[Observations, Observations]:
    """``obs`` with the pixels of ``rows`` set to ``value`` (a float, or a pixel (2,)), and
    ``obs`` without those rows."""
    uv = obs.uv.copy()
    uv[rows] = value
    keep = np.ones(len(obs), dtype=bool)
    keep[rows] = False
    return (Observations(obs.time_ns, obs.camera, uv, obs.frame_index),
            obs.select(keep))


def _fused(tmp_path, cli, name: str, rig, obs: Observations, methods=METHODS,
           timing: str = "typeA") -> tuple[dict, list[str]]:
    """The tracks ``pslog fuse`` wrote from ``obs`` written as an MCAP, and its lines of
    counts (points, drops)."""
    src, out = tmp_path / f"{name}.mcap", tmp_path / f"{name}_fused.mcap"
    with SessionWriter(src, rig, timing=timing, source="test") as writer:
        writer.add_detections(Detections.from_observations(
            [c.name for c in rig.cameras], obs))
    code, text, err = cli("fuse", src, "--method", ",".join(methods), "--gating", "off",
                          "-o", out)
    assert code == 0, err
    lines = [line for line in text.splitlines() if line.split(" ")[0] in methods]
    assert len(lines) == len(methods), text
    return read_session(out).tracks, lines


def _assert_same_bits(got, want) -> None:
    np.testing.assert_array_equal(got.time_ns, want.time_ns)
    np.testing.assert_array_equal(got.camera, want.camera)
    assert got.position_world.tobytes() == want.position_world.tobytes()
    assert set(got.quality) == set(want.quality)
    for key, column in want.quality.items():
        assert got.quality[key].tobytes() == column.tobytes(), key


# rows in the middle (one of camera 0's, and three of different cameras), the first, the
# last; pixels NaN and far beyond the image
@pytest.mark.parametrize("rows,value", [([186], 1e300), ([204], np.nan),
                                        ([13, 261, 314], 1e300), ([0], np.nan),
                                        ([-1], 1e300)])
def test_a_detection_without_a_ray_is_a_missing_one(tmp_path, cli, rows, value):
    rig, obs = _session()
    rows = [r % len(obs) for r in rows]
    damaged, without = _damaged(obs, rows, value)
    assert not np.isfinite(prepare(damaged, rig).ray_dir[rows]).any()
    got, got_lines = _fused(tmp_path, cli, "damaged", rig, damaged)
    want, want_lines = _fused(tmp_path, cli, "without", rig, without)
    assert got_lines == want_lines  # the points and the drops counted
    for method in METHODS:
        assert len(want[method]) > 300
        _assert_same_bits(got[method], want[method])


@pytest.mark.parametrize("rows", [[261], [13, 186, 204], [0]])
def test_a_partner_without_a_ray_is_missing_for_the_stereo_methods(tmp_path, cli, rows):
    """typeB timing (cam1 and cam2 share shutters, cam3 between): a detection without a ray
    beside another camera's at its instant made that one not alone, so ``typeB`` and
    ``linear`` made no prediction there (one point fewer, row 261), and a group's start
    ``sync_groups`` chains from; ``sync``, ``typeB`` and ``linear`` now fuse the session
    without it too (and ``nearest`` and ``typeA`` on this timing)."""
    methods = ("sync", "typeB", "linear", "nearest", "typeA")
    rig, obs = _session(timing="typeB")
    damaged, without = _damaged(obs, rows, 1e300)
    got, got_lines = _fused(tmp_path, cli, "damaged", rig, damaged, methods, "typeB")
    want, want_lines = _fused(tmp_path, cli, "without", rig, without, methods, "typeB")
    assert got_lines == want_lines
    for method in methods:
        assert len(want[method]) > 90
        _assert_same_bits(got[method], want[method])


@pytest.mark.parametrize("method", ["sync", "typeB", "linear"])
def test_the_stereo_methods_stream_leaves_it_out_as_the_batch(method):
    """typeB timing, rows 261, 13, 186 and 204 without a ray, pushed a detection at a
    time: the batch's points of the session without them, every quality column the same
    bits (the counts left out: the window stream does not carry typeB's and linear's
    ``prediction_failed``, with every detection intact too)."""
    rig, obs = _session(timing="typeB")
    rows = [13, 186, 204, 261]
    damaged, without = _damaged(obs, rows, 1e300)
    streamed = Track.concat(pushed_one_by_one(StreamFuser(rig, method), damaged))
    want = fuse(without, rig, method)
    assert len(want) > 90
    _assert_same_bits(streamed, want)


def test_a_pixel_beyond_the_lens_fold_over_is_a_missing_detection(tmp_path, cli):
    """A pixel inside the image but beyond the lens model's fold-over (an image corner
    under :data:`FOLDING`): no ray, the same points as without it, in batch (``pslog
    fuse``) and in the stream (``MeasuredNoiseStream``'s lens test)."""
    rig, obs = _session(lens=True)
    rows = [150, 151, 300]
    damaged, without = _damaged(obs, rows, np.array([2.0, 3.0]))
    assert not np.isfinite(prepare(damaged, rig).ray_dir[rows]).any()
    got, got_lines = _fused(tmp_path, cli, "damaged", rig, damaged)
    want, want_lines = _fused(tmp_path, cli, "without", rig, without)
    assert got_lines == want_lines
    for method in METHODS:
        assert len(want[method]) > 300
        _assert_same_bits(got[method], want[method])
    assert_same(pushed_one_by_one(StreamFuser(rig, "typeA"), damaged), fuse(without, rig,
                                                                            "typeA"))


@pytest.mark.parametrize("method,confirm", [("nearest", True), ("typeA", True),
                                            ("typeA", False)])
def test_the_stream_leaves_a_detection_without_a_ray_out_as_the_batch(method, confirm):
    """Pushed a detection at a time (``typeA``: its incremental form, through the long-gap
    confirmation's ``push`` and, without it, the one-row ``push_one``; ``nearest``: the
    window's batch run), the session with rows without a ray gives the batch's points of
    the session without them."""
    rig, obs = _session()
    damaged, without = _damaged(obs, [0, 13, 186, 261, 314, len(obs) - 1], 1e300)
    damaged2, _ = _damaged(damaged, [204], np.nan)
    without = without.select(without.time_ns != obs.time_ns[204])
    options = FusionOptions(confirm_gaps=confirm)
    assert_same(pushed_one_by_one(StreamFuser(rig, method, options), damaged2),
                fuse(without, rig, method, options))


def test_type_a_construction_rows_are_the_given_observations():
    """``explain_type_a`` (the viewer's construction) of a session with rows without a ray:
    the construction of the session without them, its rows (the newest detection, the past
    points' own and bracketing detections) those of the observations given."""
    from pslog.fusion import explain_type_a

    rig, obs = _session()
    rows = [13, 186, 204]
    damaged, without = _damaged(obs, rows, 1e300)
    got, want = explain_type_a(damaged, rig), explain_type_a(without, rig)
    kept = np.delete(np.arange(len(obs)), rows)  # (row i of ``without`` is row kept[i])

    def given(r):
        return np.where(r >= 0, kept[np.maximum(r, 0)], r)

    assert len(want.event_row) > 300
    np.testing.assert_array_equal(got.event_row, given(want.event_row))
    assert got.points_world.tobytes() == want.points_world.tobytes()
    for g, w in zip(got.past, want.past, strict=True):
        for name in ("row", "prev_row", "next_row"):
            np.testing.assert_array_equal(getattr(g, name), given(getattr(w, name)))
        assert g.points_world.tobytes() == w.points_world.tobytes()
    np.testing.assert_array_equal(damaged.time_ns[got.event_row],
                                  fuse(damaged, rig, "typeA").time_ns)


def test_a_group_start_without_a_ray_does_not_take_the_next_cameras_detection(tmp_path, cli):
    """``sync`` groups detections from the earliest not yet grouped over the tolerance
    (1 ms). paper3 with cam2 0.8 ms and cam3 1.6 ms after cam1: each instant groups cam1
    with cam2, cam3 alone. Where cam1's detection has no ray, its group held cam2's alone
    (one ray: no point) and cam3 stayed alone; without that detection cam2 and cam3 group
    and make a point. The session with such detections gives the points of the session
    without them (before: 3 points fewer here)."""
    rig = apply_timing(builtin_rig("paper3"), "sync")
    det, _ = simulate(rig, get_motion("rally"), 4.0, SimulationOptions(noise_px=0.3, seed=2))
    obs = timed_observations(det, rig)
    shift = np.array([0, 800_000, 1_600_000])[obs.camera]
    obs = Observations(obs.time_ns + shift, obs.camera, obs.uv, obs.frame_index)
    rows = list(np.flatnonzero(obs.camera == 0)[[10, 40, 70]])
    damaged, without = _damaged(obs, rows, np.nan)
    got, got_lines = _fused(tmp_path, cli, "damaged", rig, damaged, ("sync",), "sync")
    want, want_lines = _fused(tmp_path, cli, "without", rig, without, ("sync",), "sync")
    assert got_lines == want_lines
    assert len(want["sync"]) > 90
    _assert_same_bits(got["sync"], want["sync"])
