"""Type A after unseen kicks, confirmed offline (``FusionOptions.confirm_every``, ``pslog fuse
--confirm-gaps all``): every point, not only the long-gap ones, is tested against the next
detection of another camera (pslog.fusion.confirm's test) and dropped when contradicted; a
point nothing can check is kept unless it bridged a long gap. On the tests' own rallies
(paper3, 0.3 px, seeds 300 and 302) the default keeps one point beyond 5 cm just after a
kick, which the option leaves out for two to three points in all (docs/methods.md, "Type A
after kicks, confirmed offline (session 29)")."""

from __future__ import annotations

import numpy as np
import pytest
from _rally import dirty_rally
from numpy.testing import assert_array_equal

from pslog.errors import FusionError
from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions, fuse, type_a_explained
from pslog.fusion._prepare import prepare
from pslog.fusion.stream import StreamFuser
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate

EVERY = FusionOptions(confirm_every=True)


@pytest.fixture(autouse=True)
def _paper_default(monkeypatch):
    """The default as the option was measured against (session 29): without the
    innovation's wait (session 32, ``confirm.WAIT_SIGMAS``), which leaves out seed 300's
    far point by itself (``tests/test_type_a_kick_wait.py``)."""
    import pslog.fusion.confirm as confirm

    monkeypatch.setattr(confirm, "WAIT_SIGMAS", None)


def _session(seed: int):
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion, kicks = dirty_rally(seed)
    det, truth = simulate(rig, motion, 8.0, SimulationOptions(noise_px=0.3, seed=seed))[:2]
    return rig, det, truth, np.asarray(kicks)


def _keys(track) -> list[tuple[int, int]]:
    return list(zip(track.time_ns.tolist(), track.camera.tolist(), strict=True))


@pytest.mark.parametrize("seed", [300, 302])
def test_every_point_tested_leaves_out_the_point_after_a_kick_and_little_else(seed):
    rig, det, truth, kicks = _session(seed)
    paper = fuse(det, rig, "typeA")
    every = fuse(det, rig, "typeA", EVERY)
    far = errors_m(paper, truth) > 0.05
    assert far.sum() == 1  # the paper's point just after a kick (the eq. (2) depth)
    t_far = paper.time_ns[far][0] / 1e9
    assert 0 < t_far - kicks[kicks <= t_far].max() < 0.04
    assert np.all(errors_m(every, truth) <= 0.05)
    # only drops: the points kept are the paper's, to the bit, and few are left out
    keep = np.isin(paper.time_ns * 8 + paper.camera, every.time_ns * 8 + every.camera)
    assert _keys(every) == [k for k, kept in zip(_keys(paper), keep, strict=True) if kept]
    assert_array_equal(every.position_world, paper.position_world[keep])
    for name, column in every.quality.items():
        assert_array_equal(column, paper.quality[name][keep], err_msg=name)
    assert not keep[far].any()
    lost = len(paper) - len(every)
    assert 1 <= lost <= 3, lost
    assert (every.dropped["contradicted"] - paper.dropped.get("contradicted", 0)) == lost
    # a point nothing can check (no later detection of another camera: the session's end)
    # is kept unless it bridged a long gap, as without the option
    assert every.dropped.get("unconfirmed", 0) == paper.dropped.get("unconfirmed", 0)
    assert _keys(every)[-1] == _keys(paper)[-1]


def test_type_a_explained_makes_the_same_points():
    rig, det, _truth, _ = _session(300)
    obs = det.best()
    explained = type_a_explained(prepare(obs, rig), rig, EVERY)[0]
    plain = fuse(obs, rig, "typeA", EVERY)
    assert_array_equal(explained.time_ns, plain.time_ns)
    assert_array_equal(explained.position_world, plain.position_world)
    assert len(plain) < len(fuse(obs, rig, "typeA"))


def test_a_stream_refuses_it_and_live_turns_it_off():
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    with pytest.raises(FusionError, match="offline only"):
        StreamFuser(rig, "typeA", EVERY)
    from pslog.live.fuser import LiveFuser

    options = LiveFuser(rig, "typeA", options=EVERY).options
    assert not options.confirm_gaps and not options.confirm_every


def test_fuse_confirm_gaps_all_is_the_option(tmp_path, cli):
    from pslog.log import SessionWriter, read_session

    rig, det, _truth, _ = _session(302)
    path = tmp_path / "rally.mcap"
    with SessionWriter(path, rig, timing="typeA", source="test") as writer:
        writer.add_detections(det)
    out = tmp_path / "fused.mcap"
    code, _, err = cli("fuse", path, "--method", "typeA", "--confirm-gaps", "all", "-o", out)
    assert code == 0, err
    track = read_session(out).tracks["typeA"]
    every = fuse(det, rig, "typeA", EVERY)
    assert_array_equal(track.time_ns, every.time_ns)
    assert_array_equal(track.position_world, every.position_world)
    assert len(every) < len(fuse(det, rig, "typeA"))


def test_confirm_every_needs_confirm_gaps():
    """Every point confirmed as the long-gap ones are: without confirm_gaps it would be
    ignored, so it is refused (one line)."""
    with pytest.raises(FusionError, match="confirm_every needs confirm_gaps"):
        FusionOptions(confirm_gaps=False, confirm_every=True)
