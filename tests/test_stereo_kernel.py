"""nearest's compiled per-point arithmetic (pslog/fusion/_stereo_kernel.py) against the numpy
forms it replaced (``compiled=False``), bit for bit: the rows, each slot's image motion,
the rays, the least-squares points and their quality (ray miss, angle, residuals), the
validity flags and the motion covariance; on dirty sessions with and without lens
distortion (missed detections, dropped frames, damaged pixels: NaN and 1e300, no ray), and
with the kernels' pure-Python originals (``.py_func``, the _jit convention) the same."""

from __future__ import annotations

import numpy as np
import pytest

from pslog import (
    Observations,
    Rig,
    SimulationOptions,
    apply_timing,
    builtin_rig,
    get_motion,
    simulate,
)
from pslog.fusion import _stereo_kernel, prepare
from pslog.fusion._prepare import default_max_gap_s, rays_only
from pslog.fusion.stereo import fuse_nearest
from pslog.geometry import _FEW

LENS = (-0.25, 0.08, 0.001, -0.001, 0.0)


def _session(lens, seed=3, motion="throw", duration=None):
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    if lens is not None:
        rig = Rig(tuple(c.replace(dist=np.array(lens)) for c in rig.cameras), rig.name)
    det, _ = simulate(rig, get_motion(motion), duration,
                      options=SimulationOptions(noise_px=0.5, miss_rate=0.2, drop_rate=0.05,
                                                jitter_s=2e-4, seed=seed))
    obs = det.best()
    uv = obs.uv.copy()
    uv[7::23], uv[11::29] = 1e300, np.nan  # damaged pixels: no ray, no residual
    return prepare(Observations(obs.time_ns, obs.camera, uv, obs.frame_index), rig), rig


def _same(a, b):
    assert a.time_ns.tobytes() == b.time_ns.tobytes()
    assert a.position_world.tobytes() == b.position_world.tobytes()
    assert a.camera.tobytes() == b.camera.tobytes()
    assert a.dropped == b.dropped
    assert list(a.quality) == list(b.quality)
    for name in b.quality:
        assert a.quality[name].tobytes() == b.quality[name].tobytes(), name


@pytest.mark.parametrize("lens", [None, LENS])
@pytest.mark.parametrize("noise_px", [0.5, None])
def test_nearest_compiled_equals_numpy_forms_bit_for_bit(lens, noise_px):
    prep, rig = _session(lens)
    assert len(prep.obs) >= _FEW  # (below, nview_points keeps numpy's row forms)
    gap = default_max_gap_s(rig)
    with np.errstate(all="ignore"):
        want = fuse_nearest(prep, gap, noise_px, compiled=False)
        got = fuse_nearest(prep, gap, noise_px)
    assert len(want.time_ns) > 50
    if noise_px is not None:  # a covariance, with blind slots (no velocity) among them
        assert np.isfinite(want.quality["std_m"]).all() and "cov_xy_m2" in want.quality
    _same(got, want)


@pytest.mark.parametrize("lens", [None, LENS])
@pytest.mark.parametrize("noise_px", [0.5, None])
def test_nearest_in_row_blocks_equals_the_whole_arrays(monkeypatch, lens, noise_px):
    """A long session's nearest track made block by block of rows (fuse_nearest from
    2 x NEAREST_BLOCK_ROWS detections; here blocks of 64 rows, the least the compiled forms
    take) has the bits of the whole-array way: points, every quality column (the
    covariance with the slots' motion, the image-motion breaks and the choices' doubt) and
    the left-out counts; on dirty sessions with and without lens distortion."""
    import dataclasses

    from pslog.fusion import stereo

    prep, rig = _session(lens, motion="rally", duration=6.0)  # (bounces, kicks)
    doubt = np.zeros(len(prep.obs))
    doubt[5::17] = 4.0  # some detections in doubt (the gate's choices): doubt_covariance
    prep = dataclasses.replace(prep, doubt_px2=doubt)
    gap = default_max_gap_s(rig)
    # (the rows fuse_nearest makes: of the detections with a ray, as _nearest_in_blocks
    # gets them; the damaged ones are missing detections)
    rows, others = stereo.nearest_rows(rays_only(prep)[0], int(gap * 1e9))
    with np.errstate(all="ignore"):
        whole = fuse_nearest(prep, gap, noise_px)  # (shorter than 2 blocks: whole arrays)
        monkeypatch.setattr(stereo, "NEAREST_BLOCK_ROWS", _FEW)
        assert len(rows) >= 4 * _FEW
        blocked = stereo._nearest_in_blocks(rays_only(prep)[0], rows, others, gap, noise_px)
        by_fuse = fuse_nearest(prep, gap, noise_px)
    assert blocked is not None  # (every block took the compiled forms)
    assert len(whole.time_ns) > 300
    _same(blocked, whole)
    _same(by_fuse, whole)


