"""``filter``: an update far from its prior is iterated to the posterior's mode, so the point
agrees with its own detection (issue 10, session 30; docs/methods.md "The iterated update").

A track whose depth along one camera's ray is uncertain (a state of a few centimetres and
metres per second, as after a kick seen by one camera) meets the next camera's detection
hundreds of pixels from its prior: the extended Kalman step, linearised at the prior, is not
the posterior's mode and its point reprojects tens of pixels off the detection. The iterated
update (Bell & Cathey 1993) reaches the mode: checked against the mode found by hand (the
posterior's cost minimised in numpy, the projection's Jacobian by central differences).
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from test_filter import lab_rig

from pslog.fusion.filter import FILTER_QUALITY, BallFilter, FilterOptions
from pslog.motion import G
from pslog.records import NS

#: the filter's models reduced to the ballistic one with fixed noises, nothing withheld: the
#: step is the plain update alone (its published doubt on "no jump" off: its own test)
OPTIONS = dict(noise_px=0.4, accel_psd=0.3, drag_per_m=0.0, adapt_rate=0.0,
               model_switch_per_s=0.0, turn_switch_per_s=0.0, max_std_m=None,
               drag_std_per_m=0.0, surprise_cov=False, withhold=False)
T0, T1 = 1_000_000_000, 1_033_333_333


def _prior(rig, p_true=(1.4, 1.1, 1.2), along=0.8, sd=0.5):
    """(true position at T1, the state at T0: mean and covariance): a state whose depth along
    camera 0's ray is uncertain (±``sd`` m, as when camera 0 alone saw the ball since a
    kick), ``along`` m off the truth along that ray, ±1 cm across it, its velocity ±0.1 m/s."""
    p_true = np.array(p_true)
    v = np.array([1.5, -2.0, 1.0])
    dt = (T1 - T0) / NS
    p0_true = p_true - v * dt - 0.5 * np.array([0.0, 0.0, -G]) * dt * dt
    c0 = rig.cameras[0]
    ray = p_true + np.asarray(c0.R).T @ np.asarray(c0.t)  # from camera 0's centre
    ray /= np.linalg.norm(ray)
    x0 = np.concatenate([p0_true + along * ray, v + np.array([0.05, -0.05, 0.05])])
    P0 = np.zeros((6, 6))
    P0[:3, :3] = 0.01**2 * np.eye(3) + sd**2 * np.outer(ray, ray)
    P0[3:, 3:] = 0.1**2 * np.eye(3)
    return p_true, x0, P0


def _mode(cam, x, P, z, var):
    """The posterior's mode by hand: ``(x − x⁻)ᵀ P⁻¹ (x − x⁻) + ‖z − π(p)‖²/σ²`` minimised
    by Gauss-Newton in numpy from the prior, the Jacobian by central differences."""
    Pi = np.linalg.inv(P)

    def h(p):
        return cam.project(p[None])[0][0]

    xi = x.copy()
    for _ in range(50):
        J = np.zeros((2, 6))
        for k in range(3):
            d = np.zeros(3)
            d[k] = 1e-6
            J[:, k] = (h(xi[:3] + d) - h(xi[:3] - d)) / 2e-6
        r = z - h(xi[:3])
        A = Pi + J.T @ J / var
        g = J.T @ r / var - Pi @ (xi - x)
        xi = xi + np.linalg.solve(A, g)
    S = J @ P @ J.T + var * np.eye(2)
    K = P @ J.T @ np.linalg.inv(S)
    return xi, P - K @ J @ P


@pytest.mark.parametrize(("cam_index", "prior"), [
    (1, {}), (2, {}),
    # a Gauss-Newton step that lowers the pixel residual but not the posterior's cost: the
    # last steps trade pixels for the prior (a cost without the prior term stops 54 µm early)
    (1, {"p_true": (1.0, 0.7, 0.5), "along": -0.8, "sd": 0.4})])
def test_an_update_far_from_its_prior_reaches_the_posterior_mode(cam_index, prior):
    rig = lab_rig(3)
    cam = rig.cameras[cam_index]
    p_true, x0, P0 = _prior(rig, **prior)
    z = cam.project(p_true[None])[0][0]  # the detection (noise-free: the truth's pixel)
    points = {}
    for iterate in (False, True):
        flt = BallFilter(rig, FilterOptions(**OPTIONS, iterate_update=iterate))
        flt.set_state(T0, x0[:3], x0[3:], P0)
        point, quality = flt.push(T1, cam_index, *z)
        points[iterate] = (np.array(point), dict(zip(FILTER_QUALITY, quality, strict=True)),
                           flt.state())
    one, iterated = points[False], points[True]
    q1, q = one[1], iterated[1]
    # the case: far from the prior (a hundred pixels and more), within the gate, and the
    # one-step update's point pixels off its own detection and 2 std_m from the truth
    assert q["innovation_px"] > 100.0
    assert q["nis"] < 18.4 and q["jump"] == 0.0 and q["rejected"] == 0.0
    assert q1["residual_px"] > 3.0
    assert np.linalg.norm(one[0] - p_true) > 1.8 * q1["std_m"]
    # the gate's statistics are the prior's: the same with one step or iterated
    assert (q["innovation_px"], q["nis"]) == (q1["innovation_px"], q1["nis"])
    # the iterated point agrees with its own detection: the mode's residual is σ² S⁻¹ y
    # (S's variance along y hundreds of px²: a small fraction of a pixel here)
    assert q["residual_px"] < 0.1
    # it is the posterior's mode, computed by hand, and its covariance the last step's
    _, x, P = iterated[2]
    dt = (T1 - T0) / NS
    F = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    Q = 0.3 * np.block([[dt**3 / 3 * np.eye(3), dt**2 / 2 * np.eye(3)],
                        [dt**2 / 2 * np.eye(3), dt * np.eye(3)]])
    xm = F @ x0 + np.concatenate([0.5 * np.array([0.0, 0.0, -G]) * dt * dt,
                                  np.array([0.0, 0.0, -G]) * dt])
    Pm = F @ P0 @ F.T + Q
    x_mode, P_mode = _mode(cam, xm, Pm, z, 0.4**2)
    assert_allclose(x, x_mode, rtol=0, atol=1e-7)
    assert_allclose(P, P_mode, rtol=1e-5, atol=1e-12)
    # std_m covers the error to the truth (the depth along the ray stays the prior's)
    err = np.linalg.norm(iterated[0] - p_true)
    assert err < 2.0 * q["std_m"]
    assert err < np.linalg.norm(one[0] - p_true)


def test_an_update_near_its_prior_is_the_one_step_update_bit_for_bit():
    rig = lab_rig(3)
    cam = rig.cameras[1]
    p_true, x0, P0 = _prior(rig)
    P0 = np.diag([0.002**2] * 3 + [0.05**2] * 3)  # a settled state: a pixel or two away
    dt = (T1 - T0) / NS
    x0 = x0.copy()
    x0[3:] = np.array([1.5, -2.0, 1.0])
    x0[:3] = p_true - x0[3:] * dt - 0.5 * np.array([0.0, 0.0, -G]) * dt * dt + 0.001
    z = cam.project(p_true[None])[0][0]
    out = []
    for iterate in (False, True):
        flt = BallFilter(rig, FilterOptions(**OPTIONS, iterate_update=iterate))
        flt.set_state(T0, x0[:3], x0[3:], P0)
        out.append((flt.push(T1, 1, *z), flt.state()[1].tolist(), flt.state()[2].tolist()))
    assert out[0] == out[1]


def test_a_large_residual_the_linearisation_predicts_is_not_iterated():
    """The trigger is the linearisation's error ``‖r − σ² S⁻¹ y‖``, not the residual ``r``
    itself: a settled state (its prediction ±0.1 mm, far below a pixel) meets a detection
    3.5 σ off (NIS ≈ 12, accepted): the one step leaves its point about 3.5 σ off its own
    detection, as the linear model predicts it (``r ≈ σ² S⁻¹ y``), so nothing is iterated:
    the one-step update bit for bit. (A trigger on ``r`` alone, or on ``r + σ² S⁻¹ y``,
    iterates here.)"""
    rig = lab_rig(3)
    cam = rig.cameras[1]
    p_true = np.array([1.4, 1.1, 1.2])
    v = np.array([1.5, -2.0, 1.0])
    dt = (T1 - T0) / NS
    options = {**OPTIONS, "noise_px": 1.0, "accel_psd": 1e-4}
    # the prediction moved across the camera's ray so that it projects 3.5 px from z
    z = cam.project(p_true[None])[0][0]
    across = np.cross(p_true + np.asarray(cam.R).T @ np.asarray(cam.t), [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    px_per_m = np.linalg.norm(cam.project((p_true + 1e-4 * across)[None])[0][0] - z) / 1e-4
    off = 3.5 / px_per_m * across
    x0 = np.concatenate([p_true + off - v * dt - 0.5 * np.array([0.0, 0.0, -G]) * dt * dt, v])
    P0 = np.diag([1e-4**2] * 3 + [1e-3**2] * 3)
    out = []
    for iterate in (False, True):
        flt = BallFilter(rig, FilterOptions(**options, iterate_update=iterate))
        flt.set_state(T0, x0[:3], x0[3:], P0)
        point, quality = flt.push(T1, 1, *z)
        out.append((point, quality, flt.state()[1].tolist(), flt.state()[2].tolist()))
    q = dict(zip(FILTER_QUALITY, out[0][1], strict=True))
    assert 3.2 < q["innovation_px"] < 3.8 and 9.0 < q["nis"] < 18.4
    assert q["jump"] == 0.0 and q["rejected"] == 0.0
    assert q["residual_px"] > 3.0  # beyond 3 σ, but the linear model's own prediction
    assert out[0] == out[1]


@pytest.mark.parametrize(("along", "iterated"), [(0.275, False), (0.325, True)])
def test_the_trigger_is_three_sigma_of_the_linearisations_error(along, iterated):
    """Camera 1's detection of :func:`_prior`'s state moved ``along`` camera 0's ray: the one
    step leaves its point 1.12 px (2.8 σ at σ = 0.4 px) or 1.55 px (3.9 σ) off its own
    detection, where the linear model predicts 0.02 px: the first is the one step bit for bit,
    the second iterated to the mode (residual below 0.1 px). ``_ITER_SIGMAS`` 2.5 or 4 fails
    one of the two."""
    rig = lab_rig(3)
    cam = rig.cameras[1]
    p_true, x0, P0 = _prior(rig, along=along)
    z = cam.project(p_true[None])[0][0]
    out = []
    for iterate in (False, True):
        flt = BallFilter(rig, FilterOptions(**OPTIONS, iterate_update=iterate))
        flt.set_state(T0, x0[:3], x0[3:], P0)
        point, quality = flt.push(T1, 1, *z)
        out.append((point, dict(zip(FILTER_QUALITY, quality, strict=True)), flt.state()))
    r1 = out[0][1]["residual_px"]
    assert (3.5 < r1 / 0.4 < 4.0) if iterated else (2.5 < r1 / 0.4 < 3.0)
    assert out[0][1]["nis"] < 1.0 and out[0][1]["rejected"] == 0.0
    if iterated:
        assert out[1][1]["residual_px"] < 0.1
    else:
        assert out[0][0] == out[1][0] and out[0][1] == out[1][1]
        assert out[0][2][1].tolist() == out[1][2][1].tolist()
        assert out[0][2][2].tolist() == out[1][2][2].tolist()


SWITCHES = ("bounce_shape", "withhold", "start_models", "window_noise_prior", "restart_prior",
            "jump_instant", "jump_mixture_cov", "surprise_cov", "iterate_update")


def _switches() -> list[str]:
    from dataclasses import fields

    found = [f.name for f in fields(FilterOptions) if f.type in ("bool", bool)]
    assert set(SWITCHES) <= set(found), found  # (the nine of session 31, and any newer)
    return found


@pytest.mark.parametrize("name", _switches())
def test_every_switch_of_the_filter_is_true_or_false(name):
    """The filter's switches (every field annotated bool) are checked as its numbers are
    (FilterOptions.__post_init__): "no" was taken as True and None as False, silently; a
    numpy bool (from an array of settings) is a bool."""
    from pslog.errors import FusionError

    for bad in ("no", None, 0, 1.0):
        with pytest.raises(FusionError, match=rf"filter {name} must be True or False, got "
                                              rf"{bad!r}"):
            FilterOptions(**{name: bad})
    for good in (True, False, np.bool_(False)):
        assert getattr(FilterOptions(**{name: good}), name) == good
