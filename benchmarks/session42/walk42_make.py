"""walk42: a robotics lab's three unsynchronised USB webcams, rendered from scratch with cv2.

Writes into OUT (default /tmp/walk42/lab):
  true_rig.toml             the cameras as they really are (never given to pslog's fusion)
  chess/camN/*.png          chessboard shots (9x6 inner corners, 25 mm) for the intrinsics
  points_camN.csv           surveyed world points and their pixels (0.5 px), for the poses
  camN.mp4 / cam3.avi       30 fps clips: an orange ball, each camera's clock off, cam3 a
                            rolling shutter; the files start at phases PHASE (give @OFFSET)
  mocap.csv                 the ball at 200 Hz, t,x,y,z on cam1's clock (the session clock)
  detector.csv              "our own detector": cam_id,t_unix,x_px,y_px,frame_no,conf

Only numpy, cv2 and the standard library: a user's script, not pslog's.
Seeds 70000-70999.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import cv2
import numpy as np

SEED = 70042
FPS = 30.0
RADIUS = 0.03  # an orange 60 mm ball
# name, width, height, f, dist, centre, phase of the file (s), clock offset (s), drift ppm, readout
CAMS = [
    ("cam1", 640, 480, 520.0, [-0.18, 0.12, 0.0, 0.0, 0.0], (-0.7, -0.6, 2.3), 0.0, 0.0, 0.0, 0.0),
    ("cam2", 640, 480, 505.0, [-0.10, 0.04, 0.0, 0.0, 0.0], (3.7, -0.5, 2.2), 0.0111, 0.0042,
     40.0, 0.0),
    ("cam3", 1280, 720, 960.0, [-0.06, 0.02, 0.0, 0.0, 0.0], (1.5, 3.0, 2.5), 0.0289, -0.0035,
     -25.0, 0.025),
]
TARGET = np.array([1.5, 1.0, 0.2])


def look_at(c: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    z = target - c
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z])
    return r, -r @ c


def camera(i: int) -> dict:
    name, w, h, f, dist, c, phase, off, drift, readout = CAMS[i]
    r, t = look_at(np.array(c, float), TARGET)
    k = np.array([[f, 0, w / 2 - 3.5 + i], [0, f * 1.001, h / 2 + 2.0 - i], [0, 0, 1]])
    return dict(name=name, w=w, h=h, K=k, dist=np.array(dist), R=r, t=t, phase=phase, off=off,
                drift=drift, readout=readout)


def project(cam: dict, x: np.ndarray) -> np.ndarray:
    rv, _ = cv2.Rodrigues(cam["R"])
    uv, _ = cv2.projectPoints(x.reshape(-1, 1, 3).astype(np.float64), rv, cam["t"], cam["K"],
                              cam["dist"])
    return uv.reshape(-1, 2)


def motion(seed: int, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """A ball kicked about a 3 x 2 m floor: flights, bounces (e 0.7), rolls, kicks, at 1 kHz."""
    rng = np.random.default_rng(seed)
    dt = 0.001
    n = int(duration / dt) + 1
    p = np.array([1.5, 1.0, RADIUS])
    v = np.zeros(3)
    out = np.empty((n, 3))
    next_kick = 0.3
    for i in range(n):
        t = i * dt
        if t >= next_kick:
            goal = np.array([rng.uniform(0.4, 2.6), rng.uniform(0.3, 1.7)])
            flight = rng.uniform(0.5, 1.0)
            vz = rng.uniform(0.5, 3.0)
            v = np.array([*(goal - p[:2]) / flight, vz])
            next_kick = t + rng.uniform(1.0, 2.0)
        out[i] = p
        a = np.array([0.0, 0.0, -9.81]) - 0.02 * np.linalg.norm(v) * v
        if p[2] <= RADIUS + 1e-9 and abs(v[2]) < 0.05:
            a = -0.6 * v  # rolling friction
            a[2] = 0.0
            v[2] = 0.0
        v = v + a * dt
        p = p + v * dt
        if p[2] < RADIUS:
            p[2] = RADIUS
            v[2] = -0.7 * v[2] if v[2] < -0.3 else 0.0
    return np.arange(n) * dt, out


def ball_at(ts: np.ndarray, ps: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, ts, ps[:, j]) for j in range(3)], axis=-1)


def background(cam: dict, rng: np.random.Generator) -> np.ndarray:
    h, w = cam["h"], cam["w"]
    img = np.full((h, w, 3), (40, 110, 45), np.uint8)
    img = (img + rng.normal(0, 3, img.shape)).clip(0, 255).astype(np.uint8)
    lines = [((0, 0), (3, 0)), ((3, 0), (3, 2)), ((3, 2), (0, 2)), ((0, 2), (0, 0)),
             ((1.5, 0), (1.5, 2))]
    for a, b in lines:
        s = np.linspace(0, 1, 60)[:, None]
        pts = np.c_[np.array(a) + s * (np.array(b) - np.array(a)), np.zeros(60)]
        uv = project(cam, pts)
        cv2.polylines(img, [np.round(uv * 4).astype(np.int32)], False, (230, 230, 230), 2,
                      cv2.LINE_AA, shift=2)
    return img


def draw_ball(img: np.ndarray, uv: np.ndarray, r_px: float) -> None:
    def q(x: float) -> int:
        return round(float(x) * 16)

    cv2.circle(img, (q(uv[0]), q(uv[1])), q(r_px), (20, 110, 245), -1, cv2.LINE_AA, shift=4)
    cv2.circle(img, (q(uv[0] - r_px / 3), q(uv[1] - r_px / 3)), q(r_px / 3), (90, 170, 255), -1,
               cv2.LINE_AA, shift=4)


def capture(cam: dict, k: int, ts, ps) -> tuple[float, float, np.ndarray]:
    """Frame ``k`` of ``cam``: its logged time, the ball's true capture time (the camera's
    clock offset and drift, and on a rolling shutter the ball's row: iterated) and the
    ball's pixel there."""
    logged = k / FPS + cam["phase"]
    base = logged + cam["off"] + cam["drift"] * 1e-6 * logged
    tt = base
    for _ in range(3):
        uv = project(cam, ball_at(ts, ps, np.array([tt]))[0])[0]
        tt = base + cam["readout"] * uv[1] / cam["h"]
    return logged, tt, uv


