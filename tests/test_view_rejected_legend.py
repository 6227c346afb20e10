"""pslog fuse's summary and the viewer's legend count the detections each method rejected
itself (smooth's fit, the filter's gate: points kept, flagged ``rejected``), as ``pslog
eval`` does; the images draw only one track's in grey, and a track whose are not drawn is
named with the command that draws them (session 36's walk: smooth's rejections were
invisible beside the filter's, the legend and fuse's summary silent)."""

from __future__ import annotations

import json
import shlex
import subprocess

import numpy as np

from pslog.cli import main
from pslog.log import read_session


def _rrd_legend_and_grey(rrd):
    from rerun.chunk import RrdReader

    legend, grey = "", 0
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/legend":
            legend += " ".join(str(v) for v in batch.to_pylist())
        if not chunk.is_static and chunk.entity_path.endswith("/image/rejected"):
            col = batch.column("Points2D:positions").to_pylist()
            grey += sum(len(p or []) for p in col)
    return legend, grey


def test_fuse_eval_and_view_count_each_methods_own_rejections_alike(tmp_path, capsys):
    from viewers import save_rrd

    session, fused = tmp_path / "my session.mcap", tmp_path / "fused.mcap"
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                 "--duration", "3", "--noise-px", "0.5", "--spurious", "0.3",
                 "--spurious-radius", "20", "--seed", "48012", "-o", str(session)]) == 0
    capsys.readouterr()
    assert main(["fuse", str(session), "--method", "filter", "--method", "smooth",
                 "-o", str(fused)]) == 0
    fuse_out = capsys.readouterr().out
    stored = read_session(fused)
    flagged = {m: int(np.count_nonzero(t.quality["rejected"] == 1))
               for m, t in stored.tracks.items()}
    assert flagged["filter"] == 0 and flagged["smooth"] > 0  # the case: smooth's not drawn
    # fuse's summary counts them as eval does (eval --json: rejected_detections)
    assert main(["eval", str(fused), "--json"]) == 0
    evaluated = {r["method"]: r.get("rejected_detections", 0)
                 for r in json.loads(capsys.readouterr().out)}
    assert evaluated == flagged
    # and its text says why smooth flags one (the deletion test's case named), not filter's
    assert main(["eval", str(fused)]) == 0
    text = capsys.readouterr().out
    assert f"smooth    {flagged['smooth']} of {len(stored.tracks['smooth'])} points" in text
    why = next(line for line in text.splitlines() if line.startswith("  smooth: its fit"))
    assert "beyond 4.3 σ of the fit's noise" in why and "the fit bent to it" in why, why
    assert "  filter: its gate" not in text
    smooth_line = next(line for line in fuse_out.splitlines() if line.startswith("smooth "))
    assert smooth_line.endswith(f"; {flagged['smooth']} flagged rejected (its fit rejected "
                                f"their detections, the points kept)"), smooth_line
    filter_line = next(line for line in fuse_out.splitlines() if line.startswith("filter "))
    assert "flagged rejected" not in filter_line, filter_line

    rrd = tmp_path / "both.rrd"
    save_rrd([session, fused], rrd, methods=["filter", "smooth"], frames="none")
    legend, grey = _rrd_legend_and_grey(rrd)
    assert "Rejected by the method" in legend and "filter none" in legend
    assert f"not drawn: smooth {flagged['smooth']} " in legend
    assert grey == len(stored.rejections["filter"])  # the filter's gating alone

    # the command the legend names, pasted into a shell, draws smooth's in grey
    command = legend.split("`pslog view ", 1)[1].split("`", 1)[0]
    words = subprocess.run(["bash", "-c", f"printf '%s\\n' {command}"], capture_output=True,
                           text=True, check=True).stdout.splitlines()
    assert words == [str(session), str(fused), "--method", "smooth"], shlex.join(words)
    rrd2 = tmp_path / "smooth.rrd"
    capsys.readouterr()
    assert main(["view", *words, "--frames", "none", "--save", str(rrd2)]) == 0
    legend2, grey2 = _rrd_legend_and_grey(rrd2)
    assert grey2 == len(stored.rejections["smooth"]) + flagged["smooth"]
    # view's summary counts the candidates it drew, kept and grey (not the frames)
    n_candidates = read_session(session).detections.n_candidates
    assert (f"logged {n_candidates - grey2} detections, {grey2} rejected candidates, "
            in capsys.readouterr().out)
    assert f"smooth {flagged['smooth']}, grey in the images too" in legend2
    assert "not drawn" not in legend2
