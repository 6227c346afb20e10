"""Issue 12, session 25: the shared-instant methods' tests (``sync``'s N-view residual test,
``typeB`` / ``linear``'s prediction test; session 24) made faster with the same bits.

- ``stereo.refusal_noise``: each window's lower quartile by one compiled pass
  (``_stereo_kernel.window_quartiles``) instead of a numpy partition per window in a Python
  loop, and the residuals of every camera by one pass made once per Prepared
  (``_stereo_kernel.residual_norms_cameras``) instead of one per camera and one over all,
  per call; against the numpy reference (``compiled=False``), bit for bit;
- ``stereo.residual_refused``: the reprojection-weighted Gauss-Newton step
  (``_weighted_points``) only for the points whose unweighted ``d²`` exceeds the bound
  (``min(d², d²_w)`` cannot exceed it where ``d²`` does not), and the residuals
  ``nview_points`` made reused, and its sums (``d²``, the tolerance's allowance, the rays
  used) in one compiled pass (``_stereo_kernel.residual_sums``); against every point's
  step, the residuals made again and the sums with numpy (``every_step=True``,
  ``compiled=False``): the same decisions, the sums and each weighted point the bits they
  have among all.
"""

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
from pslog.fusion import stereo as S
from pslog.fusion._prepare import default_max_gap_s
from pslog.fusion.pseudo import no_detection_limits, residual_norms
from pslog.records import NS

LENS = (-0.25, 0.08, 0.001, -0.001, 0.0)


def _dirty(timing: str, lens, seed: int, real_px: float = 0.5, outliers: float = 0.03,
           motion: str = "rally", duration: float = 6.0, damaged: bool = True,
           rig: Rig | None = None):
    """(rig, observations): missed detections, dropped frames, jitter, outliers a few
    pixels off (some refused, some only by the unweighted intersection) and damaged pixels
    (1e300 and NaN: no ray, no residual; the first detection among them). ``rig``: this
    one (with ``timing``), else paper3 (with ``lens``, or none)."""
    rig = apply_timing(rig or builtin_rig("paper3"), timing)
    if lens is not None:
        rig = Rig(tuple(c.replace(dist=np.array(lens)) for c in rig.cameras), rig.name)
    det, _ = simulate(rig, get_motion(motion), duration,
                      SimulationOptions(noise_px=real_px, miss_rate=0.2, drop_rate=0.05,
                                        jitter_s=2e-4, seed=seed))
    obs = det.best()
    rng = np.random.default_rng(seed)
    uv = obs.uv.copy()
    off = rng.random(len(obs)) < outliers
    uv[off] += rng.normal(0.0, 8.0, (int(off.sum()), 2))
    if damaged:
        uv[0::53], uv[11::61] = 1e300, np.nan
    return rig, Observations(obs.time_ns, obs.camera, uv, obs.frame_index)


def test_window_quartiles_kernel_selects_numpys_element():
    """Random residuals with ties (rounded values, repeated times) in windows from empty to
    hundreds, ends inside, before and after the data: the compiled pass gives the element
    numpy's partition gives (and NaN under ``min_count``), and so does its Python
    original."""
    rng = np.random.default_rng(5)
    for trial in range(40):
        n = int(rng.integers(0, 400))
        t = np.sort(rng.integers(0, 4 * NS, n)).astype(np.int64)
        t[1::7] = t[:-1:7][: len(t[1::7])]  # repeated times
        t = np.sort(t)
        v = np.round(rng.rayleigh(1.0, n), 1 if trial % 2 else 6)
        ends = np.unique(rng.integers(-NS, 6 * NS, 50)).astype(np.int64)
        for min_count in (1, 4, 16):
            want = S._window_quartiles(t, v, ends, min_count, compiled=False)
            got = S._window_quartiles(t, v, ends, min_count)
            assert got.tobytes() == want.tobytes(), (trial, min_count)
    assert np.isfinite(want).any() and np.isnan(want).any()
    out = np.empty(len(ends))
    _stereo_kernel.window_quartiles.py_func(t, v, ends, NS, 4, np.empty(len(t)), out)
    np.testing.assert_array_equal(out / S.RAYLEIGH_QUARTILE,
                                  S._window_quartiles(t, v, ends, 4, compiled=False))


