"""Rigs: the cameras of a session plus their shutter timing, stored as TOML.

File shape (other keys are rejected)::

    name = "lab"                 # optional
    [[camera]]
    name = "cam1"                # unique; order in the file is the camera order
    width = 640
    height = 480
    K = [[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]]
    dist = [0.0, 0.0, 0.0, 0.0, 0.0]   # optional, default zeros
    R = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]  # world -> camera rotation
    t = [0.0, 0.0, 0.0]          # world -> camera translation, metres
    fps = 30.0
    offset = 0.0                 # nominal shutter offset within the frame period, seconds
    clock_offset = 0.0           # optional, default 0: clock correction, seconds
    clock_drift_ppm = 0.0        # optional, default 0: clock rate error, ppm
    readout = 0.0                # optional, default 0: rolling-shutter readout, seconds

The three clock keys are the timing model of :mod:`pslog.timing` (``pslog sync`` estimates
them); they are written only when non-zero. The first camera defines the session clock: its
``clock_offset`` and ``clock_drift_ppm`` must be 0 (its ``readout`` may be anything valid).

Built-in rigs (``paper3``, ``paper2``) and shutter presets (``sync``, ``typeA``, ``typeB``)
are described in :func:`builtin_rig` and :func:`apply_timing`. :func:`load_rig` also reads
the calibrations of aniposelib, Pose2Sim and OpenCV (:mod:`pslog.interchange.rig_formats`,
docs/interchange.md).
"""

from __future__ import annotations

import math
import tomllib
import unicodedata
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .camera import Camera, look_at
from .errors import InputError, RigError, shell_word

TIMING_PRESETS = ("sync", "typeA", "typeB")
#: Most cameras a rig may have (fusion computes geometry for every pair).
MAX_CAMERAS = 256
BUILTIN_RIGS = ("paper3", "paper2")

_TOP_KEYS = {"name", "camera"}
_CLOCK_KEYS = ("clock_offset", "clock_drift_ppm", "readout")
_CAMERA_KEYS = {"name", "width", "height", "K", "dist", "R", "t", "fps", "offset", *_CLOCK_KEYS}
_CAMERA_REQUIRED = _CAMERA_KEYS - {"dist", *_CLOCK_KEYS}


def _composed(name: str) -> str:
    """``name`` in Unicode's composed form (NFC): the form a name typed usually has."""
    return unicodedata.normalize("NFC", name)


