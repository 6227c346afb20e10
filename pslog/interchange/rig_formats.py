"""Calibrations of other tools as rigs, and rigs in their formats.

Formats (docs/interchange.md has every difference, with examples):

``anipose``
    aniposelib's ``CameraGroup.dump`` / ``load`` (and anipose's ``calibration.toml``): one
    table ``[cam_N]`` per camera with ``name``, ``size = [width, height]``, ``matrix`` (3 x 3
    K), ``distortions`` (OpenCV ``[k1, k2, p1, p2, k3]``), ``rotation`` (Rodrigues vector of
    the world -> camera rotation, radians) and ``translation`` (world -> camera, in the units
    of the calibration board: anipose users usually give the square size in millimetres),
    plus an optional ``[metadata]`` table.
``pose2sim``
    Pose2Sim's ``Calib*.toml``: the same tables (any section name, e.g. ``[cam_01]`` or
    ``[int_cam01_img]``), four distortions ``[k1, k2, p1, p2]``, sizes written as floats,
    ``fisheye = false`` in every camera table, translations in metres, and a ``[metadata]``
    table (``adjusted``, ``error``).
``opencv``
    OpenCV FileStorage YAML / XML / JSON (``cv2.FileStorage``): ``camera_matrix``,
    ``distortion_coefficients``, ``R`` (3 x 3) or ``rvec`` (Rodrigues), ``T`` or ``tvec``,
    ``image_width``, ``image_height``, optional ``camera_name``; one camera at the top level
    of a file, or several cameras, each a map at the top level (its key, or its
    ``camera_name``, is the camera's name). Matrices are ``!!opencv-matrix`` nodes or ROS
    ``camera_info``-style maps of ``rows``, ``cols``, ``data``.

None of them stores a frame rate or a shutter offset: they come from ``--fps`` and
``--offset`` (import), from the session (``pslog fuse --rig``), or are 30 fps and 0 s.
pslog writes them, and its clock keys, as extra keys (``fps``, ``offset``, ...) that
aniposelib, Pose2Sim and OpenCV readers ignore, so a rig survives a round trip exactly.

Units: pslog is in metres. A translation is read as metres unless ``units="mm"`` is given.
When the units were not given and the cameras' centres lie a median of more than
:data:`MM_SUSPECT_M` from the world origin, the file is refused as one that is most likely in
millimetres: a loud error naming ``--units``, never a silent guess either way. The mirror
check: with ``units="mm"`` given, cameras whose centres lie a median of less than
:data:`M_SUSPECT_M` both from the world origin and from each other are refused as a file in
metres (3 m read as millimetres is 3 mm). ``units="m"`` given is never checked. A pslog rig
TOML is always in metres: ``units`` given for one is refused.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Camera, holds_non_number
from ..errors import RigError, shell_word
from ..rig import Rig, parse_toml

#: formats a rig file may be in (``pslog`` is pslog's own TOML, pslog/rig.py)
FORMATS = ("pslog", "anipose", "pose2sim", "opencv")
IMPORT_FORMATS = ("auto", "anipose", "pose2sim", "opencv")
EXPORT_FORMATS = ("anipose", "pose2sim", "opencv")
#: metres per unit of a translation in a file
UNITS = {"m": 1.0, "mm": 1e-3}
#: when the units were not given: a median camera centre farther than this from the world
#: origin, metres, means a file in millimetres read as metres (1478 mm is 1478 m), refused
MM_SUSPECT_M = 100.0
#: when ``units="mm"`` was given: camera centres a median of less than this both from the
#: world origin and from each other, metres, mean a file in metres read as millimetres (a
#: rig spanning 3 m becomes 3 mm); no ball-tracking rig has its cameras 2 cm apart
M_SUSPECT_M = 0.02
#: frame rate of a camera whose file has none and for which none was given, frames/s
DEFAULT_FPS = 30.0
#: suffixes of OpenCV FileStorage files (anything else is read as TOML first)
OPENCV_SUFFIXES = (".yml", ".yaml", ".xml", ".json")
#: the camera keys pslog adds to foreign formats so that its rigs survive a round trip
_TIMING_KEYS = ("fps", "offset", "clock_offset", "clock_drift_ppm", "readout")
_DIST_NAMES = "k1, k2, p1, p2, k3"
#: tables of an aniposelib / Pose2Sim calibration that are not cameras (Pose2Sim's reader
#: skips the same ones)
_NOT_CAMERAS = ("metadata", "capture_volume", "charuco", "checkerboard")


class TimingOptionError(RigError):
    """A frame rate or shutter offset of :class:`ImportOptions` that does not fit the file
    (an offset beyond the frame period, a camera it does not have): on the command line
    (``rig import --offset``/``--fps``) a bad value, exit 2, as ``simulate``'s are."""


