"""A synced copy synced again (session 38): ``pslog sync`` of a copy ``pslog sync`` wrote
starts from the clock model recorded before the first sync (stored with the estimates as
``prior`` in the ``clock_std`` metadata, carried from sync to sync), so syncing twice or
three times gives the first sync's clocks and covariance. Before, the second sync started
from the first one's estimates and tested them as known values: the readouts of a tied sync
were then kept with σ 0 (paper3, 12 ms readouts, seed 57310: smooth's NEES 1.35 -> 3.41).
Through ``pslog`` as a process, on sessions ``pslog simulate`` writes."""

from __future__ import annotations

import json

import numpy as np
from _cli import pslog_ok as _pslog

from pslog.log import read_session
from pslog.timing import CLOCK_KEYS


def _clocks(path) -> tuple[list, dict]:
    session = read_session(path)
    stored = json.loads(session.metadata["clock_std"])
    return ([[getattr(c, k) for k in CLOCK_KEYS] for c in session.rig.cameras], stored)


def _simulate(raw, seed: int, cam3: bool = False) -> None:
    """A paper3 rally of 8 s at 0.3 px whose clocks need a sync: ``cam2`` 5 ms off (and
    ``cam3`` -7 ms), 12 ms rolling shutters, written to ``raw``."""
    _pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
           "--duration", "8", "--noise-px", "0.3", "--clock-offset", "cam2=5",
           *(("--clock-offset", "cam3=-7") if cam3 else ()), "--readout", "12",
           "--seed", seed, "-o", raw)


def test_syncing_twice_gives_the_first_syncs_clocks_and_covariance(tmp_path):
    raw = tmp_path / "raw.mcap"
    _simulate(raw, 38101, cam3=True)
    once, twice, thrice = (tmp_path / f"{n}.mcap" for n in ("once", "twice", "thrice"))
    first = json.loads(_pslog("sync", raw, "-o", once, "--json"))
    assert first["estimated"] == ["offset", "readout"]  # (the readouts kept: the case)
    out = _pslog("sync", once, "-o", twice)
    assert "synced before: estimated again from the clock model recorded before its first " \
           "sync" in out, out
    second = json.loads(_pslog("sync", twice, "-o", thrice, "--json"))
    clocks, stored = _clocks(once)
    assert stored["prior"] == {name: dict.fromkeys(CLOCK_KEYS, 0.0)
                               for name in ("cam1", "cam2", "cam3")}
    for again in (twice, thrice):
        clocks2, stored2 = _clocks(again)
        assert clocks2 == clocks  # the same fit: the same values to the bit
        assert stored2["covariance"] == stored["covariance"]
        assert stored2["prior"] == stored["prior"]  # (carried, not the first's estimates)
    assert second["estimated"] == first["estimated"]
    assert second["shared_readout"] == first["shared_readout"]
    # the readouts keep their uncertainty (before: σ 0, the first sync's values as exact)
    assert all(c["readout_std_s"] > 1e-4 for c in second["cameras"]), second["cameras"]
    assert [c["readout_std_s"] for c in second["cameras"]] == \
        [c["readout_std_s"] for c in first["cameras"]]


def test_a_rig_value_changed_since_the_sync_is_kept(tmp_path):
    """A clock value that is no longer the one the sync stored (a rig edited since, here
    through ``pslog rig show`` and ``pslog import``, which keeps no metadata) is the user's:
    a sync starts from it. (The import keeps no ``clock_std``: the imported session's
    readouts are the rig's, and the sync tests against them.)"""
    raw = tmp_path / "raw.mcap"
    _simulate(raw, 38102)
    once = tmp_path / "once.mcap"
    _pslog("sync", raw, "-o", once)
    (tmp_path / "rig.toml").write_text(_pslog("rig", "show", once))
    _pslog("export", once, "--detections", tmp_path / "det.csv")
    imported = tmp_path / "imported.mcap"
    _pslog("import", "--rig", tmp_path / "rig.toml", "--detections", tmp_path / "det.csv",
           "-o", imported)
    assert "clock_std" not in read_session(imported).metadata
    out = _pslog("sync", imported, "-o", tmp_path / "again.mcap")
    assert "synced before" not in out
    readouts = {c.name: c.readout for c in read_session(once).rig.cameras}
    stored = json.loads(read_session(tmp_path / "again.mcap").metadata["clock_std"])
    assert {n: v["readout"] for n, v in stored["prior"].items()} == readouts
    np.testing.assert_array_less(0.004, list(readouts.values()))


def test_a_copy_synced_without_its_prior_says_what_it_holds(tmp_path):
    """A copy synced before session 38 holds no ``prior``: its estimates cannot be undone,
    and the sync says so (and how to estimate them again) instead of holding them as known
    in silence. Such a copy made here: session 38's copy with the ``prior`` removed."""
    from pslog.log import copy_session

    raw = tmp_path / "raw.mcap"
    _simulate(raw, 38103)
    once = tmp_path / "once.mcap"
    _pslog("sync", raw, "-o", once)
    stored = json.loads(read_session(once).metadata["clock_std"])
    del stored["prior"]
    old = tmp_path / "old.mcap"
    copy_session(once, old, metadata={"clock_std": json.dumps(stored)})
    out = _pslog("sync", old, "-o", tmp_path / "again.mcap")
    assert "synced before by a pslog that did not record the clock model it started " \
           "from" in out, out
    assert "synced before: estimated again" not in out
    # and every later sync of it says so again: its recorded model is that copy's estimates
    # (recorded with the copy: review38 found the second sync silent)
    assert json.loads(read_session(tmp_path / "again.mcap").metadata["clock_std"])[
        "prior_estimated"] is True
    out = _pslog("sync", tmp_path / "again.mcap", "-o", tmp_path / "thrice.mcap")
    assert "synced before by a pslog that did not record the clock model it started " \
           "from" in out, out
    assert "synced before" not in _pslog("sync", raw, "-o", tmp_path / "fresh.mcap")
    assert "prior_estimated" not in read_session(tmp_path / "fresh.mcap").metadata["clock_std"]


