"""`smooth`'s final pass: when every observation lies in a fitted piece, the fit's points'
arrays are its outputs and the track's (no NaN-filled copies, no gather); otherwise the
observations outside the pieces are filled with NaN and left out. Either way the same
values."""

from __future__ import annotations

import numpy as np
from _rigs import ring_rig
from numpy.testing import assert_array_equal

from pslog.estimation import SmoothOptions, fit_trajectory
from pslog.fusion import FusionOptions, fuse
from pslog.motion import get_motion
from pslog.records import NS, Observations
from pslog.simulation import SimulationOptions, simulate


def _with_lone_detection(obs: Observations) -> Observations:
    """``obs`` and one detection of camera 0 two seconds after the last: no other camera's
    within a third of the gap bound, so no piece holds it (the fit's rows are not every
    observation)."""
    return Observations.from_unsorted(
        np.r_[obs.time_ns, obs.time_ns[-1] + 2 * NS], np.r_[obs.camera, 0],
        np.r_[obs.uv, obs.uv[:1]], np.r_[obs.frame_index, obs.frame_index[-1] + 60])


def test_outputs_are_the_same_whether_every_observation_is_fitted_or_not():
    """A lone detection no piece holds changes nothing of the fit (the same pieces): the
    points, covariances (the detector's offset and a camera bias as consider terms added),
    residuals and the track are bit for bit those of the session without it — one taken
    whole (every observation fitted), the other gathered. Fails if the whole path leaves
    out the consider terms or takes another array than the gathered one."""
    rig = ring_rig(3, "r3")
    detections, _ = simulate(rig, get_motion("rally"), 3.0,
                             SimulationOptions(noise_px=0.3, seed=5))
    obs = detections.best()
    lone = _with_lone_detection(obs)
    options = SmoothOptions(max_gap_s=0.12, detector_offset_m=5e-4, detector_bias_px=0.2)
    whole, part = fit_trajectory(obs, rig, options), fit_trajectory(lone, rig, options)
    assert whole.used.all() and len(whole.trajectory.breaks_s) > 0
    assert not part.used[-1] and part.used[:-1].all()
    assert np.isnan(part.position[-1]).all() and np.isnan(part.covariance[-1]).all()
    for name in ("position", "covariance", "residual_px", "weight"):
        assert_array_equal(getattr(part, name)[:-1], getattr(whole, name), err_msg=name)
    fusion = FusionOptions(detector_offset_m=5e-4, detector_bias_px=0.2)
    a, b = fuse(obs, rig, "smooth", fusion), fuse(lone, rig, "smooth", fusion)
    assert len(a) == len(obs) and len(b) == len(obs)
    assert_array_equal(a.time_ns, b.time_ns)
    assert_array_equal(a.camera, b.camera)
    assert_array_equal(a.position_world, b.position_world)
    assert set(a.quality) == set(b.quality) and "cov_xy_m2" in a.quality
    for name in a.quality:
        assert_array_equal(a.quality[name], b.quality[name], err_msg=name)
    # the offset's variance is in the points' covariance (5e-4² on every diagonal entry
    # beyond the white noise's and the bias's)
    assert np.all(a.quality["cov_xx_m2"] > 2.5e-7)
