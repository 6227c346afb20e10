"""`smooth` ends a piece before an end detection the fit bent to (issue 10, session 36).

``bench_dirty.py --more --validity --first-seed 49000 --misses 0.1`` found, in ``lab4``'s
rally-49000 with the faults, three `smooth` points 368-1044 mm off (faults / clean 3.19):
after 1.3333 s the ball has left ``lab4-1``, ``lab4-2`` and ``lab4-4``; only ``lab4-3`` still
sees it. ``lab4-1`` sees the static object in every frame, and the gate chose it at 1.4000 and
1.4333 s (a static object seen by one camera meets one other camera's epipolar constraint).
The piece ended on it: the fit rejected the first and the ball's detection between them and
followed the last, 1.4333 s, to its ray (residual 0.01 px) — a piece's end goes wherever its
last detection is, and the deletion test skips a piece's ends. An end detection is now tested
by the fit made without it (:func:`pslog.estimation.trajectory._ends_refitted`: its
neighbours' robust weights change, which the one-step deletion gain keeps fixed — its gain
there is 16.3, under 18.42): its deleted residual beyond χ²₂'s 1 - 1e-4 quantile in the
metric of that prediction ends the piece before it, the row without a point
(``Track.dropped["underdetermined_end"]``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_dirty import faults, more_rigs, more_sessions


def _session(kind: str):
    rig = next(r for r in more_rigs() if r.name == "lab4")
    label, motion, duration, _ = more_sessions(1, 8.0, 49000)[0]
    assert label == "rally-49000"
    extra = faults(rig, 48700, duration) if kind == "dirty" else {}
    detections, truth, ball = simulate_labelled(rig, motion, duration, SimulationOptions(
        noise_px=0.3, seed=48700, miss_rate=0.1, **extra))
    track = fuse_detections(detections, rig, ["smooth"], FusionOptions(), workers=1)[0]["smooth"]
    return rig, track, truth, ball


def test_the_issue_session_ends_before_the_static_object(monkeypatch):
    """Before: 368, 706 and 1044 mm at 1.4000 (lab4-1), 1.4167 (lab4-3), 1.4333 s (lab4-1),
    faults / clean 3.19. Now no point beyond 5 cm, the ratio under 1.05: the piece ends
    before the static object's last detection, which gets no point (counted). Since session
    42 the gate no longer chooses the object there (its rays miss at 1.4000 and 1.4333 s, and
    the image tests judge it with the tolerance of the point known at its pixel:
    ``gating._borrowed_tolerance``); the piece's end test is the safety net where a gate
    does choose it, so it is tested on the gate's choices without that rule."""
    import pslog.fusion.gating as gating

    _, gated, _, _ = _session("dirty")
    assert "underdetermined_end" not in gated.dropped  # nothing chosen there to leave out
    monkeypatch.setattr(gating, "_kernels", lambda n, wait=False: False)  # (numpy _static)
    monkeypatch.setattr(gating, "_borrowed_tolerance",
                        lambda times, table, y, own, lags, options: own)
    rig, track, truth, ball = _session("dirty")
    monkeypatch.undo()
    _, clean, clean_truth, _ = _session("clean")
    for fused in (gated, track):
        err = errors_m(fused, truth)
        assert np.max(err) < 0.05
        assert np.mean(err) / np.mean(errors_m(clean, clean_truth)) < 1.05
    assert track.dropped.get("underdetermined_end", 0) >= 1
    t_end = 1.4333e9
    assert not np.any(np.abs(track.time_ns - t_end) < 1e6)  # the static object's: no point
    ball_frames = {int(ball.frame_time_ns[f]) for f in ball.cand_frame
                   if rig.names[ball.frame_camera[f]] == "lab4-1"}
    assert not any(abs(t - t_end) < 1e6 for t in ball_frames)  # not the ball's
    # the ball's points up to the last frame four cameras saw stay
    assert np.count_nonzero((track.time_ns > 1.30e9) & (track.time_ns < 1.34e9)) == 4


def test_the_clean_session_loses_no_end():
    """The clean session: every piece's ends keep their points (no end is tested out)."""
    _, track, truth, _ = _session("clean")
    assert "underdetermined_end" not in track.dropped
    assert np.max(errors_m(track, truth)) < 0.05


def test_the_end_statistic_is_chi2_on_clean_ends(monkeypatch):
    """:func:`end_statistic` at every piece end of 30 clean held-out sessions (bench_dirty's
    5 ``--more`` rigs, 6 motions, 0.3 px, misses 0.1): χ²₂ for a detection of the ball (median
    2 ln 2 = 1.39; here 0.87, the covariance at the noise the residuals show is a little
    conservative). Without the prediction's covariance (σ² I alone) the median is 6.0 and 11
    of the 68 ends are beyond 18.42. The fit's decisions: no end left out (their one-step
    gains all below the 9.21 screen)."""
    import pslog.estimation.trajectory as T

    seen: list[tuple[float, float]] = []
    real_refitted, real_left_out = T._ends_refitted, T._left_out
    last = {}

    def left_out(t, gain, window_s, inside):  # records the one-step gains, decides as before
        last["gain"] = gain
        return real_left_out(t, gain, window_s, inside)

    def refitted(problem, options, control, sigma, k_var, spacing, candidates):
        for k in np.flatnonzero(T._end_testable(problem)):
            seen.append((T.end_statistic(problem, options, control, sigma, k_var, spacing,
                                         int(k)), last["gain"][k]))
        out = real_refitted(problem, options, control, sigma, k_var, spacing, candidates)
        assert len(out) == 0
        return out

    monkeypatch.setattr(T, "_left_out", left_out)
    monkeypatch.setattr(T, "_ends_refitted", refitted)
    for rig in more_rigs():
        for _, motion, duration, _ in more_sessions(6, 8.0, 50100):
            detections, _, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                noise_px=0.3, seed=49800, miss_rate=0.1))
            fuse_detections(detections, rig, ["smooth"], FusionOptions(), workers=1)
    stat = np.array(seen)
    assert len(stat) > 50
    assert 0.5 < np.median(stat[:, 0]) < 2.0
    assert np.count_nonzero(stat[:, 0] > 18.42) == 0
    assert np.all(stat[:, 1] < 9.21)
