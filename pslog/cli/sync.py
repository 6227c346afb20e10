"""pslog sync: every camera's clock estimated from the ball's detections, written into a copy
of the session whose rig holds the estimates."""

from __future__ import annotations

import argparse

from ._common import add_force, declare_files, number_at_most


def _estimate_list(text: str) -> tuple[str, ...]:
    from pslog.estimation.sync import PARAMETERS, SHARED_READOUT

    names = tuple(dict.fromkeys(p.strip() for p in text.split(",") if p.strip()))
    if names == ("auto",):
        return names
    usage = (f"'auto', or name parameters among {', '.join(PARAMETERS)} (comma-separated; "
             f"{SHARED_READOUT} instead of readout: one readout per camera model)")
    bad = [p for p in names if p not in (*PARAMETERS, SHARED_READOUT)]
    if not names or bad:
        problem = ("no parameter named" if not names else
                   "'auto' stands alone (it chooses the parameters)" if bad == ["auto"]
                   else f"unknown {'items' if len(bad) > 1 else 'item'} "
                   + ", ".join(repr(p) for p in bad))
        raise argparse.ArgumentTypeError(f"{text!r}: {problem}; {usage}")
    if {"readout", SHARED_READOUT} <= set(names):
        raise argparse.ArgumentTypeError(
            f"{text!r}: names both readout and {SHARED_READOUT}; name one, "
            f"{SHARED_READOUT} instead of readout (one readout per camera model)")
    return names


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("session", metavar="SESSION.mcap", help="session to synchronise")
    parser.add_argument("-o", "--output", required=True, metavar="SYNCED.mcap",
                        help="output: a copy of the session whose rig holds the estimates")
    parser.add_argument("--estimate", type=_estimate_list, default=("auto",),
                        metavar="auto|LIST",
                        help="clock parameters to estimate: auto (offsets; readouts, and "
                             "drifts on sessions of 30 s or more, each kept when a Wald "
                             "chi-square test at the 0.1 %% level says the data support "
                             "them: the table says which and why; readouts one per camera "
                             "model when its cameras' do not differ), or a comma-separated "
                             "list of offset, drift, readout, estimated as given; "
                             "readout=shared instead of readout estimates one readout per "
                             "camera model (same image size and frame rate) (default: auto)")
    # the scan steps by 1 ms: a minute is 1.2e5 costs per camera, 1e308 ms no array at all
    # (at least the session clock's nanosecond: 1e-320 left the scan no step, a traceback)
    parser.add_argument("--search-ms", type=number_at_most(6e4, "ms", "a minute",
                                                           positive=True, least=1e-6),
                        default=None, metavar="MS",
                        help="search each offset over +-MS around the rig's value, at most "
                             "a minute (default: half a frame period)")
    parser.add_argument("--regularize", choices=("auto", "on", "off"), default="auto",
                        help="replace jittery host timestamps by a robust line against frame "
                             "index first: on, off, or auto (when a camera's jitter is above "
                             "0.2 ms) (default: auto)")
    parser.add_argument("--phases", choices=("measure", "keep"), default="measure",
                        help="the shutter offsets (where in its frame period each camera's "
                             "shutter fires): measure them from the frames' corrected times "
                             "and write them into the copy's rig where the rig's are not "
                             "within 5 %% of a frame period (2 ms at most) of them "
                             "(free-running cameras whose rig says 0), or keep the rig's "
                             "(default: measure)")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object instead of the table: cameras (rig "
                             "order: each estimate and its standard deviation, and "
                             "shutter_offset_s, the offset the copy's rig holds), "
                             "phases_written (measured offsets written), residual_px, "
                             "estimated (the parameters), shared_readout (one readout per "
                             "camera model) and selection (--estimate auto: each "
                             "test's statistic and verdict; else null); the notes (e.g. host "
                             "stamps regularized) on stderr")
    add_force(parser)
    declare_files(parser, inputs=("session",), outputs=("output",),
                  sessions=("output",))


