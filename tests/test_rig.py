"""Tests of pslog.rig: TOML files, validation, built-in rigs and shutter presets."""

from __future__ import annotations

import itertools
import tomllib

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.camera import Camera
from pslog.errors import PslogError, RigError
from pslog.rig import (
    BUILTIN_RIGS,
    PAPER_VOLUME,
    TIMING_PRESETS,
    Rig,
    _toml_value,
    apply_timing,
    builtin_rig,
    check_baselines,
    load_rig,
    resolve_rig,
    save_rig,
    timing_label,
)

GOOD_TOML = """\
name = "lab"

[[camera]]
name = "cam1"
width = 640
height = 480
K = [[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]]
dist = [-0.3, 0.1, 0.001, -0.001, -0.02]
R = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
t = [0.0, 0.0, 0.0]
fps = 30.0
offset = 0.0

[[camera]]
name = "cam2"
width = 1280
height = 720
K = [[900, 0, 640], [0, 900, 360], [0, 0, 1]]
R = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
t = [0.5, -0.25, 3]
fps = 60
offset = 0.005
"""


def _random_camera(rng: np.random.Generator, name: str) -> Camera:
    """A camera whose every float uses all 53 bits (so a lossy writer would show)."""
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rotation *= np.sign(np.linalg.det(rotation))
    K = np.array([[rng.uniform(300, 900), rng.normal(0, 1e-3), rng.uniform(300, 340)],
                  [0.0, rng.uniform(300, 900), rng.uniform(200, 280)], [0.0, 0.0, 1.0]])
    dist = rng.normal(0, 0.1, 5) * np.array([1, 1, 1e-2, 1e-2, 1])
    dist[2] = 1e-17  # exponent notation
    t = rng.normal(0, 2, 3)
    t[0] = -0.0  # negative zero must survive
    fps = rng.uniform(20, 120)
    return Camera(name, 640, 480, K, dist, rotation, t, fps=fps,
                  offset=rng.uniform(0, 1) / fps)  # within the frame period


def _assert_bit_identical(a: Rig, b: Rig) -> None:
    assert a.name == b.name and a.names == b.names
    for cam_a, cam_b in zip(a.cameras, b.cameras, strict=True):
        assert cam_a == cam_b
        for key in ("K", "dist", "R", "t"):
            assert getattr(cam_a, key).tobytes() == getattr(cam_b, key).tobytes(), key
        assert np.float64(cam_a.fps).tobytes() == np.float64(cam_b.fps).tobytes()
        assert np.float64(cam_a.offset).tobytes() == np.float64(cam_b.offset).tobytes()


# ---- TOML round trip ----------------------------------------------------------------------