@dataclass(frozen=True)
class ImportOptions:
    """What a foreign calibration does not say.

    Attributes
    ----------
    units : ``"m"`` or ``"mm"``, the unit of the file's translations; None: metres, with the
        millimetre check of the module docstring
    fps : frame rate of every camera, frames/s; None: the file's (pslog's extra key), else
        :data:`DEFAULT_FPS`
    offsets : camera name -> shutter offset, seconds (others: the file's, else 0)
    """

    units: str | None = None
    fps: float | None = None
    offsets: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class RigFile:
    """A rig read from a file: the rig, the file's format, the units its translations were
    read in, and whether the file gave every camera's timing (fps and offset)."""

    rig: Rig
    format: str
    units: str
    timed: bool


# ---- detection ----------------------------------------------------------------------------

def detect_format(text: str, path: str | Path) -> tuple[str, dict[str, Any] | None]:
    """The format of a rig file's ``text``: ``(format, parsed)``, ``parsed`` the TOML
    document (pslog, anipose, pose2sim) or None (opencv).

    By suffix (``.yml .yaml .xml .json``: OpenCV FileStorage), else by content: a TOML
    document with ``[[camera]]`` is pslog's, one with tables holding ``matrix`` is aniposelib's
    (Pose2Sim's when every such table has a ``fisheye`` key); text beginning with ``%YAML``
    or ``<?xml`` is OpenCV's. Anything else: :class:`RigError` naming ``path``.
    """
    source = str(path)
    if Path(path).suffix.lower() in OPENCV_SUFFIXES:
        return "opencv", None
    try:
        data = parse_toml(text, source)
    except RigError:
        head = text.lstrip()[:16]
        if head.startswith(("%YAML", "<?xml", "<opencv_storage")):
            return "opencv", None
        raise
    if "camera" in data or set(data) <= {"name"}:
        return "pslog", data  # pslog's own checks say what is wrong with it
    tables = _camera_tables(data)
    if tables:
        fisheye = all("fisheye" in t for _, t in tables)
        return ("pose2sim" if fisheye else "anipose"), data
    keys = sorted(data)
    raise RigError(f"{source}: unknown rig format: neither a pslog rig ([[camera]] tables) "
                   f"nor an aniposelib / Pose2Sim calibration ([cam_N] tables with a matrix); "
                   f"it has {', '.join(keys[:5])}{', ...' if len(keys) > 5 else ''}")


def _camera_tables(data: dict) -> list[tuple[str, dict]]:
    """The ``(section, table)`` pairs of an aniposelib / Pose2Sim document that describe a
    camera (a table with a ``matrix``), in file order."""
    return [(k, v) for k, v in data.items() if isinstance(v, dict) and "matrix" in v]


# ---- reading ------------------------------------------------------------------------------

