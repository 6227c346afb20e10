"""Compile pslog's numba kernels now instead of at their first use.

numba compiles a kernel (:mod:`pslog._jit`) the first time it runs on a machine, then loads
it from its cache: the first ``pslog fuse`` of a fresh install spends minutes of CPU
compiling (type A's kernel, the filter's step, the smooth trajectory's passes, the gate),
every later run a fraction of a second loading. ``bash run.sh`` runs this module after
installing, so the cost is paid once, announced, before the demo or the tests:

    python -m pslog.warm

It runs the real commands on a 1.5-second simulated session in a temporary folder (simulate
with a clock offset and spurious blobs, sync, fuse with every default method, the streaming
forms of ``filter`` and ``typeA``, the latter also with every candidate through the stream
gate), which compiles every kernel in the signatures those commands use. numba compiles
under one lock per process, one kernel at a time: on two or more cores the work is split
between this process and a second one, each compiling its own kernels (no kernel in both:
they share numba's cache on disk), which about halves the wall time:

- this one: simulate, fuse with ``nearest`` and ``typeA`` (the gate's and type A's batch
  kernels), the shared-instant methods' tests (``sync``, ``typeB``, ``linear``: their noise
  and residual sums, on the same session's rows), sync, fuse with ``smooth`` (the
  trajectory's estimation kernels), then the streaming ``typeA``, one detection a push;
- the second: its own simulated session (the same command), the streaming ``filter`` (its
  per-detection step), the filter's state and prediction (``pslog live``), a lens's rays,
  the batch ``filter`` (the loop around the step, the start's window fits; the gate's
  kernels by then in the cache) and the streaming ``typeA`` through the stream gate (type
  A's kernel in the cache by then: the streams give it the batch run's argument types),
  the batch gate's whole-session choice (a dirty session's), then ``pslog redetect``'s
  compiled screen and JPEG decoder (on one small frame).

A kernel compiled by both processes would be compiled twice for nothing: the order above
keeps each kernel to one of them on a machine the two share evenly.

Nothing is written outside the temporary folders and numba's cache.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time

#: the session both processes simulate (the same command: the same session)
_SIMULATE = ["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
             "--duration", "1.5", "--noise-px", "0.3", "--spurious", "0.05",
             "--clock-offset", "cam2=3", "--seed", "1"]
#: the argument that makes ``python -m pslog.warm`` the second process (internal)
_SECOND = "--second-part"


def warm() -> float:
    """Run the commands that compile every kernel; returns the seconds it took."""
    start = time.perf_counter()
    if _cores() < 2:
        _first_part()
        _second_part()
        return time.perf_counter() - start
    # the second part in a second process, its messages into a file read if it fails (a pipe
    # nobody reads until this process is done could fill and stop it)
    with tempfile.TemporaryFile() as messages:
        second = subprocess.Popen([sys.executable, "-m", "pslog.warm", _SECOND],
                                  stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                  stderr=messages)
        try:
            _first_part()
            second.wait()
        finally:
            if second.poll() is None:  # (this one failed or was stopped)
                second.kill()
                second.wait()
        if second.returncode != 0:
            messages.seek(0)
            lines = messages.read().decode(errors="replace").strip().splitlines()
            raise RuntimeError(f"the second warm process exited {second.returncode}"
                               + (f": {lines[-1]}" if lines else ""))
    return time.perf_counter() - start


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # (not on every platform)
        return os.cpu_count() or 1


def _commands(steps: list[list[str]]) -> None:
    """``pslog`` commands in this process, their output discarded."""
    from pslog.cli import main

    os.environ.setdefault("PSLOG_PROGRESS", "off")
    with open(os.devnull, "w") as quiet:
        out, err = sys.stdout, sys.stderr
        sys.stdout = sys.stderr = quiet
        try:
            for argv in steps:
                code = main(argv)
                if code != 0:
                    raise RuntimeError(f"pslog {argv[0]} exited {code}")
        finally:
            sys.stdout, sys.stderr = out, err


def _first_part() -> None:
    """simulate; fuse with nearest and typeA first (the gate's and type A's batch kernels,
    which the second part's streams then load), the shared-instant tests' kernels, sync,
    fuse with smooth; the stream of type A one detection a push; the fused-track writer's
    block encoders."""
    with tempfile.TemporaryDirectory(prefix="pslog-warm-") as tmp:
        session = os.path.join(tmp, "session.mcap")
        synced = os.path.join(tmp, "synced.mcap")
        _commands([[*_SIMULATE, "-o", session],
                   ["fuse", session, "--method", "nearest,typeA",
                    "-o", os.path.join(tmp, "fused-a.mcap")]])
        _shared_instant_tests(session)
        _commands([["sync", session, "-o", synced],
                   ["fuse", synced, "--method", "smooth", "-o", os.path.join(tmp, "fused.mcap")]])
        _type_a_stream(session)
        # (here, not in the second part: that one is the longer, warm's critical path)
        from pslog.api import read_session

        _track_writer(os.path.join(tmp, "track.mcap"), read_session(session).rig)


def _shared_instant_tests(session: str) -> None:
    """The kernels of ``sync``'s residual test and ``typeB`` / ``linear``'s noise
    (:func:`pslog.fusion.stereo.refusal_noise`, :func:`~pslog.fusion.stereo.residual_refused`),
    which no default method runs (the warm session's type A timing has no common instant):
    called on its ``nearest`` rows (each camera's detection in its own slot, as a common
    instant's), in the argument types of a fuse."""
    from pslog.api import read_session
    from pslog.fusion import prepare, stereo
    from pslog.fusion._prepare import default_max_gap_s
    from pslog.records import NS

    data = read_session(session)
    best = data.detections.best()
    prep = prepare(best, data.rig)
    gap = default_max_gap_s(prep)
    rows, _ = stereo.nearest_rows(prep, int(gap * NS))
    residuals: list = []
    points, _, _, used = stereo.nview_points(prep, rows, None, residuals_out=residuals)
    sigma = stereo.refusal_noise(prep, best.time_ns, gap, 0.5)
    stereo.residual_refused(prep, rows, used, points, best.time_ns, sigma, gap, residuals)


def _type_a_stream(session: str) -> None:
    from pslog.api import read_session
    from pslog.fusion.stream import StreamFuser

    data = read_session(session)
    best = data.detections.best()
    fuser = StreamFuser(data.rig, "typeA")
    for i in range(min(len(best), 60)):
        fuser.push(int(best.time_ns[i]), int(best.camera[i]), best.uv[i])
    fuser.flush()


def _second_part() -> None:
    """The streaming forms (live fusion call the kernels one detection at a time) and the
    batch ``filter``, on a session of its own."""
    import numpy as np

    from pslog.api import read_session
    from pslog.fusion._prepare import _rays
    from pslog.fusion.filter import BallFilter
    from pslog.fusion.stream import StreamFuser

    with tempfile.TemporaryDirectory(prefix="pslog-warm-") as tmp:
        session = os.path.join(tmp, "session.mcap")
        _commands([[*_SIMULATE, "-o", session]])
        data = read_session(session)
        best = data.detections.best()
        fuser = StreamFuser(data.rig, "filter")
        for i in range(min(len(best), 60)):
            fuser.push(int(best.time_ns[i]), int(best.camera[i]), best.uv[i])
        fuser.flush()
        # pslog live's state and prediction to "now" of the filter (compiled: _combined,
        # _predict), once its track has started
        flt = BallFilter(data.rig)
        for i in range(len(best)):
            flt.push(int(best.time_ns[i]), int(best.camera[i]), *best.uv[i].tolist())
            if flt.state() is not None:
                flt.predict(int(best.time_ns[i]) + 10_000_000)
                break
        # a lens's rays (prepare's pass for a camera with distortion; the session's have none)
        _rays(data.rig.cameras[0], np.zeros((1, 2)))
        _commands([["fuse", session, "--method", "filter",
                    "-o", os.path.join(tmp, "fused.mcap")]])
    # every candidate through the stream gate (pslog live's default; its compiled kernels):
    # type A's kernel last, when the first part has compiled it (the stream's arguments are
    # of the batch run's types: one signature, in the cache by then)
    det = data.detections
    fuser = StreamFuser(data.rig, "typeA", candidates=True)
    for f in range(min(det.n_frames, 60)):
        rows = slice(*np.searchsorted(det.cand_frame, [f, f + 1]).tolist())
        n = rows.stop - rows.start
        if n:
            fuser.push([int(det.frame_time_ns[f])] * n, [int(det.frame_camera[f])] * n,
                       det.cand_uv[rows])
    fuser.flush()
    # the batch gate's whole-session choice (a dirty session's fuse: every frame decided by
    # those kernels in one call, gating._decide_compiled), in both forms' one signature
    from pslog.fusion import gating

    was, gating.WHOLE_COMPILED = gating.WHOLE_COMPILED, True
    try:
        gating.gate(det, data.rig, causal=False)
    finally:
        gating.WHOLE_COMPILED = was
    # pslog redetect's compiled screen and screened JPEG decoder (recorders/_jpeg.py)
    from recorders.detect import HsvRange
    from recorders.redetect import _warm_screened

    _warm_screened(HsvRange(), 5)


def _track_writer(path: str, rig) -> None:
    """The fused-track writer's compiled encoders (:mod:`pslog.log._wire`), which a long
    session's ``pslog fuse`` runs and the short warm sessions do not (a track is encoded by
    them from :data:`pslog.log.writer._BLOCK_FROM` points, a block of messages assembled
    from a megabyte): without this the first fuse of a match after an install compiled
    them, ~8 CPU s. A track of a block and a bit written as ``pslog fuse`` writes it, after
    a small message (its first block then written the other way: as a gating rejection
    before it does)."""
    import numpy as np

    from pslog.log.writer import _TRACK_BLOCK, SessionWriter
    from pslog.records import QUALITY_FIELDS, Track

    n = _TRACK_BLOCK + 300
    t = np.arange(1, n + 1, dtype=np.int64) * 11_111_111
    values = np.linspace(0.0, 1.0, n)
    track = Track("typeA", t, np.column_stack([values, values, values]),
                  (np.arange(n) % len(rig)).astype(np.int32),
                  {k: values for k in QUALITY_FIELDS})
    # and a dirty session's many rejections: a block of payloads (not whole records) of
    # over a megabyte, its chunk records assembled by _wire.assemble_records (a track's
    # first block no longer reaches it: written apart from the messages queued before it)
    from pslog.fusion.gating import Rejections
    from pslog.log.writer import _FRAME_BLOCK

    k = _FRAME_BLOCK
    rejected = Rejections(np.arange(1, k + 1, dtype=np.int64) * 11_111_111,
                          np.arange(k) % len(rig), np.arange(k), np.full((k, 2), 100.5),
                          np.ones(k), np.zeros(k, np.int8))
    with SessionWriter(path, rig, force=True, on_error="discard",
                       flush_interval_s=float("inf")) as w:
        w.add_event(0, "warm")
        w.add_track(track, last=True)
        w.add_rejections("typeA", rejected)


def main() -> int:
    if sys.argv[1:] == [_SECOND]:  # the second process of warm(): its failure is warm's
        _second_part()
        return 0
    # stopped (run.sh stopped while it warms in the background): the second process with it
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
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
