"""Read walk41's exports back with third-party readers and compare with the fused session.

    python benchmarks/session41/walk41_readback.py FUSED.mcap DIR
    (DIR holds t.csv, traj/*.tum, t.jsonl, t.parquet, t.c3d from
     pslog export FUSED.mcap --csv DIR/t.csv --tum DIR/traj --jsonl DIR/t.jsonl
     --parquet DIR/t.parquet --c3d DIR/t.c3d)
"""
import csv
import json
import sys
import warnings
from pathlib import Path

import c3d
import numpy as np
import pyarrow.parquet as pq

from pslog.log import read_session

fused, d = read_session(sys.argv[1]), Path(sys.argv[2])
tracks = fused.tracks


def report(fmt, method, pos, ref):
    same = len(pos) == len(ref)
    diff = np.abs(np.asarray(pos) - ref).max() * 1e3 if same else float("nan")
    print(f"{fmt:8} {method:7} {len(pos):5} of {len(ref):5} points, max |diff| {diff:.3g} mm")


rows = list(csv.DictReader(open(d / "t.csv")))
print("csv columns:", ", ".join(list(rows[0])[:9]), "...")
for m, t in tracks.items():
    pos = [[float(r[k]) for k in "xyz"] for r in rows if r["method"] == m]
    report("csv", m, pos, t.position_world)
for m, t in tracks.items():
    a = np.loadtxt(d / "traj" / f"{m}.tum", comments="#")
    report("tum", m, a[:, 1:4], t.position_world)
    assert np.allclose(a[:, 0], t.time_ns / 1e9, atol=1e-9)
lines = [json.loads(x) for x in open(d / "t.jsonl")]
for m, t in tracks.items():
    report("jsonl", m, [x["position"] for x in lines if x["method"] == m], t.position_world)
tab = pq.read_table(d / "t.parquet").to_pydict()
for m, t in tracks.items():
    idx = [i for i, x in enumerate(tab["method"]) if x == m]
    report("parquet", m, [[tab[k][i] for k in "xyz"] for i in idx], t.position_world)
with open(d / "t.c3d", "rb") as f, warnings.catch_warnings():
    warnings.simplefilter("ignore")
    r = c3d.Reader(f)
    labels = [s.strip() for s in r.point_labels]
    units = r.get("POINT:UNITS").string_value.strip()
    first_s = float(r.get("PSLOG:FIRST_FRAME_S").string_value.strip())
    frames = np.array([p for _, p, _ in r.read_frames()])
    print(f"c3d: labels {labels}, units {units}, rate {r.point_rate} Hz, {len(frames)} frames")
for j, m in enumerate(labels[:-1]):
    t = tracks[m]
    valid = frames[:, j, 3] != -1
    k = np.round((t.time_ns / 1e9 - first_s) * r.point_rate).astype(int)
    ok = np.abs(frames[k, j, :3] / 1e3 - t.position_world).max()
    print(f"c3d      {m:7} {valid.sum():5} of {len(t):5} points valid, max |diff| at their "
          f"frames {ok * 1e3:.3g} mm, frame-time offset max "
          f"{np.abs(t.time_ns / 1e9 - first_s - k / r.point_rate).max() * 1e3:.3f} ms")
