"""``pslog recover``: salvage every complete record of a damaged session."""

from __future__ import annotations

import argparse

from ._common import add_force, declare_files


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("session", metavar="BROKEN.mcap",
                        help="damaged session, e.g. from a killed recorder")
    parser.add_argument("-o", "--output", required=True, metavar="FIXED.mcap",
                        help="new session with every complete record of the damaged one")
    add_force(parser)
    declare_files(parser, inputs=("session",), outputs=("output",),
                  sessions=("output",))


def run(args: argparse.Namespace) -> int:
    from pslog.errors import shell_word
    from pslog.log import recover_session
    from pslog.log.recover import damage_line, describe_salvage

    # the output was checked before run() (declare_files); on any failure
    # recover_session leaves nothing half-written
    report = recover_session(args.session, args.output, force=args.force)
    if report["being_recorded"]:
        # (every other command refuses such a file: "it may still be recording")
        last = report["last_detection_ns"]
        upto = "" if last is None else f", up to t = {last / 1e9:.3f} s"
        print(f"note: {args.session} is still being recorded (another pslog is writing it): "
              f"{args.output} holds what it had written so far{upto}; run "
              f"this again once the recording has ended, for all of it")
    if report["rebuilt_metadata"]:
        # (what those messages do not hold is lost with the record: said, as a fuse of the
        # copy would take the nominal clocks without a word)
        print("the session metadata (rig, cameras) was damaged: rebuilt from the cameras' "
              "calibration and pose messages, frame rates and offsets from the detections' "
              "times (check it: 'pslog rig show FIXED.mcap'); lost with it: the clocks "
              "pslog sync estimated, if it was synced (run 'pslog sync FIXED.mcap -o "
              "SYNCED.mcap' again), and the detector settings".replace(
                  "FIXED.mcap", shell_word(args.output)))
    for d in report["repaired"]:
        print(f"repaired the record at bytes {d['start']}..{d['end']}: {d['reason']}; kept "
              f"exactly as the file's index locates it")
    if report["was_complete"]:
        print(f"{args.session} was complete; copied {report['messages']} messages to "
              f"{args.output}")
        return 0
    if report["data_complete"]:
        what = "" if report["repaired"] else " (only the summary was damaged)"
        print(f"recovered all {report['messages']} messages{what} into {args.output}")
        return 0
    # per kind, not "up to the last message": truth is written up front and images reach
    # the file before the detections of the same moment
    print(f"recovered into {args.output}: {describe_salvage(report)}")
    print(f"  skipped {len(report['damaged'])} damaged part(s), {report['discarded_bytes']} of "
          f"{report['file_bytes']} bytes; every intact record before and after was kept:")
    for d in report["damaged"]:
        print(f"    {damage_line(d)}")
    if report["unknown_channel_messages"]:
        print(f"  {report['unknown_channel_messages']} intact messages were dropped: their "
              f"channel was defined in a damaged part")
    print("  messages kept per topic:")
    for topic, n in report["topics"].items():
        print(f"    {topic}: {n}")
    return 0
