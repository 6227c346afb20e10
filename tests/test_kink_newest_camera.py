"""Type A's kink test, its newest-camera part (docs/methods.md, "Type A's kink test"): a kick
seen first by the newest camera, where that part alone decides. It is written twice, in
``type_a_kernel``'s loop (batch ``fuse``) and in ``_kinked`` (``kink_kernel``: the stream's
one-row pushes); the session below is decided by it in both, the same way.

The session: :func:`rectified_rig`'s two cameras (``left`` at the origin, ``right`` 0.5 m
along +x, both along +z, f = 500 px) at 30 fps, ``right`` 1/60 s after ``left``; no noise, no
gravity (the test's bound has ``g`` in it all the same); the ball at ``X = -0.3 + 4 s``,
``Y = 0.1``, ``Z = 2 + 3 s`` (metres, seconds), kicked back at 286 ms
(``X`` += ``-6 (s - 0.286)``). Around the kick the rows are ``left`` at 200 (``z``), 233.3
(``a``), 266.7 (``b``), 300 ms (``e``) and ``right`` at 216.7, 250 (``w``), 283.3 ms (``x``):
the kick lies between ``x`` and ``e``, so only ``e``, the newest detection, is after it.
For the point at ``e``:

- ``P_{t-1}`` is ``x`` (the previous instant), with ``left``'s bracket ``(b, e)`` (eq. (1)
  across the kick); ``P_{t-2}`` is ``b`` (``δ_pred = δ_prev``: a bounded extrapolation), with
  ``right``'s bracket ``(w, x)``; eq. (2) predicts along ``left``'s ray, so the prediction
  test passes (the interpolation used ``e`` itself).
- ``P_{t-1}``'s part: ``left``'s triplet ``(a, b, e)`` at ``P_{t-1}``'s depth does not bend
  (derived below); ``P_{t-2}``'s part: ``right``'s triplet around ``w`` (before the kick)
  does not bend.
- the newest camera's part: the same triplet ``(a, b, e)`` at the prediction's depth (deeper:
  the ball recedes) bends, the one before it, ``(z, a, b)``, does not: the change lies in
  ``(b, e)``, ``start = t_b``, which is ``P_{t-2}``'s time: refused (``start >= t_{t-2}``).
  Compared with ``P_{t-1}``'s time instead (``t_b < t_x``), or that part switched off, the
  point would be kept.
"""

from __future__ import annotations

import numpy as np
from test_fusion import BASELINE, CX, CY, F_PX, observations
from test_fusion_validity import rectified_rig
from test_stream_type_a import assert_same, pushed_one_by_one

from pslog.fusion import fuse
from pslog.fusion.innovation import DEFAULT_NOISE_PX, KINK_SIGMAS
from pslog.fusion.stream import StreamFuser
from pslog.motion import G
from pslog.records import NS, Track

KICK_MS = 286.0
PERIOD_MS = 1000.0 / 30.0


def _ball(ms: float) -> tuple[float, float, float]:
    """The ball (metres) at ``ms``: constant velocity, kicked back along x at KICK_MS."""
    s = ms / 1000.0
    x, y, z = -0.3 + 4.0 * s, 0.1, 2.0 + 3.0 * s
    if ms > KICK_MS:
        x += -6.0 * (ms - KICK_MS) / 1000.0
    return x, y, z


def _rows() -> list[tuple[float, int, float, float]]:
    """(ms, camera, u, v): 12 frames of each camera, exact pixels."""
    rows = []
    for k in range(12):
        for cam, offset in ((0, 0.0), (1, PERIOD_MS / 2)):
            ms = k * PERIOD_MS + offset
            x, y, z = _ball(ms)
            rows.append((ms, cam, F_PX * (x - cam * BASELINE) / z + CX, F_PX * y / z + CY))
    return rows


def _triangulated(u_left: float, u_right: float, v: float) -> np.ndarray:
    """The rectified pair's crossing (metres; rows are the epipolar lines, the snap sets
    the interpolated point's v to the observed one's)."""
    depth = F_PX * BASELINE / (u_left - u_right)
    return np.array([(u_left - CX) * depth / F_PX, (v - CY) * depth / F_PX, depth])