@pytest.mark.parametrize("lens", [None, LENS])
def test_every_cameras_residuals_in_one_pass_are_each_cameras_own(lens):
    """One pass over every camera's detections with each residual's camera: camera c's rows
    are the residuals of a pass over camera c's detections alone, and all of them the
    pooled pass's, bit for bit (damaged pixels among them: no residual)."""
    rig, obs = _dirty("typeB", lens, 2)
    prep = prepare(obs, rig)
    gap = default_max_gap_s(prep)
    t_all, v_all, c_all = S._refusal_residuals(prep, gap)
    limits = no_detection_limits(prep.cameras)
    pooled = residual_norms(obs.time_ns, obs.camera, obs.uv, limits, gap)
    assert t_all.tobytes() == pooled[0].tobytes() and v_all.tobytes() == pooled[1].tobytes()
    for c in range(len(rig.cameras)):
        own = np.flatnonzero(obs.camera == c)
        t, v = residual_norms(obs.time_ns[own], obs.camera[own], obs.uv[own], limits, gap)
        assert len(t) > 50
        assert t_all[c_all == c].tobytes() == t.tobytes()
        assert v_all[c_all == c].tobytes() == v.tobytes()
    assert S._refusal_residuals(prep, gap)[1] is v_all  # (made once per Prepared)
    n = len(obs)
    t_out, v_out, c_out = np.empty(n, np.int64), np.empty(n), np.empty(n, np.int64)
    j = _stereo_kernel.residual_norms_cameras.py_func(
        np.ascontiguousarray(obs.time_ns), np.ascontiguousarray(obs.camera, dtype=np.int64),
        np.ascontiguousarray(obs.uv), limits, len(limits), int(gap * NS), NS,
        t_out, v_out, c_out)
    np.testing.assert_array_equal(v_out[:j], v_all)
    np.testing.assert_array_equal(c_out[:j], c_all)


@pytest.mark.parametrize("timing,lens", [("typeB", None), ("sync", LENS), ("typeB", LENS)])
@pytest.mark.parametrize("noise_px", [0.5, None])
def test_refusal_noise_compiled_equals_the_numpy_reference(timing, lens, noise_px):
    """Each camera's σ at every detection's time (the start's pooled and per-camera
    estimates included) and at each detection's own camera, the compiled way and the
    reference, bit for bit, and between the floor and checkpoints' estimates."""
    rig, obs = _dirty(timing, lens, 4)
    prep = prepare(obs, rig)
    gap = default_max_gap_s(prep)
    times = obs.time_ns[::2]
    want = S.refusal_noise(prep, times, gap, noise_px, compiled=False)
    got = S.refusal_noise(prepare(obs, rig), times, gap, noise_px)
    assert got.tobytes() == want.tobytes()
    # measured (checkpoints every 0.25 s, each camera's own), not the floor alone; and the
    # start's estimates in the first second (the windows up to each point's own time)
    assert len(np.unique(want)) > 40
    first = times < times[0] + NS
    assert len(np.unique(want[first])) > 10
    cams = obs.camera[::2]
    want = S.refusal_noise(prep, times, gap, noise_px, cams, compiled=False)
    assert S.refusal_noise(prep, times, gap, noise_px, cams).tobytes() == want.tobytes()
    one = cams == 1
    assert S.refusal_noise(prep, times[one], gap, noise_px, cams[one]).tobytes() \
        == want[one].tobytes()