def run(args: argparse.Namespace) -> int:
    import json
    import sys

    from pslog import progress
    from pslog.api import sync
    from pslog.log import copy_session, read_session
    from pslog.timing import CLOCK_STD_KEY, clock_std_json

    progress.update(total=5, what="reading the session")
    session = read_session(args.session)
    outcome = sync(session, args.estimate,
                   search_s=None if args.search_ms is None else args.search_ms / 1e3,
                   regularize=args.regularize, phases=args.phases)
    result = outcome.result
    # the standard deviations beside the estimates they belong to (the viewer shows them)
    stds = [(c.offset_std_s, c.drift_std_ppm, c.readout_std_s) for c in result.cameras]
    estimated = result.estimated
    auto = args.estimate == ("auto",)
    selection = [_test_json(t) for t in result.selection] if auto else None
    progress.step(f"writing {args.output}")
    copy_session(args.session, args.output, rig=outcome.rig, force=args.force,
                 detections=outcome.detections if outcome.regularized else None,
                 metadata={CLOCK_STD_KEY: clock_std_json(
                     outcome.rig, stds, estimated, selection, result.clock_covariance(),
                     prior=outcome.prior, prior_estimated=outcome.prior_estimated)})
    notes = list(outcome.notes) + _negative_readouts(result)
    if args.json:
        # standard output is one JSON document (pslog batch parses it): the notes, what a
        # user should know of the run, on stderr (they were dropped: session 33)
        for note in notes:
            print(f"pslog sync: {note}", file=sys.stderr)
        print(json.dumps({"cameras": [
            {"name": c.name, "offset_s": c.offset_s, "offset_std_s": c.offset_std_s,
             "drift_ppm": c.drift_ppm, "drift_std_ppm": c.drift_std_ppm,
             "readout_s": c.readout_s, "readout_std_s": c.readout_std_s,
             "shutter_offset_s": cam.offset}
            for c, cam in zip(result.cameras, outcome.rig.cameras, strict=True)],
            "phases_written": outcome.phases_written, "residual_px": result.residual_px,
            "estimated": list(estimated), "shared_readout": result.shared_readout,
            "selection": selection}))
        return 0
    for note in outcome.notes:
        print(note)
    print(_table(result, outcome, estimated))
    if auto:
        print(_choice(result))
    elif result.shared_readout:
        print(_shared_readout_line(result.rig))
    print(_legend(estimated, auto, result.rig))
    for note in notes[len(outcome.notes):]:
        print(note)
    print(f"residual {result.residual_px:.3f} px (pixel noise {result.noise_px:.3f} px); "
          f"wrote {args.output}")
    return 0


#: a readout estimated this many standard deviations below 0 is said
NEGATIVE_READOUT_SIGMAS = 2.0


def _negative_readouts(result) -> list[str]:
    """A note for the readouts the free fit put clearly below 0 (no sensor reads its rows
    bottom to top), which sync then held at 0, the clocks fitted again
    (``SyncResult.held_readouts``): walk42's calibrated rig (centres 2-3 mm, focal lengths
    0.2 % off) put cam1's at -0.700 +- 0.247 ms, its offsets 2.1-2.4σ off the truth with it,
    without a word; with the true geometry -0.021 +- 0.149 (docs/timing.md, "σ assumes the
    calibration exact"). A readout just below 0 (within the noise: a global shutter) is held
    at 0 without a word."""
    below = [(name, value, std) for name, value, std in result.held_readouts
             if std > 0 and value < -NEGATIVE_READOUT_SIGMAS * std]
    if not below:
        return []
    said = ", ".join(f"{name} {value * 1e3:.3f} ± {std * 1e3:.3f} ms ({-value / std:.1f}σ)"
                     for name, value, std in below)
    return [f"note: readout estimated below 0 ({said}), which no camera reads: the clocks "
            f"absorb an error of the model, most often the rig's geometry (its calibration); "
            f"their σ hold the pixel noise only (docs/timing.md, \"σ assumes the calibration "
            f"exact\"); held at 0, the nearest a camera reads, and the clocks fitted again "
            f"with it"]


def _shared_readout_line(rig) -> str:
    """``readout=shared``: which cameras share a readout (a model: image size and frame
    rate); where no two cameras are of one model it said "its cameras share the value"
    beside three different readouts, and the estimate is readout's, per camera."""
    import numpy as np

    from pslog.estimation.sync import camera_models

    models = camera_models(rig, range(len(rig)))
    groups = [[rig.cameras[c].name for c in np.flatnonzero(models == m)]
              for m in range(int(models.max()) + 1)]
    if all(len(g) == 1 for g in groups):
        return ("readouts: one per camera model (readout=shared), and no two cameras here "
                "are of one model (image size and frame rate): one readout per camera, as "
                "readout estimates")
    return ("readouts: one per camera model (readout=shared): "
            + "; ".join(f"{', '.join(g)} share one" if len(g) > 1 else f"{g[0]} its own"
                        for g in groups)
            + " (the value and its standard deviation)")


