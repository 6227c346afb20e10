"""Fused tracks out to other tools: ``pslog export --tum DIR`` (evo), ``--jsonl``,
``--parquet`` and ``--c3d`` (pslog.interchange.track_formats)."""

from __future__ import annotations

import json
import subprocess
import sys
from decimal import Decimal

import numpy as np
import pytest

from pslog.log import read_session


@pytest.fixture(scope="module")
def fused(tmp_path_factory):
    """A simulated type-A session (with truth) fused by its default methods."""
    from pslog.cli import main

    folder = tmp_path_factory.mktemp("fused")
    sim, out = folder / "sim.mcap", folder / "fused.mcap"
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                 "--duration", "1.0", "--noise-px", "0.3", "-o", str(sim)]) == 0
    assert main(["fuse", str(sim), "-o", str(out)]) == 0
    return read_session(out)


def _ns(text: str) -> int:
    return int(Decimal(text) * 1_000_000_000)


def test_tum_files_hold_every_point_exactly_with_identity_orientation(fused, tmp_path, cli):
    folder = tmp_path / "traj"
    code, _, err = cli("export", fused.path, "--tum", folder)
    assert code == 0, err
    names = sorted(p.name for p in folder.iterdir())
    assert names == sorted([f"{m}.tum" for m in fused.tracks] + ["truth.tum"])
    for method, track in [*fused.tracks.items(), ("truth", fused.truth)]:
        lines = [line for line in (folder / f"{method}.tum").read_text().splitlines()
                 if not line.startswith("#")]
        assert len(lines) == len(track.time_ns)
        rows = [line.split(" ") for line in lines]
        assert all(len(r) == 8 for r in rows)  # evo: "must have 8 entries per row"
        assert [_ns(r[0]) for r in rows] == track.time_ns.tolist()  # exact ns
        np.testing.assert_array_equal(np.array([r[1:4] for r in rows], dtype=float),
                                      track.position_world)
        assert {tuple(r[4:]) for r in rows} == {("0", "0", "0", "1")}


def test_evo_ape_of_tum_files_agrees_with_pslog_truth_errors(fused, tmp_path, cli):
    """evo reads the files and its translation APE is pslog's error against the truth."""
    file_interface = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics, sync

    folder = tmp_path / "traj"
    assert cli("export", fused.path, "--tum", folder)[0] == 0
    truth = file_interface.read_tum_trajectory_file(str(folder / "truth.tum"))
    for method, track in fused.tracks.items():
        estimate = file_interface.read_tum_trajectory_file(str(folder / f"{method}.tum"))
        ref, est = sync.associate_trajectories(truth, estimate, max_diff=1e-6)
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((ref, est))
        ours = np.linalg.norm(track.position_world - fused.truth.at(track.time_ns), axis=1)
        assert len(ape.error) == len(ours)
        np.testing.assert_allclose(ape.get_statistic(metrics.StatisticsType.mean),
                                   ours.mean(), rtol=1e-9)


def test_tum_never_overwrites_without_force_and_replaces_with_it(fused, tmp_path, cli):
    folder = tmp_path / "traj"
    folder.mkdir()
    old = folder / "truth.tum"
    old.write_text("old\n")
    code, _, err = cli("export", fused.path, "--tum", folder)
    assert code == 1 and "--force" in err and "truth.tum" in err
    assert sorted(p.name for p in folder.iterdir()) == ["truth.tum"]  # none written
    assert old.read_text() == "old\n"
    assert cli("export", fused.path, "--tum", folder, "--force")[0] == 0
    assert old.read_text().startswith("#") and not list(folder.glob("*.partial"))


