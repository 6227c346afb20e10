"""Topics, protobuf schemas and metadata keys of the pslog session format (docs/log-format.md).

pslog's own message types (``pslog.DetectionFrame``, ``pslog.TruthPoint``,
``pslog.TrackPoint``) are built here from ``descriptor_pb2`` at import time, so no ``protoc`` is
needed; their field numbers are part of the format and must never change (add fields with new
numbers instead and bump :data:`FORMAT_MINOR`). The Foxglove well-known schemas come from the
``foxglove-schemas-protobuf`` package.
"""

from __future__ import annotations

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

#: Format identity, stored in the session metadata record.
FORMAT_NAME = "pslog-session"
FORMAT_MAJOR = 1  # readers refuse a higher major version
FORMAT_MINOR = 0  # additions that older readers may ignore
FORMAT_VERSION = f"{FORMAT_MAJOR}.{FORMAT_MINOR}"

#: Name of the MCAP Metadata record that marks a file as a pslog session.
SESSION_METADATA = "pslog.session"
#: Keys of that record written by pslog itself; user metadata may not use them.
#: ``derived = "true"`` marks an output made from inputs that still exist (simulate, import,
#: session copies): a partial of it left by a killed run may be removed
#: (:data:`pslog.outputs.DERIVED_KEY`).
RESERVED_KEYS = ("format", "format_version", "rig_toml", "timing", "source", "creator",
                 "created_utc", "camera_names", "derived")

PROTOBUF = "protobuf"
WORLD_FRAME = "world"

#: Quality fields with fixed field numbers in ``pslog.TrackPoint`` (others go to its map).
TRACK_FIXED_QUALITY = ("ray_miss_m", "snap_px", "ray_shift_m")

#: the points a method made but left out, by reason (``Track.dropped``, JSON
#: ``{reason: count}``): a key of the metadata of its track's channel (``/tracks/<method>``,
#: written with the track by ``pslog fuse``). Files fused before held every method's counts
#: under the same name in the session metadata record, as ``{method: {reason: count}}``
#: (docs/log-format.md, "Left-out points"); readers still read that.
LEFT_OUT_KEY = "left_out_points"
#: Track channel metadata key: the ``pslog fuse`` choices that shaped the method's points,
#: a JSON object of option name (without ``--``) to value, e.g. ``{"confirm-gaps":
#: "jumps"}`` for ``typeA`` (session 45: the default changed from ``kicks``; a file fused
#: before has none)
FUSED_WITH_KEY = "fused_with"


# ---- topics ---------------------------------------------------------------------------
def calibration_topic(camera: str) -> str:
    return f"/camera/{camera}/calibration"


def transform_topic(camera: str) -> str:
    return f"/camera/{camera}/transform"


def image_topic(camera: str) -> str:
    return f"/camera/{camera}/image"


def detections_topic(camera: str) -> str:
    return f"/camera/{camera}/detections"


def track_topic(method: str) -> str:
    return f"/tracks/{method}"


def track_scene_topic(method: str) -> str:
    return f"/tracks/{method}/scene"


def ball_truth_topic(camera: str) -> str:
    """Simulated sessions with false candidates: which candidate of each frame is the ball."""
    return f"/truth/ball/{camera}"


def rejections_topic(method: str) -> str:
    """The candidates the gating stage rejected for ``method``'s track."""
    return f"/tracks/{method}/rejections"


def parse_ball_truth_topic(topic: str) -> str | None:
    """``/truth/ball/<camera>`` -> camera, else None."""
    parts = topic.split("/")
    if len(parts) == 4 and parts[0] == "" and parts[1:3] == ["truth", "ball"]:
        return parts[3]
    return None


def parse_rejections_topic(topic: str) -> str | None:
    """``/tracks/<method>/rejections`` -> method, else None."""
    parts = topic.split("/")
    if len(parts) == 4 and parts[0] == "" and parts[1] == "tracks" and parts[3] == "rejections":
        return parts[2]
    return None


TRUTH_TOPIC = "/truth"
EVENTS_TOPIC = "/events"


def parse_camera_topic(topic: str) -> tuple[str, str] | None:
    """``/camera/<name>/<kind>`` -> (name, kind), else None."""
    parts = topic.split("/")
    if len(parts) == 4 and parts[0] == "" and parts[1] == "camera":
        return parts[2], parts[3]
    return None


def parse_track_topic(topic: str) -> str | None:
    """``/tracks/<method>`` -> method (not the ``/scene`` topic), else None."""
    parts = topic.split("/")
    if len(parts) == 3 and parts[0] == "" and parts[1] == "tracks":
        return parts[2]
    return None


# ---- pslog's own protobuf messages ------------------------------------------------------
_F = descriptor_pb2.FieldDescriptorProto


def _field(msg, name: str, number: int, kind: int, repeated: bool = False,
           type_name: str = "") -> None:
    field = msg.field.add(name=name, number=number, type=kind,
                          label=_F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL)
    if type_name:
        field.type_name = type_name


