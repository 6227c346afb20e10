"""Ball detection speed (frames/s at 640x480 on one core) and centroid accuracy.

Speed: rendered frames of the ``paper3`` rig (shaded, blurred, noisy ball over the lined
field) are run through :class:`recorders.detect.BallDetector` with ``cv2.setNumThreads(1)``.
Baselines on the same frames in the same run: a bare ``cv2.inRange`` on the BGR frame (the
cheapest possible colour test) and the one-pass detector (``downscale=1``: HSV conversion,
threshold and labelling of the whole frame).

Accuracy: unblurred frames from a camera close enough that the ball's radius is 5..10 px,
without and with lens distortion; RMS distance of the best candidate to the true projection
of the ball's centre. Reported too: the bias inherent in the measurement, i.e. how far the
centroid of the sphere's true silhouette (rendered noise-free, 8 x 8 rays per pixel, no
shading) lies from the projection of the centre (a sphere off the optical axis images as an
ellipse whose centroid is pushed outwards).

Targets (issue 4): >= 1,000 frames/s; < 0.25 px RMS for radius >= 5 px.
Run: ``python benchmarks/bench_detect.py [--frames 400]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _rate(fn, frames, repeat: int) -> float:
    for f in frames[:10]:
        fn(f)
    start = time.perf_counter()
    for _ in range(repeat):
        for f in frames:
            fn(f)
    return repeat * len(frames) / (time.perf_counter() - start)


def _close_camera(dist):
    from pslog.camera import Camera, look_at

    R, t = look_at((1.5, -0.5, 1.8), (1.5, 1.0, 0.0))
    K = np.array([[700.0, 0.0, 319.5], [0.0, 700.0, 239.5], [0.0, 0.0, 1.0]])
    return Camera("close", 640, 480, K, np.array(dist, dtype=float), R, t)


def speed(n_frames: int, repeat: int) -> float:
    import cv2

    from pslog.motion import get_motion
    from pslog.rig import builtin_rig
    from recorders.detect import BallDetector
    from recorders.render import CameraRenderer, RenderOptions

    rig = builtin_rig("paper3")
    motion = get_motion("throw")
    frames = []
    for i, cam in enumerate(rig.cameras):
        renderer = CameraRenderer(cam, RenderOptions(), i)
        times = np.linspace(0.0, motion.duration, n_frames // len(rig.cameras))
        frames += [renderer.render(motion.position, t, k) for k, t in enumerate(times)]
    cv2.setNumThreads(1)
    detector, one_pass = BallDetector(), BallDetector(downscale=1)
    low, high = (0, 60, 120), (90, 160, 255)
    r_inrange = _rate(lambda f: cv2.inRange(f, low, high), frames, repeat)
    r_one_pass = _rate(one_pass.detect, frames, repeat)
    r_ours = _rate(detector.detect, frames, repeat)
    found = np.mean([len(detector.detect(f)) > 0 for f in frames])
    print(f"speed, {len(frames)} rendered 640x480 frames x {repeat}, one core:")
    print(f"  baseline bare cv2.inRange (BGR)   {r_inrange:8.0f} frames/s")
    print(f"  baseline one-pass detector        {r_one_pass:8.0f} frames/s")
    print(f"  BallDetector (coarse + fine)      {r_ours:8.0f} frames/s   "
          f"({r_ours / r_inrange:.2f} x inRange, {r_ours / r_one_pass:.2f} x one-pass); "
          f"ball found in {100 * found:.0f} % of frames")
    return r_ours


def accuracy(n_frames: int) -> float:
    from recorders.detect import BallDetector
    from recorders.render import CameraRenderer, RenderOptions

    worst = 0.0
    print("centroid accuracy, unblurred, noise 2 levels, ball radius >= 5 px:")
    for label, dist in (("no distortion", (0, 0, 0, 0, 0)),
                        ("distortion k1=-0.25", (-0.25, 0.08, 0.001, -0.001, 0.0))):
        cam = _close_camera(dist)
        renderer = CameraRenderer(cam, RenderOptions(exposure_s=0.0, noise_sigma=2.0), 0)
        exact = CameraRenderer(cam, RenderOptions(exposure_s=0.0, noise_sigma=0.0,
                                                  supersample=8, ball_bgr=(255, 255, 255)))
        rng = np.random.default_rng(7)
        detector = BallDetector()
        errors, bias, radii = [], [], []
        while len(errors) < n_frames:
            center = np.array([rng.uniform(0.5, 2.5), rng.uniform(0.2, 1.8),
                               rng.uniform(0.03, 0.6)])
            uv, _ = cam.project(center[None])
            if not cam.in_image(uv, margin=20)[0]:
                continue
            found = detector.detect(renderer.render_positions(center[None], len(errors)))
            if len(found) == 0:
                errors.append((np.inf, np.inf))
                continue
            errors.append(found.uv[0] - uv[0])
            radii.append(renderer.apparent_radius_px(center))
            x0, y0, x1, y1 = exact._ball_roi(center[None])
            coverage, _ = exact._trace_ball(center[None], (x0, y0, x1, y1))
            vv, uu = np.mgrid[y0:y1, x0:x1]
            w = coverage / coverage.sum()
            bias.append(np.hypot((uu * w).sum() - uv[0, 0], (vv * w).sum() - uv[0, 1]))
        errors = np.asarray(errors)
        rms = float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))
        worst = max(worst, rms)
        print(f"  {label:<20} {len(errors)} frames, radius {min(radii):.1f}..{max(radii):.1f} px: "
              f"RMS {rms:.3f} px, max {np.max(np.linalg.norm(errors, axis=1)):.3f} px; "
              f"silhouette-centroid bias mean {np.mean(bias):.3f} px, max {np.max(bias):.3f} px")
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300, help="frames for the speed test")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--accuracy-frames", type=int, default=100)
    args = parser.parse_args()
    rate = speed(args.frames, args.repeat)
    rms = accuracy(args.accuracy_frames)
    print(f"targets: >= 1000 frames/s: {'PASS' if rate >= 1000 else 'FAIL'} ({rate:.0f}); "
          f"< 0.25 px RMS: {'PASS' if rms < 0.25 else 'FAIL'} ({rms:.3f} px)")


if __name__ == "__main__":
    main()