def _test_json(test) -> dict:
    """One :class:`pslog.estimation.sync.ModelTest` as JSON (NaN figures as null)."""
    import math

    def number(x: float) -> float | None:
        return None if math.isnan(x) else float(x)

    return {"parameter": test.parameter, "kept": bool(test.kept),
            "wald_chi2": number(test.statistic), "dof": test.dof,
            "threshold": number(test.threshold), "p_value": number(test.p_value),
            "reason": test.reason, "shared_wald_chi2": number(test.shared_statistic),
            "shared_dof": test.shared_dof, "shared_threshold": number(test.shared_threshold),
            "equal_wald_chi2": number(test.equal_statistic), "equal_dof": test.equal_dof,
            "equal_threshold": number(test.equal_threshold), "tied": bool(test.tied)}


#: ``--estimate auto``: a readout test whose p-value is below this level (above the 0.1 %
#: that estimates readouts) is said as suggestive (the conventional 5 %)
SUGGESTIVE_LEVEL = 0.05


def _choice(result) -> str:
    """``--estimate auto``: the model chosen and each test's figure."""
    lines = [f"model (--estimate auto): {', '.join(result.estimated)}"
             + (" (one readout per camera model)" if result.shared_readout else "")]
    for t in result.selection:
        plural = {"readout": "readouts", "drift": "drifts"}[t.parameter]
        # (the nested test of one readout per camera model beside the per-camera one:
        # either calls for readouts, which are then estimated one per camera, or one per
        # model when the test of equal readouts within each model does not reject (tied);
        # walk38: a tied choice read "one per camera ...: one readout per model")
        what = ("estimated, one per camera model (a test above its threshold calls for them, "
                "and a model's cameras do not differ)"
                if t.kept and t.parameter == "readout" and t.shared_dof and t.tied else
                "estimated, one per camera (a test above its threshold calls for them)"
                if t.kept and t.parameter == "readout" and t.shared_dof else
                "estimated" if t.kept else "not estimated")
        lines.append(f"  {plural} {what}: {t.reason}")
        held = [(c.name, float(c.readout)) for c in result.rig.cameras if c.readout]
        if t.parameter == "readout" and not t.kept and t.p_value < SUGGESTIVE_LEVEL and held:
            # (a rig that holds readouts, e.g. a synced copy synced again: the test is of
            # readouts other than those, kept, not of rolling shutters left out)
            lines.append(f"    (p = {t.p_value:.2g}, below the {SUGGESTIVE_LEVEL * 100:g} % "
                         "level: the data suggest readouts other than the rig's, kept ("
                         + ", ".join(f"{n} {r * 1e3:.3f} ms" for n, r in held)
                         + "): --estimate offset,readout estimates them again)")
        elif t.parameter == "readout" and not t.kept and t.p_value < SUGGESTIVE_LEVEL:
            # (session 35: a readout every camera shares, the ball in a band of rows,
            # shows weakly; unestimated, it delays every point by the readout times the
            # ball's mean row over the height: 8 ms on paper3 left smooth's track ~6 ms late)
            lines.append(f"    (p = {t.p_value:.2g}, below the "
                         f"{SUGGESTIVE_LEVEL * 100:g} % level: rolling shutters this "
                         "session shows only weakly; a readout left out delays every "
                         "point by about the readout times the ball's mean row over the "
                         "image height: if the cameras have rolling shutters, "
                         "give their readouts in the rig or run --estimate offset,readout)")
    return "\n".join(lines)


