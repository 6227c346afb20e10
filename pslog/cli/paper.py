"""pslog paper: reproduce the paper's Table 1 (simulation) and Table 2 (turntable)."""

from __future__ import annotations

import argparse

from ._common import noise_px, seed


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("table", choices=["table1", "table2"],
                        help="table1 (simulation) or table2 (turntable)")
    parser.add_argument("--noise-px", type=noise_px, default=None,
                        metavar="PX", help="detection noise, pixels (default: 0 for table1, "
                                           "1.0 for table2)")
    parser.add_argument("--seed", type=seed, default=0, metavar="N",
                        help="random seed (default %(default)s)")
    parser.add_argument("--json", action="store_true", help="print JSON for scripts")


def run(args: argparse.Namespace) -> int:
    import json

    from pslog import paper

    if args.table == "table1":
        noise = 0.0 if args.noise_px is None else args.noise_px
        rows = paper.table1(noise_px=noise, seed=args.seed)
        text = paper.format_table1(rows)
    else:
        noise = paper.TABLE2_NOISE_PX if args.noise_px is None else args.noise_px
        rows = paper.table2(noise_px=noise, seed=args.seed)
        text = paper.format_table2(rows, noise)
    if args.json:
        print(json.dumps({"table": args.table, "noise_px": noise, "rows": paper.as_json(rows)},
                         indent=2))
    else:
        print(text)
    return 0
