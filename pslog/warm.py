"""Compile pslog's numba kernels now instead of at their first use.

numba compiles a kernel (:mod:`pslog._jit`) the first time it runs on a machine, then loads
it from its cache: the first ``pslog fuse`` of a fresh install spends about a minute
compiling (type A's kernel, the filter's step, the smooth trajectory's passes, the track
encoder; about 50 s on this project's two-core build machine), every later run a fraction of a
second loading. ``bash run.sh`` runs this
module after installing, so the cost is paid once, announced, before the demo or the tests:

    python -m pslog.warm

It runs the real commands on a 1.5-second simulated session in a temporary folder (simulate
with a clock offset and spurious blobs, sync, fuse with every default method, the streaming
forms of ``filter`` and ``typeA``, the latter also with every candidate through the stream
gate), which compiles every kernel in the signatures those
commands use. Nothing is written outside the temporary folder and numba's cache.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time


def warm() -> float:
    """Run the commands that compile every kernel; returns the seconds it took."""
    start = time.perf_counter()
    from pslog.cli import main

    os.environ.setdefault("PSLOG_PROGRESS", "off")
    with tempfile.TemporaryDirectory(prefix="pslog-warm-") as tmp:
        session = os.path.join(tmp, "session.mcap")
        synced = os.path.join(tmp, "synced.mcap")
        fused = os.path.join(tmp, "fused.mcap")
        quiet = open(os.devnull, "w")  # closed below
        out, err = sys.stdout, sys.stderr
        sys.stdout = sys.stderr = quiet
        try:
            steps = [
                ["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                 "--duration", "1.5", "--noise-px", "0.3", "--spurious", "0.05",
                 "--clock-offset", "cam2=3", "--seed", "1", "-o", session],
                ["sync", session, "-o", synced],
                ["fuse", synced, "-o", fused],
            ]
            for argv in steps:
                code = main(argv)
                if code != 0:
                    raise RuntimeError(f"pslog {argv[0]} exited {code}")
        finally:
            sys.stdout, sys.stderr = out, err
            quiet.close()
        _stream(session)
    return time.perf_counter() - start


def _stream(session: str) -> None:
    """The streaming forms (live fusion) call the kernels one detection at a time."""
    import numpy as np

    from pslog.api import read_session
    from pslog.fusion.stream import StreamFuser

    data = read_session(session)
    best = data.detections.best()
    for method in ("filter", "typeA"):
        fuser = StreamFuser(data.rig, method)
        for i in range(min(len(best), 60)):
            fuser.push(int(best.time_ns[i]), int(best.camera[i]), best.uv[i])
        fuser.flush()
    # every candidate through the stream gate (pslog live's default; its compiled kernels)
    det = data.detections
    fuser = StreamFuser(data.rig, "typeA", candidates=True)
    for f in range(min(det.n_frames, 60)):
        rows = slice(*np.searchsorted(det.cand_frame, [f, f + 1]).tolist())
        n = rows.stop - rows.start
        if n:
            fuser.push([int(det.frame_time_ns[f])] * n, [int(det.frame_camera[f])] * n,
                       det.cand_uv[rows])
    fuser.flush()


def main() -> int:
    try:
        seconds = warm()
    except Exception as exc:  # one line: run.sh carries on, the kernels compile on first use
        print(f"pslog warm: could not compile the kernels ahead of use "
              f"({type(exc).__name__}: {exc}); they compile on first use instead",
              file=sys.stderr)
        return 1
    print(f"pslog: numba kernels ready in {seconds:.1f} s (compiled once per install, "
          f"then loaded from the cache)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
