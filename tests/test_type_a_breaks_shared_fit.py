"""Type A's ``confirm_breaks`` takes its kick instants from ``smooth``'s own fit of the session
(:class:`pslog.fusion.breaks.SessionFit`; docs/methods.md, "Type A across a break: the
backward pass"): a fuse of both methods fits once, and type A's points are the same whether
``smooth`` is fused beside it or not, in any order, on one thread or two, with a synced
session's clock covariance (which only ``smooth``'s own track needs) or without.

The session: a dirty rally (spurious blobs in 5 % of frames, a static second object seen by
one camera, another camera blind for 0.5 s) on the paper's three cameras, so that type A and
``smooth`` gate the detections differently (causal and offline) and the gate's choices in
doubt are there: the fit must be of ``smooth``'s input, not of type A's.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from _rally import dirty_rally
from numpy.testing import assert_array_equal

import pslog.fusion.smooth as smooth
from pslog.fusion import FusionOptions, fuse
from pslog.fusion.gating import fuse_detections
from pslog.rig import builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled
from pslog.timing import ClockCovariance

BREAKS = FusionOptions(confirm_every=True, confirm_sides=True, confirm_breaks=True,
                        break_source="fit")


@pytest.fixture(scope="module")
def session():
    rig = builtin_rig("paper3")
    seed = 77001
    motion, _ = dirty_rally(seed)
    options = SimulationOptions(noise_px=0.3, seed=seed - 300, spurious_rate=0.05,
                                distractors=((rig.cameras[2].name, (1.0, 1.5, 0.2)),),
                                blackouts=((rig.cameras[1].name, 2.1, 0.5),))
    detections = simulate_labelled(rig, motion, 8.0, options)[0]
    return rig, detections


def _same(a, b) -> None:
    assert_array_equal(a.time_ns, b.time_ns)
    assert_array_equal(a.camera, b.camera)
    assert_array_equal(a.position_world, b.position_world)
    assert a.quality.keys() == b.quality.keys()
    for name in a.quality:
        assert_array_equal(a.quality[name], b.quality[name], err_msg=name)
    assert a.dropped == b.dropped


def _counted(monkeypatch) -> list:
    fits: list = []
    real = smooth.session_fit
    monkeypatch.setattr(smooth, "session_fit",
                        lambda *a, **k: fits.append(1) or real(*a, **k))
    return fits


@pytest.fixture(scope="module")
def alone(session):
    rig, detections = session
    return (fuse_detections(detections, rig, ["typeA"], BREAKS)[0]["typeA"],
            fuse_detections(detections, rig, ["smooth"], BREAKS)[0]["smooth"])


def test_the_case_is_live(session, alone):
    """The option changes points here (some replaced by the backward pass), and type A's and
    smooth's gates choose differently (else the fit's input could be either's)."""
    rig, detections = session
    type_a, _ = alone
    assert np.count_nonzero(type_a.quality["span_s"] < 0) >= 5
    kicks = fuse_detections(detections, rig, ["typeA"], replace(
        BREAKS, confirm_breaks=False, break_source="image"))[0]["typeA"]
    assert len(kicks) != len(type_a) or not np.array_equal(kicks.position_world,
                                                          type_a.position_world)
    from pslog.fusion.gating import gate_for

    causal = gate_for(detections, rig, "typeA", BREAKS).observations
    offline = gate_for(detections, rig, "smooth", BREAKS).observations
    assert len(causal) != len(offline) or not np.array_equal(causal.uv, offline.uv)


@pytest.mark.parametrize("order", [["typeA", "smooth"], ["smooth", "typeA"],
                                   ["nearest", "smooth", "filter", "typeA"]])
@pytest.mark.parametrize("workers", [1, 2])
def test_one_fit_for_both_and_the_same_points(session, alone, monkeypatch, order, workers):
    rig, detections = session
    fits = _counted(monkeypatch)
    tracks = fuse_detections(detections, rig, order, BREAKS, workers=workers)[0]
    assert len(fits) == 1  # smooth's fit, shared (two: each method fitted its own)
    _same(tracks["typeA"], alone[0])
    _same(tracks["smooth"], alone[1])