def parse_rig_text(text: str, path: str | Path, fmt: str = "auto",
                   options: ImportOptions | None = None) -> RigFile:
    """A rig from the text of a rig file in any format (see the module docstring).

    Parameters
    ----------
    text : the file's text
    path : the file, for the messages and the name of a single OpenCV camera without one
    fmt : one of :data:`IMPORT_FORMATS` or ``"pslog"``
    options : units, frame rate and offsets the file does not give

    Raises
    ------
    RigError : one line naming ``path`` and the problem (missing key, wrong shape,
        non-finite value, unknown format, millimetres suspected...)
    """
    options = options or ImportOptions()
    source = str(path)
    if options.units is not None and options.units not in UNITS:
        raise RigError(f"units {options.units!r}: use one of {', '.join(UNITS)}")
    detected, data = detect_format(text, path) if fmt == "auto" else (fmt, None)
    if fmt == "pslog" and Path(path).suffix.lower() not in OPENCV_SUFFIXES:
        try:
            found = detect_format(text, path)[0]
        except RigError:
            found = "pslog"  # malformed: pslog's own parser says how
        if found != "pslog":
            raise RigError(f"{source}: an {found} calibration, not a pslog rig TOML (convert "
                           f"it with 'pslog rig import {shell_word(source)} -o rig.toml')")
    elif fmt == "pslog":
        raise RigError(f"{source}: an OpenCV FileStorage file, not a pslog rig TOML (convert "
                       f"it with 'pslog rig import {shell_word(source)} -o rig.toml')")
    if detected == "pslog":
        if options.units is not None:
            # pslog's own rig TOML is in metres by definition: a unit given for it is a
            # misunderstanding (or the wrong file), not something to apply or ignore silently
            raise RigError(f"{source}: a pslog rig TOML, always in metres: --units "
                           f"{options.units} does not apply to it (leave --units out)")
        rig = Rig.from_toml(text, source) if data is None else Rig.from_dict(data, source)
        return RigFile(_with_timing(rig, options, source), "pslog", "m", True)
    if detected in ("anipose", "pose2sim"):
        if data is None:
            data = parse_toml(text, source)
        # every table but the ones the two tools keep beside their cameras is a camera: a
        # camera table without a matrix is an error, not a camera silently left out
        tables = [(k, v) for k, v in data.items()
                  if isinstance(v, dict) and k not in _NOT_CAMERAS]
        if not tables:
            raise RigError(f"{source}: no camera table (a [cam_N] table with name, size, "
                           f"matrix, distortions, rotation, translation): not an "
                           f"{detected} calibration")
        entries = [_toml_camera(section, table, source, detected) for section, table in tables]
        name = data.get("metadata", {}).get("name", "") if isinstance(
            data.get("metadata"), dict) else ""
    elif detected == "opencv":
        entries, name = _opencv_cameras(text, path)
    else:
        raise RigError(f"{source}: unknown rig format {detected!r} (have "
                       f"{', '.join(('auto', *FORMATS))})")
    if not isinstance(name, str):
        name = ""
    return _assemble(entries, name, detected, options, source)


def _assemble(entries: list[dict], name: str, fmt: str, options: ImportOptions,
              source: str) -> RigFile:
    """The rig of the cameras read from a foreign file (``entries``: Camera keyword
    arguments, translation still in file units, timing keys only where the file had them)."""
    units = options.units or "m"
    scale = UNITS[units]
    timed = all("fps" in e and "offset" in e for e in entries)
    cameras = []
    for entry in entries:
        entry = dict(entry)
        # exact division for millimetres (x / 1000 rounds once; x * 1e-3 twice)
        entry["t"] = entry["t"] / 1000.0 if units == "mm" else entry["t"] * scale
        entry.setdefault("fps", DEFAULT_FPS)
        entry.setdefault("offset", 0.0)
        try:
            cameras.append(Camera(**entry))
        except RigError as exc:
            raise RigError(f"{source}: {exc}") from None
    try:
        rig = Rig(tuple(cameras), name)
    except RigError as exc:
        raise RigError(f"{source}: {exc}") from None
    if options.units is None:
        _check_not_millimetres(rig, source)
    elif options.units == "mm":
        _check_not_metres(rig, source)
    return RigFile(_with_timing(rig, options, source), fmt, units, timed)


def _check_not_millimetres(rig: Rig, source: str) -> None:
    centres = np.array([c.center_world for c in rig.cameras])
    median = float(np.median(np.linalg.norm(centres, axis=1)))
    if median > MM_SUSPECT_M:
        raise RigError(
            f"{source}: its cameras are a median {median:.4g} m from the world origin read "
            f"as metres: its translations look like millimetres; convert it with 'pslog rig "
            f"import {source} --units mm -o rig.toml' (or --units m to keep metres)")


