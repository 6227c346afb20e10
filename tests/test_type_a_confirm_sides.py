"""Type A after kicks, each point tested on its side of the kick (``FusionOptions.
confirm_sides``, ``pslog fuse --confirm-gaps kicks``, the default offline since session 35;
docs/methods.md, "Type A after kicks: the side of the kick (session 33)"). On the dev
session of session 33 (paper3, rally seed 37001, 0.3 px, clean) ``confirm_every`` keeps a
point 79 mm off 18 ms after a kick: the camera that confirms it has its previous detection
before the kick and its next after, so eq. (1)'s interpolation across the kick is no check;
the side test leaves it out."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from _rally import dirty_rally
from numpy.testing import assert_array_equal

from pslog.errors import FusionError
from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions, fuse
from pslog.fusion.stream import StreamFuser
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate

EVERY = FusionOptions(confirm_every=True)
SIDES = FusionOptions(confirm_every=True, confirm_sides=True, confirm_breaks=False)


def _session(seed: int = 37001):
    """bench_dirty ``--more``'s rally ``seed`` on paper3 (its noise draw ``seed - 300``)."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion, kicks = dirty_rally(seed)
    det, truth = simulate(rig, motion, 8.0, SimulationOptions(noise_px=0.3, seed=seed - 300))[:2]
    return rig, det, truth, np.asarray(kicks)


def _key(track) -> np.ndarray:
    return track.time_ns * 256 + track.camera


@pytest.fixture(scope="module")
def fused():
    rig, det, truth, kicks = _session()
    return (truth, kicks, fuse(det, rig, "typeA"), fuse(det, rig, "typeA", EVERY),
            fuse(det, rig, "typeA", SIDES))


def test_the_point_after_a_kick_that_confirm_every_keeps_is_left_out(fused):
    truth, kicks, _paper, every, sides = fused
    far = errors_m(every, truth) > 0.05
    assert far.sum() == 1
    t_far = every.time_ns[far][0] / 1e9
    assert 0 < t_far - kicks[kicks <= t_far].max() < 0.04  # just after a kick
    assert np.all(errors_m(sides, truth) <= 0.05)
    assert not np.isin(_key(every)[far], _key(sides)).any()


def test_good_points_are_kept_and_only_dropped(fused):
    truth, _kicks, paper, _every, sides = fused
    keep = np.isin(_key(paper), _key(sides))
    # only drops: the points kept are the paper's, to the bit
    assert_array_equal(sides.time_ns, paper.time_ns[keep])
    assert_array_equal(sides.position_world, paper.position_world[keep])
    for name, column in sides.quality.items():
        assert_array_equal(column, paper.quality[name][keep], err_msg=name)
    good = errors_m(paper, truth) <= 0.05
    lost = np.count_nonzero(good & ~keep)
    assert lost <= 5, lost  # (measured: 4 of 591 within 5 cm; confirm_every: 3)
    assert sides.dropped["contradicted"] - paper.dropped.get("contradicted", 0) == len(
        paper) - len(sides)


def test_a_motion_without_kicks_loses_next_to_nothing():
    from pslog.motion import get_motion

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion = get_motion("straight")
    det = simulate(rig, motion, None, SimulationOptions(noise_px=0.3, seed=5))[0]
    paper, sides = fuse(det, rig, "typeA"), fuse(det, rig, "typeA", SIDES)
    assert len(paper) - len(sides) <= 1


def test_a_stream_refuses_it_and_it_needs_confirm_every():
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    with pytest.raises(FusionError, match="offline only"):
        StreamFuser(rig, "typeA", SIDES)
    with pytest.raises(FusionError, match="confirm_sides needs confirm_every"):
        FusionOptions(confirm_sides=True)
    from pslog.live.fuser import LiveFuser

    options = LiveFuser(rig, "typeA", options=SIDES).options  # (live: a point at once)
    assert not (options.confirm_gaps or options.confirm_every or options.confirm_sides)


