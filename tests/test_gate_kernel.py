"""The compiled stream gate (pslog.fusion._gate_kernel) decides as the Python one: every
chosen candidate and every rejection with its reason, push by push, on randomized dirty
sessions; its pieces against gating's Python functions (and the kernels' own ``py_func``)
on random cases, Python's ``x ** 2`` (C's pow) and ``sum`` included."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _rally import rally
from _rigs import ring_rig
from numpy.testing import assert_array_equal

import pslog.fusion._gate_kernel as gk
from pslog.fusion import gating
from pslog.fusion.gating import GatingOptions, StreamGate, gate
from pslog.motion import G
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import (
    SimulationOptions,
    ball_mask,
    simulate,
    simulate_labelled,
    true_rig,
)

LENS = np.array([-0.25, 0.08, 0.001, -0.001, 0.0])
DISTRACTOR = (1.0, 1.5, 0.2)


def frames_of(det, per_push: int = 1, crowd_every: int = 0):
    """The frames with candidates, ``per_push`` frames per push (candidates best first);
    every ``crowd_every``-th frame with 6 more random candidates after its own."""
    rng = np.random.default_rng(0)
    starts = np.flatnonzero(np.r_[True, np.diff(det.cand_frame) != 0])
    ends = np.r_[starts[1:], det.n_candidates]
    rows = []
    for lo, hi in zip(starts.tolist(), ends.tolist(), strict=True):
        f, n = int(det.cand_frame[lo]), hi - lo
        uv = det.cand_uv[lo:hi]
        if crowd_every and len(rows) % crowd_every == crowd_every - 1:
            uv = np.r_[uv, rng.uniform(0, 600, (6, 2))]
            n = len(uv)
        rows.append((np.full(n, det.frame_time_ns[f]), np.full(n, det.frame_camera[f]),
                     uv, np.full(n, det.frame_index[f])))
    for i in range(0, len(rows), per_push):
        part = rows[i:i + per_push]
        yield tuple(np.concatenate([r[j] for r in part]) for j in range(4))


def streamed(gate_, det, per_push: int = 1, crowd_every: int = 0):
    """Every push's output, then the flush's."""
    out = [gate_.push(*frame) for frame in frames_of(det, per_push, crowd_every)]
    return [*out, gate_.flush()]


def assert_same_stream(det, rig, per_push: int = 1, crowd_every: int = 0,
                       outputs: list | None = None, **kw):
    """Both forms' pushes give the same bits and rejections; returns the rejections (and
    puts the compiled form's outputs in ``outputs``, when given)."""
    python = StreamGate(rig, compiled=False, **kw)
    compiled = StreamGate(rig, compiled=True, **kw)
    assert not python.compiled and compiled.compiled
    a = streamed(python, det, per_push, crowd_every)
    b = streamed(compiled, det, per_push, crowd_every)
    if outputs is not None:
        outputs.extend(b)
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        for u, v in zip(x, y, strict=True):
            assert_array_equal(u, v, err_msg=f"push {i}")
    ra, rb = python.rejections, compiled.rejections
    for name in ("frame_time_ns", "camera", "frame_index", "uv", "reason"):
        assert_array_equal(getattr(ra, name), getattr(rb, name), err_msg=name)
    return ra


def dirty(seed: int, rig, duration: float = 3.0, **faults):
    second, third = rig.names[1], rig.names[2]
    options = SimulationOptions(noise_px=0.3 + 0.7 * (seed % 3 == 1), seed=seed,
                                miss_rate=0.3, drop_rate=0.1, spurious_rate=0.1,
                                distractors=((second, DISTRACTOR),),
                                blackouts=((third, 1.0, 0.4),), **faults)
    motion = rally(duration, seed=seed, speed=4.0 + seed % 5, kick_every_s=0.7)[0]
    det, _, _ = simulate_labelled(rig, motion, duration, options)
    return det, true_rig(rig, options)