@dataclass(frozen=True)
class Rig:
    """An ordered set of uniquely named cameras.

    Attributes
    ----------
    cameras : tuple of Camera, in file order (camera index = position here)
    name : str, may be empty
    """

    cameras: tuple[Camera, ...]
    name: str = ""

    def __post_init__(self) -> None:
        cameras = tuple(self.cameras)
        if not cameras:
            raise RigError("a rig needs at least one camera")
        if len(cameras) > MAX_CAMERAS:  # pairwise geometry grows with the square
            raise RigError(f"a rig of {len(cameras)} cameras: at most {MAX_CAMERAS}")
        names = [c.name for c in cameras]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise RigError(f"camera names must be unique, repeated: {', '.join(duplicates)}")
        composed = [_composed(n) for n in names]
        twins = [n for n, c in zip(names, composed, strict=True) if composed.count(c) > 1]
        if twins:  # two spellings of one name: they look the same, and a name typed is one
            raise RigError(f"camera names must be unique: {' and '.join(map(repr, twins))} "
                           f"are one name in two Unicode spellings (composed and decomposed "
                           f"accents)")
        first = cameras[0]
        if first.clock_offset or first.clock_drift_ppm:
            raise RigError(
                f"camera {first.name!r}: the first camera of a rig defines the session clock, "
                f"so its clock_offset and clock_drift_ppm must be 0 (got "
                f"{first.clock_offset:g} s and {first.clock_drift_ppm:g} ppm)")
        object.__setattr__(self, "cameras", cameras)

    def __len__(self) -> int:
        return len(self.cameras)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.cameras)

    def spelling(self, name: str) -> str | None:
        """The rig's own spelling of camera ``name``: ``name``, or the camera name that is
        ``name`` in another Unicode spelling (``café`` typed composed, written decomposed in
        the rig file, as macOS does); None when the rig has no such camera."""
        if name in self.names:
            return name
        want = _composed(name)
        return next((n for n in self.names if _composed(n) == want), None)

    def index(self, name: str) -> int:
        """Camera index of ``name`` (in either Unicode spelling: :meth:`spelling`);
        :class:`RigError` naming it when unknown."""
        own = self.spelling(name)
        if own is None:
            raise RigError(f"unknown camera {name!r} (rig has {', '.join(self.names)})")
        return self.names.index(own)

    def camera(self, name: str) -> Camera:
        return self.cameras[self.index(name)]

    def with_camera(self, camera: Camera) -> Rig:
        """A rig with ``camera`` replacing the one of the same name, or appended."""
        cameras = list(self.cameras)
        if camera.name in self.names:
            cameras[self.index(camera.name)] = camera
        else:
            cameras.append(camera)
        return Rig(tuple(cameras), self.name)

    def subset(self, names: Sequence[str]) -> Rig:
        return Rig(tuple(self.camera(n) for n in names), self.name)

    # ---- TOML -------------------------------------------------------------------------
    def to_toml(self) -> str:
        """TOML text in the documented shape; floats are written as ``repr`` (shortest text
        that reads back to the same double), so loading is bit-exact."""
        lines = []
        if self.name:
            lines.append(f"name = {_toml_value(self.name)}")
        for cam in self.cameras:
            lines += ["", "[[camera]]"]
            lines += [f"{key} = {_toml_value(value)}" for key, value in _camera_items(cam)]
        return "\n".join(lines).lstrip("\n") + "\n"

    @classmethod
    def from_toml(cls, text: str, source: str = "rig") -> Rig:
        """Parse and validate rig TOML; errors name ``source``, the camera and the key."""
        return cls.from_dict(parse_toml(text, source), source)

    @classmethod
    def from_dict(cls, data: dict, source: str = "rig") -> Rig:
        unknown = sorted(set(data) - _TOP_KEYS)
        if unknown:
            raise RigError(f"{source}: unknown key(s) {', '.join(unknown)} "
                           f"(allowed: name, [[camera]])")
        name = data.get("name", "")
        if not isinstance(name, str):
            raise RigError(f"{source}: name must be a string, got {name!r}")
        tables = data.get("camera")
        if not isinstance(tables, list) or not tables:
            raise RigError(f"{source}: no [[camera]] tables")
        cameras = []
        for i, table in enumerate(tables):
            if not isinstance(table, dict):
                raise RigError(f"{source}: camera #{i + 1} is not a table")
            label = table.get("name", f"#{i + 1}")
            unknown = sorted(set(table) - _CAMERA_KEYS)
            if unknown:
                raise RigError(f"{source}: camera {label!r}: unknown key(s) {', '.join(unknown)}")
            missing = sorted(_CAMERA_REQUIRED - set(table))
            if missing:
                raise RigError(f"{source}: camera {label!r}: missing key(s) {', '.join(missing)}")
            try:
                cameras.append(Camera(**table))
            except RigError as exc:
                raise RigError(f"{source}: {exc}") from None
        try:
            return cls(tuple(cameras), name)
        except RigError as exc:
            raise RigError(f"{source}: {exc}") from None


