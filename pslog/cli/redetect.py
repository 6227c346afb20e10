"""``pslog redetect``: re-run ball detection over a session's recorded frames."""

from __future__ import annotations

import argparse

from pslog.cli._common import add_force, declare_files

DESCRIPTION = """\
Re-run ball detection over the JPEG frames stored in a session, with new settings, and
write a new session: frames, calibration, poses, truth, events and metadata are copied as
stored and the detections replaced; fused tracks are dropped (they were fused from the old
detections: fuse the new session). The result fuses like any session. Frames recorded
without an image (--no-frames), or whose image does not decode (empty, truncated, damaged),
keep their old detections; the summary counts them.

By default every frame is decoded whole and the candidates are exactly those the detector
finds in it. --fast detects in each frame decoded at half its width and height (JPEG's DCT
scaling), each ball's region brought back to full size before it is thresholded: 10-20 %
less CPU per 1280 x 720 frame, centroids 0.14-0.27 px RMS from the exact ones (no
bias; up to 0.09 px further from the truth on synthetic sessions), radii about 0.1-0.3 px
smaller: for quick looks at new settings, not for the final detections.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.cli._common import int_in
    from pslog.cli.record import add_detector_arguments

    parser.description = DESCRIPTION
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.add_argument("session", metavar="SESSION.mcap",
                        help="recorded session with frames")
    parser.add_argument("-o", "--output", required=True, metavar="SESSION.mcap",
                        help="new session file to write")
    from recorders.redetect import MAX_CANDIDATES, MAX_WORKERS

    add_detector_arguments(parser)
    for action in parser._actions:  # shared with record; bounded here (exit 2 beyond)
        if action.dest == "max_candidates":
            action.type = int_in(1, MAX_CANDIDATES)
    parser.add_argument("--workers", type=int_in(1, MAX_WORKERS), default=None, metavar="N",
                        help=f"processes decoding and detecting, at most {MAX_WORKERS} "
                             f"(default: all cores for large sessions)")
    parser.add_argument("--fast", action="store_true",
                        help="detect in frames decoded at half size: 10-20%% less CPU, "
                             "centroids 0.14-0.27 px RMS from the exact ones")
    add_force(parser)
    declare_files(parser, inputs=("session",), outputs=("output",),
                  sessions=("output",))


def run(args: argparse.Namespace) -> int:
    from pslog.cli.record import parse_hsv
    from recorders.redetect import _keep_freed_memory, redetect_session

    _keep_freed_memory()  # this short-lived process too: no page faults per copied chunk
    # the output was checked before run() (declare_files); the library checks it again
    summary = redetect_session(args.session, args.output, parse_hsv(args.hsv),
                               max_candidates=args.max_candidates, force=args.force,
                               workers=args.workers, fast=args.fast)
    print(summary.text())
    return 0
