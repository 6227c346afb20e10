"""Tables that commands print (accuracy, quality, gating, clocks, the paper's tables), laid
out by rich: columns sized to their contents, a rule under the header, plain text without
colour or control characters, so the same table reads well on a terminal, in a log file and
pasted into a report.

Cells arrive formatted (each table chooses its units and digits, e.g. ``f"{mm:.3f}"``); this
module only lays them out.
"""

from __future__ import annotations

import io
from collections.abc import Collection, Sequence


def format_table(header: Sequence[str], rows: Sequence[Sequence[str]], *,
                 left: int | Collection[int] = 1, title: str | None = None,
                 note: str | None = None) -> str:
    """A plain-text table: ``header`` and ``rows`` of formatted cells.

    Parameters
    ----------
    header : column names (units in the name: ``mean mm``)
    rows : one sequence of cell strings per row, as many as ``header``
    left : how many leading columns are left-aligned (names), or their indices; the others,
        numbers, are right-aligned
    title : a line above the table
    note : a line below it (what the columns mean)

    Returns
    -------
    str without a trailing newline
    """
    from rich import box
    from rich.console import Console
    from rich.table import Table

    if any(len(row) != len(header) for row in rows):
        raise ValueError(f"every row needs {len(header)} cells")
    left_set = set(range(left)) if isinstance(left, int) else set(left)
    table = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False, header_style=None)
    for i, name in enumerate(header):
        table.add_column(name, justify="left" if i in left_set else "right", no_wrap=True)
    for row in rows:
        table.add_row(*row)
    buffer = io.StringIO()
    Console(file=buffer, width=100_000, color_system=None, force_terminal=False,
            no_color=True, highlight=False, emoji=False, markup=False,
            legacy_windows=False).print(table)
    lines = [line.rstrip() for line in buffer.getvalue().splitlines()]
    return "\n".join(([title] if title else []) + lines + ([note] if note else []))
