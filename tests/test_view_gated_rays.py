"""``pslog view`` of a session and its fused copy draws each frame's ray and epipolar lines
from the candidate the stored gating chose, as its detections and tracks are (walk38): it
drew them from the best-scored candidate, and a static orange object every camera sees,
best-scored in most frames, drew 370 of a webcam's 599 rays and their epipolar lines to the
object while the ball's track flew beside them; and a session shown alone (type A fused on
the fly, gated) drew the best-scored candidate as the detection, the ball grey. Through
the real CLI on sessions ``pslog simulate`` writes; the .rrd read back."""

from __future__ import annotations

import numpy as np
from _cli import pslog as _pslog
from _rrd import batch_column, temporal_chunks

from pslog.log import read_session

OBJECT = np.array([1.0, 2.0, 0.1])


def _rejected(det, rej) -> np.ndarray:
    """(C,) bool: the candidates the stored rejections hold (camera, frame, pixel)."""
    keys = set(zip(rej.camera.tolist(), rej.frame_index.tolist(), rej.uv[:, 0].tolist(),
                   rej.uv[:, 1].tolist(), strict=True))
    rows = det.cand_frame
    return np.array([k in keys for k in zip(
        det.frame_camera[rows].tolist(), det.frame_index[rows].tolist(),
        det.cand_uv[:, 0].tolist(), det.cand_uv[:, 1].tolist(), strict=True)], dtype=bool)


def test_rays_and_epipolar_lines_follow_the_gates_choice_not_the_best_score(tmp_path):
    session, fused, rrd = tmp_path / "s.mcap", tmp_path / "f.mcap", tmp_path / "v.rrd"
    for args in (("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                  "--duration", "3", "--noise-px", "0.3", "--distractor", "1.0,2.0,0.1",
                  "--seed", "38001", "-o", session),
                 ("fuse", session, "--method", "typeA", "-o", fused),
                 ("view", session, fused, "--frames", "none", "--save", rrd)):
        done = _pslog(*args)
        assert done.returncode == 0, done.stderr
    stored = read_session(fused)
    det, rig = stored.detections, stored.rig
    rejected = _rejected(det, stored.rejections["typeA"])
    chunks = temporal_chunks(rrd)
    best_on_object = chosen_on_object = 0
    for c, cam in enumerate(rig.cameras):
        mine = det.frame_camera[det.cand_frame] == c
        chosen = det.cand_uv[mine & ~rejected]
        best = det.cand_uv[mine & det.best_mask()]
        at = cam.project(OBJECT[None])[0][0]
        best_on_object += int(np.count_nonzero(np.linalg.norm(best - at, axis=1) < 3))
        on_object = int(np.count_nonzero(np.linalg.norm(chosen - at, axis=1) < 3))
        chosen_on_object += on_object
        rays = np.array([s[0] for s in batch_column(chunks[f"/world/rays/{cam.name}"],
                                                    "LineStrips3D:strips") if s])
        d = rays[:, 1] - rays[:, 0]
        d /= np.linalg.norm(d, axis=1)[:, None]
        toward = (OBJECT - cam.center_world) / np.linalg.norm(OBJECT - cam.center_world)
        drawn = int(np.count_nonzero(d @ toward > np.cos(np.radians(0.3))))
        assert drawn == on_object, (cam.name, drawn, on_object)  # the object's: the gate's
        assert len(rays) == len(chosen), cam.name  # one per chosen detection
        # each other camera's epipolar lines: one per chosen detection of this camera
        other = rig.cameras[(c + 1) % len(rig)].name
        lines = batch_column(chunks[f"/world/cameras/{other}/image/epipolar/{cam.name}"],
                             "LineStrips2D:strips")
        assert sum(len(s or []) for s in lines) <= len(chosen)
    # the session alone (type A fused on the fly): the same gating, its rejections drawn
    # grey and its choices' rays (the best-scored candidate's before, the ball grey)
    alone = tmp_path / "alone.rrd"
    done = _pslog("view", session, "--frames", "none", "--save", alone)
    assert done.returncode == 0, done.stderr
    assert "fused on the fly: typeA" in done.stdout
    again = temporal_chunks(alone)
    for cam in rig.cameras:
        for entity, column in ((f"/world/rays/{cam.name}", "LineStrips3D:strips"),
                               (f"/world/cameras/{cam.name}/image/detections",
                                "Points2D:positions"),
                               (f"/world/cameras/{cam.name}/image/rejected",
                                "Points2D:positions")):
            assert batch_column(again[entity], column) == batch_column(chunks[entity],
                                                                       column), entity
    grey = sum(len(p or []) for cam in rig.cameras for p in batch_column(
        again[f"/world/cameras/{cam.name}/image/rejected"], "Points2D:positions"))
    assert grey == len(stored.rejections["typeA"])
    # the case: the object best-scored in many frames, the gate's choice in few
    assert best_on_object > 100 and chosen_on_object < 10, (best_on_object, chosen_on_object)
    print(f"object best-scored in {best_on_object} frames, chosen in {chosen_on_object}")