def test_jumps_is_the_offline_default_and_on_the_causal_form(tmp_path, cli):
    """``pslog fuse`` and :func:`pslog.fuse` confirm every point on its side of a kick by
    default (session 35: ``for_session`` turns ``confirm_every`` and ``confirm_sides`` on),
    and replace the points spanning a kick the images show (session 45: and
    ``confirm_breaks``, its source the images'; ``--confirm-gaps kicks`` the side test alone);
    ``--confirm-gaps on`` is the causal form, bare :func:`pslog.fusion.fuse`'s default."""
    import pslog
    from pslog.fusion import for_session
    from pslog.log import SessionWriter, read_session

    rig, det, _truth, _ = _session()
    path = tmp_path / "rally.mcap"
    with SessionWriter(path, rig, timing="typeA", source="test") as writer:
        writer.add_detections(det)
    sides = fuse(det, rig, "typeA", SIDES)
    jumps = fuse(det, rig, "typeA", replace(SIDES, confirm_breaks=True))
    causal = fuse(det, rig, "typeA")
    assert len(sides) < len(causal)
    assert np.any(jumps.quality["span_s"] < 0)  # (the default differs from kicks here)
    for args, expected in (((), jumps), (("--confirm-gaps", "kicks"), sides),
                           (("--confirm-gaps", "on"), causal)):
        out = tmp_path / f"fused{len(args)}{args[-1] if args else ''}.mcap"
        code, stdout, err = cli("fuse", path, "--method", "typeA", *args, "-o", out)
        assert code == 0, err
        track = read_session(out).tracks["typeA"]
        assert_array_equal(track.time_ns, expected.time_ns)
        assert_array_equal(track.position_world, expected.position_world)
        assert "ignored" not in stdout
    api = pslog.fuse(path, methods=["typeA"])["typeA"]
    assert_array_equal(api.position_world, jumps.position_world)
    bare = pslog.fuse(det, methods=["typeA"], rig=rig)["typeA"]  # (bare detections: as well)
    assert_array_equal(bare.position_world, jumps.position_world)
    # the session's default: on with confirm_gaps, an explicit choice kept
    options = for_session(FusionOptions(), {})
    assert options.confirm_every and options.confirm_sides and options.confirm_breaks
    assert options.break_source == "image"
    options = for_session(FusionOptions(confirm_gaps=False), {})
    assert options.confirm_every is False and options.confirm_sides is False
    assert options.confirm_breaks is False
    options = for_session(FusionOptions(confirm_every=True, confirm_sides=False), {})
    assert options.confirm_every and options.confirm_sides is False
    assert options.confirm_breaks is False
    options = for_session(FusionOptions(confirm_breaks=False), {})
    assert options.confirm_sides and options.confirm_breaks is False
    # named for a run without typeA: said
    code, stdout, err = cli("fuse", path, "--method", "nearest", "--confirm-gaps", "kicks",
                            "-o", tmp_path / "nearest.mcap")
    assert code == 0, err
    assert "--confirm-gaps kicks ignored: typeA does not run" in stdout


def test_the_compiled_test_decides_as_the_numpy_one(monkeypatch):
    """``confirm._sides_compiled`` (the kernel ``pslog fuse`` runs) against
    ``confirm.sides_test`` (numpy, the test's statement) on the points of every
    confirmation of dirty sessions:
    paper3 at 0.3 px, and a distorting 4-camera ring at 1 px with misses and drops, both
    with spurious blobs (gated, and best-scored without a covariance): the same decisions,
    bit for bit."""
    from _rigs import ring_rig

    import pslog.fusion.confirm as confirm
    from pslog.motion import rally_motion

    calls = []
    tests = confirm._tests_compiled

    def both(*args):  # (session 44: the kernel runs the first camera's test too)
        (rows, time_ns, camera, uv, row, idx, point, cov, gap_s, span_s, sigma, noise_px,
         max_gap_ns, _sides) = args
        cov_k = None if cov is None else np.stack([c[idx] for c in cov], axis=1)
        sides = (rows, time_ns, camera, uv, row[idx], point[idx], cov_k, gap_s[idx],
                 span_s[idx], sigma[idx], noise_px, max_gap_ns)
        calls.append((confirm._sides_compiled(*sides), confirm.sides_test(*sides)))
        return tests(*args)

    monkeypatch.setattr(confirm, "_tests_compiled", both)
    for rig, noise, misses in ((apply_timing(builtin_rig("paper3"), "typeA"), 0.3, 0.0),
                               (ring_rig(4, "lab4"), 1.0, 0.2)):
        det = simulate(rig, rally_motion(7, 6.0), 6.0, SimulationOptions(
            noise_px=noise, seed=44, miss_rate=misses, drop_rate=misses / 2,
            spurious_rate=0.05))[0]
        fuse(det, rig, "typeA", SIDES)
        fuse(det.best(), rig, "typeA", FusionOptions(confirm_every=True, confirm_sides=True,
                                                     noise_px=None))
    assert len(calls) == 4
    assert sum(int(np.count_nonzero(numpy[0])) for _, numpy in calls) > 20
    for (bad, checked), (bad_np, checked_np) in calls:
        assert_array_equal(bad, bad_np)
        assert_array_equal(checked, checked_np)


