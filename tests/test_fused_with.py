"""A fused track records the ``pslog fuse`` choices that shaped its points (session 45: type
A's ``--confirm-gaps``, whose default changed from ``kicks`` to ``jumps``): in its channel's
metadata (docs/log-format.md, ``fused_with``), read back as ``Session.fused_with``, printed
and given in JSON by ``pslog eval``, and kept by a copy that keeps the track.
"""

from __future__ import annotations

import json

from _cli import pslog_ok

from pslog.log import copy_session, read_session


def test_the_confirm_gaps_a_track_was_fused_with_is_recorded(tmp_path):
    session = tmp_path / "s.mcap"
    pslog_ok("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
             "--duration", "4", "--noise-px", "0.3", "--seed", "79701", "-o", session)
    default, kicks = tmp_path / "default.mcap", tmp_path / "kicks.mcap"
    pslog_ok("fuse", session, "-o", default, "--method", "typeA,nearest")
    pslog_ok("fuse", session, "-o", kicks, "--method", "typeA", "--confirm-gaps", "kicks")
    assert read_session(default).fused_with == {"typeA": {"confirm-gaps": "jumps"}}
    assert read_session(kicks).fused_with == {"typeA": {"confirm-gaps": "kicks"}}
    out = pslog_ok("eval", kicks)
    assert "fused with (the pslog fuse choices recorded with the track):\n" \
           "typeA     --confirm-gaps kicks" in out, out
    (report,) = json.loads(pslog_ok("eval", kicks, "--json"))
    assert report["fused_with"] == {"confirm-gaps": "kicks"}
    # a copy that keeps the track keeps its record (copy_session, replace_tracks=False)
    more = tmp_path / "more.mcap"
    smooth = read_session(default).tracks["nearest"]
    copy_session(kicks, more, tracks=[smooth], replace_tracks=False)
    assert read_session(more).fused_with == {"typeA": {"confirm-gaps": "kicks"}}
    assert set(read_session(more).tracks) == {"typeA", "nearest"}
    # no record for a session never fused, nor for the methods without such a choice
    assert read_session(session).fused_with == {}