def test_load_documented_shape(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text(GOOD_TOML, encoding="utf-8")
    rig = load_rig(path)
    assert rig.name == "lab" and rig.names == ("cam1", "cam2") and len(rig) == 2
    cam1, cam2 = rig.cameras
    assert_array_equal(cam1.dist, [-0.3, 0.1, 0.001, -0.001, -0.02])
    assert_array_equal(cam2.dist, np.zeros(5))  # optional, default zeros
    assert (cam2.width, cam2.height, cam2.fps, cam2.offset) == (1280, 720, 60.0, 0.005)
    assert_array_equal(cam2.t, [0.5, -0.25, 3.0])
    assert cam2.K.dtype == np.float64


def test_save_load_round_trip_is_bit_identical(tmp_path):
    rng = np.random.default_rng(0)
    # file order is camera order, not sorted by name
    rig = Rig(tuple(_random_camera(rng, n) for n in ("zeta", "alpha", "cam10", "cam2")),
              "round trip")
    path = tmp_path / "rig.toml"
    save_rig(rig, path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]  # no temporary left
    loaded = load_rig(path)
    _assert_bit_identical(rig, loaded)
    assert loaded.names == ("zeta", "alpha", "cam10", "cam2")
    assert loaded.to_toml() == rig.to_toml()
    # saving again replaces the file with the same text
    save_rig(loaded, path)
    assert path.read_text(encoding="utf-8") == rig.to_toml()


def test_to_toml_is_the_documented_shape():
    text = builtin_rig("paper3").to_toml()
    data = tomllib.loads(text)
    assert set(data) == {"name", "camera"}
    for table in data["camera"]:
        assert set(table) == {"name", "width", "height", "K", "dist", "R", "t", "fps", "offset"}
        assert isinstance(table["width"], int) and isinstance(table["fps"], float)
    assert Rig(builtin_rig("paper3").cameras).to_toml().startswith("[[camera]]")  # no name


@pytest.mark.parametrize("name", ["kamera-ü", 'quote " and \\ backslash', "tab\there",
                                  "new\nline", "bell\x07 del\x7f", "😀"])
def test_round_trip_of_unusual_names(name):
    rig = Rig(builtin_rig("paper2").cameras[:1], name)
    loaded = Rig.from_toml(rig.to_toml())
    assert loaded.name == name
    if name in ("kamera-ü", "😀"):  # camera names may be any text a CSV cell and topic hold
        cam = builtin_rig("paper2").cameras[0].replace(name=name)
        assert Rig.from_toml(Rig((cam,)).to_toml()).names == (name,)


@pytest.mark.parametrize("name,why", [
    ("a,b", "one of ,"), ('say "hi"', "one of ,"), ("left/right", "one of ,"),
    ("new\nline", "control character"), ("tab\there", "control character"),
    ("bell\x07", "control character"), ("del\x7f", "control character"),
    ("", "non-empty"), (" cam1", "space"), ("x" * 65, "longer than 64"),
])
def test_camera_names_that_break_csv_or_topics_are_refused_naming_file_and_camera(
        tmp_path, name, why):
    text = builtin_rig("paper2").to_toml().replace('name = "cam2"', f"name = {_toml_value(name)}")
    path = tmp_path / "rig.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(RigError, match=why) as info:
        load_rig(path)
    assert str(path) in str(info.value)
    assert "\n" not in str(info.value)  # one line, whatever the name holds


def test_to_toml_rejects_non_finite():
    # Camera refuses non-finite values, so this is only reachable by bypassing validation
    cam = builtin_rig("paper2").cameras[0]
    object.__setattr__(cam, "offset", float("nan"))
    with pytest.raises(RigError, match="non-finite"):
        Rig((cam,)).to_toml()


# ---- validation -----------------------------------------------------------------------------

def _replace_line(text: str, old: str, new: str, count: int = 1) -> str:
    assert old in text
    return text.replace(old, new, count)


@pytest.mark.parametrize("text, expected", [
    (_replace_line(GOOD_TOML, 'name = "lab"', 'name = "lab"\nscale = 2'), ["scale"]),
    (_replace_line(GOOD_TOML, "offset = 0.005", "offset = 0.005\nfocal = 3.0"),
     ["cam2", "focal"]),
    (_replace_line(GOOD_TOML, "fps = 60\n", ""), ["cam2", "fps"]),
    (_replace_line(GOOD_TOML, "t = [0.0, 0.0, 0.0]\n", ""), ["cam1", "t"]),
    (_replace_line(GOOD_TOML, 'name = "cam2"\n', ""), ["#2", "name"]),
    (_replace_line(GOOD_TOML, 'name = "cam2"', 'name = "cam1"'), ["cam1", "unique"]),
    (_replace_line(GOOD_TOML, "R = [[0.0, -1.0, 0.0]", "R = [[0.0, -1.1, 0.0]"), ["cam2", "R"]),
    (_replace_line(GOOD_TOML, "R = [[0.0, -1.0, 0.0]", "R = [[0.0, 1.0, 0.0]"), ["cam2", "R"]),
    (_replace_line(GOOD_TOML, "R = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]",
                   "R = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]"), ["cam1", "R", "shape"]),
    (_replace_line(GOOD_TOML, "[0, 900, 360]", "[1, 900, 360]"), ["cam2", "K"]),
    (_replace_line(GOOD_TOML, "[[900, 0, 640]", "[[-900, 0, 640]"), ["cam2", "K"]),
    (_replace_line(GOOD_TOML, "[[900, 0, 640]", '[["a", 0, 640]'), ["cam2", "K"]),
    (_replace_line(GOOD_TOML, "dist = [-0.3, 0.1, 0.001, -0.001, -0.02]", "dist = [0.1]"),
     ["cam1", "dist"]),
    (_replace_line(GOOD_TOML, "fps = 60", "fps = 0"), ["cam2", "fps"]),
    (_replace_line(GOOD_TOML, "fps = 60", "fps = -60.0"), ["cam2", "fps"]),
    (_replace_line(GOOD_TOML, "fps = 60", 'fps = "60"'), ["cam2", "fps"]),
    (_replace_line(GOOD_TOML, "fps = 30.0", "fps = nan"), ["cam1", "fps"]),
    (_replace_line(GOOD_TOML, "offset = 0.005", "offset = 0.02"),
     ["cam2", "offset 0.02 s", "[0, 0.0166667 s)", "60 fps"]),
    (_replace_line(GOOD_TOML, "offset = 0.005", "offset = -0.001"), ["cam2", "offset -0.001"]),
    (_replace_line(GOOD_TOML, "width = 1280", "width = 1280.0"), ["cam2", "width"]),
    (_replace_line(GOOD_TOML, "height = 480", "height = 0"), ["cam1", "height"]),
    (_replace_line(GOOD_TOML, 't = [0.5, -0.25, 3]', 't = [0.5, -0.25, inf]'), ["cam2", "t"]),
    (_replace_line(GOOD_TOML, 'name = "lab"', "name = 3"), ["name"]),
    (_replace_line(GOOD_TOML, 'K = [[600.0', 'K = [[600.0,'), ["malformed TOML"]),
    ("this is not toml\n", ["malformed TOML"]),
    ('name = "empty"\n', ["[[camera]]"]),
    ("", ["[[camera]]"]),
    ('[camera]\nname = "cam1"\n', ["[[camera]]"]),
])
def test_invalid_rig_files_are_rejected_naming_camera_and_key(tmp_path, text, expected):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(RigError) as info:
        load_rig(path)
    message = str(info.value)
    assert isinstance(info.value, PslogError)
    assert str(path) in message  # the file is named
    for part in expected:
        assert part in message, (part, message)
    assert "\n" not in message.strip()


def test_errors_from_text_name_the_source():
    with pytest.raises(RigError, match=r"^my-source: .*cam2.*fps"):
        Rig.from_toml(_replace_line(GOOD_TOML, "fps = 60\n", ""), source="my-source")


def test_missing_unreadable_and_non_utf8_files(tmp_path):
    with pytest.raises(RigError, match="not found") as info:
        load_rig(tmp_path / "nope.toml")
    assert "nope.toml" in str(info.value)
    with pytest.raises(RigError, match="cannot read"):
        load_rig(tmp_path)  # a directory
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"name = \"\xff\xfe\"\n")
    with pytest.raises(RigError, match=r"binary\.toml"):
        load_rig(binary)