def test_a_distance_a_camera_proves_leaves_out_what_the_point_covariance_hides(monkeypatch):
    """paper2 (two cameras), the library's rally, 30 fps, misses 0.1 (session 33's dev seed
    37400): a point the residual test passes (its own covariance, overconfident just after
    a kick, widens the bound) that the other camera's side reference shows more than
    ``SIDES_PROVEN_M`` off, beyond that reference's noise."""
    import pslog.fusion.confirm as confirm
    from pslog.motion import rally_motion
    from pslog.simulation import simulate_labelled

    rig = apply_timing(builtin_rig("paper2"), "typeA")
    det, truth, _ = simulate_labelled(rig, rally_motion(5 + 37400 - 300, 8.0), 8.0,
                                      SimulationOptions(noise_px=0.3, seed=37103,
                                                        miss_rate=0.1, drop_rate=0.05))
    sides = fuse(det, rig, "typeA", SIDES)
    assert np.all(errors_m(sides, truth) <= 0.05)
    monkeypatch.setattr(confirm, "SIDES_PROVEN_M", None)
    without = fuse(det, rig, "typeA", SIDES)
    assert np.count_nonzero(errors_m(without, truth) > 0.05) == 1
    assert len(without) - len(sides) == 2  # the far point and one within 5 cm


def test_type_a_explained_makes_the_same_points():
    from pslog.fusion import type_a_explained
    from pslog.fusion._prepare import prepare

    rig, det, _truth, _ = _session()
    obs = det.best()
    explained = type_a_explained(prepare(obs, rig), rig, SIDES)[0]
    plain = fuse(obs, rig, "typeA", SIDES)
    assert_array_equal(explained.time_ns, plain.time_ns)
    assert_array_equal(explained.position_world, plain.position_world)
    assert len(plain) < len(fuse(obs, rig, "typeA", EVERY))


def test_an_extrapolations_gravity_bound_by_hand():
    """``residual_test`` on a pair on one side of the point (``sides_test``'s reference:
    the line through two detections, both before the point, extrapolated): the model bound
    is ``½ g |d_prev d_next|`` (the linear extrapolant's exact error under gravity), where
    ``d_next`` is negative, and the reference's noise ``σ² ((1 − w)² + w²)`` with ``w`` = 2.
    Hand-computed on a camera at the origin looking along z (the session 33 review: the
    ``abs`` was untested; without it the bound shrinks and a point inside it is refused)."""
    from pslog.fusion.confirm import _NO_COV_FACTOR2, CONFIRM_SIGMAS, residual_test
    from pslog.motion import G
    from pslog.records import NS

    f, cx, cy = 800.0, 320.0, 240.0
    rows = np.array([[f, 0.0, cx, f, cy, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.0, 0.0, 0.0]])
    point = np.array([0.1, 0.2, 4.0])
    u0, v0 = f * 0.1 / 4.0 + cx, f * 0.2 / 4.0 + cy  # (340, 280)
    t = 10 * NS
    prev_ns, next_ns = t - 20_000_000, t - 10_000_000  # both before: d_next = -0.01 s
    sigma = 0.5
    w = 0.02 / (0.02 - 0.01)  # 2: an extrapolation
    sigma_r = sigma * np.sqrt((1 - w) ** 2 + w ** 2 + _NO_COV_FACTOR2)  # no covariance
    per_m = f * np.linalg.norm(point) / 16.0
    model = 0.5 * G * abs(0.02 * -0.01) * per_m  # 0.197 px
    bound = CONFIRM_SIGMAS * sigma_r + model
    offsets = np.array([bound - 0.01, CONFIRM_SIGMAS * sigma_r, bound + 0.01])
    k = len(offsets)
    uv = np.column_stack([u0 + offsets, np.full(k, v0)])  # the line constant: u_i = uv
    got = residual_test(rows, np.zeros(k, np.int64), np.tile(point, (k, 1)), None,
                        np.full(k, t), np.full(k, prev_ns), np.full(k, next_ns), uv, uv,
                        np.zeros(k), np.zeros(k), np.full(k, sigma), None)
    assert got.tolist() == [False, False, True]


