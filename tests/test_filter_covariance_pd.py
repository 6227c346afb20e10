"""The filter's covariance update is the standard form ``P⁻ − K S Kᵀ``, not Joseph's
(docs/methods.md, "Measurement model and Jacobian"): in exact arithmetic the same for the
optimal gain, without Joseph's guard against rounding. This checks what that guard would be
for: the raw covariances of the pair (6 x 6) and of the turn model (7 x 7) stay symmetric
and positive definite after every detection, on flights, a rally's bounces and kicks, and
turning motions, noise-free and noisy."""

from __future__ import annotations

import numpy as np
import pytest

from pslog.fusion import filter as F
from pslog.motion import get_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate


@pytest.mark.parametrize("timing", ["typeA", "typeB"])
def test_the_filters_covariances_stay_positive_definite(timing):
    rig = apply_timing(builtin_rig("paper3"), timing)
    checked = 0
    for motion in ("rally", "spiral", "turntable"):
        for noise, seed in ((0.0, 1), (1.0, 3)):
            det, _ = simulate(rig, get_motion(motion), None,
                              SimulationOptions(noise_px=noise, seed=seed, miss_rate=0.05))
            obs = det.best()
            flt = F.BallFilter(rig)
            for t, c, (u, v) in zip(obs.time_ns.tolist(), obs.camera.tolist(),
                                    obs.uv.tolist(), strict=True):
                flt.push(t, c, u, v)
                if not flt._I[F._IHAS]:
                    continue
                P = flt._S[F._SP:F._SP + 36].reshape(6, 6)
                assert np.array_equal(P, P.T)
                assert np.linalg.eigvalsh(P)[0] > 0, (motion, noise, t)
                checked += 1
                if flt._S[F._SNU] > 0:  # the turn model is in the set
                    Pt = flt._S[F._SPT:F._SPT + 49].reshape(7, 7)
                    assert np.linalg.eigvalsh(0.5 * (Pt + Pt.T))[0] > 0, (motion, noise, t)
    assert checked > 1000