def _check_not_metres(rig: Rig, source: str) -> None:
    """Refuse a rig read as millimetres whose cameras are implausibly close together: the
    median camera centre nearer than :data:`M_SUSPECT_M` to the world origin AND the median
    distance between two cameras below it (one test alone would refuse a rig whose
    origin is at a camera, or whose cameras sit on a sphere around it)."""
    centres = np.array([c.center_world for c in rig.cameras])
    from_origin = float(np.median(np.linalg.norm(centres, axis=1)))
    if len(centres) > 1:
        i, j = np.triu_indices(len(centres), k=1)
        apart = float(np.median(np.linalg.norm(centres[i] - centres[j], axis=1)))
    else:
        apart = from_origin
    if max(from_origin, apart) < M_SUSPECT_M:
        raise RigError(
            f"{source}: read as millimetres its cameras are a median {from_origin * 1e3:.4g} "
            f"mm from the world origin and {apart * 1e3:.4g} mm apart: its translations look "
            f"like metres; convert it with 'pslog rig import {shell_word(source)} --units m "
            f"-o rig.toml'")


def _with_timing(rig: Rig, options: ImportOptions, source: str) -> Rig:
    """``rig`` with the frame rate and offsets of ``options`` applied."""
    unknown = sorted(set(options.offsets) - set(rig.names))
    if unknown:
        raise TimingOptionError(f"{source}: --offset for unknown camera(s) "
                                f"{', '.join(unknown)} (rig has {', '.join(rig.names)})")
    if options.fps is None and not options.offsets:
        return rig
    cameras = []
    for cam in rig.cameras:
        changes: dict[str, float] = {}
        if options.fps is not None:
            changes["fps"] = options.fps
            if cam.name not in options.offsets and cam.offset >= 1.0 / options.fps:
                changes["offset"] = 0.0  # the file's offset does not fit the new period
        if cam.name in options.offsets:
            changes["offset"] = options.offsets[cam.name]
        try:
            cameras.append(cam.replace(**changes))
        except RigError as exc:
            raise TimingOptionError(f"{source}: {exc}") from None
    return Rig(tuple(cameras), rig.name)


def _array(value, shapes: tuple[tuple[int, ...], ...], key: str, where: str) -> np.ndarray:
    """``value`` as a finite float64 array of one of ``shapes``; RigError naming ``key``."""
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # (an integer beyond any float: 10**400)
        raise RigError(f"{where}: {key} is not numeric: {_short(value)}") from None
    if array.shape not in shapes:
        want = " or ".join(str(s) for s in shapes)
        raise RigError(f"{where}: {key} must have shape {want}, got {array.shape}")
    if holds_non_number(value):  # ("400" or true, which numpy reads as 400 or 1)
        raise RigError(f"{where}: {key} is not numeric: {_short(value)}")
    if not np.all(np.isfinite(array)):
        raise RigError(f"{where}: {key} has non-finite values")
    return array


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _distortion(values: np.ndarray, key: str, where: str) -> np.ndarray:
    """OpenCV's distortion vector (4, 5, 8, 12 or 14 coefficients) as plumb_bob's five;
    RigError if a coefficient beyond ``k3`` (rational, thin prism, tilt) is not zero."""
    values = values.ravel()
    if len(values) not in (4, 5, 8, 12, 14):
        raise RigError(f"{where}: {key} has {len(values)} coefficients (OpenCV has 4, 5, 8, "
                       f"12 or 14)")
    if len(values) > 5 and np.any(values[5:] != 0):
        raise RigError(f"{where}: {key} has non-zero coefficients beyond k3 (rational, "
                       f"thin-prism or tilt terms): pslog's cameras are plumb_bob "
                       f"({_DIST_NAMES})")
    dist = np.zeros(5)
    dist[:min(5, len(values))] = values[:5]
    return dist


def _rotation(value: np.ndarray) -> np.ndarray:
    """A 3 x 3 rotation from a Rodrigues vector (OpenCV's ``cv2.Rodrigues``, as aniposelib,
    Pose2Sim and OpenCV's calibration use) or from a 3 x 3 matrix as is."""
    if value.shape == (3, 3):
        return value
    import cv2

    return cv2.Rodrigues(value.reshape(3, 1))[0]


