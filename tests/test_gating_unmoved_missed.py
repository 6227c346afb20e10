"""The unmoved doubt at a session's start (``gating.unmoved``) when the ball was missed in
the camera's newest frame (walk38): a static orange object every camera sees, chosen
before the cameras can judge stillness, with the ball beside it in the choice's frame but
not in the frame before (5 % misses). The ball's candidate was then measured against that
frame's only candidate, the object, hundreds of pixels away: "from nowhere", no doubt, and
the filter's first points stood on the object, 0.92 m from the ball with std_m 10-22 mm.
Now it is measured against the newest frame that holds a candidate besides the choice.
Through the real CLI on a session ``pslog simulate`` writes (the new user's webcam rig)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _cli import pslog as _pslog

from pslog.log import read_session

WEBCAMS3 = Path(__file__).resolve().parents[1] / "benchmarks" / "webcams3.toml"


def test_a_missed_ball_does_not_hide_the_object_chosen_beside_it(tmp_path):
    head, *cameras = WEBCAMS3.read_text().split("[[camera]]")
    rig = tmp_path / "rig.toml"  # shutter phases 0 / 7.1 / 19.7 ms
    rig.write_text(head + "".join(
        "[[camera]]" + c.replace("offset = 0.0\n", f"offset = {phase}\n")
        for c, phase in zip(cameras, (0.0, 0.0071, 0.0197), strict=True)))
    session, fused = tmp_path / "lab.mcap", tmp_path / "fused.mcap"
    for args in (("simulate", "--rig", rig, "--motion", "rally", "--duration", "20",
                  "--noise-px", "0.5", "--miss-rate", "0.05", "--clock-offset", "cam2=6.4",
                  "--clock-offset", "cam3=-8.9", "--drift", "cam2=35", "--drift", "cam3=-22",
                  "--readout", "25", "--host-jitter", "2", "--spurious", "0.05",
                  "--distractor", "0.2,1.8,0.1", "--seed", "7", "-o", session),
                 ("fuse", session, "--method", "filter", "-o", fused)):
        done = _pslog(*args)
        assert done.returncode == 0, done.stderr
    stored = read_session(fused)
    track = stored.tracks["filter"]
    start = track.time_ns < 0.3e9
    error = np.linalg.norm(track.position_world - stored.truth.at(track.time_ns), axis=1)
    assert start.any()
    # before: a point at 0.101 s 0.92 m off (on the object), std_m 22 mm
    assert error[start].max() < 0.05, (track.time_ns[start] / 1e9, error[start])
    assert stored.left_out["filter"]["doubt"] >= 1