def test_nearest_track_holds_no_session_length_buffer_when_few_points_kept(monkeypatch):
    """nearest writes each block's kept points into columns of the session's row count
    (one copy; stereo._NearestRows): the track it returns holds those columns only while
    most rows are kept; with few kept (here a 1 ns gap: no other camera's detection is
    that close, no point made) its columns are its own, of its length, not views holding
    the session-length buffers. The points are the same either way (the test above)."""
    from pslog.fusion import stereo

    prep, rig = _session(None, motion="rally", duration=6.0)
    monkeypatch.setattr(stereo, "NEAREST_BLOCK_ROWS", _FEW)
    with np.errstate(all="ignore"):
        full = fuse_nearest(prep, default_max_gap_s(rig), 0.5)
        few = fuse_nearest(prep, 1e-9, 0.5)
    rows = len(rays_only(prep)[0].obs)  # (the detections with a ray: nearest's rows)
    assert 2 * len(full.time_ns) >= rows > 4 * _FEW
    assert len(few.time_ns) == 0 and few.dropped == {}

    def held(track):  # rows of the arrays whose memory the track's columns hold
        return {len(c if c.base is None else c.base)
                for c in (track.time_ns, track.position_world, track.camera,
                          *track.quality.values())}

    assert held(few) == {0}
    assert held(full) == {rows}  # (views of the one buffer: no join copy)


def test_nearest_kernels_python_originals_equal(monkeypatch):
    """Each kernel's pure-Python original (``.py_func``) gives the compiled kernel's bits
    (a short session: Python loops), lens distortion on."""
    prep, rig = _session(LENS, seed=5)
    gap = default_max_gap_s(rig)
    with np.errstate(all="ignore"):
        got = fuse_nearest(prep, gap, 0.5)
        # every kernel and helper the module calls (inlined ones too: their Python
        # originals, looked up by the originals at their call; nothing compiled here)
        for name in dir(_stereo_kernel):
            fn = getattr(_stereo_kernel, name)
            if hasattr(fn, "py_func"):
                monkeypatch.setattr(_stereo_kernel, name, fn.py_func)
        python = fuse_nearest(prep, gap, 0.5)
    _same(python, got)


def test_each_slot_holds_a_detection_of_its_own_camera():
    """slot_motion's kernel takes a slot's previous detections from its own camera's chain
    (``before[row]``, ``before[before[row]]``): nearest_rows puts a detection of camera c,
    and no other, in slot c (both forms, a dirty session)."""
    from pslog.fusion.stereo import nearest_rows

    prep, rig = _session(LENS)
    for compiled in (True, False):
        rows, _ = nearest_rows(prep, int(default_max_gap_s(rig) * 1e9), compiled)
        slot = np.broadcast_to(np.arange(rows.shape[1]), rows.shape)
        have = rows >= 0
        assert np.count_nonzero(have) > 2 * len(rows)
        assert np.array_equal(prep.obs.camera[rows[have]], slot[have])