def render_video(cam: dict, ts, ps, duration: float, path: Path, fourcc: str,
                 rng: np.random.Generator) -> int:
    bg = background(cam, rng)
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), FPS, (cam["w"], cam["h"]))
    n = int(duration * FPS)
    for k in range(n):
        _, tt, uv = capture(cam, k, ts, ps)
        x = ball_at(ts, ps, np.array([tt]))[0]
        depth = (cam["R"] @ x + cam["t"])[2]
        img = bg.copy()
        draw_ball(img, uv, cam["K"][0, 0] * RADIUS / depth)
        noise = rng.normal(0, 2.0, img.shape)
        vw.write((img + noise).clip(0, 255).astype(np.uint8))
    vw.release()
    return n


def chessboard_shots(cam: dict, folder: Path, rng: np.random.Generator, count: int = 14) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    h, w = cam["h"], cam["w"]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    sq = 0.025
    cols, rows = 10, 7  # squares: 9 x 6 inner corners
    for j in range(count):
        # the board 0.5-0.9 m in front of the camera, tilted
        rv = rng.uniform(-0.45, 0.45, 3)
        rb, _ = cv2.Rodrigues(rv)
        dist_m = rng.uniform(0.5, 0.9)
        centre = np.array([rng.uniform(-0.12, 0.12), rng.uniform(-0.08, 0.08), dist_m])
        origin = centre - rb @ np.array([cols * sq / 2, rows * sq / 2, 0])
        acc = np.zeros((h, w))
        for dx, dy in ((-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)):
            pix = np.stack([xs + dx, ys + dy], -1).reshape(-1, 1, 2)
            ray = cv2.undistortPoints(pix, cam["K"], cam["dist"]).reshape(-1, 2)
            d = np.c_[ray, np.ones(len(ray))]
            n = rb[:, 2]
            s = (n @ origin) / (d @ n)
            local = (s[:, None] * d - origin) @ rb
            cx = np.floor(local[:, 0] / sq)
            cy = np.floor(local[:, 1] / sq)
            inside = (cx >= 0) & (cx < cols) & (cy >= 0) & (cy < rows)
            val = np.where(inside, np.where((cx + cy) % 2 == 0, 20, 235), 150)
            acc += val.reshape(h, w) / 4
        img = (acc + rng.normal(0, 2, acc.shape)).clip(0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / f"shot{j:02d}.png"), img)


