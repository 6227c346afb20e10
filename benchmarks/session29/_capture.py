"""Session 29's measurement scripts (hold_lag, hold_run, surprise): the filter's own inputs
of a ``pslog fuse``-like run captured. Importing this module wraps
:func:`pslog.fusion.filter.fuse_filter` so that each call leaves its arguments ``(obs, rig,
max_gap_s, options, doubt)`` in ``cap["a"]``; ``orig`` is the unwrapped function, to fuse
them again with other options; :func:`dirty_sessions` gives the scripts' sessions."""
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs

from pslog.fusion import FusionOptions
from pslog.fusion import filter as FM
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

cap: dict = {}
orig = FM.fuse_filter


def capture(obs, rig, max_gap_s=None, options=None, doubt=None):
    cap["a"] = (obs, rig, max_gap_s, options, doubt)
    return orig(obs, rig, max_gap_s, options, doubt)


FM.fuse_filter = capture


def dirty_sessions(first: int, nseeds: int, fpss, misses: float, with_faults: bool = True):
    """bench_dirty ``--more``'s sessions (its five rigs at each rate of ``fpss``, its
    faults unless ``with_faults`` is False, 0.3 px, the detector missing ``misses`` of the
    frames and dropping half as many), each fused as ``pslog fuse`` does: yields ``(fps,
    rig, label, truth, (obs, rig, max_gap_s, options, doubt))``, the filter's captured
    inputs."""
    for fps in fpss:
        for base in rigs() + more_rigs():
            rig = at_rate(base, fps)
            for seed, (label, motion, duration, _) in enumerate(
                    more_sessions(nseeds, 8.0, first), start=first - 300):
                span = motion.duration if duration is None else duration
                det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                    noise_px=0.3, seed=seed, miss_rate=misses, drop_rate=misses / 2,
                    **(faults(rig, seed, span) if with_faults else {})))
                # (the hold for the next camera off: session 29's default; session 30's is on)
                fuse_detections(det, rig, ["filter"], FusionOptions(filter_hold_nis=None))
                yield fps, rig, label, truth, cap["a"]
