"""The detector's systematic error on rendered sessions, and whether each method's covariance
is honest before and after ``smooth``'s detector-offset term (issue 10; docs/estimation.md,
"The detector's systematic error").

Renders ``record --synthetic`` sessions (real HSV detection of rendered frames) on six rigs
(``paper3`` type A and B, ``paper2``, ``lab3``, ``lab4``, ``wide3``: 640 x 480 to 800 x 600,
mild to strong lens distortion) and four motions, then per session:

- the detector's error against the projection of the true centre, split by least squares
  into one 3-D offset ``δ`` of the ball seen by every camera alike (mm) and a remainder per
  camera (px RMS): what ``pslog.fusion.DETECTOR_OFFSET_M`` is characterised from;
- every default method fused as ``pslog fuse`` does, with the offset 0 ("before") and the
  session's default ("after": 0.5 mm per axis for image detections): the share of the
  truth inside 2σ (73.9 % if honest) and the NEES (1 if honest).

    python benchmarks/bench_uncertainty.py [--first-seed 1] [--quick] [--keep DIR]

``--first-seed N``: other seeds (sessions none of the figures in the docs used);
``--quick``: three sessions; ``--keep DIR``: the sessions are written there (and reused).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

#: (rig, motion, seed offset, duration s or None for the motion's own)
RUNS = [("paper3A", "throw", 0, None), ("paper3A", "spiral", 1, None),
        ("paper2A", "turntable", 2, None), ("lab3", "rally", 3, 3.0),
        ("lab4", "throw", 4, None), ("wide3", "spiral", 5, None), ("paper3B", "rally", 6, 3.0),
        ("lab4", "rally", 7, 3.0), ("wide3", "throw", 8, None)]


def _rig(name: str):
    from _rigs import ring_rig
    from bench_dirty import lab_rig

    from pslog import apply_timing, builtin_rig

    return {"paper3A": lambda: apply_timing(builtin_rig("paper3"), "typeA"),
            "paper3B": lambda: apply_timing(builtin_rig("paper3"), "typeB"),
            "paper2A": lambda: apply_timing(builtin_rig("paper2"), "typeA"),
            "lab3": lab_rig, "lab4": lambda: ring_rig(4, "lab4"),
            "wide3": lambda: ring_rig(3, "wide3", f=330.0,
                                      dist=(-0.25, 0.05, 3e-4, -2e-4, 0.0), radius=2.4,
                                      height=2.2)}[name]()


def record(folder: Path, rig: str, motion: str, seed: int, duration) -> Path:
    from pslog.motion import get_motion, rally_motion
    from recorders.synthetic import record_synthetic

    path = folder / f"rec-{rig}-{motion}-{seed}.mcap"
    if not path.exists():
        m = rally_motion(seed, duration) if motion == "rally" else get_motion(motion)
        record_synthetic(_rig(rig), m, path, duration=duration, seed=seed, frames=False,
                         status=None)
    return path


def detector_offset(session) -> tuple[np.ndarray, float]:
    """The session's 3-D offset δ (m) that best explains every camera's detection errors
    (each detection minus the projection of the true centre, to first order ``J δ``), and
    the RMS (px) of the per-camera mean errors that remain."""
    from pslog.timing import observations

    rig = session.rig
    obs = observations(session.detections, rig)
    A, y, cams = [], [], []
    for c, cam in enumerate(rig.cameras):
        sel = obs.camera == c
        X = session.truth.at(obs.time_ns[sel])
        uv = cam.project(X)[0]
        d = obs.uv[sel] - uv
        J = np.stack([(cam.project(X + 1e-5 * e)[0] - uv) / 1e-5 for e in np.eye(3)], axis=2)
        ok = np.all(np.isfinite(d), axis=1) & (np.linalg.norm(d, axis=1) < 3)
        A.append(J[ok].reshape(-1, 3))
        y.append(d[ok].reshape(-1))
        cams.append(np.full(2 * int(ok.sum()), c))
    A_, y_, cam_ = np.concatenate(A), np.concatenate(y), np.concatenate(cams)
    delta = np.linalg.lstsq(A_, y_, rcond=None)[0]
    rest = y_ - A_ @ delta
    axis = np.tile([0, 1], len(y_) // 2)
    means = [rest[(cam_ == c) & (axis == a)].mean() for c in range(len(rig)) for a in (0, 1)
             if np.any((cam_ == c) & (axis == a))]
    return delta, float(np.sqrt(np.mean(np.square(means))))


def honesty(session, offset_m) -> dict[str, tuple[float, float]]:
    """method -> (share inside 2σ, NEES), fused as ``pslog fuse`` fuses the session."""
    import pslog
    from pslog.evaluation import summarise_quality
    from pslog.fusion import FusionOptions

    tracks = pslog.fuse(session, options=FusionOptions(detector_offset_m=offset_m)).tracks
    out = {}
    for method, track in tracks.items():
        q = summarise_quality(track, session.truth)
        out[method] = (q.within_2sigma, q.nees)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--keep", type=Path, default=None)
    args = parser.parse_args()
    import pslog

    runs = RUNS[:3] if args.quick else RUNS
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        deltas, rests = [], []
        print(f"{'session':26s} {'δ mm (x, y, z)':>22s} {'rest px':>8s}  method: in 2σ / NEES "
              f"before -> after")
        for rig, motion, k, duration in runs:
            path = record(folder, rig, motion, args.first_seed + k, duration)
            session = pslog.read_session(path)
            delta, rest = detector_offset(session)
            deltas.append(delta)
            rests.append(rest)
            before, after = honesty(session, 0.0), honesty(session, None)
            cells = [f"{m} {100 * b[0]:.1f}/{b[1]:.2f} -> {100 * a[0]:.1f}/{a[1]:.2f}"
                     for m, b in before.items() for a in [after[m]]]
            print(f"{path.stem[4:]:26s} {np.array2string(delta * 1e3, precision=2):>22s} "
                  f"{rest:8.3f}  " + " | ".join(cells), flush=True)
    D = np.array(deltas)
    print(f"\n|δ| {1e3 * np.linalg.norm(D, axis=1).min():.2f}-"
          f"{1e3 * np.linalg.norm(D, axis=1).max():.2f} mm; RMS per axis "
          f"{1e3 * np.sqrt(np.mean(D**2)):.2f} mm (x, y, z: "
          f"{np.array2string(1e3 * np.sqrt(np.mean(D**2, axis=0)), precision=2)}); the "
          f"per-camera remainder {np.sqrt(np.mean(np.square(rests))):.3f} px RMS; "
          f"pslog.fusion.DETECTOR_OFFSET_M = {1e3 * pslog.fusion.DETECTOR_OFFSET_M:.2f} mm")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
