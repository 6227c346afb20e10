"""The paper's experiments, reproduced in simulation: Table 1 and Table 2.

Our camera placement (:func:`pslog.rig.builtin_rig`) and the open motion parameters
(:mod:`pslog.motion`) are our choices, documented in ``docs/paper.md``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .evaluation import evaluate
from .fusion import fuse_all
from .motion import get_motion
from .rig import apply_timing, builtin_rig
from .simulation import SimulationOptions, simulate
from .tables import format_table

#: Table 1 of the paper, average absolute 3D error in millimetres.
PAPER_TABLE1 = {
    # (cameras, method, timing): (paper's label, paper's fps, straight, spiral, non-uniform)
    (2, "nearest", "typeA"): ("unsynchronized", 60, 23.2, 21.4, 16.2),
    (2, "sync", "sync"): ("synchronized", 60, 0.03, 0.14, 0.12),
    (2, "typeA", "typeA"): ("type A", 60, 1.1, 2.2, 1.8),
    (3, "typeA", "typeA"): ("type A", 90, 1.1, 2.0, 1.7),
    (3, "typeB", "typeB"): ("type B", 60, 0.2, 0.5, 1.5),
    (3, "linear", "typeB"): ("linear prediction", 60, 0.2, 1.4, 4.4),
}
TABLE1_MOTIONS = ("straight", "spiral", "fall")
#: ``--beyond``: methods of ours beside the paper's rows (no paper figure).
BEYOND_TABLE1 = {
    (2, "smooth", "typeA"): ("smooth (ours)", None, None, None, None),
    (3, "smooth", "typeA"): ("smooth (ours)", None, None, None, None),
}
#: ``--beyond``'s faulted session: paper3 with type-A shutters watching the rally, cameras 2
#: and 3 with clock offsets of a few ms that the session's rig does not know (no genlock).
BEYOND_OFFSETS_S = {"cam2": 3.1e-3, "cam3": -4.4e-3}
BEYOND_NOISE_PX = 0.3
BEYOND_DURATION_S = 8.0
BEYOND_TIMINGS = ("nominal", "synced", "true")

#: Table 2 of the paper: mean [mm] and variance [mm²] of z on the turntable (real cameras).
PAPER_TABLE2 = {"typeA": (664.5, 2143.7), "typeB": (662.3, 112.0)}
TURNTABLE_HEIGHT_MM = 660.0

#: Default detection noise for Table 2, pixels (standard deviation per axis); see docs/paper.md.
TABLE2_NOISE_PX = 1.0
TABLE2_DURATION_S = 10.0


@dataclass(frozen=True)
class Table1Row:
    cameras: int
    method: str
    timing: str
    paper_label: str
    paper_fps: int | None  # None: a method of ours, not in the paper
    fps: float  # our measured output rate
    error_mm: dict[str, float]  # motion -> our mean error
    paper_mm: dict[str, float | None]  # motion -> the paper's mean error (None: not in it)


def table1(noise_px: float = 0.0, seed: int = 0, beyond: bool = False) -> list[Table1Row]:
    """Mean 3D error of each of the paper's Table 1 rows on its three motions; with
    ``beyond``, ``smooth`` (ours, type-A shutters) on two and three cameras after them."""
    rows = []
    entries = {**PAPER_TABLE1, **(BEYOND_TABLE1 if beyond else {})}
    for (n_cams, method, timing), (label, paper_fps, *paper) in entries.items():
        rig = apply_timing(builtin_rig("paper3" if n_cams == 3 else "paper2"), timing)
        errors, rates = {}, []
        for motion_name in TABLE1_MOTIONS:
            detections, truth = simulate(rig, get_motion(motion_name), None,
                                         SimulationOptions(noise_px=noise_px, seed=seed))
            accuracy = evaluate(fuse_all(detections, rig, [method])[method], truth)
            errors[motion_name] = accuracy.mean_mm
            rates.append(accuracy.rate_hz)
        rows.append(Table1Row(n_cams, method, timing, label, paper_fps, float(np.mean(rates)),
                              errors, dict(zip(TABLE1_MOTIONS, paper, strict=True))))
    return rows


@dataclass(frozen=True)
class Table2Row:
    method: str
    mean_z_mm: float
    var_z_mm2: float
    n_points: int
    paper_mean_z_mm: float
    paper_var_z_mm2: float


def table2(noise_px: float = TABLE2_NOISE_PX, seed: int = 0,
           duration: float = TABLE2_DURATION_S) -> list[Table2Row]:
    """Mean and variance of z on the turntable with type A and type B timing (three cameras)."""
    rows = []
    for method in ("typeA", "typeB"):
        rig = apply_timing(builtin_rig("paper3"), method)
        detections, _ = simulate(rig, get_motion("turntable"), duration,
                                 SimulationOptions(noise_px=noise_px, seed=seed))
        z_mm = fuse_all(detections, rig, [method])[method].position_world[:, 2] * 1e3
        rows.append(Table2Row(method, float(z_mm.mean()), float(z_mm.var()), len(z_mm),
                              *PAPER_TABLE2[method]))
    return rows


def _paper_cell(value, spec: str) -> str:
    return "—" if value is None else format(value, spec)


def format_table1(rows: list[Table1Row]) -> str:
    header = ["cams", "method", "timing", "fps", "(paper)"]
    for m in TABLE1_MOTIONS:
        header += [f"{m} mm", "(paper)"]
    cells = []
    for r in rows:
        row = [f"{r.cameras}", r.method, r.timing, f"{r.fps:.1f}", _paper_cell(r.paper_fps, "")]
        for m in TABLE1_MOTIONS:
            row += [f"{r.error_mm[m]:.3f}", _paper_cell(r.paper_mm[m], ".2f")]
        cells.append(row)
    return format_table(header, cells, left={1, 2},
                        title="Table 1: mean absolute 3D error [mm], ours beside the paper's")


@dataclass(frozen=True)
class BeyondRow:
    """One method on ``--beyond``'s faulted session with one timing: ``nominal`` (the
    session's rig, clocks unknown), ``synced`` (after ``pslog sync``), ``true`` (the
    simulator's clocks). Errors in millimetres."""

    method: str
    timing: str
    mean_mm: float
    p95_mm: float
    max_mm: float
    n_points: int