def _test_arguments(rig, obs, noise_px=0.5):
    """residual_refused's arguments as stereo_at_common_instants makes them, and the
    residuals nview_points made."""
    prep = prepare(obs, rig)
    gap = default_max_gap_s(prep)
    group, n_cameras = S.sync_groups(prep.obs, len(prep.centers), 1e-3)
    residuals: list[np.ndarray] = []
    points, _, time_ns, _, flags, rows, used = S.triangulate_groups(
        prep, group, len(n_cameras), noise_px, with_flags=True, with_rows=True,
        residuals_out=residuals)
    at = np.flatnonzero((n_cameras >= 2) & (flags == 0) & np.all(np.isfinite(points), axis=1))
    sigma = S.refusal_noise(prep, time_ns[at], gap, noise_px)
    return ((prep, rows[at], used[at], points[at], time_ns[at], sigma, gap),
            [r[at] for r in residuals])


@pytest.mark.parametrize("seed,real_px,lens", [(1, 2.0, None), (5, 2.0, None), (5, 0.5, LENS)])
def test_residual_test_with_the_step_where_needed_decides_as_with_every_step(
        monkeypatch, seed, real_px, lens):
    """The weighted step made only for the points whose unweighted d² exceeds the bound,
    and the residuals nview_points made reused: the same refused points as every point's
    step with the residuals made again; among those sessions, points the unweighted d²
    alone would refuse and the step keeps (the step's reason), and points refused."""
    rig, obs = _dirty("sync", lens, seed, real_px, damaged=False)
    args, residuals = _test_arguments(rig, obs)
    want = S.residual_refused(*args, every_step=True, compiled=False)
    stepped: list[int] = []
    original = S._weighted_points

    def spy(*a, **kw):
        out = original(*a, **kw)
        stepped.append(len(out))
        return out

    monkeypatch.setattr(S, "_weighted_points", spy)
    got = S.residual_refused(*args, residuals=residuals)
    assert got.tobytes() == want.tobytes()
    assert S.residual_refused(*args).tobytes() == want.tobytes()
    # a few points stepped, more than are refused: the step kept some
    assert 0 < want.sum() < stepped[0] < len(want) // 5


@pytest.mark.parametrize("rig_name", ["paper3", "lab3"])
def test_weighted_points_of_some_rows_have_their_bits_among_all(rig_name):
    """Each row's weighted point made among some rows (single rows, random subsets, the rows
    without one camera's ray) has the bits it has among all rows, the first detection
    without a ray (the row an unused slot's clipped index reads: no NaN point since
    session 26, ``tests/test_first_row_no_ray.py``). lab3's optical axes have no zero
    component: a one-row depth product ``(1, 3) @ (3,)`` is not the (k, 3) one's BLAS
    call, and differs in the last bit for some rows (paper3's: a zero component, the same
    bits)."""
    from _rigs import lab3_rig

    rig, obs = _dirty("sync", None, 6, damaged=False,
                      rig=lab3_rig() if rig_name == "lab3" else None)
    uv = obs.uv.copy()
    uv[0] = 1e300  # (the first detection: no ray; the row an unused slot reads)
    (prep, rows, used, points, _, sigma, _), _ = _test_arguments(
        rig, Observations(obs.time_ns, obs.camera, uv, obs.frame_index))
    full = S._weighted_points(prep, rows, used, points, sigma)
    assert np.isfinite(full).all() and len(full) > 50
    rng = np.random.default_rng(0)
    subsets = [np.array([i]) for i in range(len(rows))]
    subsets += [np.sort(rng.choice(len(rows), size, replace=False)) for size in (2, 3, 17, 100)]
    subsets += [np.flatnonzero(~used[:, c]) for c in range(used.shape[1])]
    for at in subsets:
        assert len(at)
        got = S._weighted_points(prep, rows, used, points, sigma, at)
        assert got.tobytes() == full[at].tobytes(), at[:5]