def _legend(estimated, auto: bool = False, rig=None) -> str:
    """What the table's columns are, which parameters were kept, and (readouts not
    estimated) the hint that most webcams need them: offsets alone left 30-35 mm on a rig of
    three rolling-shutter webcams whose readouts, estimated, brought it to 5-9 mm (typeA,
    smooth, filter means). The ``ideal`` column is explained only where the table has it
    (:func:`_differing_rates`); where it has not, the legend says why."""
    kept = [name for name in ("offset", "drift", "readout") if name not in estimated]
    columns = ("offset, drift: each camera's clock against the first camera's (ref), which "
               "defines the session clock; σ: its standard deviation; readout: rolling "
               "shutter, top row to bottom row; resid: the RMS reprojection residual of the "
               "camera's inlying detections; rig: the shutter offset the rig plans, relative "
               "to the first camera's; phase: each shutter's (top row's) phase after sync, "
               "relative to the first camera's (near rig when the shutters keep the plan; "
               "further than 5 % of a frame period (2 ms at most) from it, the copy's rig "
               "holds the phases unless --phases keep)")
    rates = None if rig is None else _differing_rates(rig)
    if rig is None or rates is None:
        columns += ("; ideal: the type-A stagger i/(n·fps), shutters evenly spread over a "
                    "frame (what typeA timing plans; other timings plan otherwise)")
    else:
        columns += f"; no ideal column: the cameras' frame rates differ ({rates}), so no " \
                   f"stagger spreads their shutters evenly"
    lines = [columns]
    if kept:
        lines.append(f"kept at the rig's values (not estimated): {', '.join(kept)}")
    if "readout" not in estimated and not auto:
        lines.append("most webcams have rolling shutters: try --estimate offset,readout "
                     "(offset,drift,readout on long sessions); readouts many σ above 0 and a "
                     "lower residual mean they matter (docs/timing.md)")
    return "\n".join(lines)


def _differing_rates(rig) -> str | None:
    """None when every camera of ``rig`` has one frame rate (the type-A stagger
    ``i / (n · fps)`` is then defined), else the rates, e.g. ``"30, 60 fps"``: with two
    rates, shutters evenly spread within one camera's period are not within another's, and
    ``i / (n · fps_i)`` compares each camera against a stagger no layout can have."""
    rates = list(dict.fromkeys(cam.fps for cam in rig.cameras))
    return None if len(rates) == 1 else f"{', '.join(f'{r:g}' for r in rates)} fps"


def _table(result, outcome, estimated=("offset", "drift", "readout")) -> str:
    """Per camera: each estimate ± std, residual, the rig's planned shutter offset and the
    achieved shutter phase (both relative to the first camera's, within the camera's frame
    period; the phase :func:`pslog.timing.shutter_phases` of every frame, as ``--phases
    measure`` writes it), and, when the cameras share one frame rate, the ideal type-A
    stagger ``i / (n · fps)``; a parameter not ``estimated`` shows the rig's value and
    ``kept`` for its σ, the first camera's offset and drift ``ref`` (0 by definition)."""
    from pslog.tables import format_table
    from pslog.timing import shutter_phases

    rig = result.rig
    n = len(rig)
    ideal = _differing_rates(rig) is None
    measured = outcome.phases if outcome.phases is not None else shutter_phases(
        outcome.detections.frame_time_ns, outcome.detections.frame_camera, rig)
    cells = []
    for i, (cam, est) in enumerate(zip(rig.cameras, result.cameras, strict=True)):
        period = cam.frame_period
        # both against the first camera, within this camera's period (measured places the
        # first camera at the rig's offset)
        rel = (float(measured.offset_s[i]) - rig.cameras[0].offset) % period
        planned = (cam.offset - rig.cameras[0].offset) % period
        def sigma(name: str, text: str, reference: bool) -> str:
            return "ref" if reference else (f"± {text}" if name in estimated else "kept")

        cells.append([cam.name, f"{est.offset_s * 1e3:.4f}",
                      sigma("offset", f"{est.offset_std_s * 1e3:.4f}", i == 0),
                      f"{est.drift_ppm:.3f}", sigma("drift", f"{est.drift_std_ppm:.3f}", i == 0),
                      f"{est.readout_s * 1e3:.3f}",
                      sigma("readout", f"{est.readout_std_s * 1e3:.3f}", False),
                      f"{est.residual_px:.3f}", f"{planned * 1e3:.3f}", f"{rel * 1e3:.3f}"]
                     + ([f"{i * period / n * 1e3:.3f}"] if ideal else []))
    return format_table(("camera", "offset ms", "σ", "drift ppm", "σ", "readout ms", "σ",
                         "resid px", "rig ms", "phase ms") + (("ideal ms",) if ideal else ()),
                        cells)