def test_rig_object_validation_and_helpers():
    paper3 = builtin_rig("paper3")
    with pytest.raises(RigError, match="at least one camera"):
        Rig(())
    with pytest.raises(RigError, match="cam1"):
        Rig((paper3.cameras[0], paper3.cameras[0]))
    assert paper3.index("cam3") == 2
    assert paper3.camera("cam2") is paper3.cameras[1]
    with pytest.raises(RigError, match="'cam9'"):
        paper3.index("cam9")
    moved = paper3.cameras[1].replace(offset=0.01)
    replaced = paper3.with_camera(moved)
    assert replaced.names == paper3.names and replaced.cameras[1].offset == 0.01
    added = paper3.with_camera(moved.replace(name="cam4"))
    assert added.names == ("cam1", "cam2", "cam3", "cam4")
    assert paper3.subset(["cam3", "cam1"]).names == ("cam3", "cam1")
    assert paper3.names == ("cam1", "cam2", "cam3")  # unchanged


# ---- built-in rigs ------------------------------------------------------------------------

def test_builtin_rigs_see_the_whole_volume():
    corners = np.array(list(itertools.product(*PAPER_VOLUME)))
    assert corners.shape == (8, 3)
    assert_allclose(corners.max(axis=0) - corners.min(axis=0), [3.0, 2.0, 2.0])
    # also points inside the volume and on its faces
    grid = np.stack(np.meshgrid(*[np.linspace(lo, hi, 7) for lo, hi in PAPER_VOLUME]),
                    axis=-1).reshape(-1, 3)
    for name in BUILTIN_RIGS:
        rig = builtin_rig(name)
        for cam in rig.cameras:
            uv, in_front = cam.project(np.vstack([corners, grid]))
            assert in_front.all(), (name, cam.name)
            assert cam.in_image(uv).all(), (name, cam.name)
            assert cam.center_world[2] == pytest.approx(3.0, abs=1e-12)  # 3.0 m high
            assert (cam.width, cam.height, cam.fps, cam.offset) == (640, 480, 30.0, 0.0)


