"""Tests of pslog.records: Detections, Observations, Track and Truth."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.errors import InputError, PslogError
from pslog.records import NS, QUALITY_FIELDS, Detections, Observations, Track, Truth

NAMES = ("cam1", "cam2", "cam3")


def _unsorted_frames():
    """Five frames given out of order, with candidates referring to the given rows.

    Given rows (time, camera): 0 (300, 0), 1 (100, 1), 2 (100, 0), 3 (200, 2), 4 (300, 1).
    Sorted order: (100, 0)=row2, (100, 1)=row1, (200, 2)=row3, (300, 0)=row0, (300, 1)=row4.
    """
    frame_time_ns = [300, 100, 100, 200, 300]
    frame_camera = [0, 1, 0, 2, 1]
    frame_index = [9, 3, 3, 6, 9]
    # row 0 has two candidates (the better one last), row 2 one, row 4 three, rows 1, 3 none
    cand_frame = [4, 0, 2, 4, 0, 4]
    cand_uv = [[40.0, 1], [0.0, 1], [20.0, 1], [41.0, 1], [1.0, 1], [42.0, 1]]
    cand_score = [0.2, 0.5, 1.0, 0.9, 0.7, 0.4]
    cand_radius = [4.0, 0.0, 2.0, 4.1, 0.1, 4.2]
    return frame_time_ns, frame_camera, frame_index, cand_frame, cand_uv, cand_radius, cand_score


def test_from_frames_sorts_frames_and_candidates():
    t, c, k, cf, uv, radius, score = _unsorted_frames()
    det = Detections.from_frames(NAMES, t, c, k, cf, uv, radius, score)
    assert det.camera_names == NAMES
    assert det.n_frames == 5 and det.n_candidates == 6
    assert_array_equal(det.frame_time_ns, [100, 100, 200, 300, 300])
    assert_array_equal(det.frame_camera, [0, 1, 2, 0, 1])
    assert_array_equal(det.frame_index, [3, 3, 6, 9, 9])
    # candidates follow their frames to the new rows, best score first within a frame
    assert_array_equal(det.cand_frame, [0, 3, 3, 4, 4, 4])
    assert_array_equal(det.cand_uv[:, 0], [20.0, 1.0, 0.0, 41.0, 42.0, 40.0])
    assert_array_equal(det.cand_score, [1.0, 0.7, 0.5, 0.9, 0.4, 0.2])
    assert_array_equal(det.cand_radius, [2.0, 0.1, 0.0, 4.1, 4.2, 4.0])
    assert_array_equal(det.candidates_per_frame(), [1, 0, 0, 2, 3])
    assert det.frame_time_ns.dtype == np.int64 and det.frame_camera.dtype == np.int32
    assert det.cand_uv.shape == (6, 2) and det.cand_uv.dtype == np.float64


def test_best_takes_first_candidate_of_each_frame_with_one():
    det = Detections.from_frames(NAMES, *_unsorted_frames())
    obs = det.best()
    assert isinstance(obs, Observations) and len(obs) == 3
    assert_array_equal(obs.time_ns, [100, 300, 300])
    assert_array_equal(obs.camera, [0, 0, 1])
    assert_array_equal(obs.frame_index, [3, 9, 9])
    assert_array_equal(obs.uv, [[20.0, 1], [1.0, 1], [41.0, 1]])


def test_from_frames_defaults_and_empty():
    det = Detections.from_frames(NAMES, [5, 1], [0, 0], [1, 0], [0], [[3.0, 4.0]])
    assert_array_equal(det.cand_frame, [1])  # given row 0 is sorted second
    assert np.isnan(det.cand_radius[0]) and det.cand_score[0] == 1.0
    empty = Detections.from_frames(NAMES, [1, 2], [0, 1], [0, 0], [], np.zeros((0, 2)))
    assert empty.n_candidates == 0
    assert_array_equal(empty.candidates_per_frame(), [0, 0])
    best = empty.best()
    assert len(best) == 0 and best.uv.shape == (0, 2)
    nothing = Detections.from_frames(NAMES, [], [], [], [], [])
    assert nothing.n_frames == 0 and len(nothing.best()) == 0


@pytest.mark.parametrize("cand_frame, frame_camera", [
    ([-1], [0, 0]),  # would wrap around to the last frame
    ([2], [0, 0]),
    ([0], [0]),
])
def test_from_frames_rejects_bad_rows(cand_frame, frame_camera):
    with pytest.raises(InputError):
        Detections.from_frames(NAMES, [1, 2], frame_camera, [0, 1], cand_frame, [[1.0, 2.0]])


def test_from_observations_round_trip():
    obs = Observations.from_unsorted([30, 10, 20, 10], [0, 2, 1, 1],
                                     [[3.0, 0], [1.0, 0], [2.0, 0], [1.5, 0]], [3, 1, 2, 1])
    det = Detections.from_observations(NAMES, obs)
    assert det.n_frames == det.n_candidates == 4
    best = det.best()
    for key in ("time_ns", "camera", "uv", "frame_index"):
        assert_array_equal(getattr(best, key), getattr(obs, key))


def test_detections_are_read_only():
    det = Detections.from_frames(NAMES, *_unsorted_frames())
    for key in ("frame_time_ns", "cand_uv", "cand_score"):
        with pytest.raises(ValueError):
            getattr(det, key)[0] = 0


@pytest.mark.parametrize("changes, match", [
    ({"frame_camera": [0, 1]}, "frame columns"),
    ({"cand_score": [1.0]}, "candidate columns"),
    ({"cand_frame": [1, 0]}, "cand_frame"),
    ({"cand_frame": [0, 3]}, "cand_frame"),
    ({"cand_frame": [-1, 0]}, "cand_frame"),
    ({"frame_camera": [0, 3, 1]}, "frame_camera"),
    ({"frame_camera": [0, -1, 1]}, "frame_camera"),
    ({"cand_uv": [1.0, 2.0]}, "cand_uv"),
])
def test_detections_validation(changes, match):
    fields = dict(camera_names=NAMES, frame_time_ns=[1, 2, 3], frame_camera=[0, 1, 2],
                  frame_index=[0, 0, 0], cand_frame=[0, 2], cand_uv=[[1.0, 2.0], [3.0, 4.0]],
                  cand_radius=[1.0, 1.0], cand_score=[1.0, 1.0])
    Detections(**fields)  # the unchanged fields are valid
    with pytest.raises(InputError, match=match) as info:
        Detections(**(fields | changes))
    assert isinstance(info.value, PslogError)


# ---- Observations -------------------------------------------------------------------------

def test_observations_ordering_validation():
    Observations([1, 1, 2], [0, 1, 0], np.zeros((3, 2)), [0, 0, 1])
    with pytest.raises(InputError, match="sorted"):
        Observations([2, 1], [0, 0], np.zeros((2, 2)), [0, 0])  # time decreasing
    with pytest.raises(InputError, match="sorted"):
        Observations([1, 1], [1, 0], np.zeros((2, 2)), [0, 0])  # camera decreasing at a tie
    with pytest.raises(InputError, match="sorted"):
        Observations([1, 1], [0, 0], np.zeros((2, 2)), [0, 0])  # a repeat
    with pytest.raises(InputError, match="length"):
        Observations([1, 2], [0, 0], np.zeros((3, 2)), [0, 0])
    with pytest.raises(InputError, match="uv"):
        Observations([1, 2], [0, 0], np.zeros((2, 3)), [0, 0])


def test_observations_from_unsorted_and_select():
    obs = Observations.from_unsorted([5, 1, 5, 3], [1, 0, 0, 2],
                                     [[0.0, 5.1], [0.0, 1.0], [0.0, 5.0], [0.0, 3.0]])
    assert_array_equal(obs.time_ns, [1, 3, 5, 5])
    assert_array_equal(obs.camera, [0, 2, 0, 1])
    assert_array_equal(obs.uv[:, 1], [1.0, 3.0, 5.0, 5.1])
    assert_array_equal(obs.frame_index, [0, 0, 0, 0])
    part = obs.select(obs.camera == 0)
    assert_array_equal(part.time_ns, [1, 5])
    assert_array_equal(obs.select([1, 3]).camera, [2, 1])


# ---- Track --------------------------------------------------------------------------------

def test_track_validation_and_select():
    track = Track("typeA", [1, 2, 3], np.arange(9.0).reshape(3, 3), [0, 1, 2],
                  {"ray_miss_m": [0.1, np.nan, 0.3]})
    assert len(track) == 3 and track.position_world.dtype == np.float64
    assert set(QUALITY_FIELDS) >= set(track.quality)
    part = track.select(np.array([True, False, True]))
    assert part.method == "typeA"
    assert_array_equal(part.time_ns, [1, 3])
    assert_array_equal(part.position_world, [[0, 1, 2], [6, 7, 8]])
    assert_array_equal(part.quality["ray_miss_m"], [0.1, 0.3])
    with pytest.raises(ValueError):
        track.quality["ray_miss_m"][0] = 1.0  # read-only
    with pytest.raises(InputError, match="typeA"):
        Track("typeA", [1, 2, 3], np.zeros((2, 3)), [0, 1, 2])
    with pytest.raises(InputError, match="typeA"):
        Track("typeA", [1, 2], np.zeros((2, 3)), [0, 1], {"snap_px": [1.0]})
    with pytest.raises(InputError, match="position_world"):
        Track("typeA", [1, 2], np.zeros((2, 2)), [0, 1])


def test_concat_of_empty_parts_keeps_their_quality_columns():
    """Parts that are all empty (a stream that made no point yet) join to an empty track with
    every part's quality columns, empty float64: a writer downstream sees the schema a track
    with points has. Before session 31 the join of empty parts had no quality column."""
    empty = Track("filter", [], np.zeros((0, 3)), [], {"std_m": [], "snap_px": []},
                  dropped={"held": 2})
    other = Track("filter", [], np.zeros((0, 3)), [], {"ray_miss_m": []})
    joined = Track.concat([empty, other, empty])
    assert list(joined.quality) == ["std_m", "snap_px", "ray_miss_m"]
    for column in joined.quality.values():
        assert column.dtype == np.float64 and column.shape == (0,)
    assert len(joined) == 0 and joined.dropped == {"held": 4}
    # with points, an empty part's column is NaN over the points (as a column missing from
    # a part with points always was)
    full = Track("filter", [5], [[1.0, 2.0, 3.0]], [1], {"std_m": [0.01]})
    joined = Track.concat([other, full])
    assert_array_equal(joined.quality["std_m"], [0.01])
    assert_array_equal(joined.quality["ray_miss_m"], [np.nan])


@pytest.mark.parametrize("method", ["filter", "typeA"])
def test_a_stream_without_points_joins_to_the_batchs_columns(method):
    """A real stream pushed too few detections to make a point: its parts joined have the
    quality columns of the batch's (empty) track of the same detections."""
    from test_fusion_validity import dirty_session

    from pslog.fusion import fuse
    from pslog.fusion.stream import StreamFuser

    rig, every = dirty_session("typeA", 0)[:2]
    obs = every.select(np.arange(2))
    fuser = StreamFuser(rig, method)
    parts = [fuser.push(obs.time_ns[i], obs.camera[i], obs.uv[i], obs.frame_index[i])
             for i in range(len(obs))]
    parts.append(fuser.flush())
    batch = fuse(obs, rig, method)
    assert len(batch) == 0 and batch.quality  # (the case: no point, but columns)
    assert set(Track.concat(parts).quality) == set(batch.quality)


