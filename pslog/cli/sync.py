"""pslog sync: every camera's clock estimated from the ball's detections, written into a copy
of the session whose rig holds the estimates."""

from __future__ import annotations

import argparse

from ._common import add_force, declare_files, number_at_most


def _estimate_list(text: str) -> tuple[str, ...]:
    from pslog.estimation.sync import PARAMETERS

    names = tuple(dict.fromkeys(p.strip() for p in text.split(",") if p.strip()))
    bad = [p for p in names if p not in PARAMETERS]
    if not names or bad:
        raise argparse.ArgumentTypeError(
            f"{text!r}: name parameters among {', '.join(PARAMETERS)} (comma-separated)")
    return names


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("session", metavar="SESSION.mcap", help="session to synchronise")
    parser.add_argument("-o", "--output", required=True, metavar="SYNCED.mcap",
                        help="output: a copy of the session whose rig holds the estimates")
    parser.add_argument("--estimate", type=_estimate_list, default=("offset",),
                        metavar="LIST", help="clock parameters to estimate: offset, drift, "
                                             "readout, comma-separated (default: offset)")
    # the scan steps by 1 ms: a minute is 1.2e5 costs per camera, 1e308 ms no array at all
    parser.add_argument("--search-ms", type=number_at_most(6e4, "ms", "a minute",
                                                           positive=True),
                        default=None, metavar="MS",
                        help="search each offset over +-MS around the rig's value, at most "
                             "a minute (default: half a frame period)")
    parser.add_argument("--regularize", choices=("auto", "on", "off"), default="auto",
                        help="replace jittery host timestamps by a robust line against frame "
                             "index first: on, off, or auto (when a camera's jitter is above "
                             "0.2 ms) (default: auto)")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object: cameras (rig order) and residual_px")
    add_force(parser)
    declare_files(parser, inputs=("session",), outputs=("output",))


def run(args: argparse.Namespace) -> int:
    import json

    import numpy as np

    from pslog.errors import FusionError
    from pslog.estimation.sync import estimate_clocks
    from pslog.log import copy_session, read_session
    from pslog.rig import check_baselines
    from pslog.timing import (
        CLOCK_STD_KEY,
        REGULARIZE_AUTO_JITTER_S,
        clock_std_json,
        regularize_detections,
        regularize_times,
    )

    session = read_session(args.session)
    rig = session.rig
    check_baselines(rig, args.session)
    detections = session.detections
    notes = []
    reports = {}
    if args.regularize != "off":
        wanted = []
        for i, cam in enumerate(rig.cameras):
            rows = np.flatnonzero(detections.frame_camera == i)
            if len(np.unique(detections.frame_index[rows])) < 3:
                continue
            _, report = regularize_times(detections.frame_time_ns[rows],
                                         detections.frame_index[rows])
            if args.regularize == "on" or report.jitter_s > REGULARIZE_AUTO_JITTER_S:
                wanted.append(cam.name)
        if wanted:
            detections, reports = regularize_detections(detections, wanted)
            for name, rep in reports.items():
                notes.append(f"{name}: host stamps regularized (jitter {rep.jitter_s * 1e3:.3f} "
                             f"ms, {rep.n_outliers} outliers, {rep.n_dropped} dropped frames)")
            detections, early = _from_session_start(detections)
            if early:
                notes.append(f"{early} frame(s) regularized to before the session clock's "
                             f"zero left out of the copy")
    obs, gated_note = _ball_candidates(detections, rig)
    if len(obs) == 0:
        raise FusionError(f"{args.session} has no detection: nothing to sync on")
    search_s = None if args.search_ms is None else args.search_ms / 1e3
    try:
        result = estimate_clocks(obs, rig, args.estimate, search_s, regularized=reports)
    except FusionError as exc:
        # with false candidates (a distractor) the failure may be theirs, not the ball's
        # motion's; say so
        several = int((detections.candidates_per_frame() > 1).sum())
        if not several:
            raise
        raise FusionError(f"{exc}; note: {several} of {detections.n_frames} frames hold "
                          f"several candidates and a false one the gating kept (a "
                          f"reflection, a second ball) may be the cause") from None
    # the standard deviations beside the estimates they belong to (the viewer shows them)
    stds = [(c.offset_std_s, c.drift_std_ppm, c.readout_std_s) for c in result.cameras]
    copy_session(args.session, args.output, rig=result.rig, force=args.force,
                 detections=detections if notes else None,
                 metadata={CLOCK_STD_KEY: clock_std_json(result.rig, stds)})
    if args.json:
        print(json.dumps({"cameras": [
            {"name": c.name, "offset_s": c.offset_s, "offset_std_s": c.offset_std_s,
             "drift_ppm": c.drift_ppm, "drift_std_ppm": c.drift_std_ppm,
             "readout_s": c.readout_s, "readout_std_s": c.readout_std_s}
            for c in result.cameras], "residual_px": result.residual_px}))
        return 0
    for note in notes + ([gated_note] if gated_note else []):
        print(note)
    print(_table(result, obs))
    print(f"residual {result.residual_px:.3f} px (pixel noise {result.noise_px:.3f} px); "
          f"wrote {args.output}")
    return 0


