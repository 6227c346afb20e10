"""A hostile environment around a real ``pslog live`` process (session 41, hostile41): over
real UDP, honest frames of a simulated rally interleaved with malformed, truncated,
oversized, duplicated, reordered, past- and future-stamped datagrams and a camera the rig
lacks; the ``--out`` receiver closed mid-run; a flood of datagrams; a second fuser on the
busy port; then SIGINT. Prints what the fuser said and checks its promises.

Run: python live.py WORKDIR [SEED] (seeds 66000-66999)."""

from __future__ import annotations

import json
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

TREE = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(TREE))
from pslog.live.protocol import (  # noqa: E402
    DetectionDatagram,
    detection_datagrams,
    encode_detections,
)
from tests._live import rally_session  # noqa: E402

work = Path(sys.argv[1])
seed = int(sys.argv[2]) if len(sys.argv) > 2 else 66100
rnd = random.Random(seed)
ENV = {**os.environ, "PYTHONPATH": str(TREE), "PSLOG_PROGRESS": "off"}
problems: list[str] = []


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start(listen: int, out: int, record: Path, extra=()) -> tuple[subprocess.Popen, list]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "pslog.cli", "live", "--rig", "paper3", "--timing", "typeA",
         "--listen", f"udp://127.0.0.1:{listen}", "--out", f"udp://127.0.0.1:{out}",
         "--jsonl", "--record", record, "--status-every", "0.5", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    err: list[str] = []
    threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True).start()
    return proc, err


def wait_for(err: list[str], text: str, timeout: float = 120) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if any(text in line for line in err):
            return True
        time.sleep(0.05)
    return False


listen, out = free_port(), free_port()
record = work / "live.mcap"
record.unlink(missing_ok=True)
receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
receiver.bind(("127.0.0.1", out))
receiver.settimeout(0.01)
proc, err = start(listen, out, record)
out_lines: list[str] = []
threading.Thread(target=lambda: out_lines.extend(proc.stdout), daemon=True).start()
assert wait_for(err, "listening"), "".join(err)
print("ready:", err[-1].strip())

# a second fuser on the busy port
second = subprocess.run([sys.executable, "-m", "pslog.cli", "live", "--rig", "paper3",
                         "--listen", f"udp://127.0.0.1:{listen}", "--duration", "1"],
                        capture_output=True, text=True, env=ENV, timeout=120)
lines = [x for x in second.stderr.splitlines() if x.strip()]
print(f"busy port: exit {second.returncode}: {second.stderr.strip()!r}")
if second.returncode != 1 or len(lines) != 1 or "Traceback" in second.stderr:
    problems.append(f"busy port: {second.returncode} {second.stderr!r}")

rig, det = rally_session(3.0, seed=seed)
epoch = time.time_ns() + 200_000_000
frames = detection_datagrams(det, epoch, 1_000_000)
tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sent = {"honest": 0, "hostile": 0, "flood": 0}


def send(data: bytes, kind: str = "hostile") -> None:
    try:
        tx.sendto(data, ("127.0.0.1", listen))
        sent[kind] += 1
    except OSError as exc:
        sent.setdefault(f"send error {exc.errno}", 0)
        sent[f"send error {exc.errno}"] += 1


def hostile(d: DetectionDatagram) -> list[bytes]:
    good = encode_detections(d)
    t = d.t_capture_ns
    return rnd.sample([
        good,  # duplicate
        good[:rnd.randrange(0, len(good))],  # truncated
        good + bytes(rnd.randrange(1, 4000)),  # oversized
        os.urandom(rnd.randrange(0, 3000)),  # noise
        encode_detections(DetectionDatagram("cam9", d.sequence, d.frame_index, t, t, d.uv)),
        encode_detections(DetectionDatagram(d.camera, d.sequence + 1000, d.frame_index, t
                                            - 10**10, t, d.uv)),  # past
        encode_detections(DetectionDatagram(d.camera, d.sequence + 1, d.frame_index, t
                                            + 86400 * 10**9, t, d.uv)),  # future
        good[:4] + b"\x02" + good[5:],  # version 2
        good[:40] + b"\xff" * 4 + good[44:],  # name not UTF-8
        good[:6] + (65).to_bytes(2, "little") + good[8:],  # k = 65
        b"",  # empty
    ], 3)


held = None
closed_receiver = flooded = False
for i, d in enumerate(frames):
    wait = (d.t_capture_ns - time.time_ns()) / 1e9
    if wait > 0:
        time.sleep(wait)
    if held is not None:  # out of order: the held frame after its successor
        send(encode_detections(d), "honest")
        send(encode_detections(held), "honest")
        held = None
    elif rnd.random() < 0.05:
        held = d
    else:
        send(encode_detections(d), "honest")
    for bad in hostile(d) if rnd.random() < 0.3 else ():
        send(bad)
    if i == len(frames) // 3 and not closed_receiver:
        receiver.close()  # the robot goes away
        closed_receiver = True
    if i == len(frames) // 2 and not flooded:
        flooded = True
        good = encode_detections(d)
        for _ in range(60_000):  # as fast as the socket takes them
            send(rnd.choice([os.urandom(rnd.randrange(0, 2200)), good, good[:30]]), "flood")
        send(bytes(65_000), "flood")  # the largest a UDP datagram carries (about)
time.sleep(1.0)
if proc.poll() is not None:
    problems.append(f"live ended by itself: exit {proc.returncode}")
proc.send_signal(signal.SIGINT)
try:
    code = proc.wait(120)
except subprocess.TimeoutExpired:
    proc.kill()
    code = None
    problems.append("HANG after SIGINT")
time.sleep(0.5)
text = "".join(err)
print("sent:", sent)
print("exit:", code)
print("stderr tail:\n" + "".join(err[-4:]))
if code != 0:
    problems.append(f"exit {code}")
if "Traceback" in text or "Warning:" in text:
    problems.append("traceback or warning on stderr")
if "drops:" not in text:
    problems.append("no drops said")
bad_json = 0
for line in out_lines:
    try:
        json.loads(line)
    except ValueError:
        bad_json += 1
print(f"jsonl: {len(out_lines)} lines, {bad_json} not JSON")
if bad_json or not out_lines:
    problems.append(f"jsonl {len(out_lines)} lines, {bad_json} bad")
info = subprocess.run([sys.executable, "-m", "pslog.cli", "info", record],
                      capture_output=True, text=True, env=ENV)
print(f"info of the recording: exit {info.returncode}; {info.stdout.splitlines()[:2]}")
if info.returncode != 0:
    problems.append(f"info {info.returncode} {info.stderr!r}")
print("PROBLEMS:", problems or "none")
