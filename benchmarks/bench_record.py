"""Recording throughput: decoded 640x480 frames -> detect + JPEG-encode + write a session.

Three cameras replay pre-rendered frames (``paper3`` rig, the throw; stored decoded in
``.npy`` files, so no video decoding is measured) through the real recorder
(:func:`recorders.record`: one process per camera, one writer), as fast as it goes, and the
frames per second from the start to the finished MCAP are printed. Baseline measured in the
same run: the same work (detect, encode, ``SessionWriter.add_frame``) in one process.

Target (issue 4): >= 270 frames/s in total on a 2-core machine (three times the real-time
load of three 30 fps cameras).
Run: ``python benchmarks/bench_record.py [--frames-per-camera 600] [--jpeg-quality 90]``
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    import cv2

    from pslog.log import SessionWriter, read_session
    from pslog.motion import get_motion
    from pslog.rig import apply_timing, builtin_rig
    from recorders.detect import BallDetector
    from recorders.record import jpeg_params, record
    from recorders.render import CameraRenderer, RenderOptions
    from recorders.sources import FramesSpec

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames-per-camera", type=int, default=600)
    parser.add_argument("--distinct", type=int, default=45,
                        help="distinct rendered frames per camera (replayed cyclically)")
    parser.add_argument("--jpeg-quality", type=int, default=90)
    args = parser.parse_args()

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion = get_motion("throw")
    n = args.frames_per_camera
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        stacks = []
        for i, cam in enumerate(rig.cameras):
            renderer = CameraRenderer(cam, RenderOptions(), i)
            times = cam.offset + np.arange(args.distinct) / cam.fps
            stack = np.stack([renderer.render(motion.position, t, k)
                              for k, t in enumerate(times)])
            np.save(tmp / f"{cam.name}.npy", stack)
            stacks.append(stack)
        total = n * len(rig)
        print(f"{len(rig)} cameras x {n} frames of 640x480 (JPEG quality {args.jpeg_quality}), "
              f"{os.cpu_count()} cores")

        # baseline: everything in one process
        cv2.setNumThreads(1)
        detector = BallDetector()
        params = jpeg_params(args.jpeg_quality)
        start = time.perf_counter()
        with SessionWriter(tmp / "serial.mcap", rig) as writer:
            for k in range(n):
                for i, cam in enumerate(rig.cameras):
                    frame = stacks[i][k % args.distinct]
                    found = detector.detect(frame)
                    jpeg = cv2.imencode(".jpg", frame, params)[1].tobytes()
                    writer.add_frame(i, k, round((cam.offset + k / cam.fps) * 1e9),
                                     found.uv, found.radius, found.score, image=jpeg)
        serial = total / (time.perf_counter() - start)

        specs = {cam.name: FramesSpec(str(tmp / f"{cam.name}.npy"), n, cam.fps, cam.offset)
                 for cam in rig.cameras}
        start = time.perf_counter()
        summary = record(rig, specs, tmp / "pipeline.mcap", jpeg_quality=args.jpeg_quality,
                         status=None)
        wall = time.perf_counter() - start
        pipeline = summary.n_frames / wall
        session = read_session(tmp / "pipeline.mcap")
        assert session.detections.n_frames == total == session.n_images, summary.text
        size = (tmp / "pipeline.mcap").stat().st_size
        print(f"  baseline, one process (detect + encode + write)   {serial:7.1f} frames/s")
        print(f"  pipeline, {len(rig)} camera processes + writer        {pipeline:7.1f} frames/s "
              f"({pipeline / serial:.2f} x baseline; {wall:.1f} s incl. start-up, "
              f"{size / 1e6:.0f} MB)")
        print(f"target >= 270 frames/s: {'PASS' if pipeline >= 270 else 'FAIL'}")


if __name__ == "__main__":
    main()
