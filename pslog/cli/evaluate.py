"""pslog eval: accuracy of a session's fused tracks against its ground truth, and what their
per-point quality, the gating's rejections, the points left out and the detections each
method rejected say (without ground truth: those alone)."""

from __future__ import annotations

import argparse
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ._common import add_method_option, declare_files

    parser.add_argument("session", metavar="FUSED.mcap",
                        help="fused session (from 'pslog fuse'); with ground truth (simulated "
                             "or synthetic sessions) the accuracy too, over the points the truth "
                             "can score (the others, e.g. outside the truth's time span, "
                             "listed as not scored with the points each method left out), "
                             "else the quality figures alone")
    add_method_option(parser, "only this method's track (repeat, or a comma-separated list, "
                              "for several; default: every track)")
    parser.add_argument("--truth", metavar="TRUTH.csv|.tum",
                        help="score against this ground truth instead of the session's own "
                             "(motion capture, a measured trajectory): a CSV whose header "
                             "names t (or time, timestamp), x, y, z (other columns ignored), "
                             "times in seconds on the original clock, the clock of the CSV "
                             "'pslog import' read (Unix-epoch stays Unix-epoch, as 'pslog "
                             "export --csv' writes times), or a TUM file 'timestamp tx ty tz "
                             "[qx qy qz qw]' on the session clock (as 'pslog export --tum' "
                             "writes truth.tum); the two clocks are one unless the session was "
                             "imported with an origin; world metres; interpolated linearly "
                             "between its samples; a truth on the other clock is refused, "
                             "naming the origin between them (docs/interchange.md)")
    parser.add_argument("--json", action="store_true", help="print JSON for scripts")
    declare_files(parser, inputs=("session", "truth"))


def run(args: argparse.Namespace) -> int:
    import json

    import numpy as np

    from pslog import progress
    from pslog.errors import InputError, shell_word
    from pslog.evaluation import (
        all_rejection_counts,
        assess,
        format_accuracy_table,
        format_quality_table,
        format_rejection_table,
        unscored_counts,
    )
    from pslog.log import read_session
    from pslog.records import by_reason

    progress.update(total=2, what="reading the session")
    session = read_session(args.session)
    progress.step("evaluating")
    # a real session has no truth: no accuracy, but the truth-free quality figures
    # (reprojection residual, gaps, std) and the gating's counts still hold
    truth = session.truth if session.truth is not None and len(session.truth) else None
    if not session.tracks:
        raise InputError(f"{args.session} has no fused tracks; run 'pslog fuse' first")
    methods = args.methods or list(session.tracks)
    missing = [m for m in methods if m not in session.tracks]
    if missing:
        raise InputError(f"no track for method(s) {', '.join(missing)} in {args.session} "
                         f"(have {', '.join(session.tracks)})")
    truth_line = shift_note = None
    if args.truth is not None:  # a truth of one's own (motion capture), on the session clock
        from pslog.interchange.truth_files import describe, read_truth_file, truth_for_tracks
        from pslog.log.csvio import session_clock_origin

        origin = session_clock_origin(session.metadata, session.path)
        read = read_truth_file(args.truth)
        own = truth is not None
        truth = truth_for_tracks(read, [session.tracks[m] for m in methods], origin)
        truth_line = describe(read, truth, origin) + (
            "; the session's own truth not used" if own else "")
        shift_note = _shift_note(truth, [session.tracks[m] for m in methods])
    # accuracy and quality of each track (the truth at its times made once for both)
    rows, quality = map(list, zip(*(assess(session.tracks[m], truth) for m in methods),
                                  strict=True))
    # the gating's rejections, against the ball labels of a simulated dirty session
    gated = all_rejection_counts({m: session.rejections[m] for m in methods
                                  if m in session.rejections},
                                 session.detections, session.ball_truth)
    left_out = session.left_out  # points the methods did not vouch for
    # points a method wrote that the truth cannot score (outside its time span: a rolling
    # shutter's ball row read after the frame's time; a gap in it): the accuracy table's
    # counts and these add up to the points the fuse wrote
    unscored = {m: unscored_counts(session.tracks[m], truth) for m in methods}
    # detections a method's own test rejected (filter's gate, smooth's fit): each keeps its
    # point (the prediction, the trajectory's), flagged ``rejected``
    rejected = {m: int(np.count_nonzero(session.tracks[m].quality["rejected"] == 1))
                for m in methods if "rejected" in session.tracks[m].quality}
    # type A's points made from the detections after them (--confirm-gaps breaks: the
    # paper's construction spanned a break of smooth's fit; span_s < 0), scored with the rest
    backward = {m: n for m in methods if "span_s" in session.tracks[m].quality
                and (n := int(np.count_nonzero(session.tracks[m].quality["span_s"] < 0)))}
    if args.json:
        if shift_note is not None:  # (stdout holds the JSON document alone)
            print(shift_note, file=sys.stderr)
        # NaN (a summary a track has no column for, or no truth) and ±inf (a zero
        # covariance's NEES) are null: strict JSON has neither
        # without truth: the points and output rate still (pslog batch's summary)
        print(json.dumps(_strict([{**(r.as_dict() if r is not None else {
                               "method": q.method, "n_points": q.n_points,
                               "rate_hz": _rate(session.tracks[q.method])}),
                           "quality": q.as_dict(),
                           **({"gating": gated[q.method].as_dict()}
                              if q.method in gated else {}),
                           "left_out": left_out.get(q.method, {}),
                           "not_scored": unscored[q.method],
                           **({"rejected_detections": rejected[q.method]}
                              if q.method in rejected else {}),
                           **({"backward_points": backward[q.method]}
                              if q.method in backward else {}),
                           **({"fused_with": session.fused_with[q.method]}
                              if q.method in session.fused_with else {})}
                          for r, q in zip(rows, quality, strict=True)]), indent=2,
                         allow_nan=False))
    else:
        if truth_line is not None:
            print(truth_line)
        if shift_note is not None:
            print(shift_note)
        if truth is None:
            print(f"{args.session} has no ground truth (only sessions of 'pslog simulate', "
                  f"'pslog record --synthetic' and 'pslog demo' have one; 'pslog live "
                  f"--synthetic' records none): no accuracy; the quality figures without it "
                  f"(to compare with a truth of your own, e.g. motion capture: 'pslog "
                  f"eval {shell_word(args.session)} --truth TRUTH.csv', t,x,y,z on the "
                  f"original clock, or 'pslog export --csv / --tum' for tools of your own: "
                  f"docs/interchange.md)")
        else:
            print(format_accuracy_table([r for r in rows if r is not None]))
        print()
        print(format_quality_table(quality))
        settings = {m: session.fused_with[m] for m in methods if m in session.fused_with}
        if settings:  # (recorded since session 45: the default --confirm-gaps changed then)
            print()
            print("fused with (the pslog fuse choices recorded with the track):")
            for m, chosen in settings.items():
                print(f"{m:<9} " + " ".join(f"--{k} {v}" for k, v in chosen.items()))
        if gated:
            print()
            print("gating (candidates rejected; detections: frames whose every candidate "
                  "was rejected; correct: not the ball; ball lost: the ball rejected; false "
                  "kept: not the ball yet kept)")
            print(format_rejection_table(list(gated.values())))
        shown = [m for m in methods if left_out.get(m) or unscored[m]]
        if shown:
            from pslog.evaluation import LEFT_OUT_TEXT, NOT_SCORED_TEXT

            print()
            print("points left out (invalid or untrustworthy)"
                  + (", and points written but not scored" * any(unscored.values()))
                  + ", by reason:")
            for m in shown:
                left = by_reason(left_out.get(m, {}))
                skipped = by_reason(unscored[m])
                print(f"{m:<9} " + "; ".join(
                    [left] * bool(left) + [f"not scored: {skipped}"] * bool(skipped)))
            texts = {**LEFT_OUT_TEXT, **NOT_SCORED_TEXT}
            reasons = dict.fromkeys(r for m in shown
                                    for r in (*left_out.get(m, {}), *unscored[m]))
            for r in reasons:
                if r in texts:
                    print(f"  {r}: {texts[r]}")
        if any(rejected.values()):
            print()
            print("detections the method rejected (each point kept, flagged rejected: "
                  "filter's the prediction, smooth's the trajectory):")
            for m, n in rejected.items():
                print(f"{m:<9} {n} of {len(session.tracks[m])} points")
            for m in (m for m in REJECTED_TEXT if rejected.get(m)):
                print(f"  {m}: {REJECTED_TEXT[m]}")
        if backward:
            print()
            print("points made from the detections after them (--confirm-gaps jumps, the "
                  "default, or breaks: the paper's construction, from the detections before, "
                  "spanned a kick the images show or a velocity break of smooth's fit; type A's "
                  "point "
                  "from the time-reversed detections replaced it; span_s < 0; in the tables "
                  "with the rest, no Figure 2 in pslog view):")
            for m, n in backward.items():
                print(f"{m:<9} {n} of {len(session.tracks[m])} points")
    return 0


