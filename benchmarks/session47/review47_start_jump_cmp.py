"""The session-47 review: the filter's points with a held start's ``pb`` from ``_START_PB`` -1
(a jump reaching back to the start withdraws it) against 0 (80b8c27), on the randomized sessions
of ``review47_stream_check.py``: the points removed are starts (their errors, mm), every other
point, column and count the same. Usage: ``PYTHONPATH=.:tests:benchmarks/session47 python
benchmarks/session47/review47_start_jump_cmp.py FIRST LAST [fast]``."""

import sys

import numpy as np
from review47_stream_check import session, session_fast

import pslog.fusion.filter as FM
from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions, fuse


def main() -> None:
    bad, errs = 0, []
    for seed in range(int(sys.argv[1]), int(sys.argv[2])):
        make = session_fast if sys.argv[3:] == ["fast"] else session
        rig, det, _, truth = make(seed)
        FM._START_PB = 0
        a = fuse(det, rig, "filter", FusionOptions())
        FM._START_PB = -1
        b = fuse(det, rig, "filter", FusionOptions())
        kb = set(zip(b.time_ns.tolist(), b.camera.tolist(), strict=True))
        keep = np.array([k in kb for k in zip(a.time_ns.tolist(), a.camera.tolist(),
                                                 strict=True)], bool)
        gone = np.flatnonzero(~keep)
        same = np.array_equal(a.position_world[keep], b.position_world) and all(
            np.array_equal(a.quality[q][keep], b.quality[q], equal_nan=True) for q in a.quality)
        others = ({k: v for k, v in a.dropped.items() if k != "held"}
                  == {k: v for k, v in b.dropped.items() if k != "held"})
        held = b.dropped.get("held", 0) - a.dropped.get("held", 0) == len(gone)
        if not (same and others and held and np.all(a.quality["init"][gone] == 1)):
            bad += 1
            print("DIFF", seed, len(a), len(b), a.dropped, b.dropped, flush=True)
        errs += (1000 * errors_m(a, truth)[gone]).round(1).tolist()
    print("sessions differing otherwise:", bad, "removed:", len(errs), sorted(errs))


if __name__ == "__main__":
    main()