@dataclass(frozen=True)
class BeyondClock:
    """``pslog sync``'s offset estimate of one camera against the simulator's truth."""

    camera: str
    true_offset_ms: float
    offset_ms: float
    offset_std_ms: float


def table_beyond(seed: int = 0, noise_px: float = BEYOND_NOISE_PX,
                 duration: float = BEYOND_DURATION_S
                 ) -> tuple[list[BeyondRow], list[BeyondClock]]:
    """typeA and smooth on a session of cameras without genlock: paper3 (type-A shutters)
    watching the rally, cameras 2 and 3 with clock offsets (:data:`BEYOND_OFFSETS_S`) the
    session's rig does not know; with the nominal timing, after ``pslog sync`` (offsets
    estimated from the detections, as the command does) and with the true timing."""
    from .estimation.sync import estimate_clocks
    from .simulation import true_rig

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    opts = SimulationOptions(noise_px=noise_px, seed=seed, clock_offset_s=BEYOND_OFFSETS_S)
    detections, truth = simulate(rig, get_motion("rally"), duration, opts)
    synced = estimate_clocks(detections.best(), rig, ("offset",))
    rigs = {"nominal": rig, "synced": synced.rig, "true": true_rig(rig, opts)}
    rows = []
    for method in ("typeA", "smooth"):
        for timing in BEYOND_TIMINGS:
            acc = evaluate(fuse_all(detections, rigs[timing], [method])[method], truth)
            rows.append(BeyondRow(method, timing, acc.mean_mm, acc.p95_mm, acc.max_mm,
                                  acc.n_points))
    clocks = [BeyondClock(est.name, BEYOND_OFFSETS_S.get(est.name, 0.0) * 1e3,
                          est.offset_s * 1e3, est.offset_std_s * 1e3)
              for est in synced.cameras[1:]]
    return rows, clocks


def format_beyond(rows: list[BeyondRow], clocks: list[BeyondClock],
                  noise_px: float = BEYOND_NOISE_PX) -> str:
    lines = [f"Beyond the paper: cameras without genlock (paper3, type-A shutters, rally "
             f"{BEYOND_DURATION_S:g} s, {noise_px:g} px; clock offsets unknown to the rig)",
             "sync: " + ", ".join(f"{c.camera} {c.offset_ms:.3f} ± {c.offset_std_ms:.3f} ms "
                                  f"(true {c.true_offset_ms:.3f})" for c in clocks)]
    header = ["method"]
    for t in BEYOND_TIMINGS:
        header += [f"{t} mean mm", "p95 mm", "max mm"]
    cells = []
    for method in ("typeA", "smooth"):
        by = {r.timing: r for r in rows if r.method == method}
        row = [method]
        for t in BEYOND_TIMINGS:
            row += [f"{by[t].mean_mm:.2f}", f"{by[t].p95_mm:.2f}", f"{by[t].max_mm:.1f}"]
        cells.append(row)
    return "\n".join(lines) + "\n" + format_table(header, cells)


def format_table2(rows: list[Table2Row], noise_px: float) -> str:
    return format_table(
        ("method", "points", "mean z mm", "(paper)", "var z mm²", "(paper)"),
        [(r.method, f"{r.n_points}", f"{r.mean_z_mm:.1f}", f"{r.paper_mean_z_mm:.1f}",
          f"{r.var_z_mm2:.1f}", f"{r.paper_var_z_mm2:.1f}") for r in rows],
        title=f"Table 2: turntable at z = {TURNTABLE_HEIGHT_MM:.0f} mm, detection noise "
              f"{noise_px:g} px; ours beside the paper's (real cameras)")


def as_json(rows) -> list[dict]:
    return [asdict(r) for r in rows]
