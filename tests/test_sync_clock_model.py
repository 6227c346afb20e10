"""``pslog sync``'s clock parametrisation is the timing model of :mod:`pslog.timing`.

The estimator (:class:`pslog.estimation.sync._Clocks`) works on

    τ = ℓ + o'_c + d_c · 1e-6 · (ℓ − ℓ_m) + r_c · (v / h_c − 1/2),
    o'_c = o_c + d_c · 1e-6 · ℓ_m + (r_c − r_1) / 2,

which must be the rig's model ``t = ℓ + o_c + d_c · 1e-6 · ℓ + r_c · v / h_c``
(:func:`pslog.timing.true_times_s`) less the common shift ``r_1 / 2`` (docs/timing.md, "What
pslog sync estimates"): else the estimator would fit one model and the readers correct by
another. Checked by hand on one camera, then on many random detections against the timing
module's own function, with the affine map back and its Jacobian."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from pslog.estimation.sync import PARAMETERS, _Clocks
from pslog.records import NS, Observations
from pslog.rig import Rig, builtin_rig
from pslog.timing import true_times_s


def _rig(readout1=0.010, cam2=(0.002, 10.0, 0.020), cam3=(-0.004, -25.0, 0.0)) -> Rig:
    cams = builtin_rig("paper3").cameras
    o2, d2, r2 = cam2
    o3, d3, r3 = cam3
    return Rig((cams[0].replace(readout=readout1),
                cams[1].replace(clock_offset=o2, clock_drift_ppm=d2, readout=r2),
                cams[2].replace(clock_offset=o3, clock_drift_ppm=d3, readout=r3)), "clocks")


def _unknowns(n_cams: int = 3):
    # as estimate_clocks names them: camera 1's offset and drift are never unknowns
    return [(c, p) for c in range(n_cams) for p in PARAMETERS
            if not (c == 0 and p in ("offset", "drift"))]


def _rig_values(rig: Rig, unknowns) -> np.ndarray:
    key = {"offset": "clock_offset", "drift": "clock_drift_ppm", "readout": "readout"}
    return np.array([float(getattr(rig.cameras[c], key[p])) for c, p in unknowns])


def test_the_internal_offset_of_one_camera_by_hand():
    # ℓ_m = 5 s; camera 2: offset 2 ms, drift 10 ppm, readout 20 ms; camera 1's readout 10 ms:
    # o'_2 = 0.002 + 10e-6 · 5 + (0.020 - 0.010) / 2 = 0.00705 s
    rig = _rig()
    unknowns = _unknowns()
    clocks = _Clocks(rig, unknowns, 5.0)
    inner = dict(zip(unknowns, clocks.to_internal(_rig_values(rig, unknowns)), strict=True))
    assert inner[(1, "offset")] == pytest.approx(0.00705, abs=1e-15)
    # camera 3: -0.004 + (-25e-6) · 5 + (0 - 0.010) / 2 = -0.009125 s
    assert inner[(2, "offset")] == pytest.approx(-0.009125, abs=1e-15)
    assert inner[(1, "drift")] == 10.0 and inner[(2, "readout")] == 0.0
    # a detection of camera 2 logged at 7 s on row 360 of 480:
    # τ = 7 + 0.00705 + 10e-6 · (7 - 5) + 0.020 · (360/480 - 1/2) = 7.01207 s
    # and the rig's model: 7 + 0.002 + 10e-6 · 7 + 0.020 · 0.75 = 7.01707 = τ + r_1 / 2
    obs = Observations.from_unsorted([7 * NS], [1], [[100.0, 360.0]])
    tau = clocks.times(obs, clocks.to_internal(_rig_values(rig, unknowns)))
    assert tau[0] == pytest.approx(7.01207, abs=1e-12)
    assert tau[0] + 0.010 / 2 == pytest.approx(7.01707, abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_estimators_times_are_the_timing_models_less_half_camera_1s_readout(seed):
    rng = np.random.default_rng(seed)
    rig = _rig(readout1=rng.uniform(0.0, 0.03),
               cam2=(rng.uniform(-0.01, 0.01), rng.uniform(-80, 80), rng.uniform(0, 0.03)),
               cam3=(rng.uniform(-0.01, 0.01), rng.uniform(-80, 80), rng.uniform(0, 0.03)))
    time_ns = np.unique(rng.integers(10**9, 130 * 10**9, 500))  # up to 130 s
    n = len(time_ns)
    cam = rng.integers(0, 3, n)
    uv = np.stack([rng.uniform(0, 640, n), rng.uniform(0, 480, n)], axis=1)
    obs = Observations.from_unsorted(time_ns, cam, uv)
    logged = obs.time_ns / NS
    l_mid = 0.5 * float(logged.min() + logged.max())
    unknowns = _unknowns()
    clocks = _Clocks(rig, unknowns, l_mid)
    theta = clocks.to_internal(_rig_values(rig, unknowns))
    c = obs.camera
    height = np.array([float(k.height) for k in rig.cameras])[c]
    offset = np.array([k.clock_offset for k in rig.cameras])[c]
    drift = np.array([k.clock_drift_ppm for k in rig.cameras])[c]
    readout = np.array([k.readout for k in rig.cameras])[c]
    expected = true_times_s(logged, obs.uv[:, 1], height, offset, drift, readout)
    assert_allclose(clocks.times(obs, theta), expected - rig.cameras[0].readout / 2,
                    rtol=0, atol=1e-12)
    # the map back is the inverse, and affine: its matrix is its finite difference
    assert_allclose(clocks.to_external(theta), _rig_values(rig, unknowns), rtol=0, atol=1e-15)
    M = clocks.to_external_matrix()
    step = rng.normal(size=len(theta)) * 1e-3
    assert_allclose(clocks.to_external(theta + step) - clocks.to_external(theta), M @ step,
                    rtol=0, atol=1e-12)
    # ∂τ/∂(o', d, r) = [1, 1e-6 (ℓ - ℓ_m), v/h - 1/2]: central differences of the times
    jac = clocks.jacobian(logged, obs.uv[:, 1], c)
    for j, (cam_j, name) in enumerate(unknowns):
        h = np.zeros(len(theta))
        h[j] = 1e-4 if name != "drift" else 1.0
        diff = (clocks.times(obs, theta + h) - clocks.times(obs, theta - h)) / (2 * h[j])
        column = jac[:, PARAMETERS.index(name)] * (c == cam_j)
        assert_allclose(diff, column, rtol=1e-6, atol=1e-9)