def test_builtin_rig_names():
    assert builtin_rig("paper3").names == ("cam1", "cam2", "cam3")
    paper2 = builtin_rig("paper2")
    assert paper2.names == ("cam1", "cam2")
    assert paper2.cameras[0] == builtin_rig("paper3").cameras[0]
    with pytest.raises(RigError, match="paper4"):
        builtin_rig("paper4")


def test_builtin_cameras_are_distinct_viewpoints():
    centres = np.array([c.center_world for c in builtin_rig("paper3").cameras])
    distances = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    assert distances[np.triu_indices(3, 1)].min() > 2.0


# ---- shutter presets ----------------------------------------------------------------------

def test_timing_sync():
    rig = apply_timing(apply_timing(builtin_rig("paper3"), "typeA"), "sync")
    assert [c.offset for c in rig.cameras] == [0.0, 0.0, 0.0]


def test_timing_type_a_paper3_is_one_ninetieth_apart():
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    offsets = np.array([c.offset for c in rig.cameras])
    assert_allclose(offsets, [0.0, 1 / 90, 2 / 90], rtol=0, atol=1e-15)
    assert_allclose(np.diff(offsets), 1 / 90, rtol=0, atol=1e-15)
    assert rig.name == "paper3" and rig.names == ("cam1", "cam2", "cam3")
    # everything but the offsets is kept
    for before, after in zip(builtin_rig("paper3").cameras, rig.cameras, strict=True):
        assert after == before.replace(offset=after.offset)


def test_timing_type_a_uses_each_camera_fps():
    rig = Rig((builtin_rig("paper2").cameras[0].replace(fps=60.0),
               builtin_rig("paper2").cameras[1].replace(fps=25.0)))
    offsets = [c.offset for c in apply_timing(rig, "typeA").cameras]
    assert_allclose(offsets, [0.0, 1 / (2 * 25.0)], rtol=0, atol=1e-15)


def test_timing_type_b():
    rig = apply_timing(builtin_rig("paper3"), "typeB")
    assert_allclose([c.offset for c in rig.cameras], [0.0, 1 / 60, 0.0], rtol=0, atol=1e-15)
    four = builtin_rig("paper3").with_camera(builtin_rig("paper3").cameras[0].replace(name="c4"))
    assert_allclose([c.offset for c in apply_timing(four, "typeB").cameras],
                    [0.0, 1 / 60, 1 / 60, 0.0], rtol=0, atol=1e-15)
    with pytest.raises(RigError, match=r"typeB.*3 cameras"):
        apply_timing(builtin_rig("paper2"), "typeB")


def test_unknown_timing():
    assert TIMING_PRESETS == ("sync", "typeA", "typeB")
    with pytest.raises(RigError, match="typeC"):
        apply_timing(builtin_rig("paper3"), "typeC")


def test_timing_survives_toml_round_trip():
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    _assert_bit_identical(rig, Rig.from_toml(rig.to_toml()))


# ---- resolve_rig ------------------------------------------------------------------------

def test_resolve_rig_by_name_and_path(tmp_path, monkeypatch):
    for name in BUILTIN_RIGS:
        _assert_bit_identical(resolve_rig(name), builtin_rig(name))
    path = tmp_path / "lab.toml"
    path.write_text(GOOD_TOML, encoding="utf-8")
    assert resolve_rig(path).names == ("cam1", "cam2")
    assert resolve_rig(str(path)).name == "lab"
    monkeypatch.chdir(tmp_path)
    assert resolve_rig("lab.toml").names == ("cam1", "cam2")