def test_fuse_of_type_a_alone_fits_smooths_input(session, alone, monkeypatch):
    """:func:`pslog.fusion.fuse` of the detections (no other method) gates them as ``smooth``
    does for the fit: the same points as beside ``smooth``, and the fit's observations are
    ``smooth``'s (its offline gate's choices, its rule for those in doubt), not type A's
    causal gate's."""
    from pslog.fusion import _smooth_fit_of, prepare
    from pslog.fusion._prepare import default_max_gap_s
    from pslog.fusion.gating import gate_for, prepared_for

    rig, detections = session
    fits = _counted(monkeypatch)
    _same(fuse(detections, rig, "typeA", BREAKS), alone[0])
    assert len(fits) == 1
    resolved = replace(BREAKS, max_gap_s=default_max_gap_s(rig))
    causal = gate_for(detections, rig, "typeA", BREAKS)
    fitted = _smooth_fit_of(detections, prepared_for(causal, rig), rig, BREAKS).fitted()[1]
    own = smooth.session_fit(prepared_for(gate_for(detections, rig, "smooth", BREAKS), rig),
                             rig, resolved)[1]
    assert_array_equal(fitted.time_ns, own.time_ns)
    assert_array_equal(fitted.uv, own.uv)
    assert len(fitted) != len(causal.observations)
    # Observations (no gate): every method's own preparation is the fit's input
    obs = detections.best()
    assert_array_equal(_smooth_fit_of(obs, prepare(obs, rig), rig, BREAKS).fitted()[1].uv,
                       obs.uv)


def test_the_clocks_covariance_moves_no_break(session, alone, monkeypatch):
    """With a synced session's clock covariance ``smooth``'s fit carries its consider part
    (its own track's), type A's fit alone does not: the same breaks, so the same points,
    each with its consider covariance; one fit either way."""
    rig, detections = session
    cov = np.diag([0.5e-3, 0.5e-3]) ** 2
    clock = ClockCovariance([1, 2], [0, 0], cov)
    options = replace(BREAKS, clock_covariance=clock)
    fits = _counted(monkeypatch)
    both = fuse_detections(detections, rig, ["typeA", "smooth"], options)[0]
    assert len(fits) == 1
    type_a = fuse_detections(detections, rig, ["typeA"], options)[0]["typeA"]
    assert len(fits) == 2
    _same(both["typeA"], type_a)
    assert_array_equal(type_a.position_world, alone[0].position_world)
    assert np.all(type_a.quality["std_m"] > alone[0].quality["std_m"] - 1e-15)


def test_type_a_lets_the_fit_go_once_it_has_the_breaks(session):
    """Type A's use of the shared fit ends when it has the breaks (its backward pass, the
    peak of a ``breaks`` fuse, does not hold the fit and ``smooth``'s input); ``smooth``'s
    use keeps it until ``smooth`` is done; each use released once; the input dropped
    (``on_drop``) with the last."""
    from pslog.fusion import default_max_gap_s, prepare
    from pslog.fusion.breaks import SessionFit

    rig, detections = session
    obs = detections.best()
    prep = prepare(obs, rig)
    options = replace(BREAKS, max_gap_s=default_max_gap_s(rig))
    dropped: list = []
    alone = SessionFit(lambda: prep, rig, options, on_drop=lambda: dropped.append("alone"))
    breaks = alone.take_breaks()
    assert len(breaks) and dropped == ["alone"]
    with pytest.raises(RuntimeError, match="after its last release"):
        alone.fitted()
    both = SessionFit(lambda: prep, rig, options, ("typeA", "smooth"),
                      on_drop=lambda: dropped.append("both"))
    assert_array_equal(both.take_breaks(), breaks)
    assert not both.release("typeA")  # (released already: nothing more)
    assert both.fitted()[0] is not None and dropped == ["alone"]
    assert both.release("smooth") and dropped == ["alone", "both"]
    assert not both.release("smooth")


def test_fuse_all_of_observations_fits_once(session, monkeypatch):
    """:func:`pslog.fusion.fuse_all` of Observations (no gate: every method's one
    preparation) shares the fit as ``start_fusion`` does: one fit for type A and ``smooth``,
    type A's points those of type A fused alone."""
    from pslog.fusion import fuse_all

    rig, detections = session
    obs = detections.best()
    alone = fuse(obs, rig, "typeA", BREAKS)
    fits = _counted(monkeypatch)
    both = fuse_all(obs, rig, ["smooth", "typeA"], BREAKS)
    assert len(fits) == 1  # (two: each method fitted its own)
    _same(both["typeA"], alone)
