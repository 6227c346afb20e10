"""The fusion method registry: the CLI, default_methods, StreamFuser and the causality test
read it, so a new method is one entry."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import pslog.fusion as fusion
from pslog import SimulationOptions, apply_timing, get_motion, simulate
from pslog.errors import FusionError
from pslog.fusion import METHODS, Method, causal_methods, default_methods, fuse
from pslog.fusion.stream import StreamFuser
from pslog.log import read_session
from pslog.records import QUALITY_FIELDS, Track


def test_every_entry_is_complete():
    for name, method in METHODS.items():
        assert isinstance(method, Method) and method.name == name
        assert method.description and method.reference and callable(method.function)
        assert method.needs <= {"shared", "alone"}
    assert METHODS["smooth"].causal is False and METHODS["smooth"].needs == frozenset()
    assert "smooth" not in causal_methods() and "typeA" in causal_methods()


@pytest.mark.parametrize("method", list(METHODS))
def test_every_quality_column_a_method_writes_is_described(method, rig3):
    """A user reads what a column means in QUALITY_FIELDS (eval, export and the docs list it)."""
    timing = "typeB" if "shared" in METHODS[method].needs else "typeA"
    rig = apply_timing(rig3, timing)
    detections, _ = simulate(rig, get_motion("throw"), 1.0,
                             SimulationOptions(noise_px=0.3, seed=1))
    track = fuse(detections, rig, method)
    assert len(track) > 0
    assert set(track.quality) <= set(QUALITY_FIELDS), set(track.quality) - set(QUALITY_FIELDS)


def test_streaming_refuses_an_offline_method_with_the_reason(rig3):
    with pytest.raises(FusionError, match=r"'smooth' is offline .* streaming methods: sync"):
        StreamFuser(rig3, "smooth")


def test_cli_help_lists_every_registered_method(cli, capsys):
    with pytest.raises(SystemExit) as stop:
        cli("fuse", "--help")
    assert stop.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    for method in METHODS.values():
        assert f"{method.name}: {method.description}" in out
    with pytest.raises(SystemExit) as stop:
        cli("fuse", "x.mcap", "--method", "bogus", "-o", "y.mcap")
    err = capsys.readouterr().err
    assert stop.value.code == 2
    assert "smooth" in err  # the choices come from the registry


def test_a_new_method_is_one_registry_entry(monkeypatch, rig3, sim_session, tmp_path, cli):
    def centroid(prep, rig, options):
        # a toy method: the centroid of the camera centres at every detection
        n = len(prep.obs)
        return Track("centroid", prep.obs.time_ns, np.tile(prep.centers.mean(axis=0), (n, 1)),
                     prep.obs.camera)

    entry = Method("centroid", centroid, True, False, frozenset(), "a toy", "this test")
    monkeypatch.setitem(fusion.METHODS, "centroid", entry)
    assert "centroid" in default_methods(sim_session.detections, rig3)
    assert len(fuse(sim_session.detections, rig3, "centroid")) == len(
        sim_session.detections.best())
    assert "centroid" in causal_methods()
    StreamFuser(rig3, "centroid")
    code, _, err = cli("fuse", sim_session.path, "--method", "centroid", "-o",
                         tmp_path / "c.mcap")
    assert code == 0, err
    assert "centroid" in read_session(tmp_path / "c.mcap").tracks
    offline = dataclasses.replace(entry, causal=False)
    monkeypatch.setitem(fusion.METHODS, "centroid", offline)
    with pytest.raises(FusionError, match="offline"):
        StreamFuser(rig3, "centroid")