def test_resolve_rig_unknown(tmp_path):
    with pytest.raises(RigError) as info:
        resolve_rig(tmp_path / "missing.toml")
    assert "missing.toml" in str(info.value) and "paper3" in str(info.value)
    with pytest.raises(RigError, match="'paper9'"):
        resolve_rig("paper9")


# ---- hostile values (issue 8) -------------------------------------------------------------

@pytest.mark.parametrize("key,value,why", [
    ("width", "99999999999", "beyond any camera"), ("height", "70000", "beyond any camera"),
    ("fps", "1e300", "fps must be in"),
    ("K", "[[1e300, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]]", "beyond any lens"),
    ("t", "[1e300, 0.0, 0.0]", "at most"),
])
def test_absurd_sizes_are_refused_naming_file_and_camera(tmp_path, key, value, why):
    lines = [f"{key} = {value}" if line.startswith(f"{key} = ") and i < 12 else line
             for i, line in enumerate(GOOD_TOML.splitlines())]
    path = tmp_path / "rig.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(RigError, match=why) as info:
        load_rig(path)
    assert str(path) in str(info.value) and "'cam1'" in str(info.value)


def test_a_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_bytes(b"\xef\xbb\xbf" + GOOD_TOML.encode())
    assert load_rig(path) == Rig.from_toml(GOOD_TOML)


def test_cameras_at_one_centre_are_refused_for_stereo_naming_both():
    rig = builtin_rig("paper3")
    same = rig.with_camera(rig.cameras[2].replace(R=rig.cameras[0].R, t=rig.cameras[0].t + 1e-5))
    assert check_baselines(rig) is rig
    with pytest.raises(RigError, match="'cam1' and 'cam3' are at the same centre") as info:
        check_baselines(same, "lab.toml")
    assert str(info.value).startswith("lab.toml: ")


def test_timing_label_names_the_preset_the_offsets_are():
    rig = builtin_rig("paper3")
    for preset in TIMING_PRESETS:
        assert timing_label(apply_timing(rig, preset)) == preset
    assert timing_label(apply_timing(builtin_rig("paper2"), "typeA")) == "typeA"
    odd = rig.with_camera(rig.cameras[1].replace(offset=0.005))
    assert timing_label(odd) == "custom"


def test_a_rig_of_thousands_of_cameras_is_refused():
    cam = builtin_rig("paper3").cameras[0]
    cameras = tuple(cam.replace(name=f"c{i}", t=cam.t + np.array([0.0, 0.0, 0.01 * i]))
                    for i in range(257))
    with pytest.raises(RigError, match="at most 256"):
        Rig(cameras)
    assert len(check_baselines(Rig(cameras[:256]))) == 256


# ---- clock keys (pslog.timing's model) ------------------------------------------------

def test_clock_keys_round_trip_exactly(tmp_path):
    rng = np.random.default_rng(4)
    cams = [_random_camera(rng, n) for n in ("a", "b", "c")]
    cams[0] = cams[0].replace(readout=rng.uniform(0, 1) / cams[0].fps)
    cams[1] = cams[1].replace(clock_offset=-rng.uniform(0, 0.05),
                              clock_drift_ppm=rng.normal(0, 30))
    cams[2] = cams[2].replace(clock_offset=1e-17, readout=rng.uniform(0, 0.5) / cams[2].fps)
    rig = Rig(tuple(cams), "clocks")
    path = tmp_path / "rig.toml"
    save_rig(rig, path)
    loaded = load_rig(path)
    _assert_bit_identical(rig, loaded)
    for a, b in zip(rig.cameras, loaded.cameras, strict=True):
        for key in ("clock_offset", "clock_drift_ppm", "readout"):
            assert np.float64(getattr(a, key)).tobytes() == np.float64(getattr(b, key)).tobytes()
    tables = tomllib.loads(path.read_text())["camera"]
    # written only when non-zero
    assert set(tables[0]) & {"clock_offset", "clock_drift_ppm", "readout"} == {"readout"}
    assert {"clock_offset", "clock_drift_ppm"} <= set(tables[1]) and "readout" not in tables[1]
    # a camera differing only in a clock key differs
    assert rig.cameras[1] != rig.cameras[1].replace(clock_drift_ppm=0.0)


