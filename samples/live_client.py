"""A robot controller's side of `pslog live --out udp://HOST:PORT`: receive the 3D points.

Run: python samples/live_client.py [HOST:PORT] [COUNT]   (default 127.0.0.1:10010, forever;
with a COUNT it gives up after 30 s without a point)
Layout of the 224-byte point datagram: docs/live.md (pslog.live.protocol). No pslog needed.
"""
import socket
import struct
import sys
import time

POINT = struct.Struct("<4sBBBBQqqq3d6ddII3d3d32s16s")  # little-endian, 224 bytes

host, _, port = (sys.argv[1] if len(sys.argv) > 1 else "127.0.0.1:10010").rpartition(":")
count = int(sys.argv[2]) if len(sys.argv) > 2 else -1
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind((host, int(port)))
if count > 0:
    sock.settimeout(30.0)  # a run that ended before COUNT points: do not wait for ever
print(f"listening on udp://{host}:{port}", flush=True)
while count != 0:
    try:
        data = sock.recv(1024)
    except TimeoutError:
        sys.exit(f"no point for 30 s: {count} of {sys.argv[2]} not received")
    if len(data) != POINT.size or data[:5] != b"PSLP\x01":
        continue  # not a version-1 point datagram
    f = POINT.unpack(data)
    seq, t_capture, t_emit = f[5], f[6], f[7]
    x, y, z = f[9:12]
    vx, vy, vz = f[24:27]  # predicted velocity at t_emit (NaN: the method has none)
    camera, method = f[27][:f[3]].decode(), f[28][:f[4]].decode()
    age_ms = (time.time_ns() - t_capture) / 1e6  # capture to now, same wall clock
    print(f"{seq} {method} {camera} t={t_capture / 1e9:.6f} x={x:.4f} y={y:.4f} z={z:.4f} "
          f"v=({vx:.2f},{vy:.2f},{vz:.2f}) age={age_ms:.2f}ms", flush=True)
    count -= 1