def surveyed_points(cam: dict, rng: np.random.Generator, path: Path) -> None:
    # markers on the floor and on poles of known heights around the field
    pts = []
    for x in np.linspace(0, 3, 7):
        for y in np.linspace(0, 2, 5):
            pts.append((x, y, 0.0 if (x + y) % 1 else 0.5))
    pts = np.array(pts)
    uv = project(cam, pts) + rng.normal(0, 0.5, (len(pts), 2))
    ok = (uv[:, 0] > 0) & (uv[:, 0] < cam["w"]) & (uv[:, 1] > 0) & (uv[:, 1] < cam["h"])
    with path.open("w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["x", "y", "z", "u", "v"])
        for p, q in zip(pts[ok], uv[ok], strict=True):
            wr.writerow([f"{p[0]:.4f}", f"{p[1]:.4f}", f"{p[2]:.4f}", f"{q[0]:.3f}",
                         f"{q[1]:.3f}"])


def write_true_rig(cams: list[dict], path: Path) -> None:
    lines = ['name = "walk42-true"', ""]
    for c in cams:
        lines += ["[[camera]]", f'name = "{c["name"]}"', f"width = {c['w']}",
                  f"height = {c['h']}", f"K = {c['K'].tolist()}", f"dist = {c['dist'].tolist()}",
                  f"R = {c['R'].tolist()}", f"t = {c['t'].tolist()}", "fps = 30.0",
                  f"offset = {c['phase']}", f"clock_offset = {c['off']}",
                  f"clock_drift_ppm = {c['drift']}", f"readout = {c['readout']}", ""]
    path.write_text("\n".join(lines))


def detector_csv(cams: list[dict], ts, ps, duration: float, path: Path,
                 rng: np.random.Generator) -> None:
    """Our own detector's output: Unix-epoch host times, 0.4 px noise, 4 % misses (no row)."""
    epoch = 1_780_000_000.25
    rows = []
    for c in cams:
        for k in range(int(duration * FPS)):
            logged, _, uv = capture(c, k, ts, ps)
            if rng.random() < 0.04:
                continue
            uv = uv + rng.normal(0, 0.4, 2)
            rows.append((c["name"], f"{epoch + logged:.6f}", f"{uv[0]:.3f}", f"{uv[1]:.3f}", k,
                         f"{rng.uniform(0.6, 0.99):.2f}"))
    rng.shuffle(rows)
    with path.open("w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["cam_id", "t_unix", "x_px", "y_px", "frame_no", "conf"])
        wr.writerows(rows)


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "/tmp/walk42/lab")
    duration = float(sys.argv[2]) if len(sys.argv) > 2 else 36.0
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(SEED)
    cams = [camera(i) for i in range(3)]
    write_true_rig(cams, out / "true_rig.toml")
    ts, ps = motion(SEED + 1, duration + 0.2)
    with (out / "mocap.csv").open("w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["t", "x", "y", "z"])
        for i in range(0, len(ts), 5):  # 200 Hz
            wr.writerow([f"{ts[i]:.3f}", *(f"{v:.5f}" for v in ps[i])])
    for c in cams:
        chessboard_shots(c, out / "chess" / c["name"], rng)
        surveyed_points(c, rng, out / f"points_{c['name']}.csv")
    detector_csv(cams, ts, ps, duration, out / "detector.csv", rng)
    kinds = [("mp4", "mp4v"), ("mp4", "mp4v"), ("avi", "MJPG")]
    for c, (ext, fourcc) in zip(cams, kinds, strict=True):
        n = render_video(c, ts, ps, duration, out / f"{c['name']}.{ext}", fourcc, rng)
        print(c["name"], n, "frames", file=sys.stderr)


if __name__ == "__main__":
    main()
