"""Type A's kink test compiled (innovation.kinked_points -> _pseudo_kernel.kink_kernel): the
same flags, bit for bit, as the columnar numpy form it replaced (kept here as the reference),
as its own pure-Python original (``py_func``), and on real sessions of fuse()."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import _pseudo_kernel, fuse, innovation
from pslog.fusion._prepare import Prepared
from pslog.motion import G
from pslog.records import NS


def _reference_bends(prep, a, b, c, point, speed, sigma):
    """The columnar form innovation._bends had before the kernel (numpy, elementwise)."""
    time_ns, uv = prep.obs.time_ns, prep.uv_undistorted
    cam = prep.obs.camera[b]
    cameras = prep.cameras
    fx = np.array([c_.K[0, 0] for c_ in cameras])[cam]
    fy = np.array([c_.K[1, 1] for c_ in cameras])[cam]
    cx = np.array([c_.K[0, 2] for c_ in cameras])[cam]
    cy = np.array([c_.K[1, 2] for c_ in cameras])[cam]
    r2 = np.array([c_.R[2] for c_ in cameras])[cam]
    tz = np.array([c_.t[2] for c_ in cameras])[cam]
    with np.errstate(invalid="ignore", divide="ignore"):
        dt1 = (time_ns[b] - time_ns[a]) / NS
        dt2 = (time_ns[c] - time_ns[b]) / NS
        v1x, v1y = (uv[b, 0] - uv[a, 0]) / dt1, (uv[b, 1] - uv[a, 1]) / dt1
        v2x, v2y = (uv[c, 0] - uv[b, 0]) / dt2, (uv[c, 1] - uv[b, 1]) / dt2
        dx, dy = v2x - v1x, v2y - v1y
        change = np.sqrt(dx * dx + dy * dy)
        sigma_change = sigma * np.sqrt(1.0 / dt1 ** 2 + (1.0 / dt1 + 1.0 / dt2) ** 2
                                       + 1.0 / dt2 ** 2)
        focal = np.maximum(fx, fy)
        depth = r2[:, 0] * point[:, 0] + r2[:, 1] * point[:, 1] + r2[:, 2] * point[:, 2] + tz
        ox, oy = (uv[b, 0] - cx) / focal, (uv[b, 1] - cy) / focal
        pixel_speed = np.maximum(np.sqrt(v1x * v1x + v1y * v1y), np.sqrt(v2x * v2x + v2y * v2y))
        acceleration = (focal * G * np.sqrt(1.0 + ox * ox + oy * oy)
                        + 2.0 * speed * pixel_speed) / depth
        bound = (innovation.KINK_SIGMAS * sigma_change
                 + 0.5 * (dt1 + dt2) * acceleration)
        return (dt1 > 0) & (dt2 > 0) & (depth > 0) & (change > bound)


def _reference_kinked(prep, events, past, noise_px, max_gap_ns):
    """The columnar form innovation.kinked_points had before the kernel."""
    p1, p2, predicted = past
    time_ns = prep.obs.time_ns
    sigma = np.broadcast_to(innovation.DEFAULT_NOISE_PX if noise_px is None
                            else np.asarray(noise_px, dtype=np.float64), events.shape)
    before, after = innovation._previous_next(prep.obs.camera)
    t_event = time_ns[events]
    with np.errstate(invalid="ignore", divide="ignore"):
        d = p1.points_world - p2.points_world
        speed = (np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
                 / ((time_ns[p1.row] - time_ns[p2.row]) / NS))
    triplets = []

    def bend(a, b, c, point):
        triplets.append((a, b, c, point))
        return len(triplets) - 1

    def earlier(rows):
        return np.where(rows >= 0, before[np.maximum(rows, 0)], -1)

    parts = []
    for p in (p1, p2):
        prev, nxt = p.prev_row, p.next_row
        first = earlier(prev)
        parts.append((bend(first, prev, nxt, p.points_world),
                      bend(prev, nxt, np.where(nxt >= 0, after[np.maximum(nxt, 0)], -1),
                           p.points_world),
                      bend(earlier(first), first, prev, p.points_world)))
    b = before[events]
    a = earlier(b)
    newest = (bend(a, b, events, predicted), bend(earlier(a), a, b, predicted))
    k = len(events)
    a_all, b_all, c_all = (np.concatenate([t[i] for t in triplets]) for i in range(3))
    available = ((a_all >= 0) & (b_all >= 0) & (c_all >= 0)
                 & (c_all <= np.tile(events, len(triplets)))
                 & (np.tile(t_event, len(triplets)) - time_ns[np.maximum(a_all, 0)]
                    <= 2 * max_gap_ns))
    bent_all = available & _reference_bends(
        prep, np.maximum(a_all, 0), np.maximum(b_all, 0), np.maximum(c_all, 0),
        np.concatenate([t[3] for t in triplets]), np.tile(speed, len(triplets)),
        np.tile(sigma, len(triplets)))

    def has(i):
        return available[i * k:(i + 1) * k]

    def bent(i):
        return bent_all[i * k:(i + 1) * k]

    kinked = np.zeros(k, dtype=bool)
    for at, later, before_prev in parts:
        kinked |= bent(at) & np.where(has(later), bent(later), ~bent(before_prev))
    last, before_last = newest
    start = time_ns[np.where(bent(before_last), np.maximum(a, 0), np.maximum(b, 0))]
    kinked |= bent(last) & (start >= time_ns[p2.row])
    return kinked


def _synthetic(seed: int, n: int = 600, k: int = 400):
    """A random session: 3 cameras (paper3's), piecewise-linear 2D tracks with kinks, ties
    and gaps in time, past points' rows and brackets anywhere (some missing, some after
    the newest detection), points in front of the cameras and some behind."""
    rng = np.random.default_rng(seed)
    cameras = builtin_rig("paper3").cameras
    camera = rng.integers(0, 3, n)
    steps = rng.choice([0, 1_000_000, 8_000_000, 33_333_333, 400_000_000], n,
                       p=[0.05, 0.1, 0.4, 0.4, 0.05])
    time_ns = np.cumsum(steps).astype(np.int64)
    velocity = rng.normal(0, 200, (n, 2)) * (rng.random((n, 1)) < 0.15)
    uv = 320 + np.cumsum(velocity * 0.033 + rng.normal(0, 0.4, (n, 2)), axis=0)
    uv[rng.random(n) < 0.02] = np.nan
    prep = SimpleNamespace(obs=SimpleNamespace(time_ns=time_ns, camera=camera),
                           uv_undistorted=uv, cameras=cameras,
                           lens_rows=Prepared.lens_rows.func(SimpleNamespace(cameras=cameras)))
    events = np.sort(rng.choice(np.arange(10, n), k, replace=False)).astype(np.int64)

    def rows(offset):
        return np.maximum(events - rng.integers(offset, offset + 12, k), 0)

    def past(offset):
        row = rows(offset)
        prev = np.where(rng.random(k) < 0.1, -1, row - rng.integers(0, 6, k))
        nxt = np.where(rng.random(k) < 0.1, -1, prev + rng.integers(1, 8, k))
        world = rng.normal([1.5, 1.0, 1.0], [1.0, 1.0, 1.0], (k, 3))
        world[rng.random(k) < 0.05] = [0.0, 0.0, 40.0]  # behind some camera
        return SimpleNamespace(row=row, prev_row=np.maximum(prev, -1),
                               next_row=np.minimum(nxt, n - 1), points_world=world)

    p1, p2 = past(1), past(8)
    predicted = rng.normal([1.5, 1.0, 1.0], 1.0, (k, 3))
    sigma = rng.uniform(0.1, 2.0, k)
    return prep, events, (p1, p2, predicted), sigma


def _kernel_args(prep, events, past, sigma, max_gap_ns):
    p1, p2, predicted = past
    before, after = innovation._previous_next(prep.obs.camera)
    lens = np.array([[c.K[0, 0], c.K[1, 1], c.K[0, 2], c.K[1, 2], *c.R[2], c.t[2]]
                     for c in prep.cameras])
    return (events, p1.row, p1.prev_row, p1.next_row, p1.points_world, p2.row, p2.prev_row,
            p2.next_row, p2.points_world, predicted, sigma, before, after, prep.obs.time_ns,
            prep.uv_undistorted, prep.obs.camera, lens, max_gap_ns, NS)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("max_gap_ns", [50_000_000, 500_000_000])
def test_kernel_equals_columnar_reference_and_py_func(seed, max_gap_ns):
    prep, events, past, sigma = _synthetic(seed)
    reference = _reference_kinked(prep, events, past, sigma, max_gap_ns)
    # the test decides both ways here (not all refused, not none)
    assert 0 < np.count_nonzero(reference) < len(events)
    compiled = innovation.kinked_points(prep, events, past, sigma, max_gap_ns)
    assert compiled.tobytes() == reference.tobytes()
    args = _kernel_args(prep, events, past, sigma, max_gap_ns)
    change, root = np.empty(len(args[13])), np.empty(len(args[13]))
    with np.errstate(all="ignore"):  # (numpy scalars warn where the kernel gives inf/nan)
        _pseudo_kernel.bend_rows.py_func(args[13], args[14], args[11], args[12], NS, change,
                                         root)
    # the kernel with bend_rows' tables and without (each triplet's terms where read: a
    # stream's one point), compiled and in Python
    for tables in ((change, root), (np.empty(0), np.empty(0))):
        for fn in (_pseudo_kernel.kink_kernel, _pseudo_kernel.kink_kernel.py_func):
            python = np.zeros(len(events), dtype=bool)
            with np.errstate(all="ignore"):
                fn(*args, python, *tables)
            assert python.tobytes() == reference.tobytes()


def test_scalar_noise_and_none_equal_reference():
    prep, events, past, _ = _synthetic(11)
    for noise in (None, 0.3, 1.0):
        assert (innovation.kinked_points(prep, events, past, noise, 200_000_000).tobytes()
                == _reference_kinked(prep, events, past, noise, 200_000_000).tobytes())


def test_hand_computed_bend():
    """One camera's track at ``v`` px/s, then at rest at the image centre (a stop; the
    ball still: |V| = 0). With σ = 0.5 px, δ = 1/30 s: σ_Δv = 0.5 √(900 + 3600 + 900) =
    36.7 px/s; the model bound at a depth of 3 m on the optical axis is
    ½ (2δ) f g / 3 = 0.109 f px/s, so ``v`` 1 px/s above 5 σ_Δv + 0.109 f bends, 1 px/s
    below it does not."""
    cam = builtin_rig("paper3").cameras[0]
    f = max(cam.K[0, 0], cam.K[1, 1])
    point = cam.center_world + 3.0 * cam.R[2]
    assert abs(float(cam.R[2] @ point + cam.t[2]) - 3.0) < 1e-9
    time_ns = np.arange(3, dtype=np.int64) * (NS // 30)
    dt = (time_ns[1] - time_ns[0]) / NS
    lens = np.array([[cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2], *cam.R[2],
                      cam.t[2]]])
    camera = np.zeros(3, dtype=np.int64)
    cx, cy = cam.K[0, 2], cam.K[1, 2]
    bound = 5 * 0.5 * np.sqrt(3 / dt ** 2 + 3 / dt ** 2) + dt * f * G / 3.0
    for change, expected in ((bound + 1.0, True), (bound - 1.0, False)):
        uv = np.array([[cx - change * dt, cy], [cx, cy], [cx, cy]])  # v1 = change, v2 = 0
        for fn in (_pseudo_kernel._bend, _pseudo_kernel._bend.py_func):
            got = fn(0, 1, 2, *point, 0.0, 0.5, time_ns, uv, camera, lens, NS)
            assert got is expected or got == expected, (change, fn)
    assert abs(bound - (5 * 36.74 + 0.109 * f)) < 1.0  # the figures of the docstring


def _turntable(n_cameras: int, noise: float, seed: int):
    from test_stream_type_a import _quad_rig

    rig = (apply_timing(builtin_rig("paper2"), "typeA") if n_cameras == 2 else
           apply_timing(builtin_rig("paper3"), "typeA") if n_cameras == 3 else _quad_rig())
    det, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(
        noise_px=noise, miss_rate=0.2, drop_rate=0.1, jitter_s=0.0005, seed=seed))
    return det.best(), rig


def _reference_fuse_type_a(prep, max_gap_s, noise_px, events=None, seen=None, noise=None,
                           explain=True, cov_noise_px=None):
    """fuse_type_a as it was before its decisions moved into the kernel's loop: the kernel
    on every target without deciding (each point's prediction, innovation terms and past
    points in (k,) columns), then the tests on the columns: NoiseEstimate.sigmas, the
    prediction test and the columnar reference of the kink test (_reference_kinked)."""
    from pslog.fusion import pseudo
    from pslog.fusion.stereo import count_invalid
    from pslog.records import Track

    assert events is None and seen is None and noise is None and not explain
    assert prep.doubt_px2 is None  # (best() detections: no choice in doubt)
    time_ns, n = prep.obs.time_ns, len(prep.obs)
    prev_b, next_b, previous_instant = pseudo._all_brackets(prep)
    cam, ki, rr, rtki, f9, lens = _pseudo_kernel.camera_tables(prep)
    k = n
    ff = np.empty((2, 1, len(_pseudo_kernel.FLOATS)))
    fi = np.empty((2, 1, len(_pseudo_kernel.INTS)), dtype=np.int64)
    past_rows, past_points = np.empty((2, k, 3), dtype=np.int64), np.empty((2, k, 3))
    refused, has = np.zeros(n, dtype=np.int64), np.empty(k, dtype=bool)
    predicted, points = np.empty((k, 3)), np.empty((k, 3))
    flags = np.empty(k, dtype=np.int64)
    innov, factor, model = np.empty(k), np.empty(k), np.empty(k)
    quality_table = np.empty((len(pseudo._QUALITY), k))
    rows_out = np.empty(k, dtype=np.int64)
    var_px = float(noise_px if cov_noise_px is None else cov_noise_px)
    max_gap_ns = int(max_gap_s * NS)
    args = (np.arange(n), previous_instant, 2 * len(prep.centers), pseudo.MAX_EXTRAPOLATION,
            max_gap_ns, time_ns, prep.obs.camera, prev_b, next_b, prep.uv_undistorted,
            prep.observed_rays, prep.centers, ki, rr, f9, cam, pseudo._SPAN_TIE_NS,
            pseudo.MIN_RAY_ANGLE_DEG, prep.ray_dir, prep.observed_direction_jacobians,
            pseudo._jacobian_rows(prep) if lens else np.zeros((1, 4)), lens, rtki, NS, var_px,
            True, ff, fi, refused, has, predicted, points, flags, innov, factor, model,
            quality_table, past_rows, past_points)
    made = _pseudo_kernel.type_a_kernel(
        *args, False, 0.0, np.empty(0), 0, prep.lens_rows, np.empty(0, dtype=np.int64),
        np.empty(0, dtype=np.int64), np.empty(0), np.empty(0), np.zeros(0, dtype=bool),
        rows_out, np.zeros(8, dtype=np.int64), np.empty(1))
    events = rows_out[:made]
    predicted, points, flags = predicted[:made], points[:made], flags[:made]
    innov, factor, model = innov[:made], factor[:made], model[:made]
    finite = np.all(np.isfinite(points), axis=1)
    good = finite & (flags == 0)
    with np.errstate(invalid="ignore"):
        sigma = innovation.NoiseEstimate().sigmas(np.where(good, innov, np.nan) / factor,
                                                  noise_px)
        failed = good & (innov > innovation.INNOVATION_SIGMAS * (sigma * factor) + model)
    # the σ the kernel takes in its loop (deciding) at each point it keeps: the reference's
    before, after = innovation.previous_next_rows(prep)
    change, root = np.empty(n), np.empty(n)
    _pseudo_kernel.bend_rows(time_ns, prep.uv_undistorted, before, after, NS, change, root)
    kept_rows, sigmas = np.empty(k, dtype=np.int64), np.empty(k)
    kept = _pseudo_kernel.type_a_kernel(
        *args[:28], np.zeros(n, dtype=np.int64), np.empty(k, dtype=bool), np.empty((k, 3)),
        np.empty((k, 3)), np.empty(k, dtype=np.int64), np.empty(k), np.empty(k), np.empty(k),
        np.empty((len(pseudo._QUALITY), k)), np.empty((2, k, 3), dtype=np.int64),
        np.empty((2, k, 3)), True, float(noise_px), np.empty(k), 0, prep.lens_rows, before,
        after, change, root, np.zeros(0, dtype=bool), kept_rows, np.empty(8, dtype=np.int64),
        sigmas)
    assert sigmas[:kept].tobytes() == sigma[np.searchsorted(events, kept_rows[:kept])].tobytes()
    p1, p2 = (SimpleNamespace(row=past_rows[s, :made, 0], prev_row=past_rows[s, :made, 1],
                              next_row=past_rows[s, :made, 2], points_world=past_points[s, :made])
              for s in range(2))
    kinked = good & ~failed & _reference_kinked(prep, events, (p1, p2, predicted), sigma,
                                                max_gap_ns)
    keep = good & ~failed & ~kinked
    dropped = dict(count_invalid(flags[finite]))
    dropped.update((f"past_{r}", c) for r, c in count_invalid(refused).items())
    if failed.any():
        dropped["prediction_failed"] = int(failed.sum())
    if kinked.any():
        dropped["kink"] = int(kinked.sum())
    quality = {name: column[:made][keep] for name, column in zip(pseudo._QUALITY,
                                                                  quality_table, strict=True)}
    return Track("typeA", time_ns[events[keep]], points[keep],
                 prep.obs.camera[events[keep]], quality, dropped), None


@pytest.mark.parametrize("n_cameras,noise", [(2, 0.0), (3, 0.3), (4, 1.0)])
def test_fuse_decisions_equal_columnar_reference(monkeypatch, n_cameras, noise):
    """fuse() on real sessions: the decisions type A's kernel takes in its loop (the tests'
    noise estimate, the prediction test, the kink test) keep and drop the points the
    columnar reference does (the former fuse_type_a: NoiseEstimate.sigmas, the prediction
    test and the kink test on (k,) columns), with the same counts and the same bits."""
    import pslog.fusion.pseudo

    obs, rig = _turntable(n_cameras, noise, seed=7)
    compiled = fuse(obs, rig, "typeA")
    calls = []

    def reference(prep, max_gap_s, noise_px, events, seen, noise, explain, cov_noise_px,
                  table_out):
        # (the registry's entry point; no quality table handed out: the copying rescale)
        calls.append(len(prep.obs))
        return _reference_fuse_type_a(prep, max_gap_s, noise_px, events, seen, noise,
                                      explain=explain, cov_noise_px=cov_noise_px)

    monkeypatch.setattr(pslog.fusion.pseudo, "_fuse_type_a", reference)
    columnar = fuse(obs, rig, "typeA")
    assert calls
    assert compiled.dropped == columnar.dropped
    assert compiled.dropped.get("kink", 0) > 0 and compiled.dropped.get("prediction_failed", 0) > 0
    assert compiled.time_ns.tobytes() == columnar.time_ns.tobytes()
    assert compiled.position_world.tobytes() == columnar.position_world.tobytes()
    assert compiled.quality.keys() == columnar.quality.keys()
    for name, column in compiled.quality.items():
        assert column.tobytes() == columnar.quality[name].tobytes(), name