def _size(value, where: str) -> tuple[int, int]:
    size = _array(value, ((2,),), "size", where)
    if np.any(size != np.round(size)):
        raise RigError(f"{where}: size must be whole pixels [width, height], got "
                       f"{size.tolist()}")
    return int(size[0]), int(size[1])


def _toml_camera(section: str, table: dict, source: str, fmt: str) -> dict:
    """Camera keyword arguments from one aniposelib / Pose2Sim camera table."""
    where = f"{source}: [{section}]"
    missing = [k for k in ("matrix", "size", "distortions", "rotation", "translation")
               if k not in table]
    if missing:
        raise RigError(f"{where}: missing key(s) {', '.join(missing)}")
    if "fisheye" in table and not isinstance(table["fisheye"], bool):  # ("true" was not one)
        raise RigError(f"{where}: fisheye must be true or false, got {_short(table['fisheye'])}")
    if table.get("fisheye") is True:
        raise RigError(f"{where}: a fisheye camera (OpenCV's fisheye model): pslog's cameras "
                       f"are plumb_bob ({_DIST_NAMES})")
    name = table.get("name", section)
    if not isinstance(name, str):
        name = str(name)  # aniposelib writes str(name); a bare number is still a name
    width, height = _size(table["size"], where)
    entry = {
        "name": name, "width": width, "height": height,
        "K": _array(table["matrix"], ((3, 3),), "matrix", where),
        "dist": _distortion(_array(table["distortions"], ((4,), (5,), (8,), (12,), (14,)),
                                   "distortions", where), "distortions", where),
        "R": _rotation(_array(table["rotation"], ((3,), (3, 3)), "rotation", where)),
        "t": _array(table["translation"], ((3,),), "translation", where),
    }
    for key in _TIMING_KEYS:
        if key in table:
            entry[key] = table[key]
    return entry


def _opencv_cameras(text: str, path: str | Path) -> tuple[list[dict], str]:
    """Camera keyword arguments from an OpenCV FileStorage text (one or several cameras),
    and the rig's name (a top-level ``rig_name`` string, as pslog writes; else empty)."""
    source = str(path)
    storage = _opencv_open(text, source)  # its nodes are valid only while it lives
    root = storage.root()
    if not root.isMap():
        raise RigError(f"{source}: not an OpenCV FileStorage map of camera keys")
    name_node = root.getNode("rig_name")
    name = name_node.string() if name_node.isString() else ""
    if "camera_matrix" in root.keys():
        return [_opencv_camera(root, None, Path(path).stem, source)], name
    cameras = []
    for key in root.keys():
        node = root.getNode(key)
        if not node.isMap():
            continue
        if "camera_matrix" in node.keys():
            cameras.append(_opencv_camera(node, key, key, source))
        elif set(node.keys()) & _OPENCV_CAMERA_KEYS:  # a camera, not silently dropped
            raise RigError(f"{source}: {key}: missing key camera_matrix")
    if not cameras:
        raise RigError(f"{source}: missing key camera_matrix (at the top level for one "
                       f"camera, or in one map per camera)")
    return cameras, name


#: An OpenCV camera map's keys besides ``camera_matrix``: a map with any of them is a camera.
_OPENCV_CAMERA_KEYS = frozenset({"image_width", "image_height", "distortion_coefficients",
                                 "R", "rvec", "T", "tvec", "camera_name"})