def parse_toml(text: str, source: str) -> dict:
    """``tomllib.loads(text)``; :class:`RigError` naming ``source`` if malformed, nested too
    deeply for Python's stack (``K = [[[[...]]]]`` a few hundred deep: tomllib parses arrays
    recursively, and its RecursionError was a traceback) or holding an integer beyond Python's
    4300 digits (its ValueError, likewise)."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RigError(f"{source}: malformed TOML: {exc}") from None
    except RecursionError:
        raise RigError(f"{source}: malformed TOML: arrays or tables nested too deeply (a "
                       f"rig's deepest is a matrix, two levels)") from None
    except ValueError as exc:  # (not a TOMLDecodeError: an integer of over 4300 digits)
        raise RigError(f"{source}: malformed TOML: a number of more digits than any rig's "
                       f"({str(exc).partition(';')[0]})") from None


def load_rig(path: str | Path, fmt: str = "auto", options=None) -> Rig:
    """Load a rig file: pslog's TOML, or a calibration of aniposelib, Pose2Sim or OpenCV
    (format detected from the suffix and content, or ``fmt``; see
    :mod:`pslog.interchange.rig_formats`, whose ``ImportOptions`` ``options`` are)."""
    return load_rig_file(path, fmt, options).rig


def load_rig_file(path: str | Path, fmt: str = "auto", options=None):
    """:func:`load_rig`, returning the :class:`~pslog.interchange.rig_formats.RigFile`
    (the rig, the file's format, its translation units, whether it gave the timing)."""
    from .inputs import MAX_RIG_BYTES, check_input_file
    from .interchange.rig_formats import parse_rig_text

    path = Path(path)
    try:
        # a device or FIFO would be read for ever, a huge file whole into memory
        check_input_file(path, "rig file", MAX_RIG_BYTES)
    except InputError as exc:
        if path.is_file() and _is_session_file(path):  # (a session of more than 1 MB)
            raise RigError(_session_not_rig(path)) from None
        raise RigError(str(exc)) from None
    if _is_session_file(path):  # not "'utf-8' codec can't decode byte 0x89"
        raise RigError(_session_not_rig(path))
    try:
        # utf-8-sig: a byte-order mark (Windows editors) is accepted and dropped
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise RigError(f"rig file not found: {path}") from None
    except OSError as exc:
        raise RigError(f"cannot read rig file {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:  # (not the codec's own words)
        raise RigError(f"cannot read rig file {path}: not a text file (byte {exc.start} is "
                       f"not UTF-8 text)") from None
    return parse_rig_text(text, path, fmt, options)


def _session_not_rig(path: Path) -> str:
    return (f"{path} is a session, not a rig file (take its rig with 'pslog rig show "
            f"{shell_word(path)} > rig.toml')")


def save_rig(rig: Rig, path: str | Path, inputs=()) -> None:
    """Write ``rig`` as TOML over ``path`` (an existing file is replaced only by the complete
    new one: :func:`pslog.outputs.replacing`); ``path`` may not be one of ``inputs``.
    An OS fault is a one-line :class:`~pslog.outputs.WriteError`."""
    from .outputs import replacing

    with replacing(path, force=True, inputs=inputs) as f:
        f.write(rig.to_toml())


def _is_session_file(path: Path) -> bool:
    """Whether ``path`` is a regular file starting with the MCAP magic (a session)."""
    from .log._mcapio import starts_as_mcap

    return starts_as_mcap(path)


def resolve_rig(name_or_path: str | Path, timing_from: Rig | None = None,
                not_applied: list[str] | None = None,
                metadata: dict[str, str] | None = None) -> Rig:
    """A built-in rig by name (``paper3``, ``paper2``), a rig file (pslog's TOML, or an
    aniposelib / Pose2Sim / OpenCV calibration: :func:`load_rig`), or a session file (an
    MCAP file: the rig it was recorded, synced or corrected with).

    ``timing_from``: for a calibration file (aniposelib, Pose2Sim, OpenCV: geometry only,
    even one pslog exported with its ``fps`` / ``offset`` / clock keys), the frame rate,
    offset and clock keys of the camera of the same name in this rig (e.g. the session's,
    for ``pslog fuse --rig``: its synced clocks stay); a pslog rig TOML or a session file
    gives its own timing. Without it, a calibration file without timing keys takes 30 fps
    and offset 0.

    ``not_applied``: a list that receives the names of the cameras whose timing keys the
    calibration file holds (a pslog-exported one: ``fps`` and ``offset`` on every camera)
    and ``timing_from``'s replaced with other values (``pslog fuse --rig`` says so).

    ``metadata``: a dict that receives a session file's metadata (e.g. the covariance of the
    clocks ``pslog sync`` estimated, which ``pslog fuse --rig`` takes with the clocks).
    """
    if str(name_or_path) in BUILTIN_RIGS:
        return builtin_rig(str(name_or_path))
    path = Path(name_or_path)
    if not path.exists():
        from .inputs import not_there

        if (why := not_there(path)) is not None:
            raise RigError(f"no rig {str(name_or_path)!r}: {why}")
        raise RigError(f"no rig {str(name_or_path)!r}: not a file and not a built-in rig "
                       f"({', '.join(BUILTIN_RIGS)})")
    if _is_session_file(path):  # a session's rig (e.g. a synced one's), as `pslog rig show`
        from .log import read_session

        session = read_session(path)
        if metadata is not None:
            metadata.update(session.metadata or {})
        return session.rig
    loaded = load_rig_file(path)
    if timing_from is None or loaded.format == "pslog":
        return loaded.rig
    cameras = []
    for cam in loaded.rig.cameras:
        if cam.name in timing_from.names:
            source = timing_from.camera(cam.name)
            timing = {key: getattr(source, key) for key in ("fps", "offset", *_CLOCK_KEYS)}
            if not_applied is not None and loaded.timed and any(
                    getattr(cam, key) != value for key, value in timing.items()):
                not_applied.append(cam.name)
            cam = cam.replace(**timing)
        cameras.append(cam)
    try:
        return Rig(tuple(cameras), loaded.rig.name)
    except RigError as exc:
        raise RigError(f"{path}: {exc}") from None


# ---- built-in rigs and shutter presets ------------------------------------------------

#: The simulated volume of the paper's section 3.1: x 0..3 m, y 0..2 m, z 0..2 m.
PAPER_VOLUME = ((0.0, 3.0), (0.0, 2.0), (0.0, 2.0))

# The paper mounts its cameras 3.0 m high and gives nothing else. We place them around the
# 3.0 x 2.0 m area so that each sees the whole 3 x 2 x 2 m volume: cam1 beyond the x = 0 end,
# cam2 beside the long y = 0 side, cam3 beyond the x = 3 end, all looking at the volume's
# centre (1.5, 1.0, 1.0) with a 640 x 480 image and f = 400 px (77° horizontal field).
_PAPER_EYES = {
    "cam1": (-1.5, 1.0, 3.0),
    "cam2": (1.5, -2.0, 3.0),
    "cam3": (4.5, 1.0, 3.0),
}
_PAPER_TARGET = (1.5, 1.0, 1.0)
_PAPER_K = ((400.0, 0.0, 319.5), (0.0, 400.0, 239.5), (0.0, 0.0, 1.0))


def builtin_rig(name: str) -> Rig:
    """The rigs of the paper's simulation.

    ``paper3``: three 640 x 480, 30 fps cameras 3.0 m above the ground (see ``_PAPER_EYES``),
    offsets zero (apply a timing preset). ``paper2``: its cameras ``cam1`` and ``cam2``.
    """
    if name not in BUILTIN_RIGS:
        raise RigError(f"unknown built-in rig {name!r} (have {', '.join(BUILTIN_RIGS)})")
    cameras = []
    for cam_name, eye in _PAPER_EYES.items():
        R, t = look_at(eye, _PAPER_TARGET)
        cameras.append(Camera(cam_name, 640, 480, np.array(_PAPER_K), np.zeros(5), R, t,
                              fps=30.0, offset=0.0))
    if name == "paper2":
        cameras = cameras[:2]
    return Rig(tuple(cameras), name)


def apply_timing(rig: Rig, preset: str) -> Rig:
    """The rig with its shutter offsets set by a preset.

    - ``sync``: every offset 0 (ordinary synchronised stereo, the paper's Figure 1(a)).
    - ``typeA``: camera ``i`` (0-based) at ``i / (n * fps_i)``: n cameras spread evenly over
      one frame period (Figure 1(b); 1/90 s apart for three 30 fps cameras).
    - ``typeB``: first and last camera at 0, the others at half a period (Figure 1(c)).
    """
    n = len(rig)
    if preset == "sync":
        offsets = [0.0] * n
    elif preset == "typeA":
        offsets = [i / (n * cam.fps) for i, cam in enumerate(rig.cameras)]
    elif preset == "typeB":
        if n < 3:
            raise RigError(f"timing typeB needs at least 3 cameras, rig has {n}")
        offsets = [0.0 if i in (0, n - 1) else 0.5 / cam.fps for i, cam in enumerate(rig.cameras)]
    else:
        raise RigError(f"unknown timing {preset!r} (have {', '.join(TIMING_PRESETS)})")
    return Rig(tuple(c.replace(offset=o) for c, o in zip(rig.cameras, offsets, strict=True)),
               rig.name)


def timing_label(rig: Rig) -> str:
    """The name of the rig's shutter timing, from its offsets: the preset of
    :func:`apply_timing` whose offsets these are (to 1 ns; ``sync`` first), else ``custom``.

    A session's ``timing`` label is always this, so that it agrees with the offsets stored
    with it.
    """
    offsets = np.array([c.offset for c in rig.cameras])
    for preset in TIMING_PRESETS:
        try:
            reference = np.array([c.offset for c in apply_timing(rig, preset).cameras])
        except RigError:  # typeB of fewer than three cameras
            continue
        if np.allclose(offsets, reference, rtol=0.0, atol=1e-9):
            return preset
    return "custom"


#: Closest two camera centres may be, metres, for stereo geometry between them.
MIN_BASELINE_M = 1e-3


def check_baselines(rig: Rig, source: str = "rig") -> Rig:
    """``rig`` if every two cameras are at least :data:`MIN_BASELINE_M` apart, else
    :class:`RigError` naming ``source`` and the two cameras.

    Two cameras at one centre have no epipolar geometry (their fundamental matrix is zero)
    and their rays cross everywhere along the line of sight: no triangulation. (A rig being
    calibrated may hold such cameras, e.g. chessboard intrinsics before any pose, so this is
    checked where geometry is used, not on every rig.)
    """
    centres = np.array([c.center_world for c in rig.cameras])
    distance = np.linalg.norm(centres[:, None] - centres[None, :], axis=2)
    distance[np.tril_indices(len(centres))] = np.inf  # each pair once, not a camera itself
    a, b = np.unravel_index(np.argmin(distance), distance.shape)
    if distance[a, b] < MIN_BASELINE_M:
        raise RigError(
            f"{source}: cameras {rig.names[a]!r} and {rig.names[b]!r} are at the same centre "
            f"({distance[a, b] * 1e3:.3g} mm apart): no stereo between them (no epipolar "
            f"line, rays that never cross at a point); calibrate their poses")
    return rig


def _camera_items(cam: Camera) -> list[tuple[str, object]]:
    """The TOML keys and values of ``cam``, in file order (clock keys only when non-zero)."""
    items: list[tuple[str, object]] = [
        ("name", cam.name), ("width", cam.width), ("height", cam.height), ("K", cam.K),
        ("dist", cam.dist), ("R", cam.R), ("t", cam.t), ("fps", cam.fps),
        ("offset", cam.offset)]
    items += [(key, getattr(cam, key)) for key in _CLOCK_KEYS if getattr(cam, key) != 0]
    return items


def _toml_value(value) -> str:
    """One TOML value: scalars rendered by tomli-w, arrays laid out inline here.

    tomli-w does the escaping of strings (control characters, quotes) and the formatting of
    numbers (``repr`` of a float: the shortest text that reads back to the same double).
    The arrays are joined here rather than by ``tomli_w.dumps`` of the whole document
    because tomli-w writes every array one item per line: a 3 x 3 ``K`` would take 17
    lines of a file people read and edit by hand, where ``[[fx, 0, cx], ...]`` takes one.
    """
    import tomli_w

    if isinstance(value, np.ndarray | list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, np.integer):
        value = int(value)
    elif isinstance(value, np.floating | float):
        value = float(value)
        if not math.isfinite(value):
            raise RigError(f"cannot write non-finite value {value!r} to TOML")
    # the one public entry point of tomli-w is a whole document: render {"v": value}
    return tomli_w.dumps({"v": value}).removeprefix("v = ").removesuffix("\n")