@pytest.mark.parametrize("lens", [None, LENS])
def test_residual_sums_compiled_equal_numpys(lens):
    """d², the tolerance's allowance Σ e_c²/σ_c² (slots with and without a previous
    detection: the image speed measured or the unknown one) and the rays used, compiled
    and with numpy, bit for bit; from nview_points' residuals and made again; the kernel's
    Python original the same."""
    from pslog.fusion.innovation import previous_next_rows

    rig, obs = _dirty("sync", lens, 2)
    args, residuals = _test_arguments(rig, obs)
    prep, rows, used, _, time_ns, sigma, gap = args
    want = S._refusal_sums(*args, None, compiled=False)
    for given in (None, residuals):
        got = S._refusal_sums(*args, given)
        for a, b in zip(got, want, strict=True):
            assert a.tobytes() == b.tobytes()
    d2, e2, n = want
    assert np.isfinite(d2).all() and np.isfinite(e2).sum() > 100 and len(np.unique(n)) >= 2
    # a used slot without a residual (its point behind that camera): d² infinite
    behind = [r.copy() for r in residuals]
    behind[1][np.flatnonzero(used[:, 1])[::9]] = np.nan
    want_behind = S._refusal_sums(*args, behind, compiled=False)
    assert np.isinf(want_behind[0]).sum() > 5
    for a, b in zip(S._refusal_sums(*args, behind), want_behind, strict=True):
        assert a.tobytes() == b.tobytes()
    # both branches of the allowance: the shift measured, and the unknown speed's
    blind = np.array([[r >= 0 and previous_next_rows(prep)[0][r] < 0 for r in row]
                      for row in np.where(used, rows, -1)])
    assert blind.any() and (~blind & used).any()
    k = len(rows)
    out = (np.zeros(k), np.zeros(k), np.empty(k, dtype=np.int64))
    _stereo_kernel.residual_sums.py_func(
        rows, used, np.array(residuals), sigma, time_ns, prep.obs.time_ns,
        prep.uv_undistorted, previous_next_rows(prep)[0], used.any(axis=0),
        int(gap * NS) / NS, float(NS), S.UNKNOWN_IMAGE_SPEED_PX_S, *out)
    for a, b in zip(out, want, strict=True):
        np.testing.assert_array_equal(a, b)


_WARMED = """
import sys
from pslog.fusion import _stereo_kernel, fuse
from pslog.log import SessionWriter
from pslog.motion import rally_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate
from pslog.timing import observations
from pslog.warm import _shared_instant_tests

kernels = (_stereo_kernel.window_quartiles, _stereo_kernel.residual_norms_cameras,
           _stereo_kernel.residual_sums)
rig = apply_timing(builtin_rig("paper3"), "typeA")
detections, _ = simulate(rig, rally_motion(seed=1, duration=1.0), 1.0,
                         SimulationOptions(noise_px=0.3, seed=2))
with SessionWriter(sys.argv[1], rig) as w:
    w.add_detections(detections)
_shared_instant_tests(sys.argv[1])
print(*(len(k.signatures) for k in kernels))
for timing, methods in (("sync", ("sync",)), ("typeB", ("typeB", "linear"))):
    rig = apply_timing(builtin_rig("paper3"), timing)
    detections, _ = simulate(rig, rally_motion(seed=1, duration=1.0), 1.0,
                             SimulationOptions(noise_px=0.3, seed=2))
    for method in methods:
        fuse(observations(detections, rig), rig, method)  # (read-only columns)
print(*(len(k.signatures) for k in kernels))
"""


def test_warm_compiles_the_tests_kernels_in_the_signatures_fuse_uses(tmp_path):
    """``python -m pslog.warm`` runs the shared-instant tests on its type-A session's rows
    (no default method reaches them): each kernel in the one signature that ``sync``,
    ``typeB`` and ``linear`` then load (none compiled again at a user's first fuse)."""
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-c", _WARMED, str(tmp_path / "s.mcap")],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split("\n")[:2] == ["1 1 1", "1 1 1"]