def _build_file() -> descriptor_pb2.FileDescriptorProto:
    file = descriptor_pb2.FileDescriptorProto(name="pslog/session.proto", package="pslog",
                                              syntax="proto3")

    det = file.message_type.add(name="DetectionFrame")
    _field(det, "time_ns", 1, _F.TYPE_INT64)          # capture time, session clock, ns
    _field(det, "camera", 2, _F.TYPE_STRING)          # camera name
    _field(det, "frame_index", 3, _F.TYPE_INT64)      # the camera's frame counter
    # candidate i is (u[i], v[i], radius[i], score[i]); packed parallel arrays decode fast
    _field(det, "u", 4, _F.TYPE_DOUBLE, repeated=True)       # pixels, as detected
    _field(det, "v", 5, _F.TYPE_DOUBLE, repeated=True)       # pixels, as detected
    _field(det, "radius", 6, _F.TYPE_DOUBLE, repeated=True)  # pixels, NaN if unknown
    _field(det, "score", 7, _F.TYPE_DOUBLE, repeated=True)   # [0, 1]

    truth = file.message_type.add(name="TruthPoint")
    _field(truth, "time_ns", 1, _F.TYPE_INT64)
    for number, axis in enumerate("xyz", start=2):
        _field(truth, axis, number, _F.TYPE_DOUBLE)   # world metres

    track = file.message_type.add(name="TrackPoint")
    _field(track, "time_ns", 1, _F.TYPE_INT64)
    _field(track, "method", 2, _F.TYPE_STRING)
    for number, axis in enumerate("xyz", start=3):
        _field(track, axis, number, _F.TYPE_DOUBLE)   # world metres
    _field(track, "camera", 6, _F.TYPE_STRING)        # camera whose shutter made the point
    for number, name in enumerate(TRACK_FIXED_QUALITY, start=7):
        _field(track, name, number, _F.TYPE_DOUBLE)   # NaN where not applicable
    entry = track.nested_type.add(name="QualityEntry")
    entry.options.map_entry = True
    _field(entry, "key", 1, _F.TYPE_STRING)
    _field(entry, "value", 2, _F.TYPE_DOUBLE)
    _field(track, "quality", 10, _F.TYPE_MESSAGE, repeated=True,
           type_name=".pslog.TrackPoint.QualityEntry")
    rejection = file.message_type.add(name="Rejection")
    _field(rejection, "time_ns", 1, _F.TYPE_INT64)      # the frame's logged time, ns
    _field(rejection, "camera", 2, _F.TYPE_STRING)      # camera name
    _field(rejection, "frame_index", 3, _F.TYPE_INT64)  # the camera's frame counter
    _field(rejection, "u", 4, _F.TYPE_DOUBLE)           # the candidate's pixel, as detected
    _field(rejection, "v", 5, _F.TYPE_DOUBLE)
    _field(rejection, "score", 6, _F.TYPE_DOUBLE)       # the detector's score
    _field(rejection, "reason", 7, _F.TYPE_STRING)      # pslog.fusion.gating.REASONS
    return file


_FILE = _build_file()
_POOL = descriptor_pool.DescriptorPool()
_POOL.Add(_FILE)


def _message_class(name: str):
    return message_factory.GetMessageClass(_POOL.FindMessageTypeByName(name))


DetectionFrame = _message_class("pslog.DetectionFrame")
TruthPoint = _message_class("pslog.TruthPoint")
TrackPoint = _message_class("pslog.TrackPoint")
Rejection = _message_class("pslog.Rejection")


def file_descriptor_set(message_class) -> bytes:
    """Serialized ``FileDescriptorSet`` of ``message_class`` and its dependencies: the MCAP
    schema data of the ``protobuf`` schema encoding."""
    fds = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(file_descriptor) -> None:
        for dep in file_descriptor.dependencies:
            if dep.name not in seen:
                seen.add(dep.name)
                add(dep)
        file_descriptor.CopyToProto(fds.file.add())

    add(message_class.DESCRIPTOR.file)
    return fds.SerializeToString()


#: Every message class the writer registers, by schema name.
SCHEMAS = {cls.DESCRIPTOR.full_name: cls for cls in (
    CameraCalibration, FrameTransform, CompressedImage, Log, SceneUpdate,
    DetectionFrame, TruthPoint, TrackPoint, Rejection)}


# ---- small conversions ----------------------------------------------------------------
def set_timestamp(stamp, time_ns: int) -> None:
    """Fill a ``google.protobuf.Timestamp`` from integer nanoseconds (floor division keeps
    ``nanos`` in [0, 1e9) for negative times too)."""
    stamp.seconds, stamp.nanos = divmod(int(time_ns), 1_000_000_000)


def quaternion_xyzw(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w), w >= 0, of a 3x3 rotation matrix (Shepperd's method,
    stable for every rotation).

    Not scipy's ``Rotation.from_matrix(m).as_quat(canonical=True)``, which gives the same
    quaternion (to 2.2e-16, tests/test_conversions.py): importing ``scipy.spatial`` costs
    about 0.2 s, paid by every command that writes a session (``record`` and ``live`` at their
    start) for one rotation per camera."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = np.trace(m)
    diag = np.diag(m)
    i = int(np.argmax(np.r_[trace, diag]))
    if i == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = np.array([(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s,
                      (m[1, 0] - m[0, 1]) / s, 0.25 * s])
    else:
        a = i - 1
        b, c = (a + 1) % 3, (a + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[a, a] - m[b, b] - m[c, c])
        q = np.empty(4)
        q[a] = 0.25 * s
        q[b] = (m[b, a] + m[a, b]) / s
        q[c] = (m[c, a] + m[a, c]) / s
        q[3] = (m[c, b] - m[b, c]) / s
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def rotation_from_quaternion(q_xyzw) -> np.ndarray:
    """3x3 rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q_xyzw, dtype=np.float64) / np.linalg.norm(q_xyzw)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