def _random_call(rng, rows: np.ndarray) -> tuple:
    """Random arguments of ``sides_test``: n observations of a random subset of the cameras
    (some times repeated, some pixels NaN or inf), k points on some of their rows, a
    covariance absent, finite (up to metres), partly NaN or indefinite, the stated noise
    None, 0 or not."""
    m = len(rows)
    n = int(rng.integers(0, 50))
    k = int(rng.integers(0, n + 1)) if n else 0
    step = rng.integers(1, 20_000_000, n)
    step[rng.random(n) < 0.1] = 0
    time_ns = np.cumsum(step).astype(np.int64)
    camera = rng.choice(rng.choice(m, int(rng.integers(1, m + 1)), replace=False), n)
    uv = rng.normal(500.0, 200.0, (n, 2))
    uv[rng.random((n, 2)) < rng.choice([0.0, 0.05, 0.3])] = np.nan
    if n and rng.random() < 0.3:
        uv[rng.integers(0, n)] = np.inf
    e = np.sort(rng.choice(n, k, replace=False)) if k else np.zeros(0, dtype=np.int64)
    point = rng.normal([0.0, 0.0, 0.5], [3.0, 2.0, 0.5], (k, 3))
    kind = rng.integers(0, 4)
    cov = None if kind == 0 else np.abs(rng.normal(0.0, 10 ** rng.uniform(-6, 0.5), (k, 6)))
    if kind == 2:
        cov[rng.random(k) < 0.3] = np.nan
    elif kind == 3:
        cov[:, 3:] = rng.normal(0.0, 1e-3, (k, 3))
    gap_s, span_s = np.abs(rng.normal(0.01, 0.01, k)), np.abs(rng.normal(0.03, 0.02, k))
    sigma = np.abs(rng.normal(0.5, 0.3, k))
    noise = [None, 0.0, 0.3, 1.0][int(rng.integers(0, 4))]
    max_gap_ns = int(rng.choice([10_000_000, 40_000_000, 3_600 * 10**9]))
    return (rows, time_ns, camera, uv, e, point, cov, gap_s, span_s, sigma, noise, max_gap_ns)


