"""Regenerate ``samples/throw.mcap``: a recorded synthetic hand throw with frames.

Three cameras of the built-in ``paper3`` rig with type-A shutter timing (1/90 s apart) watch
the ``throw`` motion for 1.5 s; frames are rendered (motion blur 4 ms, sensor noise 2 levels,
seed 0) and stored as JPEG at quality 60 (4:4:4 colour) to keep the file under 5 MB. Everything is
deterministic: rerunning this script gives the same frames, detections and truth (only the
creation time in the metadata and the message order in the file change).

Usage: ``python samples/make_sample.py [--force] [-o PATH]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pslog.rig import builtin_rig
from recorders import record_synthetic

SAMPLE = Path(__file__).with_name("throw.mcap")


def make_sample(output: Path = SAMPLE, force: bool = False):
    return record_synthetic(builtin_rig("paper3"), "throw", output, timing="typeA",
                            duration=1.5, fast=True, frames=True, jpeg_quality=60, seed=0,
                            force=force)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=SAMPLE)
    parser.add_argument("--force", action="store_true", help="overwrite the existing file")
    args = parser.parse_args(argv)
    summary = make_sample(args.output, args.force)
    size = args.output.stat().st_size
    print(f"{args.output}: {summary.n_frames} frames, {size / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