def _opencv_open(text: str, source: str):
    import cv2

    if not text.strip():
        raise RigError(f"{source}: empty file: not an OpenCV FileStorage file")
    storage = cv2.FileStorage()
    level = cv2.utils.logging.getLogLevel()
    # OpenCV logs its own lines on stderr besides raising: the error is ours to say, once
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        opened = storage.open(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except cv2.error as exc:
        # OpenCV's words: "... parse in function '(3): Missing , between the elements'"
        # (the line and why; the bare exc.err, e.g. "parse", says neither)
        found = re.search(r"\((\d+)\): (.+?)'?\s*$", str(exc))
        reason = (f"line {found.group(1)}: {found.group(2)}" if found else
                  " ".join(str(exc.err or exc).split()))
        raise RigError(f"{source}: malformed OpenCV FileStorage file: {reason}") from None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if not opened:
        raise RigError(f"{source}: not an OpenCV FileStorage file (YAML, XML or JSON)")
    return storage


def _opencv_node(node, keys: tuple[str, ...], where: str, required: bool = True):
    for key in keys:
        child = node.getNode(key)
        if not child.empty() and not child.isNone():
            return key, child
    if required:
        raise RigError(f"{where}: missing key {' or '.join(keys)}")
    return None, None


def _node_numbers(seq, key: str, where: str) -> list[float]:
    """The numbers of a FileStorage sequence node; RigError naming ``key`` for an item that
    is not one (``real()`` of a string is 1.8e308: "K has an entry of 1.8e+308 pixels")."""
    values = []
    for i in range(seq.size()):
        item = seq.at(i)
        if not (item.isReal() or item.isInt()):
            shown = repr(item.string()) if item.isString() else "not a number"
            raise RigError(f"{where}: {key} is not numeric: item {i + 1} is {shown}")
        values.append(item.real())
    return values


def _opencv_matrix(node, key: str, where: str) -> np.ndarray:
    """A matrix node: ``!!opencv-matrix`` (``rows``, ``cols``, ``dt``, ``data``), a ROS
    ``camera_info`` map (``rows``, ``cols``, ``data``), or a plain sequence of numbers."""
    import cv2

    if node.isMap() and node.getNode("dt").empty():
        rows, cols, data = (node.getNode(k) for k in ("rows", "cols", "data"))
        if rows.empty() or cols.empty() or not data.isSeq():
            raise RigError(f"{where}: {key} is a map without rows, cols and data")
        values = _node_numbers(data, key, where)
        shape = (int(rows.real()), int(cols.real()))
        if shape[0] * shape[1] != len(values):
            raise RigError(f"{where}: {key} has {len(values)} values for {shape[0]} x "
                           f"{shape[1]}")
        return np.array(values, dtype=np.float64).reshape(shape)
    if node.isSeq():
        return np.array(_node_numbers(node, key, where), dtype=np.float64)
    try:
        value = node.mat()
    except cv2.error:
        value = None
    if value is None:
        raise RigError(f"{where}: {key} is not a matrix")
    return np.asarray(value, dtype=np.float64)


def _opencv_camera(node, key: str | None, default_name: str, source: str) -> dict:
    where = f"{source}: {key}" if key is not None else source
    name_node = node.getNode("camera_name")
    name = name_node.string() if name_node.isString() else default_name
    width_key, width = _opencv_node(node, ("image_width",), where)
    height_key, height = _opencv_node(node, ("image_height",), where)
    k_key, k_node = _opencv_node(node, ("camera_matrix",), where)
    d_key, d_node = _opencv_node(node, ("distortion_coefficients",), where, required=False)
    r_key, r_node = _opencv_node(node, ("R", "rvec"), where)
    t_key, t_node = _opencv_node(node, ("T", "tvec"), where)
    size = []
    for size_key, size_node in ((width_key, width), (height_key, height)):
        if size_node.isString():
            raise RigError(f"{where}: {size_key} must be a number of pixels, got "
                           f"{size_node.string()!r} (a string)")
        if not (size_node.isInt() or size_node.isReal()):
            raise RigError(f"{where}: {size_key} must be a number of pixels")
        value = size_node.real()
        if not size_node.isInt() and not (math.isfinite(value) and value == round(value)):
            raise RigError(f"{where}: {size_key} must be a whole number of pixels")
        size.append(int(value))
    K = _array(_opencv_matrix(k_node, k_key, where), ((3, 3),), k_key, where)
    if d_node is None:
        dist = np.zeros(5)
    else:
        raw = _opencv_matrix(d_node, d_key, where)
        dist = _distortion(_array(raw.ravel(), ((raw.size,),), d_key, where), d_key, where)
    r_raw = _opencv_matrix(r_node, r_key, where)
    if r_key == "rvec" or r_raw.size == 3:
        rvec = _array(r_raw.ravel(), ((3,),), r_key, where)
        R = _rotation(rvec)
    else:
        R = _array(r_raw, ((3, 3),), r_key, where)
    t = _array(_opencv_matrix(t_node, t_key, where).ravel(), ((3,),), t_key, where)
    entry = {"name": name, "width": size[0], "height": size[1], "K": K, "dist": dist,
             "R": R, "t": t}
    for timing_key in _TIMING_KEYS:
        child = node.getNode(timing_key)
        if child.isReal() or child.isInt():
            entry[timing_key] = child.real()
    return entry


# ---- writing ------------------------------------------------------------------------------

def _rvec(R: np.ndarray) -> list[float]:
    import cv2

    return [float(v) for v in cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0].ravel()]


