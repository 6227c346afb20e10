"""typeA's incremental streaming form (pslog.fusion.pseudo.TypeAStream): each pushed
detection's point from the rows it can reach, bit for bit the batch's, its dropped counts
included, whatever the pushes' sizes."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from test_fusion_validity import dirty_session, observations, rectified_rig

from pslog.fusion import FusionOptions, fuse
from pslog.fusion.pseudo import TypeAStream
from pslog.fusion.stream import StreamFuser
from pslog.records import Track


def pushed_one_by_one(fuser, obs) -> list[Track]:
    """Each detection of ``obs`` in a push of its own, then the flush: the parts returned."""
    parts = [fuser.push(obs.time_ns[i], obs.camera[i], obs.uv[i], obs.frame_index[i])
             for i in range(len(obs))]
    parts.append(fuser.flush())
    return parts


def assert_same(parts, batch):
    """Every column, quality column and dropped count of the joined stream is the batch's."""
    joined = Track.concat(parts)
    assert_array_equal(joined.time_ns, batch.time_ns)
    assert_array_equal(joined.camera, batch.camera)
    assert_array_equal(joined.position_world, batch.position_world)
    assert set(joined.quality) == set(batch.quality)
    for key, column in batch.quality.items():
        assert_array_equal(joined.quality[key], column, err_msg=key)
    assert joined.dropped == batch.dropped


def test_type_a_streams_through_its_incremental_form():
    rig = dirty_session("typeA", 0)[0]
    # (by default through pslog.fusion.confirm's ConfirmedStream, which holds long-gap points)
    # (and MeasuredNoiseStream around it: the covariance at the measured noise)
    assert isinstance(StreamFuser(rig, "typeA").incremental.inner.inner, TypeAStream)
    options = FusionOptions(confirm_gaps=False)
    assert isinstance(StreamFuser(rig, "typeA", options).incremental.inner, TypeAStream)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("noise_px", [0.5, None])
@pytest.mark.parametrize("lens", [True, False])
def test_one_detection_per_push_equals_batch_with_its_drops(seed, noise_px, lens):
    # (one row a push: TypeAStream._push_one, the decisions on scalars; without a lens the
    # new row's rays in one compiled pass, _prepare_kernel.lensless_rows)
    rig, obs, _ = dirty_session("typeA", seed, lens=lens)
    # (no long-gap point held: tests/test_dirty_confirm.py has those)
    options = FusionOptions(noise_px=noise_px, confirm_gaps=False)
    batch = fuse(obs, rig, "typeA", options)
    assert len(batch) > 15
    if seed == 0:  # every kind of drop the one-row path decides is met
        assert {"prediction_failed", "kink", "outside_view"} <= set(batch.dropped)
    fuser = StreamFuser(rig, "typeA", options)
    parts = pushed_one_by_one(fuser, obs)
    assert all(len(p) <= 1 for p in parts[:-1])  # each point with the detection that makes it
    assert len(parts[-1]) == 0
    assert_same(parts, batch)


def test_pushes_of_several_detections_equal_batch():
    # pushes of 1 to 7 rows of mixed cameras: each row's point from one kernel call
    rig, obs, _ = dirty_session("typeA", 3)
    batch = fuse(obs, rig, "typeA")
    sizes = np.random.default_rng(0).integers(1, 8, len(obs))
    edges = np.r_[0, np.cumsum(sizes)]
    edges = [*edges[edges < len(obs)].tolist(), len(obs)]
    fuser = StreamFuser(rig, "typeA")
    parts = [fuser.push(obs.time_ns[a:b], obs.camera[a:b], obs.uv[a:b], obs.frame_index[a:b])
             for a, b in itertools.pairwise(edges)]
    parts.append(fuser.flush())
    assert_same(parts, batch)


def _behind_then_in_front(n: int) -> list[tuple]:
    """``n`` rows (ms, camera, u, v) of a static ball seen by rectified_rig's two cameras in
    turn: at a negative disparity for the first 10, a positive one after."""
    return [(10 * i, i % 2, 320.0 if i % 2 == 0 else (380.0 if i < 10 else 260.0), 240.0)
            for i in range(n)]


def test_refused_past_points_are_counted_once_each_as_in_batch():
    # a static ball first at a negative disparity (every pseudo-stereo pair crosses behind
    # both cameras: refused, each detection once, though several points reach it), then at
    # a positive one (points)
    rig = rectified_rig(offsets=(0.0, 1 / 60))
    obs = observations(_behind_then_in_front(20))
    batch = fuse(obs, rig, "typeA")
    assert batch.dropped.get("past_behind_camera", 0) >= 4 and len(batch) > 3, batch.dropped
    fuser = StreamFuser(rig, "typeA")
    parts = pushed_one_by_one(fuser, obs)
    assert_same(parts, batch)