@pytest.mark.parametrize("seed", range(6))
def test_compiled_stream_gate_equals_the_python_one_on_random_dirty_sessions(seed):
    """30 % misses, 10 % drops, spurious blobs on 10 % of the frames, a static distractor,
    a blackout; seeds alternate a strong lens, clock offsets with rolling shutters, a wait
    (the methods that wait for the tolerance), a short max gap, two frames per push; the
    rejections are many and of three kinds or four, and both gates agree on each."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    faults: dict = {}
    kw: dict = {}
    if seed % 2:
        rig = Rig(tuple(c.replace(dist=LENS) for c in rig.cameras), rig.name)
    if seed in (1, 4):
        faults = {"clock_offset_s": {"cam2": 0.004, "cam3": -0.006},
                  "readout_s": dict.fromkeys(rig.names, 0.01)}
    if seed == 2:
        kw = {"wait_s": 0.004}
    if seed == 3:
        kw = {"max_gap_s": 0.04}
    det, rig = dirty(seed, rig, **faults)
    rejected = assert_same_stream(det, rig, per_push=2 if seed == 5 else 1, **kw)
    assert len(rejected) > 50
    assert len(set(rejected.reason.tolist())) >= 3  # rejected by three gates or more
    # and both are the batch gate's
    batch = gate(det, rig, causal=True, wait_s=kw.get("wait_s", 0.0),
                 max_gap_s=kw.get("max_gap_s"))
    assert_array_equal(rejected.reason, batch.rejections.reason)


def test_compiled_stream_gate_equals_the_python_one_on_four_cameras_at_240_fps():
    """A ring of four lensed cameras at 240 fps (60 frames of stillness history each, more
    than the state's first 64 rows hold with the blackout's gap: the arrays grow) and a
    frame with many candidates (the candidate columns grow)."""
    ring = ring_rig(4, "ring4")
    rig = Rig(tuple(c.replace(fps=240.0, offset=i / (4 * 240.0))
                    for i, c in enumerate(ring.cameras)), ring.name)
    det, rig = dirty(3, rig, duration=1.0)
    rejected = assert_same_stream(det, rig, crowd_every=97)
    assert len(rejected) > 50



def test_compiled_stream_gate_applies_the_long_stillness_test():
    """gating._still_long in the compiled form: paper2's ball flying at 2 m/s along cam1's
    optical axis (test_gating_paired_static) is still in cam1's image, its support by cam2
    holding in every frame; beyond LONG_STILL static_s that stillness is longer than a ball
    in flight can keep across this ray, and both forms call it static ('motion') frame for
    frame, none before the window."""
    from test_gating_paired_static import _toward

    rig = apply_timing(builtin_rig("paper2"), "typeA")
    det, _ = simulate(rig, _toward(rig, 1, 2.0, 0.0),
                      options=SimulationOptions(noise_px=0.3, seed=1))
    rejected = assert_same_stream(det, rig)
    motion_t = rejected.frame_time_ns[rejected.reason == gating.MOTION] / 1e9
    assert len(motion_t) >= 10
    assert motion_t.min() > gating.LONG_STILL * GatingOptions().static_s


@pytest.mark.parametrize("crowd_every", [0, 5])
def test_compiled_stream_gate_takes_each_pairs_smaller_long_stillness_tolerance(crowd_every):
    """gating._still_pair in the compiled form: a lob rising toward a steep camera along
    its ray (test_gating_paired_static.lob, 30 deg from the vertical) is not static in
    either form (the newest depth's tolerance alone called it static at 0.83 s); with 6
    random candidates in every 5th frame the pairs' tolerances differ, the same decisions."""
    from test_gating_paired_static import lob, lob_rig

    rig = lob_rig()
    det, _ = simulate(rig, lob(30.0, 2.0, 0.6), options=SimulationOptions(noise_px=0.3, seed=0))
    rejected = assert_same_stream(det, rig, crowd_every=crowd_every)
    if not crowd_every:
        assert np.all(rejected.frame_time_ns >= 1.0e9), rejected.frame_time_ns


def test_compiled_stream_gate_leaves_an_unpointed_candidate_to_the_track():
    """gating._columns's ``unpointed`` in the compiled form: paper2, the tests' rally seed 3
    at 1 px (test_gating_dirty_limits): cam0's last ball carried 83-117 ms "supports" cam1's
    next balls with a ray that makes no point with theirs; the track judges them at its own
    allowance and keeps the two at 8.55-8.59 s (the track-alone 3 cm lost the one at
    8.583 s), in both forms, push by push."""
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    motion = rally(20.0, seed=3, speed=4.0, kick_every_s=0.9)[0]
    det, _, ball = simulate_labelled(rig, motion, 20.0, SimulationOptions(noise_px=1.0, seed=3))
    chosen: list = []  # the compiled form's (the same stream, not streamed again)
    assert_same_stream(det, rig, outputs=chosen)
    is_ball = ball_mask(det, ball)
    frame_t = det.frame_time_ns[det.cand_frame]
    near = is_ball & (det.frame_camera[det.cand_frame] == 1) & (frame_t > 8.54e9) & (
        frame_t < 8.59e9)
    assert near.sum() == 2
    kept = {(int(t), int(c)) for out in chosen for t, c in zip(out[0], out[1], strict=True)}
    for t in frame_t[near].tolist():
        assert (t, 1) in kept, t / 1e9

def random_track(rng, n: int, bounce: bool):
    t = np.sort(rng.uniform(-0.1, 0.0, n))
    p0, v = rng.normal(0, 2, 3), rng.normal(0, 5, 3)
    pts = p0 + v * t[:, None] + 0.5 * np.array([0, 0, -G]) * t[:, None] ** 2
    pts += rng.normal(0, 0.2 if bounce else 0.002, pts.shape)
    return t, pts, rng.uniform(0, 0.02, n)


@pytest.mark.parametrize("fn", ["compiled", "py_func"])
def test_track_prediction_equals_gating_track(fn):
    """_Track.predict (ballistic line fit, the bounce refit on the newest three, Python's
    pow and sum) and the kernel give the same bits over random tracks."""
    rng = np.random.default_rng(4)
    options = GatingOptions()
    opt = gk.options_array(options, 0, 100_000_000, G)
    predict = gk.predict if fn == "compiled" else gk.predict.py_func
    refits = 0
    for trial in range(300):
        n = int(rng.integers(0, 12))
        t, pts, age = random_track(rng, n, bounce=trial % 2 == 1)
        track = gating._Track(options)
        trk = np.zeros((4 * options.track_points + 1, 5))
        n_trk = 0
        for i in range(n):
            track.add(float(t[i]), pts[i], float(age[i]))
            trk[n_trk] = (t[i], *pts[i], age[i])
            n_trk += 1
            if n_trk > 4 * options.track_points:
                trk[:options.track_points] = trk[n_trk - options.track_points:n_trk]
                n_trk = options.track_points
        at = float(rng.uniform(0.0, 0.05))
        want = track.predict(at)
        out = np.zeros(4)
        got = predict(trk, n_trk, at, opt, out)
        assert got == (want is not None)
        if want is not None:
            assert out[:3].tolist() == list(want[0]) and out[3] == want[1]
            k = len(track.t)
            ts = [x - at for x in track.t[max(0, k - 6):]]
            ys = [(float(p[0]), float(p[1]), float(p[2]) + 0.5 * u * u * G)
                  for u, p in zip(ts, track.p[max(0, k - 6):], strict=True)]
            refits += gating._line_fit(ts, ys)[1] > 0.5 * options.track_m
    assert refits > 20  # the bounce branch ran


def test_points_and_lines_equal_gating_on_random_cases():
    rng = np.random.default_rng(5)
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    constants = gating._rig_constants(rig)
    centers, k_inv, rot = (np.array(c, dtype=np.float64) for c in constants)
    F = gating.fundamental_matrices(rig.cameras)
    rays = np.zeros((4, 6))
    for _ in range(500):
        a = int(rng.integers(0, 3))
        ray = rng.normal(size=3)
        ray /= np.linalg.norm(ray)
        if rng.random() < 0.1:
            ray[0] = math.nan
        ratio = rng.choice([0.3, 0.9, 1.5, math.inf, math.nan], size=3)
        ratio[a] = math.nan
        carried = rng.uniform(0, 640, (3, 2))
        want = gating._points_one(a, ray.tolist(), ratio.tolist(), carried.tolist(), constants)
        got = gk.points_one(a, ray, ratio, carried, centers, k_inv, rot, rays)
        if want[0] is None:
            assert not got[0] and got[4] == want[1] and math.isnan(got[5])
        else:
            assert got[0] and list(got[1:4]) == list(want[0])
            assert got[4] == want[1] and got[5] == want[2]
        b = (a + 1) % 3
        u, v = rng.uniform(-50, 700, 2)
        line = gating._line_of(F[a, b].tolist(), u, v)
        got_line = gk._line_of(F[a, b], u, v)
        assert np.array_equal(got_line, line, equal_nan=True)



def test_batch_points_compiled_equal_the_numpy_form_bit_for_bit():
    """gating._points' compiled form (_gate_kernel.points_all, which pslog fuse uses) gives
    the numpy form's points, in-front flags and misses, bit for bit, on random candidates:
    unsupported, one support, parallel rays (det ~ 0), NaN own rays, inf/NaN ratios."""
    rng = np.random.default_rng(11)
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    constants = gating._rig_constants(rig)
    n, m = 4000, 3
    camera = rng.integers(0, m, n).astype(np.int32)
    ray = rng.normal(size=(n, 3))
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    ray[rng.random(n) < 0.05, 0] = math.nan
    ratio = rng.choice([0.3, 0.9, 1.0, 1.5, math.inf, math.nan], size=(n, m))
    ratio[np.arange(n), camera] = math.nan
    carried = rng.uniform(-50, 700, (n, m, 2))
    carried[rng.random((n, m)) < 0.05] = math.nan
    # parallel: the carried ray of camera b through b's own centre along the candidate's ray
    _centers, k_inv, rot = (np.array(c, dtype=np.float64) for c in constants)
    par = np.flatnonzero(rng.random(n) < 0.05)
    for i in par.tolist():
        b = (int(camera[i]) + 1) % m
        ratio[i] = math.nan
        ratio[i, b] = 0.5
        d = rot[b] @ ray[i]  # the candidate's direction in b's camera frame
        if np.isfinite(d).all() and d[2] != 0:
            uv = (np.linalg.inv(k_inv[b]) @ (d / d[2]))[:2]
            carried[i, b] = uv
    c = gating._Candidates(camera, np.zeros(n, dtype=np.int64), np.zeros((n, 2)), ray,
                           np.arange(n))
    want = gating._points_arrays(c, ratio, carried, constants)
    got = gating._points(c, rig, ratio, carried, constants)  # gk imported: compiled
    assert "pslog.fusion._gate_kernel" in __import__("sys").modules
    for w, g in zip(want, got, strict=True):
        assert w.dtype == g.dtype and w.shape == g.shape
        assert_array_equal(w.view(np.uint8), g.view(np.uint8))  # the bits, NaNs included
    assert np.isfinite(want[0]).all(axis=1).sum() > n // 4  # points made
    assert (~want[1]).sum() > 10 and np.isnan(want[2]).sum() > 10  # behind, no point

@pytest.mark.parametrize("timing", ["typeA", "typeB", "sync"])
def test_batch_support_compiled_equals_the_numpy_form_bit_for_bit(timing):
    """gating._support's compiled form (_gate_kernel.support_all, which pslog fuse uses)
    gives the numpy form's ratios, carried pixels and frames used, bit for bit, in every
    form the gate runs (causal without and with a wait, offline; the usual and a short
    gap), on dirty sessions: several candidates a frame (a distractor, spurious blobs, 6
    more in some frames), missed and dropped frames, a camera gone blind."""
    from pslog.geometry import fundamental_matrices

    seen = np.zeros(3, dtype=np.int64)
    for seed in range(2):
        det, rig = dirty(seed, apply_timing(builtin_rig("paper3"), timing), 3.0)
        c, tables = gating.gate_common(det, rig)
        F = fundamental_matrices(rig.cameras)
        options = GatingOptions()
        for causal, wait_ns in ((True, 0), (True, 1_000_000), (False, 0)):
            for gap_ns in (round(3.5e9 / 30), 20_000_000):
                want = gating._support(c, rig, F, tables, options, gap_ns, causal, wait_ns,
                                       compiled=False)
                got = gating._support(c, rig, F, tables, options, gap_ns, causal, wait_ns,
                                      compiled=True)
                for w, g in zip(want, got, strict=True):
                    assert w.dtype == g.dtype and w.shape == g.shape
                    assert_array_equal(w.view(np.uint8), g.view(np.uint8),
                                       err_msg=f"seed {seed} causal {causal} wait {wait_ns}")
                ratio = want[0]
                seen += [(ratio <= 1.0).sum(), np.isinf(ratio).sum(), np.isnan(ratio).sum()]
    # every kind of outcome met: supported, no plausible pair, no frame near
    assert seen.min() > 0 and seen[0] > 1000


def _static_sessions():
    """Sessions for gating._static: dirty rallies (a distractor standing still, spurious
    blobs), paper2 with a static object that one camera sees alone (the image test and its
    support), paper2's ball flying along cam1's ray (the long image test) and a lob toward
    a steep camera (each pair's smaller tolerance)."""
    from test_gating_paired_static import _session, _toward, lob, lob_rig

    yield dirty(0, apply_timing(builtin_rig("paper3"), "typeA"), 3.0)
    rig, det, _truth, _ball = _session("paper2")
    yield det, rig
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    yield simulate(rig, _toward(rig, 1, 2.0, 0.0),
                   options=SimulationOptions(noise_px=0.3, seed=1))[0], rig
    rig = lob_rig()
    yield simulate(rig, lob(30.0, 2.0, 0.6), options=SimulationOptions(noise_px=0.3,
                                                                       seed=0))[0], rig


def test_batch_static_compiled_equals_the_numpy_form():
    """gating._static's compiled form (_gate_kernel.static_camera, which pslog fuse uses)
    gives the numpy form's static flags and stillness, bit for bit, in both gating forms,
    with and without the image tests (``paired``), on sessions where each of its tests
    calls something static."""
    from pslog.geometry import fundamental_matrices

    found = still = 0
    for det, rig in _static_sessions():
        c, tables = gating.gate_common(det, rig)
        F = fundamental_matrices(rig.cameras)
        options = GatingOptions()
        for causal in (True, False):
            ratio, carried, _ = gating._support(c, rig, F, tables, options,
                                                round(3.5e9 / 30), causal, 0)
            points, _, miss = gating._points(c, rig, ratio, carried)
            points[miss > options.track_m] = np.nan
            for paired in (gating._paired(ratio), None):
                want = gating._static(c, tables, rig, options, points, paired, compiled=False)
                got = gating._static(c, tables, rig, options, points, paired, compiled=True)
                for w, g in zip(want, got, strict=True):
                    assert w.dtype == g.dtype and w.shape == g.shape
                    assert_array_equal(w.view(np.uint8), g.view(np.uint8))
                found += int(want[0].sum())
                still += int((want[1] > 0).sum())
    assert found > 50 and still > 20


def test_python_pow_and_sum_are_reproduced():
    """CPython's ``x ** 2`` is C's pow, not ``x * x`` (they differ in the last bit on some
    values); the kernels call pow with an exponent the compiler cannot fold; ``sum`` is the
    one this Python has (SUM_MODE)."""
    assert gk.SUM_MODE in (0, 1)
    rng = np.random.default_rng(6)
    x = rng.normal(size=20000) * 10.0 ** rng.integers(-20, 20, 20000)
    squared = np.array([v ** 2 for v in x.tolist()])
    assert np.any(squared != x * x)  # (otherwise this test shows nothing)
    trk = np.zeros((25, 5))
    opt = gk.options_array(GatingOptions(), 0, 1, G)
    out = np.zeros(3)
    for _ in range(200):  # _line_fit's residual squares and sums on random points
        n = int(rng.integers(1, 7))
        trk[:n] = rng.normal(size=(n, 5)) * 10.0 ** rng.integers(-3, 3)
        rms = gk._line_fit(trk, 0, n, 0.25, opt, out)
        ts = [float(t) - 0.25 for t in trk[:n, 0]]
        ys = [(p[1], p[2], p[3] + 0.5 * u * u * G) for u, p in zip(ts, trk[:n].tolist(),
                                                                   strict=True)]
        p0, want = gating._line_fit(ts, ys)
        assert rms == want and out.tolist() == p0


@pytest.mark.parametrize("compiled", [False, True])
def test_a_flush_before_any_push_returns_nothing(compiled):
    """(The compiled state's history bound starts below what an int64 holds: a live run
    stopped before its first datagram flushed a gate that had seen nothing.)"""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    for wait_s in (0.0, 0.004):
        out = StreamGate(rig, wait_s=wait_s, compiled=compiled).flush()
        assert [len(a) for a in out] == [0, 0, 0, 0]


def test_a_large_batch_gate_loads_its_kernels_a_small_one_never_waits_for_numba():
    """gating._kernels: a gate of many candidates loads the compiled kernels itself (pslog
    fuse's gate started before the preload thread had imported them and ran the numpy
    forms, ~1 CPU s more on a 90-minute match); a small one does not start numba."""
    import subprocess
    import sys

    code = """
import sys
from pslog.fusion import gating
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate
from pslog.motion import rally_motion
rig = apply_timing(builtin_rig("paper3"), "typeA")
det, _ = simulate(rig, rally_motion(1, 1.0), options=SimulationOptions(noise_px=0.3, seed=1))
gating._KERNELS_FROM = int(sys.argv[1])
gating.gate(det, rig, causal=True)
print("numba" in sys.modules, "pslog.fusion._gate_kernel" in sys.modules)
"""
    for limit, loaded in ((10, "True True"), (10**9, "False False")):
        done = subprocess.run([sys.executable, "-c", code, str(limit)], capture_output=True,
                              text=True, check=True)
        assert done.stdout.split() == loaded.split(), (limit, done.stdout, done.stderr)


def test_lags_kernel_is_the_numpy_form():
    # each camera's distance to the nearer of the latest frame and the next one looked at
    # (the frame before them not counted; -1: none), ties, cameras with no frame, gaps of
    # seconds and of one nanosecond
    rng = np.random.default_rng(9)
    n, m = 5_000, 4
    t = np.sort(rng.integers(0, 10**10, n))
    tables = []
    used = np.full((n, m, 3), -1, dtype=np.int64)
    for b in range(m):
        times = np.zeros(0, np.int64) if b == 2 else np.sort(rng.integers(0, 10**10, 400))
        tables.append((times, None))
        if len(times):
            used[:, b] = rng.integers(-1, len(times), (n, 3))
    used[::7, 1, 1] = used[::7, 1, 2]  # ties
    tables[3] = (tables[3][0].copy(), None)
    tables[3][0][:] = t[rng.integers(0, n, 400)] + rng.integers(-1, 2, 400)
    expected = gating._lags(t, tables, used)
    got = gating._lags(t, tables, used, compiled=True)
    assert np.isinf(expected[:, 2]).all() and np.isinf(expected).sum() < n * m
    assert_array_equal(got, expected)