def test_clock_keys_default_to_zero_and_plain_rigs_do_not_change():
    rig = load_rig_text(GOOD_TOML)
    for cam in rig.cameras:
        assert (cam.clock_offset, cam.clock_drift_ppm, cam.readout) == (0.0, 0.0, 0.0)
        assert not cam.has_clock_correction
    assert "clock" not in builtin_rig("paper3").to_toml()
    assert "readout" not in builtin_rig("paper3").to_toml()


def load_rig_text(text: str) -> Rig:
    return Rig.from_toml(text, source="x.toml")


@pytest.mark.parametrize("key, value, message", [
    ("clock_offset", "nan", "clock_offset must be finite"),
    ("clock_offset", "1e6", "clock_offset 1e\\+06 s is beyond"),
    ("clock_offset", '"3 ms"', "clock_offset must be a number"),
    ("clock_drift_ppm", "-5000.0", "clock_drift_ppm -5000 is beyond"),
    ("clock_drift_ppm", "inf", "clock_drift_ppm must be finite"),
    ("readout", "-0.001", "readout -0.001 s must be in \\[0, 0.0166667 s\\)"),
    ("readout", "0.02", "readout 0.02 s must be in \\[0, 0.0166667 s\\)"),
])
def test_clock_keys_are_validated_naming_file_and_camera(key, value, message):
    text = GOOD_TOML + f"{key} = {value}\n"  # on cam2 (60 fps)
    with pytest.raises(RigError, match=f"x.toml: camera 'cam2': {message}"):
        load_rig_text(text)


@pytest.mark.parametrize("key", ["clock_offset", "clock_drift_ppm"])
def test_first_camera_clock_must_be_zero(key):
    text = GOOD_TOML.replace('offset = 0.0\n', f'offset = 0.0\n{key} = 0.002\n', 1)
    with pytest.raises(RigError, match=r"x.toml: camera 'cam1': the first camera of a rig "
                                       r"defines the session clock"):
        load_rig_text(text)
    # its readout may be anything valid
    text = GOOD_TOML.replace('offset = 0.0\n', 'offset = 0.0\nreadout = 0.03\n', 1)
    assert load_rig_text(text).cameras[0].readout == 0.03


def test_toml_writer_round_trips_awkward_floats_bit_for_bit():
    """The tomli-w rendered values: subnormals, -0.0, 17-digit values, huge and tiny
    exponents come back as the same doubles (bytes compared, so -0.0 is not 0.0)."""
    rng = np.random.default_rng(7)
    cam = builtin_rig("paper2").cameras[0]
    dist = np.array([5e-324, -0.0, 1e-300, 0.1 + 0.2, -999.9999999999999])
    t = np.array([-0.0, 123456.78901234567, 2.0 ** -1074 * 3])
    K = np.array([[1.0000000000000002, 2.5e-17, 319.49999999999994], [0.0, 9999999.999999998,
                 rng.uniform(0, 480)], [0.0, 0.0, 1.0]])
    fps = 29.97002997002997
    awkward = cam.replace(dist=dist, t=t, K=K, fps=fps, offset=1 / fps - 1e-15,
                          readout=np.nextafter(0.0, 1.0))
    rig = Rig((awkward, cam.replace(name="cam2", clock_offset=-1e-9,
                                    clock_drift_ppm=-0.0 + 3.3333333333333335)))
    loaded = Rig.from_toml(rig.to_toml())
    _assert_bit_identical(rig, loaded)
    for a, b in zip(rig.cameras, loaded.cameras, strict=True):
        for key in ("clock_offset", "clock_drift_ppm", "readout"):
            assert np.float64(getattr(a, key)).tobytes() == np.float64(
                getattr(b, key)).tobytes(), key