def test_tum_force_replaces_an_earlier_export_as_a_whole_and_keeps_other_files(fused,
                                                                              tmp_path, cli):
    """An earlier export's smooth.tum, for a method the new session lacks, would sit beside
    the new files (evo_ape then compares two sessions): refused without --force, removed
    with it; a .tum of another tool and any other file stay."""
    folder = tmp_path / "traj"
    assert cli("export", fused.path, "--tum", folder)[0] == 0
    assert (folder / "smooth.tum").exists()
    (folder / "mine.tum").write_text("0 1 2 3 0 0 0 1\n")
    (folder / "notes.txt").write_text("my notes\n")
    typea = tmp_path / "typeA.mcap"  # the same session fused by typeA only
    assert cli("fuse", fused.path, "--method", "typeA", "-o", typea)[0] == 0
    (folder / "typeA.tum").unlink()
    (folder / "truth.tum").unlink()  # no file of the new export exists: the old ones say no
    code, _, err = cli("export", typea, "--tum", folder)
    assert code == 1 and "earlier export" in err and "smooth.tum" in err and "--force" in err
    assert (folder / "smooth.tum").exists() and not (folder / "typeA.tum").exists()
    assert cli("export", typea, "--tum", folder, "--force")[0] == 0
    assert sorted(p.name for p in folder.iterdir()) == ["mine.tum", "notes.txt", "truth.tum",
                                                        "typeA.tum"]
    assert (folder / "mine.tum").read_text() == "0 1 2 3 0 0 0 1\n"


def test_jsonl_has_one_object_per_point(fused, tmp_path, cli):
    path = tmp_path / "t.jsonl"
    assert cli("export", fused.path, "--jsonl", path)[0] == 0
    records = [json.loads(line) for line in path.read_text().splitlines()]
    assert len(records) == sum(len(t) for t in fused.tracks.values())
    for method, track in fused.tracks.items():
        mine = [r for r in records if r["method"] == method]
        assert [r["time_ns"] for r in mine] == track.time_ns.tolist()
        assert [_ns(r["time"]) for r in mine] == track.time_ns.tolist()
        np.testing.assert_array_equal([r["position"] for r in mine], track.position_world)
        assert [r["camera"] for r in mine] == [fused.rig.names[c] for c in track.camera]
        for key, values in track.quality.items():
            got = np.array([np.nan if r["quality"][key] is None else r["quality"][key]
                            for r in mine])
            np.testing.assert_array_equal(got, values)  # NaN written as null, read as NaN


def test_parquet_columns(fused, tmp_path, cli):
    pq = pytest.importorskip("pyarrow.parquet")
    path = tmp_path / "t.parquet"
    assert cli("export", fused.path, "--parquet", path)[0] == 0
    table = pq.read_table(path).to_pydict()
    for method, track in fused.tracks.items():
        rows = [i for i, m in enumerate(table["method"]) if m == method]
        assert [table["time_ns"][i] for i in rows] == track.time_ns.tolist()
        for axis, key in enumerate("xyz"):
            assert [table[key][i] for i in rows] == track.position_world[:, axis].tolist()
        for key, values in track.quality.items():
            got = [table[key][i] for i in rows]
            assert got == [None if np.isnan(v) else v for v in values.tolist()]


