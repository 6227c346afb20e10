"""walk41's robot-side receiver, written from docs/live.md's PSLP table alone (no pslog).

    python walk41_receiver.py HOST:PORT SECONDS OUT.json

Collects point datagrams for SECONDS after the first one, checks every field the docs
promise (magic/version, 224 bytes, sequence +1, camera index vs name, mask bit of the
camera, covariance symmetric positive definite, emit >= arrival >= capture) and writes the
points and the latencies (arrival->emit, capture->emit, capture->receipt) as JSON.
"""
import json
import socket
import struct
import sys
import time

import numpy as np

POINT = struct.Struct("<4sBBBBQqqq3d6ddII3d3d32s16s")
assert POINT.size == 224
host, _, port = sys.argv[1].rpartition(":")
seconds = float(sys.argv[2])
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind((host, int(port)))
sock.settimeout(90.0)
pts, problems, first = [], [], None
while first is None or time.monotonic() - first < seconds:
    try:
        data = sock.recv(4096)
    except TimeoutError:
        break
    now = time.time_ns()
    if first is None:
        first = time.monotonic()
        sock.settimeout(2.0)  # the run's end: 2 s without a point
    if len(data) != 224 or data[:5] != b"PSLP\x01":
        problems.append(f"bad datagram {len(data)} {data[:5]!r}")
        continue
    f = POINT.unpack(data)
    cam_idx, seq, t_cap, t_emit, t_arr = f[2], f[5], f[6], f[7], f[8]
    xyz = f[9:12]
    c = f[12:18]
    cov = np.array([[c[0], c[1], c[2]], [c[1], c[3], c[4]], [c[2], c[4], c[5]]])
    resid, mask, flags = f[18], f[19], f[20]
    cam = f[27][:f[3]].decode()
    method = f[28][:f[4]].decode()
    if pts and seq != pts[-1]["seq"] + 1:
        problems.append(f"sequence jump {pts[-1]['seq']} -> {seq}")
    if not mask & (1 << cam_idx):
        problems.append(f"seq {seq}: mask {mask:b} lacks camera {cam_idx} ({cam})")
    if not (t_cap <= t_arr <= t_emit):
        problems.append(f"seq {seq}: times not ordered cap {t_cap} arr {t_arr} emit {t_emit}")
    if np.all(np.isfinite(cov)) and np.linalg.eigvalsh(cov).min() <= 0:
        problems.append(f"seq {seq}: covariance not positive definite")
    std = float(np.sqrt(np.trace(cov) / 3)) if np.all(np.isfinite(cov)) else None
    pts.append(dict(seq=seq, cam=cam, cam_idx=cam_idx, method=method, t=t_cap / 1e9,
                    xyz=list(xyz), std_m=std, resid=resid, mask=mask, flags=flags,
                    fuse_ms=(t_emit - t_arr) / 1e6, e2e_ms=(t_emit - t_cap) / 1e6,
                    recv_ms=(now - t_cap) / 1e6))
json.dump(dict(points=pts, problems=problems), open(sys.argv[3], "w"))
lat = np.array([p["fuse_ms"] for p in pts]) if pts else np.zeros(1)
rec = np.array([p["recv_ms"] for p in pts]) if pts else np.zeros(1)
print(f"{len(pts)} points, {len(problems)} problems; arrival->emit median {np.median(lat):.3f} "
      f"p99 {np.percentile(lat, 99):.3f} ms; capture->receipt median {np.median(rec):.3f} "
      f"p99 {np.percentile(rec, 99):.3f} ms")
for p in problems[:10]:
    print("  problem:", p)
