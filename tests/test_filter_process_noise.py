"""The filter's process-noise adaptation by hand (docs/methods.md, "Process noise adaptation"):
after an accepted update of camera ``c`` whose previous accepted innovation ``y'`` (within
``max_gap_s``) is known,

    r = clip(y'ᵀ S⁻¹ y, −4, 4),   q ← clip(q · exp(η (r − r₀)), q_min, q_max),

``η`` = 0.5, ``r₀`` = 0.4, ``S`` and ``y`` the current update's; the update itself is made
with the ``q`` before. Two EKF steps of one camera computed here with numpy, the filter's
``q`` after each compared."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pslog.estimation.projection import project_with_jacobian
from pslog.fusion.filter import BallFilter, FilterOptions
from pslog.motion import G
from pslog.records import NS
from pslog.rig import builtin_rig

SIGMA = 0.4
Q_FLOOR, Q_START = 0.3, 2.0


def _step(x, P, dt, q, z, cam):
    """One ballistic EKF step (drag-free, this test's options): prediction, then update."""
    a = np.array([0.0, 0.0, -G])
    x = np.concatenate([x[:3] + x[3:] * dt + 0.5 * a * dt**2, x[3:] + a * dt])
    F = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    Q = q * np.block([[dt**3 / 3 * np.eye(3), dt**2 / 2 * np.eye(3)],
                      [dt**2 / 2 * np.eye(3), dt * np.eye(3)]])
    P = F @ P @ F.T + Q
    h, J = project_with_jacobian(cam, x[:3][None])
    H = np.hstack([J[0], np.zeros((2, 3))])
    S = H @ P @ H.T + SIGMA**2 * np.eye(2)
    y = z - h[0]
    K = P @ H.T @ np.linalg.inv(S)
    return x + K @ y, P - K @ S @ K.T, y, np.linalg.inv(S)


@pytest.mark.parametrize("lag_m", [0.004, -0.004])
def test_q_follows_the_product_of_a_cameras_consecutive_innovations(lag_m):
    rig = builtin_rig("paper3")
    cam = rig.cameras[1]
    options = FilterOptions(noise_px=SIGMA, accel_psd=Q_FLOOR, drag_per_m=0.0, adapt_rate=0.0,
                            model_switch_per_s=0.0, turn_switch_per_s=0.0, max_std_m=None)
    flt = BallFilter(rig, options)
    P0 = np.diag([4e-6, 4e-6, 4e-6, 0.04, 0.04, 0.04])
    x0 = np.array([1.5, 1.0, 1.2, 2.0, -0.5, 1.0])
    t = [1 * NS, 1 * NS + 11_111_111, 1 * NS + 22_222_222]
    flt.set_state(t[0], x0[:3], x0[3:], P0)
    flt._q = Q_START
    # detections a few mm off the predictions, the same way both times (a lag: r > 0) or
    # opposite ways (r < 0)
    x, P, q = x0, P0, Q_START
    previous = None
    for k, sign in ((1, 1.0), (2, 1.0 if lag_m > 0 else -1.0)):
        dt = (t[k] - t[k - 1]) / NS
        predicted = x[:3] + x[3:] * dt + 0.5 * np.array([0, 0, -G]) * dt**2
        z = cam.project(predicted[None] + sign * abs(lag_m) * np.array([[1.0, 0.6, 0.0]]))[0][0]
        x, P, y, Si = _step(x, P, dt, q, z, cam)
        flt.push(t[k], 1, *z)
        if previous is not None:  # the camera's previous accepted innovation is known
            r = min(max(float(previous @ Si @ y), -4.0), 4.0)
            q = min(max(q * math.exp(0.5 * (r - 0.4)), Q_FLOOR), 100.0)
            assert (r > 0.4) == (lag_m > 0)
        previous = y
        _, x_f, P_f = flt.state()
        np.testing.assert_allclose(x_f, x, rtol=0, atol=1e-10)
        np.testing.assert_allclose(P_f, P, rtol=1e-9, atol=1e-15)
        assert flt._q == pytest.approx(q, rel=1e-12)
    assert flt._q != Q_START  # it moved: up on a lag, down towards the floor otherwise
