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
    parser.add_argument("--beyond", action="store_true",
                        help="table1 only: add smooth (ours) beside the paper's methods, and "
                             "a second table: typeA and smooth on a session whose cameras' "
                             "clock offsets are unknown (no genlock), with the nominal timing, "
                             "after 'pslog sync' and with the true timing")
    parser.add_argument("--json", action="store_true", help="print JSON for scripts")


def run(args: argparse.Namespace) -> int:
    import json

    from pslog import paper

    from ._common import usage_error

    beyond = None
    rows: list  # Table1Row or Table2Row
    if args.beyond and args.table != "table1":
        return usage_error("paper", "argument --beyond: only with table1")
    if args.table == "table1":
        noise = 0.0 if args.noise_px is None else args.noise_px
        rows = paper.table1(noise_px=noise, seed=args.seed, beyond=args.beyond)
        text = paper.format_table1(rows)
        if args.beyond:
            beyond = paper.table_beyond(seed=args.seed)
            text += "\n\n" + paper.format_beyond(*beyond)
    else:
        noise = paper.TABLE2_NOISE_PX if args.noise_px is None else args.noise_px
        rows = paper.table2(noise_px=noise, seed=args.seed)
        text = paper.format_table2(rows, noise)
    if args.json:
        out = {"table": args.table, "noise_px": noise, "rows": paper.as_json(rows)}
        if beyond is not None:
            out["beyond"] = {"noise_px": paper.BEYOND_NOISE_PX,
                             "rows": paper.as_json(beyond[0]),
                             "sync": paper.as_json(beyond[1])}
        print(json.dumps(out, indent=2))
    else:
        print(text)
    return 0
