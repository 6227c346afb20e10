"""Session 26: a session whose first detections have no ray (a pixel beyond the image, NaN)
refused good N-view points.

The residual test's reprojection-weighted step (``stereo._weighted_points``) summed every
camera any point uses; an unused slot (row -1) read the ray of the row its index is clipped
to, row 0, with weight 0. Where row 0 has no ray, ``0 · NaN`` made the weighted point of
every point without that camera's ray NaN (81 of 152 on the session below), so those points
were tested on the unweighted intersection's ``d²`` alone, which refuses points the step
keeps (one camera noisier than another at its depth). An unused slot now adds ``0 · I``.

The rule checked on real files through ``pslog fuse``: what a point's test decides does not
depend on which detection comes first in the session. The session is fused as recorded
(its first detections without a ray) and with one more detection before them, alone
(no partner, 2 s before the next: no point, no image speed, no noise residual) and with a
ray: the same points, the same refusals.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_no_ray_detection import _fused

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import stereo as S
from pslog.fusion._prepare import prepare
from pslog.log import SessionWriter, read_session
from pslog.records import NS, Detections, Observations
from pslog.timing import observations as timed_observations

METHODS = ("sync", "typeB", "linear")


def _dirty(seed: int):
    """(rig, observations) of a 6 s paper3 rally at 2 px of noise with misses, drops, jitter
    and 3 % outliers a few pixels off, its times from 2 s on."""
    rig = apply_timing(builtin_rig("paper3"), "sync")
    det, _ = simulate(rig, get_motion("rally"), 6.0,
                      SimulationOptions(noise_px=2.0, miss_rate=0.2, drop_rate=0.05,
                                        jitter_s=2e-4, seed=seed))
    obs = timed_observations(det, rig)
    rng = np.random.default_rng(seed)
    uv = obs.uv.copy()
    off = rng.random(len(obs)) < 0.03
    uv[off] += rng.normal(0.0, 8.0, (int(off.sum()), 2))
    return rig, Observations(obs.time_ns - obs.time_ns[0] + 2 * NS, obs.camera, uv,
                             obs.frame_index)


def _write(path, rig, obs: Observations) -> None:
    with SessionWriter(path, rig, timing="sync", source="test") as writer:
        writer.add_detections(Detections.from_observations(
            [c.name for c in rig.cameras], obs))


@pytest.mark.parametrize("damaged,value", [((0,), 1e300), ((0,), np.nan)])
def test_points_do_not_depend_on_the_first_detection_having_a_ray(tmp_path, cli, damaged,
                                                                  value):
    rig, obs = _dirty(1)
    uv = obs.uv.copy()
    uv[list(damaged)] = value  # (no ray: beyond the image, or not a number)
    damaged_obs = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    prep = prepare(damaged_obs, rig)
    assert not np.isfinite(prep.ray_dir[0]).any()
    # one more detection 2 s before the rest, with a ray (the first camera's first one's
    # pixel), alone: it makes no point and enters no test
    first = np.flatnonzero(obs.camera == obs.camera[0])[len(damaged)]
    lead = Observations(np.r_[0, obs.time_ns], np.r_[obs.camera[0], obs.camera],
                        np.r_[obs.uv[first][None], uv], np.r_[0, obs.frame_index + 1])
    assert np.isfinite(prepare(lead, rig).ray_dir[0]).all()

    got, got_lines = _fused(tmp_path, cli, "damaged", rig, damaged_obs, METHODS, "sync")
    want, want_lines = _fused(tmp_path, cli, "lead", rig, lead, METHODS, "sync")
    assert got_lines == want_lines  # the points and the refusals counted
    for method in METHODS:
        g, w = got[method], want[method]
        np.testing.assert_array_equal(g.time_ns, w.time_ns)
        np.testing.assert_array_equal(g.position_world, w.position_world)


@pytest.mark.parametrize("damaged", [(0,), (0, 1, 2)])
def test_weighted_points_are_finite_whatever_row_0_holds(damaged):
    """The weighted step of every point of the session above, its first detection (or
    first three) without a ray: no NaN (with the fix undone: every point without that
    camera's ray, 77 of 149)."""
    rig, obs = _dirty(1)
    uv = obs.uv.copy()
    uv[list(damaged)] = 1e300
    points = []
    for o in (Observations(obs.time_ns, obs.camera, uv, obs.frame_index), obs):
        prep = prepare(o, rig)
        group, n_cameras = S.sync_groups(prep.obs, len(prep.centers), 1e-3)
        pts, _, time_ns, _, flags, rows, used = S.triangulate_groups(
            prep, group, len(n_cameras), 0.5, with_flags=True, with_rows=True)
        at = np.flatnonzero((n_cameras >= 2) & (flags == 0)
                            & np.all(np.isfinite(pts), axis=1))
        sigma = S.refusal_noise(prep, time_ns[at], 0.1, 0.5)
        points.append((time_ns[at], S._weighted_points(prep, rows[at], used[at], pts[at],
                                                       sigma)))
    (t_damaged, damaged), (t_intact, _) = points
    assert len(damaged) > 100 and np.isfinite(damaged).all()
    # the same points but the one row 0 makes
    common = np.isin(t_intact, t_damaged)
    assert common.sum() >= len(t_intact) - len(damaged)
    assert np.array_equal(t_damaged, t_intact[common])


@pytest.mark.parametrize("damaged", [(0,), (0, 1, 2)])
def test_smooth_skips_first_detections_without_a_ray_as_if_absent(tmp_path, cli, damaged):
    """``smooth`` leaves the detections without a ray out of its fit, but took its time
    origin (the spline's parameter, seconds since it) from the session's first detection,
    with a ray or not: every time's rounding differed from the session without those
    detections (every point by ~1e-10 m, and through the break search's decisions one by
    13.7 mm on this session's typeA-timed twin). Its origin is now the first usable
    detection: the session fused with its first detections beyond the image (``pslog
    fuse``, real files) gives the bits of the session without them, as a row in the middle
    or at the end did already."""
    rig, obs = _dirty(1)
    uv = obs.uv.copy()
    uv[list(damaged)] = 1e300
    keep = np.ones(len(obs), dtype=bool)
    keep[list(damaged)] = False
    tracks = []
    for name, o in (("damaged", Observations(obs.time_ns, obs.camera, uv, obs.frame_index)),
                    ("without", Observations(obs.time_ns[keep], obs.camera[keep],
                                             obs.uv[keep], obs.frame_index[keep]))):
        src, out = tmp_path / f"{name}.mcap", tmp_path / f"{name}_fused.mcap"
        _write(src, rig, o)
        code, _, err = cli("fuse", src, "--method", "smooth", "--gating", "off", "-o", out)
        assert code == 0, err
        tracks.append(read_session(out).tracks["smooth"])
    got, want = tracks
    assert len(got) > 300
    np.testing.assert_array_equal(got.time_ns, want.time_ns)
    assert got.position_world.tobytes() == want.position_world.tobytes()
    assert got.quality["std_m"].tobytes() == want.quality["std_m"].tobytes()
