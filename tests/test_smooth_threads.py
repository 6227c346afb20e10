"""The break scan in blocks of candidates, on one thread or two (PSLOG_SMOOTH_THREADS): the
same bits as one batch of every candidate, whatever the thread count."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from _rally import rally
from numpy.testing import assert_array_equal

from pslog import builtin_rig
from pslog.errors import PslogError
from pslog.estimation import _breaks, fit_trajectory
from pslog.estimation.trajectory import MotionPrior
from pslog.rig import apply_timing
from pslog.simulation import SimulationOptions, simulate

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "throw.mcap"


def _scan_case(C=40, seed=0):
    """Candidates of a break scan on random linearised detections, as trajectory builds them
    (windows of ±5 spacings, cut at neighbours: windows of different lengths)."""
    rng = np.random.default_rng(seed)
    h = 0.011
    n = 1200
    t = np.sort(rng.uniform(0.0, 4.0, n))
    J = rng.normal(size=(n, 2, 3)) * 300
    z = rng.normal(size=(n, 2))
    w = rng.uniform(0.5, 4.0, n)
    centers = np.sort(rng.uniform(0.2, 3.8, C))
    bounds = np.stack([centers - rng.uniform(0.3, 1.0, C) * h,
                       centers + rng.uniform(0.3, 1.0, C) * h], axis=1)
    limits = np.stack([centers - rng.uniform(2, 9, C) * h, centers + rng.uniform(2, 9, C) * h],
                      axis=1)
    return t, J, z, w, centers, bounds, limits, h, 5 * h, MotionPrior()


@pytest.mark.parametrize("block", [1, 3, 16])
def test_the_scan_in_blocks_on_one_or_two_threads_is_one_batch_bit_for_bit(monkeypatch, block):
    case = _scan_case()
    monkeypatch.setattr(_breaks, "_BLOCK", 10**9)  # one batch of every candidate
    monkeypatch.setenv("PSLOG_SMOOTH_THREADS", "1")
    tau, gain = _breaks.scan(*case)
    assert np.all(np.isfinite(gain)) and len(tau) == 40
    monkeypatch.setattr(_breaks, "_BLOCK", block)
    for threads in ("1", "2"):
        monkeypatch.setenv("PSLOG_SMOOTH_THREADS", threads)
        t2, g2 = _breaks.scan(*case)
        assert_array_equal(t2, tau)
        assert_array_equal(g2, gain)



def test_the_refinement_in_blocks_on_one_or_two_threads_is_one_batch_bit_for_bit(monkeypatch):
    t, J, z, w, centers, _, limits, h, half, prior = _scan_case()
    bounds = np.stack([centers - h / 4, centers + h / 5], axis=1)  # scan_near's quarter
    case = (t, J, z, w, centers, bounds, limits, h, half, prior)
    monkeypatch.setattr(_breaks, "_BLOCK", 10**9)
    monkeypatch.setenv("PSLOG_SMOOTH_THREADS", "1")
    tau, edge = _breaks.scan_near(*case)
    assert np.all((tau >= bounds[:, 0]) & (tau <= bounds[:, 1]))
    monkeypatch.setattr(_breaks, "_BLOCK", 3)
    for threads in ("1", "2"):
        monkeypatch.setenv("PSLOG_SMOOTH_THREADS", threads)
        t2, e2 = _breaks.scan_near(*case)
        assert_array_equal(t2, tau)
        assert_array_equal(e2, edge)

def test_a_fit_on_one_thread_is_the_fit_on_two_bit_for_bit(monkeypatch):
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion, _ = rally(20, seed=5)
    detections, _ = simulate(rig, motion, 20, SimulationOptions(noise_px=0.5, seed=2))
    obs = detections.best()
    monkeypatch.setattr(_breaks, "_BLOCK", 2)  # several blocks even on a short session
    fits = []
    for threads in ("1", "2"):
        monkeypatch.setenv("PSLOG_SMOOTH_THREADS", threads)
        fits.append(fit_trajectory(obs, rig))
    one, two = fits
    assert len(one.trajectory.breaks_s) >= 3  # the scan ran, on several blocks
    assert_array_equal(one.trajectory.breaks_s, two.trajectory.breaks_s)
    assert_array_equal(one.trajectory.control, two.trajectory.control)
    assert_array_equal(one.position, two.position)
    assert_array_equal(one.covariance, two.covariance)


@pytest.mark.parametrize("text, expected", [("1", 1), ("2", 2), ("", 2), (" 1 ", 1),
                                            ("64", 64), ("000000000001", 1),
                                            ("1000000", 10**6), ("9" * 5000, float("inf"))],
                         ids=["1", "2", "unset", "spaces", "64", "zeros-1", "million",
                              "5000-digits"])
def test_the_thread_count_comes_from_the_environment(monkeypatch, text, expected):
    """No upper bound to refuse: a count above the CPUs this process may use is taken as
    that many (the rule of the docstring, README and fuse --help), however many digits (5000
    of them were refused as 'no whole number': int() parses at most 4300)."""
    import os

    monkeypatch.setenv("PSLOG_SMOOTH_THREADS", text)
    cpus = len(os.sched_getaffinity(0))
    assert _breaks.smooth_threads() == min(expected, cpus)


@pytest.mark.parametrize("text", ["two", "0", "-3", "1.5", "0" * 20, "1e3"])
def test_a_thread_count_that_is_no_whole_number_from_1_is_a_clear_error(monkeypatch, text):
    monkeypatch.setenv("PSLOG_SMOOTH_THREADS", text)
    with pytest.raises(PslogError, match=rf"PSLOG_SMOOTH_THREADS.*'{text}'"):
        _breaks.smooth_threads()


def test_pslog_fuse_says_a_bad_thread_count_before_it_fuses(tmp_path, monkeypatch, capsys):
    from pslog.cli import main

    monkeypatch.setenv("PSLOG_SMOOTH_THREADS", "0")
    out = tmp_path / "out.mcap"
    assert main(["fuse", str(SAMPLE), "-o", str(out), "--method", "smooth"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "PSLOG_SMOOTH_THREADS" in err and not out.exists()
    assert main(["fuse", str(SAMPLE), "-o", str(out), "--method", "typeA"]) == 0


@pytest.mark.parametrize("blocks, threads, expected", [
    (1, "2", 1), (2, "2", 1), (3, "2", 1), (4, "2", 2), (9, "2", 2), (4, "1", 1)])
def test_a_scan_of_few_blocks_stays_on_one_thread(monkeypatch, blocks, threads, expected):
    # a second thread's start, arena and pool cost about a block's work: a scan of fewer
    # than _THREAD_BLOCKS blocks (a session of a few minutes) runs them on this thread
    assert _breaks._THREAD_BLOCKS == 4
    monkeypatch.setenv("PSLOG_SMOOTH_THREADS", threads)
    cpus = len(os.sched_getaffinity(0))
    assert _breaks.scan_threads(blocks) == min(expected, cpus)
    monkeypatch.setenv("PSLOG_SMOOTH_THREADS", "0")
    with pytest.raises(PslogError, match="PSLOG_SMOOTH_THREADS"):
        _breaks.scan_threads(blocks)  # a bad count is an error at any size


def test_a_scan_of_few_blocks_starts_no_thread(monkeypatch):
    # below the threshold every block runs on this thread and no other is started; from it,
    # one helper thread (PSLOG_SMOOTH_THREADS=2) runs beside this one, which works too
    import threading

    case = _scan_case(C=40)
    seen: list[str] = []
    alive: set[str] = set()
    block = _breaks._scan_block

    def recording(*args, **kwargs):
        seen.append(threading.current_thread().name)
        alive.update(t.name for t in threading.enumerate())
        return block(*args, **kwargs)

    monkeypatch.setattr(_breaks, "_scan_block", recording)
    monkeypatch.setenv("PSLOG_SMOOTH_THREADS", "2")
    monkeypatch.setattr(_breaks, "_BLOCK", 14)  # 3 blocks
    before = {t.name for t in threading.enumerate()}
    _breaks.scan(*case)
    assert seen == [threading.current_thread().name] * 3
    assert alive == before
    seen.clear()
    monkeypatch.setattr(_breaks, "_BLOCK", 10)  # 4 blocks
    _breaks.scan(*case)
    assert len(seen) == 4
    if len(os.sched_getaffinity(0)) > 1:
        assert set(seen) <= {threading.current_thread().name, "pslog-smooth-scan-1"}
        assert "pslog-smooth-scan-1" in alive
    assert {t.name for t in threading.enumerate()} == before  # the helper has ended


def test_on_threads_gives_every_result_in_its_place_and_raises_a_jobs_error():
    import threading

    jobs = [(i, i + 1) for i in range(0, 40, 2)]
    for threads in (2, 3):
        assert _breaks.on_threads(lambda a, b: (a, b, a * b), jobs, threads) == [
            (a, b, a * b) for a, b in jobs]
    ran: list[int] = []

    def failing(a, b):
        ran.append(a)
        if a == 10:
            raise ValueError("block 10")
        return a

    before = {t.name for t in threading.enumerate()}
    with pytest.raises(ValueError, match="block 10"):
        _breaks.on_threads(failing, jobs, 2)
    assert {t.name for t in threading.enumerate()} == before  # every helper stopped
    assert 10 in ran
