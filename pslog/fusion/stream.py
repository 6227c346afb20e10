"""The causal streaming form of fusion: detections pushed as they arrive, points out.

Every method is causal, so running the batch kernel over a trailing window of recent
detections gives, for each new detection, the same point as the batch run over the whole
session. A point is *settled*, and emitted, once nothing that could still arrive can change it:

- ``typeA`` and ``nearest`` use only detections at or before the new one in (time, camera)
  order, so its point is emitted as soon as it is pushed;
- ``sync``, ``typeB`` and ``linear`` group detections within the tolerance, so a point at
  ``t`` is emitted once a detection later than ``t + tolerance`` arrives, or on :meth:`flush`.
"""

from __future__ import annotations

import numpy as np

from ..errors import FusionError
from ..geometry import fundamental_matrices
from ..records import NS, Observations, Track
from ..rig import Rig
from . import METHODS, FusionOptions, causal_methods, check_method, check_tolerance, fuse
from ._prepare import default_max_gap_s, prepare


class StreamFuser:
    """Incremental fusion of one rig's detections with one method.

    Parameters
    ----------
    rig : Rig
    method : a name of a causal method of :data:`pslog.fusion.METHODS` (an offline one,
        such as ``smooth``, is refused: each of its points uses every detection)
    options : FusionOptions

    Examples
    --------
    >>> fuser = StreamFuser(rig, "typeA")                        # doctest: +SKIP
    >>> track = fuser.push(time_ns, camera, uv)                  # doctest: +SKIP
    """

    def __init__(self, rig: Rig, method: str, options: FusionOptions | None = None) -> None:
        if len(rig) < 2:
            raise FusionError(f"fusion needs at least two cameras; rig has {len(rig)}")
        self.rig = rig
        self.method = check_method(method)
        if not METHODS[method].causal:
            raise FusionError(f"method {method!r} is offline (each of its points uses every "
                              f"detection) and cannot stream; streaming methods: "
                              f"{', '.join(causal_methods())}")
        self._immediate = not METHODS[method].waits_tolerance
        self.options = options or FusionOptions()
        check_tolerance(rig, self.options.tolerance_s)
        self._max_gap_s = self.options.max_gap_s or default_max_gap_s(rig)
        # history a new point may reach back to: two bridged gaps plus two tolerances
        self._history_ns = int((2 * self._max_gap_s + 2 * self.options.tolerance_s) * NS) + 1
        self._settle_ns = 0 if self._immediate else int(self.options.tolerance_s * NS)
        self._F = fundamental_matrices(rig.cameras)
        self._time = np.zeros(0, np.int64)
        self._camera = np.zeros(0, np.int32)
        self._uv = np.zeros((0, 2))
        self._frame = np.zeros(0, np.int64)
        self._emitted_until: tuple[int, int] = (np.iinfo(np.int64).min, -1)  # (time, camera)

    def push(self, time_ns, camera, uv, frame_index=None) -> Track:
        """Add detections (arrays, or scalars for one) in (time, camera) order, no earlier than
        any pushed before; returns the points that became settled (possibly none)."""
        time_ns = np.atleast_1d(np.asarray(time_ns, dtype=np.int64))
        camera = np.atleast_1d(np.asarray(camera, dtype=np.int32))
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        frame_index = (np.zeros(len(time_ns), np.int64) if frame_index is None
                       else np.atleast_1d(np.asarray(frame_index, dtype=np.int64)))
        if len(time_ns) == 0:
            return self._settled(final=False)
        if len(self._time) and (time_ns[0], camera[0]) <= (self._time[-1], self._camera[-1]):
            raise FusionError("StreamFuser.push: detections must arrive in (time, camera) "
                              f"order; got t={time_ns[0]} ns after t={self._time[-1]} ns")
        self._time = np.concatenate([self._time, time_ns])
        self._camera = np.concatenate([self._camera, camera])
        self._uv = np.concatenate([self._uv, uv])
        self._frame = np.concatenate([self._frame, frame_index])
        return self._settled(final=False)

    def flush(self) -> Track:
        """Emit every remaining point (end of stream)."""
        return self._settled(final=True)

    def _settled(self, final: bool) -> Track:
        if len(self._time) == 0:
            return _empty(self.method)
        obs = Observations(self._time, self._camera, self._uv, self._frame)
        try:
            track = fuse(obs, self.rig, self.method, self.options,
                         prepared=prepare(obs, self.rig, self._F))
        except FusionError:
            if not final and not self._immediate:
                track = _empty(self.method)  # no common instant in the window yet
            else:
                raise
        newest = int(self._time[-1])
        key_t, key_c = self._emitted_until
        new = (track.time_ns > key_t) | ((track.time_ns == key_t) & (track.camera > key_c))
        if not final and self._settle_ns:
            new &= track.time_ns < newest - self._settle_ns
        out = track.select(new)
        if len(out):
            self._emitted_until = (int(out.time_ns[-1]), int(out.camera[-1]))
        # keep only the history the next points can reach
        keep = self._time >= newest - self._history_ns - self._settle_ns
        self._time, self._camera = self._time[keep], self._camera[keep]
        self._uv, self._frame = self._uv[keep], self._frame[keep]
        return out


def _empty(method: str) -> Track:
    return Track(method, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32))