def test_nearest_rows_and_motion_by_hand():
    """Three cameras 10 ms apart (30 ms periods), camera 1's second detection missed: each
    point's rows are the latest detection of every other camera within the gap, and a
    slot's motion extrapolates its camera's track to the point's time (quadratic through
    three detections: exact for a quadratic track; linear through two)."""
    from pslog.fusion.stereo import nearest_rows, slot_motion

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    t = np.arange(12, dtype=np.int64) * 10_000_000  # cameras 0, 1, 2, 0, 1, 2, ...
    cam = (np.arange(12) % 3).astype(np.int32)
    keep = np.arange(12) != 4  # camera 1 at 40 ms missed

    def u(s):  # every image's track along u: 30 px/s, 1000 px/s²
        return 300 + 30 * s + 500 * s * s

    ts = t[keep] / 1e9
    uv = np.stack([u(ts), np.full(len(ts), 240.0)], axis=1)
    prep = prepare(Observations(t[keep], cam[keep], uv, np.arange(keep.sum())), rig)
    gap_ns = 35_000_000
    rows, others = nearest_rows(prep, gap_ns)
    # rows: 0 cam0 0 ms, 1 cam1 10, 2 cam2 20, 3 cam0 30, 4 cam2 50 (cam1's 10 ms: too old)
    assert rows.tolist()[:5] == [[0, -1, -1], [0, 1, -1], [0, 1, 2], [3, 1, 2], [3, -1, 4]]
    assert others.tolist()[:5] == [0, 1, 2, 2, 1]
    assert rows[10].tolist() == [8, 9, 10]  # camera 2 at 110 ms: 90 ms and 100 ms
    want_rows, want_others = nearest_rows(prep, gap_ns, compiled=False)
    assert np.array_equal(rows, want_rows) and np.array_equal(others, want_others)
    # a partner exactly max_gap before the point is within it (<=): cam1's 10 ms for the
    # point at 30 ms, 20 ms gap (review: a < here survived the tests)
    for compiled in (True, False):
        assert nearest_rows(prep, 20_000_000, compiled=compiled)[0][3].tolist() == [3, 1, 2]
        # and a camera's detections exactly max_gap apart make its slot's motion (30 ms)
        exact = slot_motion(prep, rows, prep.obs.time_ns, 0.03, compiled=compiled)
        assert exact[0].rows[10].tolist() == [8, 5, 3]
    time_ns = prep.obs.time_ns
    motion = slot_motion(prep, rows, time_ns, gap_ns / 1e9)
    p = 10
    # camera 0's slot: 90, 60 and 30 ms, 20 ms before the point: quadratic
    m0 = motion[0]
    assert m0.rows[p].tolist() == [8, 5, 3]
    assert m0.lag[p] == pytest.approx(0.02, rel=1e-12)
    assert m0.shift[p, 0] == pytest.approx((u(0.09) - u(0.06)) / 0.03 * 0.02, rel=1e-9)
    assert m0.shift[p, 0] + m0.accel[p, 0] == pytest.approx(u(0.11) - u(0.09), rel=1e-9)
    assert m0.quadratic[p] @ [u(0.09), u(0.06), u(0.03)] == pytest.approx(u(0.11), rel=1e-12)
    # camera 1's slot: 100 and 70 ms (its 10 ms one 60 ms earlier: beyond the gap): linear
    m1 = motion[1]
    assert m1.rows[p].tolist() == [9, 6, -1]
    assert m1.accel[p].tolist() == [0.0, 0.0]
    assert m1.quadratic[p].tolist() == m1.linear[p].tolist()
    assert m1.linear[p] == pytest.approx([4 / 3, -1 / 3, 0.0], rel=1e-12)
    assert m1.shift[p, 0] == pytest.approx((u(0.1) - u(0.07)) / 0.03 * 0.01, rel=1e-9)
    # the point's own slot: no lag, no move
    assert motion[2].lag[p] == 0.0 and motion[2].shift[p].tolist() == [0.0, 0.0]
    # point 1's camera-0 slot has no previous detection: no velocity (a blind slot)
    assert motion[0].rows[1].tolist() == [0, -1, -1] and motion[0].lag[1] > 0
    for a, b in zip(motion, slot_motion(prep, rows, time_ns, gap_ns / 1e9, compiled=False),
                    strict=True):
        for x, y in zip(a, b, strict=True):
            assert x.tobytes() == y.tobytes()


@pytest.mark.parametrize("lens", [None, LENS])
def test_quadratic_residuals_compiled_equal_numpy_and_by_hand(lens):
    """:func:`quadratic_residuals` by its compiled pass (``nearest``'s noise and break
    terms: recorded and undistorted pixels) gives the numpy columns' bits, NaN where they
    are (no three previous detections within the gap, damaged pixels), and a detection's
    residual and weight by hand from the Lagrange weights through its camera's three
    previous detections."""
    from pslog.fusion.stereo import quadratic_residuals

    prep, rig = _session(lens)
    gap = default_max_gap_s(rig)
    recorded = np.where(np.isfinite(prep.uv_undistorted), prep.obs.uv, np.nan)
    for uv in (prep.uv_undistorted, recorded):
        with np.errstate(all="ignore"):
            want = quadratic_residuals(prep, uv, gap, compiled=False)
        got = quadratic_residuals(prep, uv, gap)
        assert got[0].tobytes() == want[0].tobytes()
        assert got[1].tobytes() == want[1].tobytes()
        assert 0 < np.count_nonzero(np.isnan(got[1])) < len(got[1]) // 2
    # by hand: camera 0's first detection with three previous ones, each within the gap
    res, weight = quadratic_residuals(prep, prep.uv_undistorted, gap)
    rows = prep.per_camera[0]
    i = next(i for i in range(3, len(rows)) if np.all(np.isfinite(res[rows[i]])))
    t = prep.obs.time_ns[rows[i - 3:i + 1]] / 1e9  # oldest first
    u = prep.uv_undistorted[rows[i - 3:i + 1]]
    # the quadratic through the three previous detections, at the detection's time
    lagrange = [np.prod([(t[3] - t[k]) / (t[j] - t[k]) for k in range(3) if k != j])
                for j in range(3)]
    assert np.allclose(res[rows[i]], u[3] - sum(w * u[j] for j, w in enumerate(lagrange)),
                       rtol=1e-9, atol=1e-9)
    assert np.isclose(weight[rows[i]], 1 + sum(w * w for w in lagrange), rtol=1e-12)
