"""Reading rerun recordings (.rrd) back in the viewer tests (test_view, test_live_viewers):
the chunks' record batches by entity path, and their columns."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader

#: the rerun command of this environment
RERUN = Path(sys.executable).with_name("rerun")


def rrd_chunks(rrd: Path, unfinished: bool = False
               ) -> tuple[dict[str, list[pa.RecordBatch]], set[str]]:
    """Temporal record batches by entity path, and the static entity paths. ``unfinished``:
    a file a killed client left (no footer: the reader's warning silenced)."""
    temporal: dict[str, list[pa.RecordBatch]] = {}
    static: set[str] = set()
    with warnings.catch_warnings():
        if unfinished:
            warnings.simplefilter("ignore")
        stream = list(RrdReader(rrd).stream())
    for chunk in stream:
        if chunk.is_static:
            static.add(chunk.entity_path)
        else:
            temporal.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return temporal, static


def temporal_chunks(rrd: Path) -> dict[str, list[pa.RecordBatch]]:
    """Temporal chunks' record batches by entity path."""
    return rrd_chunks(rrd)[0]


def batch_column(batches: list[pa.RecordBatch], name: str) -> list:
    """Column ``name`` of record batches, joined, as Python values."""
    return [v for b in batches for v in b.column(name).to_pylist()]


def capture_times(batches: list[pa.RecordBatch]) -> np.ndarray:
    """The ``capture_time`` timeline of record batches, joined (int64 ns)."""
    return np.concatenate([b.column("capture_time").cast(pa.int64()).to_numpy()
                           for b in batches])