def _bend(uv: dict, t: dict, a: str, b: str, c: str, speed: float, depth: float):
    """|Δv| of one camera's triplet (px/s) and its bound at ``depth`` (the documented test,
    σ the default noise: too few points for a measured one)."""
    d1, d2 = (t[b] - t[a]) / NS, (t[c] - t[b]) / NS
    v1, v2 = (uv[b] - uv[a]) / d1, (uv[c] - uv[b]) / d2
    noise = KINK_SIGMAS * DEFAULT_NOISE_PX * np.sqrt(1 / d1**2 + (1 / d1 + 1 / d2) ** 2
                                                     + 1 / d2**2)
    offset = (uv[b] - [CX, CY]) / F_PX
    most = (F_PX * G * np.sqrt(1 + offset @ offset)
            + 2 * speed * max(np.linalg.norm(v1), np.linalg.norm(v2))) / depth
    return float(np.linalg.norm(v2 - v1)), float(noise + 0.5 * (d1 + d2) * most), float(noise)


def test_hand_derivation_the_newest_camera_alone_sees_the_kick():
    obs = observations(_rows())
    names = {"z": (0, 6), "a": (0, 7), "b": (0, 8), "e": (0, 9),
             "r": (1, 6), "w": (1, 7), "x": (1, 8)}  # (camera, frame)
    row = {n: int(np.flatnonzero((obs.camera == c)
                                 & (np.abs(obs.time_ns - (f * PERIOD_MS + c * PERIOD_MS / 2)
                                           * 1e6) < 1))[0]) for n, (c, f) in names.items()}
    t = {n: int(obs.time_ns[r]) for n, r in row.items()}
    uv = {n: obs.uv[r] for n, r in row.items()}
    assert t["x"] / 1e6 < KICK_MS < t["e"] / 1e6
    # P_{t-1}: x's ray and left's eq. (1) between b and e; P_{t-2}: b's and right's (w, x)
    w1 = (t["x"] - t["b"]) / (t["e"] - t["b"])
    p1 = _triangulated((1 - w1) * uv["b"][0] + w1 * uv["e"][0], uv["x"][0], uv["x"][1])
    w2 = (t["b"] - t["w"]) / (t["x"] - t["w"])
    p2 = _triangulated(uv["b"][0], (1 - w2) * uv["w"][0] + w2 * uv["x"][0], uv["b"][1])
    predicted = p1 + (p1 - p2) * (t["e"] - t["x"]) / (t["x"] - t["b"])
    speed = float(np.linalg.norm(p1 - p2) / ((t["x"] - t["b"]) / NS))
    # left's depth is z (its camera frame is the world's); the prediction is deeper
    assert predicted[2] > p1[2] + 0.2
    change, at_predicted, _ = _bend(uv, t, "a", "b", "e", speed, predicted[2])
    _, at_p1, _ = _bend(uv, t, "a", "b", "e", speed, p1[2])
    # the newest camera's part bends, P_{t-1}'s (the same triplet) does not, each by > 2 %
    assert at_predicted * 1.02 < change < at_p1 / 1.02, (at_predicted, change, at_p1)
    # (z, a, b) and right's (r, w, x) lie before the kick: within half the noise bound alone
    before, _, noise = _bend(uv, t, "z", "a", "b", speed, predicted[2])
    assert before < 0.5 * noise
    partner, _, noise = _bend(uv, t, "r", "w", "x", speed, p2[2])
    assert partner < 0.5 * noise
    # so the change lies in (b, e): it starts at t_b, P_{t-2}'s time, after P_{t-1}'s not
    assert t["b"] < t["x"]


def test_batch_and_stream_refuse_the_point_only_the_newest_camera_sees():
    rig = rectified_rig(offsets=(0.0, 1 / 60))
    obs = observations(_rows())
    batch = fuse(obs, rig, "typeA")
    e_ns = round(9 * PERIOD_MS * 1e6)  # left's first detection after the kick (e)
    # e refused by the kink test (its newest camera's part, derived above) and the two
    # next points (whose P_{t-1}'s partner bracket holds the kick); none failed otherwise
    assert batch.dropped == {"kink": 3}, batch.dropped
    assert e_ns not in set(batch.time_ns.tolist())
    # the points before e and the kick are made: e was a candidate like them
    assert {round(k * PERIOD_MS * 1e6) for k in (7, 8)} <= set(batch.time_ns.tolist())
    # the stream (one row a push: kink_kernel's _kinked) decides it the same way
    parts = pushed_one_by_one(StreamFuser(rig, "typeA"), obs)
    assert e_ns not in set(Track.concat(parts).time_ns.tolist())
    assert_same(parts, batch)
