"""Record a rendered synthetic rig: the whole pipeline with ground truth and no hardware."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import IO, Literal

import numpy as np

from pslog.errors import InputError
from pslog.motion import BALL_RADIUS, Motion, get_motion
from pslog.records import NS, Truth
from pslog.rig import TIMING_PRESETS, Rig, apply_timing, timing_label
from pslog.simulation import check_duration, check_exposure, shutter_times

from .detect import HsvRange
from .record import RecordSummary, StopRequest, record
from .render import RenderOptions
from .sources import SyntheticSpec


def synthetic_truth(rig: Rig, motion: Motion, duration_s: float) -> Truth:
    """The ball centre at every shutter time of every camera in ``[0, duration_s)``, on the
    true clock (the session's: the first camera's)."""
    times = np.unique(np.concatenate([np.round(shutter_times(c, duration_s) * NS)
                                      for c in rig.cameras]).astype(np.int64))
    return Truth(times, motion.position(times / NS))


def record_synthetic(
    rig: Rig,
    motion: Motion | str,
    output: str | Path,
    *,
    duration: float | None = None,
    fast: bool = True,
    frames: bool = True,
    jpeg_quality: int = 90,
    seed: int = 0,
    force: bool = False,
    timing: str | None = None,
    hsv: HsvRange | None = None,
    max_candidates: int = 5,
    ball_radius: float = BALL_RADIUS,
    exposure_s: float = 0.004,
    noise_sigma: float = 2.0,
    render: RenderOptions | None = None,
    status: IO[str] | Literal["stderr"] | None = "stderr",
    stop_request: StopRequest | None = None,
    prefix: str = "",
) -> RecordSummary:
    """Render what every camera of ``rig`` sees of a ball following ``motion`` and record it
    (detections, frames, ground truth) into the session ``output``.

    Parameters
    ----------
    rig : cameras and shutter offsets (``timing`` may set the offsets from a preset); a
        camera with clock corrections (``clock_offset``, ``clock_drift_ppm``, ``readout``)
        sees the ball at the true times of its stamps
        (:class:`recorders.live.LoggedClockPosition`)
    motion : a :class:`pslog.motion.Motion` (its ``position`` a module-level function) or
        the name of one of :data:`pslog.motion.MOTIONS`
    duration : seconds, at least a frame period (default: the motion's natural duration)
    fast : render as fast as possible (False: in real time, like cameras)
    timing : ``sync``, ``typeA`` or ``typeB`` to apply that preset to the rig first; None
        keeps the rig's offsets (the metadata names the matching preset, else ``custom``)
    ball_radius, exposure_s, noise_sigma, seed : rendering (see :class:`RenderOptions`);
        ``render`` overrides them all when given
    frames, jpeg_quality, hsv, max_candidates, force, status, stop_request, prefix : as
        :func:`recorders.record`

    Returns
    -------
    RecordSummary
    """
    if isinstance(motion, str):
        motion = get_motion(motion)
    if timing is not None:
        if timing not in TIMING_PRESETS:
            raise InputError(f"unknown timing {timing!r} (have {', '.join(TIMING_PRESETS)})")
        rig = apply_timing(rig, timing)
    duration = motion.duration if duration is None else float(duration)
    # at least a frame period and not beyond a simulation's frames, as pslog record and
    # simulate check (a shorter one recorded no file, and pslog demo then said 'no such
    # file: session.mcap')
    check_duration(rig, duration)
    options = render or RenderOptions(ball_radius=ball_radius, exposure_s=exposure_s,
                                      noise_sigma=noise_sigma, seed=seed)
    check_exposure(rig, options.exposure_s)  # a shutter open into the next frame is absurd
    # a camera whose clock the rig corrects (a rig from 'pslog sync') sees the ball at the
    # true times of its stamps, as 'pslog live --synthetic' renders it: the stored rig's
    # corrections then recover the motion (before, the nominal times were rendered and the
    # stored corrections moved every point off it: 19 mm against 0.7 on a 3 s rally)
    from .live import LoggedClockPosition

    specs = {}
    for i, cam in enumerate(rig.cameras):
        seen = (replace(motion, position=LoggedClockPosition(motion.position, cam))
                if cam.has_clock_correction else motion)
        specs[cam.name] = SyntheticSpec(cam, i, seen, options, duration, realtime=not fast)
    metadata = {
        "synthetic_motion": motion.name,
        "synthetic_ball_radius_m": repr(options.ball_radius),
        "synthetic_exposure_s": repr(options.exposure_s),
        "synthetic_noise_sigma": repr(options.noise_sigma),
        "synthetic_seed": str(options.seed),
    }
    return record(rig, specs, output, duration_s=duration, frames=frames,
                  jpeg_quality=jpeg_quality, hsv=hsv, max_candidates=max_candidates,
                  force=force, timing=timing or timing_label(rig),
                  source=f"record --synthetic motion={motion.name}", metadata=metadata,
                  truth=synthetic_truth(rig, motion, duration), status=status,
                  stop_request=stop_request, prefix=prefix)