#: Why a method flags a detection rejected (its point kept), said under eval's counts
REJECTED_TEXT = {
    "filter": "its gate: the detection outside the innovation gate (NIS beyond 18.4, χ²₂'s "
              "1 - 1e-4 quantile), even with a bounce or kick before it; the point is the "
              "prediction",
    "smooth": "its fit: the detection's residual beyond 4.3 σ of the fit's noise (χ²₂'s "
              "1 - 1e-4 quantile), or the fit bent to it (leaving it out lowered the fit's "
              "cost beyond that level: a blob near the ball's ray), the fit made without it; "
              "the point is the trajectory's",
}


def _rate(track) -> float | None:
    """A track's output rate, Hz (:func:`pslog.evaluation.output_rate_hz`), None if NaN."""
    from pslog.evaluation import output_rate_hz

    rate = output_rate_hz(track.time_ns)
    return None if rate != rate else rate


def _strict(value):
    """``value`` with every non-finite float (NaN, ±inf) made None, recursively."""
    import math

    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    return value


def _shift_note(truth, tracks) -> str | None:
    """A ``note:`` line when the tracks fit a truth of one's own best with its times moved
    by a millisecond or more (:func:`pslog.interchange.truth_files.truth_clock_shift`): a
    motion-capture clock a few ms off the cameras' moves every error by the ball's speed
    times the offset, charged to the fusion in silence (walk40: 4 ms put smooth's median at
    8.9 mm, 1.8 mm on the cameras' clock)."""
    from pslog.interchange.truth_files import truth_clock_shift

    found = truth_clock_shift(truth, tracks)
    if found is None or not found.notable:
        return None
    return (f"note: the tracks fit this truth best with its times moved by "
            f"{found.shift_s * 1e3:+.2f} ms ({found.method}'s median error "
            f"{found.median_mm:.3g} mm there, {found.median_given_mm:.3g} mm as given): the "
            f"truth's clock may be that far off the cameras' (the first camera's, which "
            f"'pslog sync' keeps), or the tracks' times off the ball's (clocks never synced, "
            f"rolling shutters' readouts not estimated); the figures are as given")
