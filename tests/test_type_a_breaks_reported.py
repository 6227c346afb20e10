"""``--confirm-gaps breaks`` said where a user looks (session 37's walk): type A's points made
from the detections after them (the backward pass's, ``span_s`` < 0) are counted alike by
``pslog fuse``'s summary line, ``pslog eval`` (text and ``--json``) and the viewer's legend
(which draws no Figure 2 for them). Before, only the withheld points (``break``) were said:
a session whose every spanning point was replaced read as the default's, 15 replaced points
of a rally unmentioned anywhere but in ``span_s``'s sign."""

from __future__ import annotations

import json

import numpy as np

from pslog.log import read_session

SEED = 55001  # (session 37's walk: a paper3 rally, type-A shutters, 0.3 px)


def _legend(rrd) -> str:
    from rerun.chunk import RrdReader

    return " ".join(" ".join(str(v) for v in chunk.to_record_batch().to_pylist())
                    for chunk in RrdReader(rrd).stream() if chunk.entity_path == "/legend")


def test_fuse_eval_and_view_count_the_points_from_the_detections_after_them(tmp_path, cli):
    from viewers import save_rrd

    session = tmp_path / "rally.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                       "--noise-px", "0.3", "--seed", SEED, "-o", session)
    assert code == 0, err
    fused = tmp_path / "breaks.mcap"
    code, out, err = cli("fuse", session, "--method", "typeA", "--confirm-gaps", "breaks",
                         "-o", fused)
    assert code == 0, err
    track = read_session(fused).tracks["typeA"]
    n = int(np.count_nonzero(track.quality["span_s"] < 0))
    assert n > 1, n
    assert (f"; {n} points made from the detections after them (--confirm-gaps breaks: the "
            f"paper's construction spanned a velocity break of smooth's fit; span_s < 0)"
            ) in out, out

    code, out, err = cli("eval", fused)
    assert code == 0, err
    assert "points made from the detections after them (--confirm-gaps breaks" in out, out
    assert f"typeA     {n} of {len(track)} points" in out, out
    code, out, err = cli("eval", fused, "--json")
    assert code == 0, err
    (report,) = json.loads(out)
    assert report["backward_points"] == n

    rrd = tmp_path / "breaks.rrd"
    save_rrd([session, fused], rrd, methods="typeA")
    assert (f"{n} typeA points made from the detections after them (--confirm-gaps breaks: "
            f"span_s < 0, as pslog eval counts them) have none.") in _legend(rrd)

    # the default (kicks) replaces nothing, and none of them says so
    default = tmp_path / "kicks.mcap"
    code, out, err = cli("fuse", session, "--method", "typeA", "-o", default)
    assert code == 0, err
    assert "made from the detections after" not in out
    assert not np.any(read_session(default).tracks["typeA"].quality["span_s"] < 0)
    code, out, err = cli("eval", default)
    assert code == 0 and "made from the detections after" not in out, out
    assert "backward_points" not in json.loads(cli("eval", default, "--json")[1])[0]