def test_a_parameter_the_new_sync_does_not_estimate_keeps_the_copys_value(tmp_path):
    """A copy synced for its offsets, synced again for its readouts alone (``--estimate
    readout``): the offsets are not estimated, so they stay the copy's (the first sync's),
    as the table says ("kept at the rig's values"), and the readouts are fitted at them.
    Found in session 38's review: every value the first sync stored was put back to its
    ``prior``, the offsets too — the copy's 4.562 / -7.143 ms became 0 / 0 in silence and
    the readouts absorbed them (9.1 / 16.6 / -1.9 ms, cam3's clipped to 0; the truth 12)."""
    raw = tmp_path / "raw.mcap"
    _simulate(raw, 38101, cam3=True)
    once, twice = tmp_path / "once.mcap", tmp_path / "twice.mcap"
    _pslog("sync", raw, "-o", once, "--estimate", "offset")
    out = _pslog("sync", once, "-o", twice, "--estimate", "readout")
    assert "synced before" not in out  # (nothing put back: the readouts were the prior's)
    offsets = [c.clock_offset for c in read_session(once).rig.cameras]
    assert abs(offsets[1] - 0.005) < 0.002 and abs(offsets[2] + 0.007) < 0.002
    synced = read_session(twice).rig.cameras
    assert [c.clock_offset for c in synced] == offsets
    assert all(0.004 < c.readout < 0.020 for c in synced), [c.readout for c in synced]
    # the model before the first sync is carried, the kept offsets' too (review39: the copy
    # recorded the first sync's offsets as its prior, and a third sync started from them,
    # its note saying it started from the model recorded before the first sync): a third
    # sync of both parameters is the same sync of the session itself
    stored = json.loads(read_session(twice).metadata["clock_std"])
    assert stored["prior"] == json.loads(read_session(once).metadata["clock_std"])["prior"]
    thrice, fresh = tmp_path / "thrice.mcap", tmp_path / "fresh.mcap"
    _pslog("sync", twice, "-o", thrice, "--estimate", "offset,readout")
    _pslog("sync", raw, "-o", fresh, "--estimate", "offset,readout")
    assert _clocks(thrice)[0] == _clocks(fresh)[0]


def test_auto_keeps_a_drift_it_does_not_try_where_the_ball_spans_less_than_30_s(tmp_path):
    """``--estimate auto`` tries drifts on the ball's observations' span (30 s or more,
    select_clocks): a copy synced for its drifts, synced again with auto where the ball is
    seen 10 s of a 31 s session, keeps them (auto does not estimate them: "kept at the
    rig's values"), the offsets estimated again at them. Found in session 39's review: the
    span was the frames' (31 s), so the drifts were put back to the recorded 0 in silence
    (cam2's 221 ppm) and the offsets absorbed them (6.8 -> 12.6 ms; the truth 5)."""
    raw = tmp_path / "raw.mcap"
    _pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
           "--duration", "31", "--noise-px", "0.3", "--clock-offset", "cam2=5", "--drift",
           "cam2=300", *(a for cam in ("cam1", "cam2", "cam3")
                         for a in ("--blackout", f"{cam}=0:21")), "--seed", 60201, "-o", raw)
    once, twice = tmp_path / "once.mcap", tmp_path / "twice.mcap"
    _pslog("sync", raw, "-o", once, "--estimate", "offset,drift")
    out = _pslog("sync", once, "-o", twice)
    assert "drifts not estimated: not tried, the session (10 s) is shorter" in out, out
    drifts = [c.clock_drift_ppm for c in read_session(once).rig.cameras]
    assert drifts[1] > 100, drifts  # (the case: a drift the first sync estimated)
    synced = read_session(twice).rig.cameras
    assert [c.clock_drift_ppm for c in synced] == drifts
    assert abs(synced[1].clock_offset - read_session(once).rig.cameras[1].clock_offset) < 1e-5


def test_a_clock_value_edited_in_the_copys_rig_is_the_start_of_the_next_sync(tmp_path):
    """recorded_clocks puts back a recorded value only where the copy's rig still holds the
    value its sync stored: a copy whose cam2 offset was edited since (its rig replaced, the
    metadata kept) is synced from that edited offset, cam3's unedited one put back to the
    recorded 0 — the ``prior`` the new copy records. (The import test above keeps no
    metadata: it never reached this rule; without the rule's test this one fails.)"""
    from pslog.log import copy_session

    raw = tmp_path / "raw.mcap"
    _simulate(raw, 60202, cam3=True)
    once, edited, twice = (tmp_path / f"{n}.mcap" for n in ("once", "edited", "twice"))
    _pslog("sync", raw, "-o", once, "--estimate", "offset")
    rig = read_session(once).rig
    assert abs(rig.cameras[2].clock_offset + 0.007) < 0.002  # (the case: estimated)
    copy_session(once, edited, rig=rig.__class__(
        (rig.cameras[0], rig.cameras[1].replace(clock_offset=0.004), rig.cameras[2]),
        rig.name))
    assert "clock_std" in read_session(edited).metadata
    _pslog("sync", edited, "-o", twice, "--estimate", "offset")
    prior = json.loads(read_session(twice).metadata["clock_std"])["prior"]
    assert prior["cam2"]["clock_offset"] == 0.004
    assert prior["cam3"]["clock_offset"] == 0.0
