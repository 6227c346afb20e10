"""Clocks estimated without offsets (``--estimate readout``, ``readout=shared`` or ``drift``
alone: the rig's offsets right, kept). The estimator's offsets ``o'_c = o_c + d_c · 1e-6 ·
ℓ_m + (r_c - r_1) / 2`` (:class:`pslog.estimation.sync._Clocks`) were held at the rig's
values, so each estimated readout or drift moved its camera's offset unseen, and the rig
written kept ``o_c``: a model the fit never made. On paper3 with readouts 4, 12 and 20 ms and
the true offsets in the rig, the readouts alone came out -17.4, 17.0 and 50.4 ms (residual
0.398 px where the offsets and readouts together give 0.363 px)."""

from __future__ import annotations

import numpy as np

from pslog.estimation.sync import _Clocks, estimate_clocks
from pslog.fusion.gating import gate
from pslog.motion import get_motion
from pslog.records import Observations
from pslog.rig import Rig, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled

READOUTS = (0.004, 0.012, 0.020)
OFFSETS = (0.0, 0.007, -0.011)


def test_readouts_estimated_alone_keep_the_rigs_offsets_and_find_the_readouts():
    base = builtin_rig("paper3")
    true = Rig(tuple(c.replace(readout=r, clock_offset=o)
                     for c, r, o in zip(base.cameras, READOUTS, OFFSETS, strict=True)),
               base.name)
    det, _, _ = simulate_labelled(true, get_motion("rally"), 8.0,
                                  SimulationOptions(noise_px=0.3, seed=57200))
    plain = Rig(tuple(c.replace(readout=0.0, clock_offset=0.0) for c in true.cameras),
                base.name)
    obs = gate(det, plain, causal=False).observations  # (at their logged times)
    start = Rig(tuple(c.replace(readout=0.0) for c in true.cameras), base.name)
    both = estimate_clocks(obs, start, ("offset", "readout"))
    alone = estimate_clocks(obs, start, ("readout",))
    assert [c.offset_s for c in alone.cameras] == list(OFFSETS)
    got = np.array([c.readout_s for c in alone.cameras])
    assert np.all(np.abs(got - READOUTS) < 1.5e-3), got
    assert alone.residual_px < both.residual_px + 0.01


def test_the_times_jacobian_is_the_times_derivative_without_offsets():
    """:meth:`_Clocks.times_jacobian` against finite differences of :meth:`_Clocks.times`
    (affine in the parameters) for drifts, per-camera and tied readouts (``readout=shared``:
    cam1 with cam3) without offsets, and with them; and the rig's offsets come back from
    :meth:`_Clocks.to_external`."""
    base = builtin_rig("paper3")
    rig = Rig(tuple(c.replace(readout=r, clock_offset=o, clock_drift_ppm=d)
                    for c, r, o, d in zip(base.cameras, READOUTS, OFFSETS, (0.0, 30.0, -20.0),
                                          strict=True)), base.name)
    rng = np.random.default_rng(57201)
    n = 60
    cam = np.repeat(np.arange(3), n // 3).astype(np.int32)
    logged = np.sort(rng.uniform(0.0, 40.0, n))
    obs = Observations(np.round(logged * 1e9).astype(np.int64), cam,
                       rng.uniform(0.0, 480.0, (n, 2)), np.arange(n))
    cases = [(["readout"], None), (["drift"], None), (["drift", "readout"], None),
             (["offset", "readout"], None), (["readout"], [0, 1, 0])]
    for names, tie in cases:
        unknowns = [(c, p) for c in range(3) for p in names
                    if not (c == 0 and p in ("offset", "drift"))]
        params = _Clocks(rig, unknowns, 20.0, tie)
        theta = params.to_internal(np.array(
            [float(getattr(rig.cameras[c], {"offset": "clock_offset", "drift":
                                            "clock_drift_ppm", "readout": "readout"}[p]))
             for c, p in unknowns]))
        jac = params.times_jacobian(logged, obs.uv[:, 1], cam) @ params.M
        for j in range(len(theta)):
            step = np.zeros(len(theta))
            step[j] = 1e-3
            fd = (params.times(obs, theta + step) - params.times(obs, theta - step)) / 2e-3
            np.testing.assert_allclose(jac[:, j], fd, atol=1e-7, err_msg=f"{names} {j}")
        if "offset" not in names:
            ext = params._external(params._full(theta + 1e-3))
            np.testing.assert_allclose(ext[:, 0], OFFSETS, atol=1e-15)
