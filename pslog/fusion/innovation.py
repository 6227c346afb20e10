"""Type A's innovation test: a point whose prediction the newest detection contradicts.

Type A's output ``P'_t`` (eqs. (2)-(4) of the paper) takes its depth along the newest
viewing ray from the linear prediction ``P̂_t = P_{t-1} + ρ (P_{t-1} - P_{t-2})``,
``ρ = δ_pred / δ_prev``. Across a kick or a bounce (a change of motion between the past
points and the newest detection), and all the more across the long gaps a blind camera
leaves, the prediction is wrong, and eq. (4) puts the point at the wrong depth: the
newest camera cannot see a depth error, but it does see the prediction's error across
its ray. The *innovation* ``r`` (pixels, in the recorded image) is the distance between the
newest detection and the projection of ``P̂_t``; under the model (ballistic motion between
the three instants, Gaussian detection noise ``σ`` per image axis) it is

- noise: each past point, triangulated from detections, projects into the newest camera
  with an error of about ``σ`` per axis; ``P̂_t`` combines them with weights ``1 + ρ`` and
  ``ρ``, and the newest detection adds its own, so ``σ_r = σ √(1 + (1 + ρ)² + ρ²)`` per axis;
- model: eq. (2) extrapolates linearly; under a constant acceleration ``a`` its error is
  exactly ``½ a δ_pred (δ_pred + δ_prev)`` (the remainder of linear interpolation through
  ``t-2`` and ``t-1`` evaluated at ``t``), at most ``½ g δ_pred (δ_pred + δ_prev)`` for a
  ball in flight, ``f / depth`` pixels per metre in the newest camera.

The point is refused when ``r > k σ_r + e_model`` with ``k = 5``: for a Gaussian 2D error
``P(|r| > k σ_r) = exp(-k² / 2) ≈ 4e-6``, so under the model (and the stated noise) a valid
point is essentially never refused; the test fires when the model failed — the motion
changed inside the prediction's interval — which is what it is for. It is the innovation
test a Kalman filter applies to each measurement (Bar-Shalom, Li and Kirubarajan, *Estimation
with Applications to Tracking and Navigation*, 2001, ch. 5.4), applied to eq. (2)'s
prediction. docs/methods.md, "Type A's prediction test", has the figures.
"""

from __future__ import annotations

import numpy as np

from ..motion import G
from ..records import NS

#: Refuse a prediction whose innovation exceeds this many standard deviations (plus the
#: model bound): a Gaussian 2D innovation does with probability exp(-K²/2) ~ 4e-6.
INNOVATION_SIGMAS = 5.0
#: The detection noise assumed when the caller gives none (FusionOptions' default).
DEFAULT_NOISE_PX = 0.5


def failed_predictions(prep, events: np.ndarray, j1: np.ndarray, j2: np.ndarray,
                       predicted: np.ndarray, innovation_px: np.ndarray,
                       noise_px: float | None) -> np.ndarray:
    """Which type A points the newest detection contradicts (module docstring).

    Parameters
    ----------
    prep : pslog.fusion._prepare.Prepared, the session's observations
    events, j1, j2 : (k,) int, rows of the newest detection and of ``P_{t-1}``, ``P_{t-2}``
    predicted : (k, 3) float, eq. (2)'s ``P̂_t``, world metres
    innovation_px : (k,) float, distance between the newest detection and the projection
        of ``P̂_t``, recorded-image pixels (NaN: not projectable; never refused here, the
        validity flags judge it)
    noise_px : float or None, the detections' noise per image axis, pixels (None: 0.5)

    Returns
    -------
    (k,) bool, True where the innovation exceeds ``k σ_r + e_model``
    """
    time_ns = prep.obs.time_ns
    delta_pred = (time_ns[events] - time_ns[j1]) / NS
    delta_prev = (time_ns[j1] - time_ns[j2]) / NS
    focal = np.array([max(c.K[0, 0], c.K[1, 1]) for c in prep.cameras])[prep.obs.camera[events]]
    sigma = DEFAULT_NOISE_PX if noise_px is None else float(noise_px)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = delta_pred / delta_prev
        sigma_r = sigma * np.sqrt(1.0 + (1.0 + rho) ** 2 + rho ** 2)
        depth = np.linalg.norm(predicted - prep.ray_origin[events], axis=1)
        model_px = 0.5 * G * delta_pred * (delta_pred + delta_prev) * focal / depth
        return innovation_px > INNOVATION_SIGMAS * sigma_r + model_px


def failed_counts(failed: np.ndarray) -> dict[str, int]:
    """``Track.dropped``'s count of the points :func:`failed_predictions` refused."""
    n = int(np.count_nonzero(failed))
    return {"prediction_failed": n} if n else {}