# ---- Truth --------------------------------------------------------------------------------

def test_truth_validation():
    with pytest.raises(InputError, match="increasing"):
        Truth([0, 2, 2], np.zeros((3, 3)))
    with pytest.raises(InputError, match="increasing"):
        Truth([3, 2], np.zeros((2, 3)))
    with pytest.raises(InputError, match="length"):
        Truth([1, 2], np.zeros((3, 3)))
    with pytest.raises(InputError, match="position_world"):
        Truth([1, 2], np.zeros((2, 2)))


def test_truth_at_exact_at_samples_linear_between_nan_outside():
    rng = np.random.default_rng(0)
    time_ns = np.cumsum(rng.integers(1, 40_000_000, 50)) + 123
    positions = rng.normal(size=(50, 3)) * 3
    truth = Truth(time_ns, positions)
    assert len(truth) == 50
    # exactly (bit for bit) the samples at the sampled times, in any order
    order = rng.permutation(50)
    assert_array_equal(truth.at(time_ns[order]), positions[order])
    # linear in between
    w = rng.uniform(0, 1, 49)
    between = time_ns[:-1] + np.round(w * np.diff(time_ns)).astype(np.int64)
    w_exact = (between - time_ns[:-1]) / np.diff(time_ns)
    expected = positions[:-1] + w_exact[:, None] * (positions[1:] - positions[:-1])
    assert_allclose(truth.at(between), expected, rtol=0, atol=1e-12)
    # NaN outside the sampled span, even one nanosecond outside
    outside = truth.at([time_ns[0] - 1, time_ns[-1] + 1, -10 * NS])
    assert np.all(np.isnan(outside))


def test_truth_single_sample_and_empty():
    truth = Truth([5], [[1.0, 2.0, 3.0]])
    assert_array_equal(truth.at([5]), [[1.0, 2.0, 3.0]])
    assert np.all(np.isnan(truth.at([4, 6])))
    empty = Truth(np.zeros(0, np.int64), np.zeros((0, 3)))
    assert np.all(np.isnan(empty.at([0, 1])))
    assert truth.at([]).shape == (0, 3)


def test_records_are_read_only_without_freezing_the_callers_arrays():
    uv = np.array([[1.0, 2.0], [3.0, 4.0]])
    obs = Observations(np.array([0, 1]), np.array([0, 1]), uv, np.array([0, 0]))
    uv[0, 0] = 5.0  # the caller may still write its own array
    with pytest.raises(ValueError, match="read-only"):
        obs.uv[0, 0] = 6.0