def _quad_rig(fps=(60, 240, 120, 60)):
    """paper3 and a fourth camera at the opposite corner, type A offsets, a strong lens and
    mixed frame rates (a distorted camera's rays were one matmul whose last bits depended on
    how many rows it was given: one per push vs all in batch)."""
    from pslog import Rig, apply_timing, builtin_rig, look_at

    lens = np.array([-0.35, 0.15, 0.002, -0.002, -0.03])
    paper = builtin_rig("paper3")
    R, t = look_at((-1.0, -1.5, 2.5), (1.5, 1.0, 1.0))
    cams = (*paper.cameras, paper.cameras[0].replace(name="cam4", R=R, t=t))
    cams = tuple(c.replace(dist=lens, fps=f) for c, f in zip(cams, fps, strict=True))
    return apply_timing(Rig(cams, "quad4"), "typeA")


@pytest.mark.parametrize("n_cameras", [2, 4])
def test_two_and_four_camera_streams_equal_batch(n_cameras):
    # the compiled kernels loop over any number of cameras: partner choice, brackets, masks
    from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate

    rig = (apply_timing(builtin_rig("paper2"), "typeA") if n_cameras == 2 else _quad_rig())
    det, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(
        noise_px=0.5, miss_rate=0.2, drop_rate=0.1, jitter_s=0.0005, seed=5))
    obs = det.best()
    batch = fuse(obs, rig, "typeA")
    assert len(batch) > 20
    if n_cameras == 4:
        assert batch.quality["camera_mask"].max() >= 8  # the fourth camera takes part
    fuser = StreamFuser(rig, "typeA")
    parts = pushed_one_by_one(fuser, obs)
    assert_same(parts, batch)


@pytest.mark.parametrize("noise_px", [None, 0.0, 0.8])
def test_noise_estimate_one_point_path_equals_batch(noise_px):
    """NoiseEstimate.sigmas of one point (a stream's push: a median made once per
    checkpoint) gives the batch call's bits, pushes of one and of several points mixed,
    points not made (NaN) among them, past several checkpoints and windows."""
    from pslog.fusion.innovation import NoiseEstimate

    rng = np.random.default_rng(3)
    x = 1.2 * np.hypot(rng.standard_normal(1500), rng.standard_normal(1500))
    x[rng.random(1500) < 0.1] = np.nan
    whole = NoiseEstimate().sigmas(x, noise_px)
    sizes = rng.choice([1, 1, 1, 2, 5, 40], size=1500)
    cuts = np.minimum(np.cumsum(sizes), 1500)
    split = NoiseEstimate()
    parts = [split.sigmas(x[a:b], noise_px)
             for a, b in itertools.pairwise([0, *np.unique(cuts).tolist()])]
    assert_array_equal(np.concatenate(parts), whole)
    assert len(np.unique(whole)) > 10  # (checkpoints past the first: medians, not the floor)


def test_noise_estimate_long_runs_of_one_point_equal_batch():
    """A stream's pushes of one point only (the live case), 1,500 of them: NoiseEstimate
    appends each innovation in place in a buffer whose kept tail (the last window and
    checkpoint interval) moves to its front when full, several times here: the batch
    call's bits throughout."""
    from pslog.fusion.innovation import _TAIL_BUFFER, NOISE_EVERY, NOISE_WINDOW, NoiseEstimate

    rng = np.random.default_rng(5)
    x = 1.2 * np.hypot(rng.standard_normal(1500), rng.standard_normal(1500))
    x[rng.random(1500) < 0.1] = np.nan
    whole = NoiseEstimate().sigmas(x, 0.3)
    split = NoiseEstimate()
    assert_array_equal([split.sigmas(x[i:i + 1], 0.3)[0] for i in range(1500)], whole)
    assert 1350 > 3 * (_TAIL_BUFFER - NOISE_WINDOW - NOISE_EVERY)  # (moved 3 times or more)
    assert len(np.unique(whole)) > 10


def test_far_and_refused_rows_one_per_push_equal_batch_without_a_lens():
    """A lensless rig's far-off pixels (a damaged datagram's 1e300: no ray, as prepare has
    it) and a static ball crossing behind the cameras (past refusals, counted once), one row
    a push, are the batch's: points, quality and dropped counts."""
    rig = rectified_rig(offsets=(0.0, 1 / 60))
    assert not any(np.any(c.dist) for c in rig.cameras)
    rows = _behind_then_in_front(30)
    rows[14] = (140, 0, 1e300, 240.0)
    rows[21] = (210, 1, -7e3, 240.0)
    obs = observations(rows)
    batch = fuse(obs, rig, "typeA")
    assert batch.dropped.get("past_behind_camera", 0) >= 4 and len(batch) > 3, batch.dropped
    fuser = StreamFuser(rig, "typeA")
    parts = pushed_one_by_one(fuser, obs)
    assert_same(parts, batch)
    # the stream's point columns are its own: later pushes do not change earlier points
    assert all(not p.time_ns.flags.writeable for p in parts)
