"""The session-47 review's randomized check: ``StreamFuser`` pushes + flush against the batch for
``filter`` (hold on, ``hold_start``), ungated (one detection per push as Python numbers, one-row
arrays, mixed and random chunks) and gated (``push`` and ``push_frame`` of every frame's
candidates), on dirty simulated sessions (2-4 cameras, misses, drops, spurious blobs, a static
object). Usage: ``PYTHONPATH=.:tests python benchmarks/session47/review47_stream_check.py FIRST
LAST [fast]`` (seeds 85000-85999; ``fast``: :func:`session_fast`)."""
import sys

import numpy as np
from _rally import rally
from test_filter import lab_rig
from test_stream_gating import assert_same_track, push_frames

from pslog.fusion import FusionOptions, fuse
from pslog.fusion.filter import FilterOptions, fuse_filter
from pslog.fusion.stream import StreamFuser
from pslog.records import Track
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig

DISTRACTOR = (1.0, 1.5, 0.2)


def session(seed):
    rng = np.random.default_rng(seed)
    ncam = int(rng.integers(2, 5))
    if rng.random() < 0.5 and ncam in (2, 3):
        rig = apply_timing(builtin_rig("paper3" if ncam == 3 else "paper2"), "typeA")
        extra = {"distractors": ((rig.names[1], DISTRACTOR),)} if rng.random() < 0.5 else {}
    else:
        rig = lab_rig(ncam, fps=float(rng.choice([30.0, 60.0])))
        extra = {}
    dur = 3.0
    opts = SimulationOptions(noise_px=float(rng.choice([0.3, 0.5, 1.0])), seed=seed,
                             miss_rate=float(rng.choice([0.1, 0.3, 0.5])),
                             drop_rate=float(rng.choice([0.0, 0.1])),
                             spurious_rate=float(rng.choice([0.05, 0.1, 0.2])), **extra)
    det, truth, _ = simulate_labelled(rig, rally(dur, seed=seed, speed=4.0 + seed % 3,
                                             kick_every_s=0.6)[0], dur, opts)
    return true_rig(rig, opts), det, rng, truth


def session_fast(seed):
    """One camera at 120-300 fps beside 30 fps ones, blackouts of the others in half the
    sessions (a camera alone for many detections: ``_HOLD_MAX`` reached)."""
    from pslog.rig import Rig

    rng = np.random.default_rng(seed)
    ncam = int(rng.integers(2, 5))
    rig = lab_rig(ncam, fps=30.0)
    fast = float(rng.choice([120.0, 240.0, 300.0]))
    rig = Rig((rig.cameras[0].replace(fps=fast, offset=0.0), *rig.cameras[1:]), rig.name)
    blackouts = tuple((n, float(rng.uniform(0.3, 2.0)), float(rng.uniform(0.2, 0.8)))
                      for n in rig.names[1:]) if rng.random() < 0.5 else ()
    dur = 2.0
    opts = SimulationOptions(noise_px=float(rng.choice([0.3, 1.0])), seed=seed,
                             miss_rate=float(rng.choice([0.1, 0.3])), drop_rate=0.05,
                             spurious_rate=float(rng.choice([0.05, 0.2])), blackouts=blackouts)
    det, truth, _ = simulate_labelled(rig, rally(dur, seed=seed, speed=4.0 + seed % 3,
                                             kick_every_s=0.6)[0], dur, opts)
    return true_rig(rig, opts), det, rng, truth


def chunks(obs, rng, mode):
    n = len(obs.time_ns)
    if mode == "one":
        for i in range(n):
            yield int(obs.time_ns[i]), int(obs.camera[i]), obs.uv[i].tolist()
    elif mode == "rows":
        for i in range(n):
            yield obs.time_ns[i:i + 1], obs.camera[i:i + 1], obs.uv[i:i + 1]
    elif mode == "mixed":
        i = 0
        while i < n:
            k = int(rng.choice([1, 1, 1, 2, 3, 5, 17]))
            if k == 1 and rng.random() < 0.5:
                yield int(obs.time_ns[i]), int(obs.camera[i]), obs.uv[i].tolist()
            else:
                yield obs.time_ns[i:i + k], obs.camera[i:i + k], obs.uv[i:i + k]
            i += k
    else:
        i = 0
        while i < n:
            k = int(rng.integers(1, 41))
            yield obs.time_ns[i:i + k], obs.camera[i:i + k], obs.uv[i:i + k]
            i += k


def main() -> None:
    stats = {"sessions": 0, "starts_held_withdrawn": 0, "fail": 0, "held": 0}
    lo, hi = int(sys.argv[1]), int(sys.argv[2])
    for seed in range(lo, hi):
        make = session_fast if sys.argv[3:] == ["fast"] else session
        rig, det, rng, _ = make(seed)
        theta = float(rng.choice([0.0, 2.0, 6.0]))
        # ungated: best candidates, the filter's own rejections
        obs = det.best()
        batch = fuse_filter(obs, rig, options=FilterOptions(hold_nis=theta))
        nostart = fuse_filter(obs, rig, options=FilterOptions(hold_nis=theta, hold_start=False))
        stats["starts_held_withdrawn"] += (batch.dropped.get("held", 0)
                                           - nostart.dropped.get("held", 0))
        stats["held"] += batch.dropped.get("held", 0)
        for mode in ("one", "rows", "mixed", "random"):
            fuser = StreamFuser(rig, "filter", FusionOptions(filter_hold_nis=theta))
            parts = [fuser.push(*c) for c in chunks(obs, rng, mode)]
            parts.append(fuser.flush())
            try:
                assert_same_track(Track.concat(parts), batch)
            except AssertionError as e:
                stats["fail"] += 1
                print("FAIL ungated", seed, mode, theta, str(e)[:300], flush=True)
        # gated
        options = FusionOptions(filter_hold_nis=theta)
        gbatch = fuse(det, rig, "filter", options)
        for form in ("push", "push_frame"):
            fuser = StreamFuser(rig, "filter", options, candidates=True)
            try:
                assert_same_track(Track.concat([*push_frames(fuser, det, form), fuser.flush()]),
                                  gbatch)
            except AssertionError as e:
                stats["fail"] += 1
                print("FAIL gated", seed, form, theta, str(e)[:300], flush=True)
        stats["sessions"] += 1
        print(seed, rig.name, len(rig.cameras), len(obs), len(batch), batch.dropped, flush=True)
    print(stats)


if __name__ == "__main__":
    main()