def test_the_compiled_test_decides_as_the_numpy_one_on_any_input(monkeypatch):
    """(session 35's review) ``confirm._sides_compiled`` against ``confirm.sides_test`` on
    random inputs the sessions above never make: no point, one camera, a camera without
    rows, repeated times, NaN and infinite pixels, a NaN or indefinite covariance, the stated
    noise None or 0, the module's switches changed (``SIDES_NEARER`` off, ``SIDES_PROVEN_M``
    None or 0, ``CONFIRM_SIGMAS`` 2): the same decisions, bit for bit, and each switch
    reaching the kernel (it changes some decision)."""
    import pslog.fusion.confirm as confirm

    rows = confirm._camera_rows(apply_timing(builtin_rig("paper3"), "typeA"))
    rng = np.random.default_rng(45035)
    changed = dict.fromkeys(("nearer", "proven", "sigmas"), False)
    n_bad = n_points = 0
    for _ in range(400):
        args = _random_call(rng, rows)
        nearer, proven, sigmas = (bool(rng.random() < 0.7), [None, 0.0255, 0.0][
            int(rng.integers(0, 3))], float(rng.choice([4.0, 2.0])))
        results = []
        for switches in ((nearer, proven, sigmas), (not nearer, proven, sigmas),
                         (nearer, None if proven is not None else 0.0255, sigmas),
                         (nearer, proven, 6.0 - sigmas)):
            for name, value in zip(("SIDES_NEARER", "SIDES_PROVEN_M", "CONFIRM_SIGMAS"),
                                   switches, strict=True):
                monkeypatch.setattr(confirm, name, value)
            bad, checked = confirm._sides_compiled(*args)
            bad_np, checked_np = confirm.sides_test(*args)
            assert_array_equal(bad, bad_np)
            assert_array_equal(checked, checked_np)
            results.append(bad_np)
        for key, other in zip(changed, results[1:], strict=True):
            changed[key] |= not np.array_equal(results[0], other)
        n_bad += int(np.count_nonzero(results[0]))
        n_points += len(results[0])
    assert all(changed.values()), changed
    assert 0 < n_bad < n_points


def test_confirm_every_alone_is_the_same_test_offline_as_bare(tmp_path):
    """(session 35's review) ``FusionOptions(confirm_every=True)`` is ``--confirm-gaps all``
    (every point against the next camera's interpolation) in :func:`pslog.fusion.fuse`, as
    it was in every entry before session 35; :func:`pslog.fuse` of the session made it
    ``kicks`` (``confirm_sides`` None read as ``confirm_every``): the same options, other
    points. An explicit ``confirm_every`` leaves ``confirm_sides`` None off everywhere."""
    import pslog
    from pslog.fusion import for_session
    from pslog.log import SessionWriter

    rig, det, _truth, _ = _session()
    path = tmp_path / "rally.mcap"
    with SessionWriter(path, rig, timing="typeA", source="test") as writer:
        writer.add_detections(det)
    every = FusionOptions(confirm_every=True)
    bare = fuse(det, rig, "typeA", every)
    assert len(bare) > len(fuse(det, rig, "typeA", SIDES))
    for got in (pslog.fuse(path, methods=["typeA"], options=every)["typeA"],
                pslog.fuse(det, methods=["typeA"], rig=rig, options=every)["typeA"]):
        assert_array_equal(got.time_ns, bare.time_ns)
        assert_array_equal(got.position_world, bare.position_world)
    assert for_session(every, {}).confirm_sides is False
    assert for_session(FusionOptions(confirm_every=False), {}).confirm_sides is False
    assert for_session(FusionOptions(), {}).confirm_sides is True


def test_pslog_fuse_preloads_the_compiled_test_in_the_signature_it_runs():
    """(session 35's review) The kick test is ``pslog fuse``'s default but its kernel module
    was not among typeA's preloaded kernels: its cache load (~20 ms) fell on type A's way.
    Now preloaded, in the signature a session's call uses (no other one loaded after)."""
    import pslog.fusion.confirm as confirm
    from pslog.fusion import METHODS
    from pslog.fusion._confirm_kernel import _preload, confirm_kernel

    assert "pslog.fusion._confirm_kernel" in METHODS["typeA"].kernels
    _preload()
    loaded = list(confirm_kernel.signatures)
    assert len(loaded) >= 1
    calls = []
    compiled = confirm._tests_compiled

    def spy(*args):
        calls.append(args)
        return compiled(*args)

    rig, det, _truth, _ = _session()
    try:
        confirm._tests_compiled = spy
        fuse(det, rig, "typeA", SIDES)
        fuse(det.best(), rig, "typeA", FusionOptions(confirm_every=True, confirm_sides=False,
                                                     noise_px=None))
    finally:
        confirm._tests_compiled = compiled
    assert len(calls) == 2
    # (every array handed read-only, whatever the caller's: one signature; session 44)
    assert list(confirm_kernel.signatures) == loaded