def _t_out(t: np.ndarray, units: str) -> list[float]:
    return [float(v) for v in (np.asarray(t) * 1000.0 if units == "mm" else np.asarray(t))]


def _timing_items(cam: Camera) -> list[tuple[str, float]]:
    """pslog's extra keys: the frame rate and offset always, the clock keys when not 0."""
    return [(key, getattr(cam, key)) for key in _TIMING_KEYS
            if key in ("fps", "offset") or getattr(cam, key) != 0]


def rig_to_toml_calibration(rig: Rig, fmt: str = "anipose", units: str = "m") -> str:
    """``rig`` as an aniposelib (``anipose``) or Pose2Sim (``pose2sim``) ``calibration.toml``.

    Sections are ``cam_0``, ``cam_1``... (zero-padded beyond ten cameras, as aniposelib loads
    its sections in sorted order); translations in ``units``; rotations as Rodrigues vectors;
    ``pose2sim``: ``fisheye = false``, four distortions when ``k3`` is 0, sizes as floats and
    ``[metadata] adjusted = false, error = 0.0``; pslog's ``fps``, ``offset`` and clock keys
    are extra keys the two tools ignore.
    """
    from ..rig import _toml_value

    if fmt not in ("anipose", "pose2sim"):
        raise RigError(f"unknown TOML calibration format {fmt!r} (anipose, pose2sim)")
    width = 1 if len(rig) <= 10 else len(str(len(rig) - 1))
    lines: list[str] = []
    for i, cam in enumerate(rig.cameras):
        dist = [float(v) for v in cam.dist]
        if fmt == "pose2sim" and dist[4] == 0:
            dist = dist[:4]
        size: list = [cam.width, cam.height]
        if fmt == "pose2sim":
            size = [float(cam.width), float(cam.height)]
        section = f"cam_{i:0{width}d}" if fmt == "anipose" else f"cam_{i + 1:02d}"
        items: list[tuple[str, object]] = [
            ("name", cam.name), ("size", size), ("matrix", cam.K), ("distortions", dist),
            ("rotation", _rvec(cam.R)), ("translation", _t_out(cam.t, units))]
        if fmt == "pose2sim":
            items.append(("fisheye", False))
        items += _timing_items(cam)
        lines += [f"[{section}]", *(f"{k} = {_toml_value(v)}" for k, v in items), ""]
    metadata: list[tuple[str, object]] = []
    if fmt == "pose2sim":
        metadata += [("adjusted", False), ("error", 0.0)]
    if rig.name:
        metadata.append(("name", rig.name))
    if metadata:
        lines += ["[metadata]", *(f"{k} = {_toml_value(v)}" for k, v in metadata), ""]
    return "\n".join(lines)


def rig_to_opencv(rig: Rig, suffix: str = ".yml", units: str = "m") -> str:
    """``rig`` as an OpenCV FileStorage text (``suffix`` ``.yml``/``.yaml``: YAML, ``.xml``:
    XML, ``.json``: JSON), written by ``cv2.FileStorage``: one map ``camera_<i>`` per camera
    holding ``camera_name``, ``image_width``, ``image_height``, ``camera_matrix``,
    ``distortion_coefficients`` (1 x 5), ``R`` (3 x 3), ``rvec``, ``T`` (3 x 1, ``units``)
    and pslog's timing keys. Doubles are written with 17 significant digits: exact."""
    text = _opencv_text(rig, suffix, units)
    if not _names_read_back(rig, text):
        kind = _OPENCV_KIND.get(suffix.lower(), "YAML")
        bad = _first_lost_name(rig, text, suffix)
        ok = [s for s in (".xml", ".json", ".yml") if _OPENCV_KIND[s] != kind
              and _names_read_back(rig, _opencv_text(rig, s, units))]
        raise RigError(f"name {bad!r} does not survive OpenCV's {kind} writer (its reader "
                       f"takes it for another value, or cannot read the file): rename it"
                       + (f", or write {' or '.join(ok)}" if ok else ""))
    return text