def _ball_candidates(detections, rig):
    """Each frame's ball at its LOGGED time: the best-scored candidate when no frame holds
    more than one, else the one the gating stage chooses (:func:`pslog.fusion.gating.gate`,
    offline, at the rig's clocks: its epipolar gate allows for the ball's motion between
    shutters, so clocks wrong by some milliseconds still pass the ball and stop a static
    second object or a reflection), and a note saying how many candidates it rejected."""
    import numpy as np

    if not np.any(detections.candidates_per_frame() > 1) or len(rig) < 2:
        return detections.best(), None
    from pslog.fusion.gating import gate

    gated = gate(detections, rig, causal=False)
    note = (f"{len(gated.rejections)} of {len(gated.chosen)} candidates rejected by gating "
            f"(the ball chosen among each frame's candidates, as `pslog fuse` does)")
    return gated.kept(detections).best(), note


def _from_session_start(detections):
    """``detections`` without the frames whose (regularized) time is before 0, and how many
    were left out: a session's log times start at its clock's zero."""
    import numpy as np

    keep = detections.frame_time_ns >= 0
    if keep.all():
        return detections, 0
    new_row = np.cumsum(keep) - 1
    cand = keep[detections.cand_frame]
    out = detections.__class__.from_frames(
        detections.camera_names, detections.frame_time_ns[keep], detections.frame_camera[keep],
        detections.frame_index[keep], new_row[detections.cand_frame[cand]],
        detections.cand_uv[cand], detections.cand_radius[cand], detections.cand_score[cand])
    return out, int(np.count_nonzero(~keep))


def _table(result, obs) -> str:
    """Per camera: each estimate ± std, residual, and the achieved shutter phase against the
    ideal stagger ``i / (n · fps)``."""
    import numpy as np

    from pslog.records import NS
    from pslog.timing import camera_parameters, true_times_ns

    rig = result.rig
    p = camera_parameters(rig)
    n = len(rig)
    header = (f"{'camera':<10} {'offset ms':>18} {'drift ppm':>16} {'readout ms':>16} "
              f"{'resid px':>9} {'phase ms':>9} {'ideal ms':>9}")
    lines = [header, "-" * len(header)]
    phase0 = None
    for i, (cam, est) in enumerate(zip(rig.cameras, result.cameras, strict=True)):
        rows = obs.camera == i
        period = cam.frame_period
        top = true_times_ns(obs.time_ns[rows], 0.0, p["height"][i], p["clock_offset"][i],
                            p["clock_drift_ppm"][i], 0.0) / NS  # each frame's top row
        angle = 2 * np.pi * np.mod(top, period) / period
        phase = (np.angle(np.mean(np.exp(1j * angle))) / (2 * np.pi) * period) % period \
            if len(top) else float("nan")
        phase0 = phase if phase0 is None else phase0
        rel = (phase - phase0) % period
        lines.append(
            f"{cam.name:<10} {est.offset_s * 1e3:>9.4f} ±{est.offset_std_s * 1e3:<7.4f}"
            f"{est.drift_ppm:>8.3f} ±{est.drift_std_ppm:<7.3f}"
            f"{est.readout_s * 1e3:>8.3f} ±{est.readout_std_s * 1e3:<7.3f}"
            f"{est.residual_px:>9.3f} {rel * 1e3:>9.3f} {i * period / n * 1e3:>9.3f}")
    return "\n".join(lines)
