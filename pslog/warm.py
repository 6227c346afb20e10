"""Compile pslog's numba kernels now instead of at their first use.

numba compiles a kernel (:mod:`pslog._jit`) the first time it runs on a machine, then loads
it from its cache: the first ``pslog fuse`` of a fresh install spends about a minute
compiling (type A's kernel, the filter's step, the smooth trajectory's passes, the track
encoder; about 50 s on this project's two-core build machine), every later run a fraction of a
second loading. ``bash run.sh`` runs this
module after installing, so the cost is paid once, announced, before the demo or the tests:

    python -m pslog.warm

It runs the real commands on a 3-second simulated session in a temporary folder (simulate
with a clock offset and spurious blobs, sync, fuse with every default method: a track of
more than 256 points, written by the compiled track encoder), and, in a second process
where two cores are free, the streaming forms of ``filter`` and ``typeA`` (the latter also
with every candidate through the stream gate) and direct calls of the kernels those
commands reach only on some inputs or that the library's functions use (the filter's
state and prediction, eq. (1)'s pseudo stereo points, the smooth trajectory's reference
and degenerate-window kernels, a lens's rays, a large block's record assembler, the
recorders' compiled colour screen of a long ``pslog redetect``). That compiles every kernel
of pslog and recorders (``python tools/warm_coverage.py`` checks it) in the signatures
those calls use. Nothing is written outside the temporary folder and numba's cache.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time


def warm() -> float:
    """Run the commands that compile every kernel; returns the seconds it took.

    Where two cores are free, the streaming forms and the direct calls (:func:`_side`)
    compile in a second process while this one syncs and fuses (numba compiles on one
    core; each process loads from the cache what the other has written meanwhile)."""
    start = time.perf_counter()
    from pslog.cli import main

    os.environ.setdefault("PSLOG_PROGRESS", "off")
    with tempfile.TemporaryDirectory(prefix="pslog-warm-") as tmp:
        session = os.path.join(tmp, "session.mcap")
        synced = os.path.join(tmp, "synced.mcap")
        fused = os.path.join(tmp, "fused.mcap")
        _run(main, ["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                    "--duration", "3", "--noise-px", "0.3", "--spurious", "0.05",
                    "--clock-offset", "cam2=3", "--seed", "1", "-o", session])
        side = None
        cores = (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                 else os.cpu_count() or 1)
        if cores >= 2:
            log = open(os.path.join(tmp, "side.log"), "w")  # closed below
            side = subprocess.Popen(
                [sys.executable, "-c", "import sys; from pslog.warm import _side; "
                 "_side(sys.argv[1])", session], stdout=log, stderr=subprocess.STDOUT)
        try:
            _run(main, ["sync", session, "-o", synced])
            _run(main, ["fuse", synced, "-o", fused])
            if side is None:
                _side(session)
        finally:
            if side is not None:
                code = side.wait()
                log.close()
                if code != 0:
                    with open(log.name) as f:
                        last = (f.read().strip().splitlines() or ["no output"])[-1]
                    raise RuntimeError(f"its second process exited {code}: {last}")
    return time.perf_counter() - start


def _run(main, argv: list[str]) -> None:
    """``pslog argv``, its output discarded."""
    quiet = open(os.devnull, "w")  # closed below
    out, err = sys.stdout, sys.stderr
    sys.stdout = sys.stderr = quiet
    try:
        code = main(argv)
    finally:
        sys.stdout, sys.stderr = out, err
        quiet.close()
    if code != 0:
        raise RuntimeError(f"pslog {argv[0]} exited {code}")


def _side(session: str) -> None:
    """The streaming forms and the direct calls (run beside sync and fuse)."""
    os.environ.setdefault("PSLOG_PROGRESS", "off")
    _direct(session)
    _stream(session)
    _in_memory(session)
    _detector()


def _in_memory(session: str) -> None:
    """The filter over arrays in memory (writable; a session read from a file gives
    read-only ones, another signature of the same kernel): the library's callers' form."""
    import numpy as np

    from pslog.api import read_session
    from pslog.fusion.filter import BallFilter, _track

    data = read_session(session)
    best = data.detections.best()
    _track(BallFilter(data.rig), np.array(best.time_ns), np.array(best.camera),
           np.array(best.uv))


def _detector() -> None:
    """The recorders' compiled colour screen (``pslog redetect`` of a long session; imported
    here only: the core never imports the recording layer)."""
    import numpy as np

    from recorders.detect import BallDetector

    BallDetector(compiled=True).detect(np.zeros((16, 16, 3), np.uint8))


def _stream(session: str) -> None:
    """The streaming forms (live fusion) call the kernels one detection at a time."""
    import numpy as np

    from pslog.api import read_session
    from pslog.fusion.stream import StreamFuser

    data = read_session(session)
    best = data.detections.best()
    for method in ("filter", "typeA"):
        fuser = StreamFuser(data.rig, method)
        for i in range(len(best)):  # all: past the buffer's first trim
            fuser.push(int(best.time_ns[i]), int(best.camera[i]), best.uv[i])
        fuser.flush()
    # every candidate through the stream gate (pslog live's default; its compiled kernels)
    det = data.detections
    fuser = StreamFuser(data.rig, "typeA", candidates=True)
    for f in range(det.n_frames):
        rows = slice(*np.searchsorted(det.cand_frame, [f, f + 1]).tolist())
        n = rows.stop - rows.start
        if n:
            fuser.push([int(det.frame_time_ns[f])] * n, [int(det.frame_camera[f])] * n,
                       det.cand_uv[rows])
    fuser.flush()


def _direct(session: str) -> None:
    """Kernels the commands above reach only on some inputs, or through public functions
    the library's users (and its tests) call: compiled in the signatures those calls use."""
    import numpy as np

    from pslog.api import read_session
    from pslog.estimation import _normal
    from pslog.fusion import prepare, pseudo_stereo_points
    from pslog.fusion.filter import BallFilter

    data = read_session(session)
    best = data.detections.best()
    # the filter's state and prediction (pslog live's sinks, the library's BallFilter)
    flt = BallFilter(data.rig)
    for i in range(min(len(best), 30)):
        flt.push(int(best.time_ns[i]), int(best.camera[i]), float(best.uv[i, 0]),
                 float(best.uv[i, 1]))
    flt.state()
    flt.predict(int(best.time_ns[min(len(best), 30) - 1]) + 10_000_000)
    # eq. (1)'s pseudo stereo points of given pairs (pslog.fusion.pseudo_stereo_points)
    prep = prepare(best, data.rig)
    pseudo_stereo_points(prep, np.array([1]), np.array([2]), max_gap_ns=1_000_000_000)
    # the smooth trajectory's normal equations by points, its covariance band's references
    rng = np.random.default_rng(0)
    m, r = 8, 64
    first = rng.integers(0, m - 3, r)
    J = rng.normal(size=(r, 2, 3))
    M = np.einsum("nai,naj->nij", J, J)
    ab, _ = _normal.accumulate_points(first, rng.random((r, 4)), M, np.zeros((r, 3)), m)
    ab[11] += 1e-3
    U = _normal.factor(ab)
    _normal.covariance_band_rows(U)
    _normal.covariance_band_sequential(U)
    # the local windows' dense normal equations and solve (a degenerate window's path)
    from pslog.estimation import _kernels

    B, W, n = 2, 6, 3 * m
    H, rhs = _kernels.window_normal(np.eye(n), np.zeros(n), rng.integers(0, m - 3, (B, W)),
                                    rng.random((B, W, 4)), np.ascontiguousarray(M[:B * W].reshape(
                                        B, W, 3, 3)), rng.normal(size=(B, W, 3)),
                                    np.ones((B, W), dtype=bool))
    _kernels.window_solve(H, rhs, 3, n)
    # a lens's rays (prepare() on a rig with distortion)
    from pslog.fusion._prepare import _rays

    _rays(data.rig.cameras[0], np.zeros((4, 2)))
    # a large block's MCAP records laid by the compiled loop (a long fused track's writer);
    # its payload is a writable array or read-only bytes
    from pslog.log._wire import assemble_records

    lengths = np.full(4, 5, dtype=np.int64)
    starts = np.arange(0, 20, 5, dtype=np.int64)
    heads = np.zeros((4, 31), dtype=np.uint8)
    for payload in (np.zeros(20, np.uint8), np.frombuffer(bytes(20), dtype=np.uint8)):
        assemble_records(np.zeros(200, np.uint8), heads, starts * 9, payload, starts, lengths)


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