@pytest.mark.filterwarnings("ignore:No analog data found")  # c3d's reader, on reading
def test_c3d_one_point_per_method_and_truth_in_millimetres(fused, tmp_path, cli):
    c3d = pytest.importorskip("c3d")
    path = tmp_path / "t.c3d"
    # a real process: c3d's "No analog data found" UserWarning would reach its stderr
    run = subprocess.run([sys.executable, "-m", "pslog.cli", "export", str(fused.path),
                          "--c3d", str(path)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stderr == "", run.stderr
    with open(path, "rb") as f:
        reader = c3d.Reader(f)
        labels = [s.strip() for s in reader.point_labels]
        assert labels == [*sorted(fused.tracks), "truth"]
        assert reader.get("POINT:UNITS").string_value.strip() == "mm"
        assert reader.point_rate == pytest.approx(90.0)
        frames = np.array([points for _, points, _ in reader.read_frames()])
    first = min(int(t.time_ns.min()) for t in fused.tracks.values())
    for j, method in enumerate(sorted(fused.tracks)):
        track = fused.tracks[method]
        index = np.round((track.time_ns - first) * 90.0 / 1e9).astype(int)
        # type A's points are on the 90 Hz grid: every one lands on its own frame
        np.testing.assert_allclose(frames[index, j, :3], track.position_world * 1000.0,
                                   rtol=1e-6, atol=1e-3)
        empty = np.setdiff1d(np.arange(len(frames)), index)
        assert np.all(frames[empty, j, 3] == -1)  # no point: invalid
    times = first + np.round(np.arange(len(frames)) * 1e9 / 90.0).astype(np.int64)
    np.testing.assert_allclose(frames[:, -1, :3], fused.truth.at(times) * 1000.0, atol=1e-3)


def test_nothing_to_export_and_session_without_tracks(tmp_path, cli, sim_session):
    code, _, err = cli("export", sim_session.path, "--jsonl", tmp_path / "t.jsonl")
    assert code == 1 and "no fused tracks" in err and not (tmp_path / "t.jsonl").exists()
    code, _, err = cli("export", sim_session.path, "--tum", tmp_path / "traj")
    assert code == 1 and not (tmp_path / "traj").exists()


@pytest.mark.filterwarnings("ignore:No analog data found")
def test_c3d_says_which_methods_irregular_times_resampled(tmp_path, cli):
    """Jittered shutters (2 ms): some points of a method would fall on one frame (the nearer
    was kept, the other left out, before session 43); such a method is resampled onto the
    grid, linear between its points, and the command says which and how many frames hold
    it; the file holds the exact time of its first frame."""
    c3d = pytest.importorskip("c3d")
    from pslog.interchange.track_formats import c3d_grid

    sim, fused_path, path = tmp_path / "j.mcap", tmp_path / "f.mcap", tmp_path / "t.c3d"
    assert cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
               "--duration", "3", "--jitter-ms", "2", "--seed", "1", "-o", sim)[0] == 0
    assert cli("fuse", sim, "--method", "typeA", "--method", "nearest", "-o",
               fused_path)[0] == 0
    session = read_session(fused_path)
    code, out, err = cli("export", fused_path, "--c3d", path)
    assert code == 0, err
    rate, first, _n = c3d_grid(session)
    with open(path, "rb") as f:
        reader = c3d.Reader(f)
        labels = [s.strip() for s in reader.point_labels]
        first_s = reader.get("PSLOG:FIRST_FRAME_S").string_value.strip()
        frames = np.array([points for _, points, _ in reader.read_frames()])
    assert Decimal(first_s) * 1_000_000_000 == first
    said = {}
    for part in out.split("cameras firing together): ")[1].split("; ")[0].split(", "):
        method, n, _frames, _from, total, _points = part.split()
        said[method] = int(n)
        assert int(total) == len(session.tracks[method])
    assert said and "left out" not in out
    for j, method in enumerate(labels[:-1]):
        track = session.tracks[method]
        written = int(np.count_nonzero(frames[:, j, 3] != -1))
        frame = np.round((track.time_ns - first) * rate / 1e9).astype(int)
        if method in said:  # resampled: frames between its points, more than it had apart
            assert written == said[method] > len(np.unique(frame))
        else:  # its points, each on its own frame
            assert written == len(track) == len(np.unique(frame))


def test_c3d_of_regular_times_leaves_nothing_out(fused, tmp_path, cli):
    pytest.importorskip("c3d")
    code, out, err = cli("export", fused.path, "--c3d", tmp_path / "t.c3d")
    assert code == 0 and "left out" not in out, err


def _pair_rig(cli, folder, fps: float, cam2_offset_s: float):
    """``paper2``'s two cameras at ``fps``, camera 2's shutter ``cam2_offset_s`` after camera
    1's: the rig file written in ``folder``."""
    code, text, err = cli("rig", "show", "paper2")
    assert code == 0, err
    head, cam2 = text.replace("fps = 30.0", f"fps = {fps}").split('name = "cam2"')
    rig = folder / "pair.toml"
    rig.write_text(head + 'name = "cam2"' + cam2.replace("offset = 0.0",
                                                         f"offset = {cam2_offset_s}"))
    return rig


@pytest.mark.filterwarnings("ignore:No analog data found")
def test_c3d_of_an_uneven_pair_holds_every_point_on_a_finer_grid(tmp_path, cli):
    """Two 60 fps cameras whose shutters are 4 ms apart (and so 12.7 ms the other way), the
    ball missed in a fifth of the frames: the densest track's median interval (12.7 ms)
    gave 78.8 Hz, on which about a third of its points shared a frame and were left out
    (session 39's walk); the grid is now the lowest multiple of 60 Hz holding each point on
    a frame of its own, near its time (240 Hz)."""
    c3d = pytest.importorskip("c3d")
    from pslog.interchange.track_formats import c3d_grid

    rig = _pair_rig(cli, tmp_path, 60.0, 0.004)
    sim, fused_path, path = tmp_path / "s.mcap", tmp_path / "f.mcap", tmp_path / "t.c3d"
    assert cli("simulate", "--rig", rig, "--motion", "throw", "--noise-px", "0.3",
               "--miss-rate", "0.2", "--seed", "68500", "-o", sim)[0] == 0
    assert cli("fuse", sim, "--method", "typeA", "--method", "smooth", "-o",
               fused_path)[0] == 0
    session = read_session(fused_path)
    rate, first, _n = c3d_grid(session)
    assert rate == pytest.approx(240.0)
    code, out, err = cli("export", fused_path, "--c3d", path)
    assert code == 0 and "left out" not in out, err
    with open(path, "rb") as f:
        reader = c3d.Reader(f)
        assert reader.point_rate == pytest.approx(240.0)
        labels = [s.strip() for s in reader.point_labels]
        frames = np.array([points for _, points, _ in reader.read_frames()])
    for j, method in enumerate(labels[:-1]):
        track = session.tracks[method]
        index = np.round((track.time_ns - first) * rate / 1e9).astype(int)
        assert len(np.unique(index)) == len(track) > 50  # every point on its own frame
        assert np.max(np.abs(first + index * 1e9 / rate - track.time_ns)) < 0.2e6  # ns
        np.testing.assert_allclose(frames[index, j, :3], track.position_world * 1000.0,
                                   rtol=1e-6, atol=1e-3)


@pytest.mark.filterwarnings("ignore:No analog data found")
def test_c3d_of_a_close_pair_with_misses_leaves_nothing_out(tmp_path, cli):
    """review41b: two 30 fps cameras 3 ms apart, the ball missed in a tenth of the frames:
    the intervals' median (30 ms) set a 33 Hz grid, on which 4 in 10 of type A's points
    shared a frame and were left out, and the frame rates' multiples up to 8 (240 Hz) hold
    the pair's points apart on no grid they keep to: now the multiples up to C3D's frame
    limit, the lowest holding every point apart (300 Hz: 30 fps x 10), each within 0.4 ms
    of its frame."""
    pytest.importorskip("c3d")
    from pslog.interchange.track_formats import c3d_grid

    rig = _pair_rig(cli, tmp_path, 30.0, 0.003)
    sim, fused_path, path = tmp_path / "s.mcap", tmp_path / "f.mcap", tmp_path / "t.c3d"
    assert cli("simulate", "--rig", rig, "--motion", "throw", "--noise-px", "0.3",
               "--miss-rate", "0.1", "--seed", "69300", "-o", sim)[0] == 0
    assert cli("fuse", sim, "--method", "typeA", "-o", fused_path)[0] == 0
    session = read_session(fused_path)
    rate, first, _n = c3d_grid(session)
    track = session.tracks["typeA"]
    index = np.round((track.time_ns - first) * rate / 1e9).astype(int)
    assert len(np.unique(index)) == len(track) > 50, rate  # every point on its own frame
    assert np.max(np.abs(first + index * 1e9 / rate - track.time_ns)) < 0.4e6  # ns
    assert rate <= 330.0  # (the lowest such multiple of 30 Hz, not the finest)
    code, out, err = cli("export", fused_path, "--c3d", path)
    assert code == 0 and "left out" not in out, err
