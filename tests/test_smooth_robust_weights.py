"""``smooth``'s robust loss is the Cauchy kernel of docs/estimation.md, term (1):
``ρ(s) = c² log(1 + s / c²)``, ``s = ‖r‖² / σ²``, ``c = 3``, whose iteratively reweighted
Gauss–Newton weight is ``ρ'(s) = 1 / (1 + s / c²)``: one scale σ for every detection, a
detection 3σ off counts half. Checked on a fit's own output (its residuals, weights and the
σ it reports), against the formula written here."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose

from pslog.estimation import fit_trajectory
from pslog.motion import get_motion
from pslog.records import Observations
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate

C = 3.0


def test_the_weights_are_the_cauchy_kernels_derivative_at_one_scale():
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    detections, _ = simulate(rig, get_motion("throw"), None,
                             SimulationOptions(noise_px=0.4, seed=5))
    obs = detections.best()
    uv = obs.uv.copy()
    # detections pushed 1, 2, 3, 5 and 40 pixels off (across the range of the kernel)
    rows = np.arange(20, len(obs) - 20, max(1, (len(obs) - 40) // 10))[:10]
    push = np.array([1.0, 2.0, 3.0, 5.0, 40.0, 1.0, 2.0, 3.0, 5.0, 40.0])[:len(rows)]
    uv[rows, 0] += push
    fit = fit_trajectory(Observations(obs.time_ns, obs.camera, uv, obs.frame_index), rig)
    used = fit.used & np.isfinite(fit.residual_px)
    assert used.sum() > 50
    sigma = fit.trajectory.noise_px
    s = (fit.residual_px[used] / sigma) ** 2
    assert_allclose(fit.weight[used], 1.0 / (1.0 + s / C**2), rtol=1e-9)
    # 40 px off counts for nearly nothing; Gaussian residuals (s ~ χ²₂, median 2 ln 2) for
    # about 1 / (1 + 1.39 / 9) = 0.87
    assert fit.weight[rows][push == 40.0].max() < 0.01
    assert 0.8 < np.median(fit.weight[used]) < 0.95
