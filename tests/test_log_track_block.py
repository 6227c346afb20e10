"""SessionWriter.add_track writes, block by block, the very bytes protobuf gives each point's
TrackPoint and SceneUpdate (pslog.log._encode), zeros, -0.0, NaN and long ids included."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader

from pslog.log import SessionWriter
from pslog.log import _schemas as S
from pslog.log import writer as W
from pslog.records import Track


def _track(n: int, method: str, extra: bool, rng) -> Track:
    t = np.sort(rng.integers(0, 10**13, n))
    t[0] = 0
    xyz = rng.normal(size=(n, 3))
    xyz[1::7, 0] = 0.0
    xyz[2::7, 1] = -0.0
    xyz[3::11] = 0.0
    xyz[4::13, 2] = np.nan
    quality = {"ray_miss_m": rng.random(n), "snap_px": np.where(rng.random(n) < .3, 0.0, 1.5)}
    if extra:
        quality["std_m"] = rng.random(n)
        quality["n_detections"] = rng.integers(0, 5, n).astype(float)
        quality["cov_xx_m2"] = np.where(rng.random(n) < .5, -0.0, 2e-5)
    return Track(method, t, xyz, rng.integers(0, 3, n).astype(np.int32), quality)


@pytest.mark.parametrize("extra", [True, False])
def test_track_blocks_are_protobufs_own_bytes(tmp_path, rig3, extra):
    rng = np.random.default_rng(5)
    n = W._TRACK_BLOCK + 1234  # more than one block
    tracks = [_track(n, "typeA", extra, rng), _track(300, "nearest", extra, rng)]
    path = tmp_path / "t.mcap"
    with SessionWriter(path, rig3) as w:
        for track in tracks:
            w.add_track(track)
        w.add_track(tracks[1])  # again: scene ids go on from 300
    got: dict[str, list[bytes]] = {}
    with open(path, "rb") as f:
        for _s, c, m in make_reader(f).iter_messages(log_time_order=False):
            got.setdefault(c.topic, []).append((m.log_time, m.data))
    for k, (track, first_id) in enumerate(((tracks[0], 0), (tracks[1], 0), (tracks[1], 300))):
        method, color = track.method, W.TRACK_COLORS[min(k, 1)]
        points = got[S.track_topic(method)]
        scenes = got[S.track_scene_topic(method)]
        if method == "nearest":
            points = points[first_id:first_id + len(track)]
            scenes = scenes[first_id:first_id + len(track)]
        for i in range(len(track)):
            x, y, z = track.position_world[i].tolist()
            t = int(track.time_ns[i])
            msg = S.TrackPoint(time_ns=t, method=method, x=x, y=y, z=z,
                               camera=rig3.names[track.camera[i]],
                               ray_miss_m=track.quality["ray_miss_m"][i],
                               snap_px=track.quality["snap_px"][i],
                               ray_shift_m=float("nan"))
            for key, values in track.quality.items():
                if key not in S.TRACK_FIXED_QUALITY:
                    msg.quality[key] = float(values[i])
            assert points[i] == (t, msg.SerializeToString()), (method, i)
            assert scenes[i] == (t, W.scene_point(method, first_id + i, t, (x, y, z), color))


def test_the_block_path_is_taken(rig3):
    """The blocks above are the numpy encoder's, not the per-point fallback's."""
    rng = np.random.default_rng(6)
    for extra in (True, False):
        track = _track(500, "typeA", extra, rng)
        fixed = {k: (track.quality[k].tolist() if k in track.quality else [float("nan")] * 500)
                 for k in S.TRACK_FIXED_QUALITY}
        template = W._quality_template({k: v for k, v in track.quality.items()
                                        if k not in S.TRACK_FIXED_QUALITY})
        block = W._track_block(track, 0, 500, "typeA", rig3.names, fixed, template, 0,
                               W.TRACK_COLORS[0], 1, 2)
        assert block is not None and len(block.time) == 1000
