"""Issue 10 (session 33): ``pslog demo``'s typeA row and the paper's Table 1 (its typeA
rows) with ``FusionOptions(confirm_every=True, confirm_sides=True)`` against the default.

    PYTHONPATH=. python benchmarks/session33/demo_table.py DEMO_FOLDER
(``DEMO_FOLDER``: a ``pslog demo --no-view --out DIR`` run's folder)"""
import sys
from unittest import mock

from pslog import paper
from pslog.evaluation import evaluate, format_accuracy_table
from pslog.fusion import FusionOptions, for_session, fuse_all
from pslog.log import read_session

VARIANTS = {"default": FusionOptions(),
            "every": FusionOptions(confirm_every=True),
            "kicks": FusionOptions(confirm_every=True, confirm_sides=True)}


def main():
    session = read_session(sys.argv[1] + "/session.mcap")
    for name, opt in VARIANTS.items():
        track = fuse_all(session.detections, session.rig, ["typeA"],
                         for_session(opt, session.metadata))["typeA"]
        print(name, "demo:")
        print(format_accuracy_table([evaluate(track, session.truth)]))
    import pslog.fusion as fusion

    real = fusion.fuse_all
    for name, opt in VARIANTS.items():
        def with_option(det, rig, methods, options=None, _opt=opt, **kw):
            return real(det, rig, methods, _opt if options is None else options, **kw)

        with mock.patch.object(paper, "fuse_all", with_option):
            rows = [(r.cameras, r.fps, r.error_mm) for r in paper.table1() if r.method == "typeA"]
        print(name, "table1 typeA rows:", rows)


if __name__ == "__main__":
    main()