#: the FileStorage format of each OpenCV suffix
_OPENCV_KIND = {".yml": "YAML", ".yaml": "YAML", ".xml": "XML", ".json": "JSON"}


def _opencv_text(rig: Rig, suffix: str, units: str) -> str:
    """:func:`rig_to_opencv`'s text, names unchecked (its names may not read back)."""
    import cv2

    flags = cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY
    flags |= {".xml": cv2.FILE_STORAGE_FORMAT_XML, ".json": cv2.FILE_STORAGE_FORMAT_JSON}.get(
        suffix.lower(), cv2.FILE_STORAGE_FORMAT_YAML)
    storage = cv2.FileStorage(".yml", flags)
    for i, cam in enumerate(rig.cameras):
        storage.startWriteStruct(f"camera_{i}", cv2.FileNode_MAP)
        storage.write("camera_name", cam.name)
        storage.write("image_width", cam.width)
        storage.write("image_height", cam.height)
        storage.write("camera_matrix", np.asarray(cam.K, dtype=np.float64))
        storage.write("distortion_coefficients",
                      np.asarray(cam.dist, dtype=np.float64).reshape(1, 5))
        storage.write("R", np.asarray(cam.R, dtype=np.float64))
        storage.write("rvec", np.array(_rvec(cam.R)).reshape(3, 1))
        storage.write("T", np.array(_t_out(cam.t, units)).reshape(3, 1))
        for key, value in _timing_items(cam):
            storage.write(key, float(value))
        storage.endWriteStruct()
    if rig.name:
        storage.write("rig_name", rig.name)
    return storage.releaseAndGetString()


def _read_back_names(text: str) -> tuple[list[str], str] | None:
    """The camera names and rig name OpenCV's reader finds in ``text``; None if it cannot
    read it."""
    try:
        cameras, name = _opencv_cameras(text, "export")
    except RigError:
        return None
    return [c["name"] for c in cameras], name


def _names_read_back(rig: Rig, text: str) -> bool:
    """Whether ``text`` reads back with ``rig``'s camera names and rig name: OpenCV's YAML
    writer leaves ``null`` and ``true`` unquoted (read back as no string and as 1: the
    camera came back named ``camera_1``), and its YAML and JSON writers write a name ``'``
    as a file neither reader reads."""
    return _read_back_names(text) == (list(rig.names), rig.name)


def _first_lost_name(rig: Rig, text: str, suffix: str) -> str:
    """The first of ``rig``'s names that ``text`` (its OpenCV text) does not read back."""
    back = _read_back_names(text)
    if back is not None:
        for mine, theirs in zip(rig.names, back[0], strict=False):
            if mine != theirs:
                return mine
        if back[1] != rig.name:
            return rig.name
    # (unreadable: the first name OpenCV's writer cannot write alone)
    for cam in rig.cameras:
        alone = Rig((cam.replace(clock_offset=0.0, clock_drift_ppm=0.0),))
        if not _names_read_back(alone, _opencv_text(alone, suffix, "m")):
            return cam.name
    return rig.name


def rig_to_format(rig: Rig, fmt: str, units: str = "m", suffix: str = ".yml") -> str:
    """``rig`` as the text of a file in ``fmt`` (one of :data:`EXPORT_FORMATS`)."""
    if units not in UNITS:
        raise RigError(f"units {units!r}: use one of {', '.join(UNITS)}")
    if fmt == "opencv":
        return rig_to_opencv(rig, suffix, units)
    if fmt in ("anipose", "pose2sim"):
        return rig_to_toml_calibration(rig, fmt, units)
    raise RigError(f"unknown export format {fmt!r} (have {', '.join(EXPORT_FORMATS)})")
