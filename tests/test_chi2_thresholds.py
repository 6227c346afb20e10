"""Every gate and robust scale that its docstring names as a quantile of a distribution is
that quantile, by an independent formula (:mod:`scipy.stats`, or the closed form of 2
degrees of freedom ``-2 ln(1 - p)``): a threshold edited without its reason fails here.

| constant | documented as |
|---|---|
| ``FilterOptions.gate`` 18.4 | χ²₂ 99.99 % (docs/methods.md, "Gating") |
| ``FilterOptions.confirm_nis`` 9.21 | χ²₂ 99 % |
| ``stereo.KINK_GATE`` 9.21, ``pseudo.MODEL_GATE`` | χ²₂ 99 % |
| ``filter._PRIOR_GATE`` 22.458 | χ²₆ 99.9 % |
| ``filter._chi2_lower(dof, p)`` | χ² ``p`` quantile, exact for even dof |
| ``filter._chi2_quantile(dof)`` | χ² 99.9 % by Wilson–Hilferty (above it, within 2.3 %) |
| ``evaluation.CHI2_3D_2SIGMA`` | P(χ²₃ <= 4) |
| ``innovation.RAYLEIGH_MEDIAN`` | median of ‖N(0, I₂)‖ = √(χ²₂ median) |
| ``innovation.chi2_threshold(dof)`` | χ²_dof at ``1 - exp(-25/2)`` (type A's 5σ; 25 at 2 dof) |
| ``stereo.RAYLEIGH_QUARTILE`` | lower quartile of ‖N(0, I₂)‖ |
| ``confirm._HALF_NORMAL_MEDIAN`` | median of \\|N(0, 1)\\| |
| ``trajectory._END_JUMP_SCALED`` (``Fit.rejected``) | √(χ²₂ 99.99 %), in σ of the residual norm |
"""

from __future__ import annotations

import math

import pytest
from scipy import stats

from pslog.evaluation import CHI2_3D_2SIGMA
from pslog.fusion import confirm, innovation, pseudo, stereo
from pslog.fusion import filter as F


def _chi2_2(p: float) -> float:
    """The ``p`` quantile of χ²₂ in closed form: ``P(χ²₂ <= x) = 1 - e^{-x/2}``."""
    return -2.0 * math.log1p(-p)


def test_the_two_dof_gates_are_their_quantiles():
    options = F.FilterOptions()
    assert _chi2_2(0.9999) == pytest.approx(stats.chi2.ppf(0.9999, 2), rel=1e-12)
    assert options.gate == pytest.approx(_chi2_2(0.9999), abs=0.05)  # 18.42, printed 18.4
    assert options.confirm_nis == pytest.approx(_chi2_2(0.99), abs=0.005)  # 9.2103
    assert stereo.KINK_GATE == pytest.approx(_chi2_2(0.99), abs=0.005)
    assert pseudo.MODEL_GATE == stereo.KINK_GATE


def test_the_restart_prior_gate_is_chi2_6_at_99_9_percent():
    assert F._PRIOR_GATE == pytest.approx(stats.chi2.ppf(0.999, 6), abs=5e-4)


@pytest.mark.parametrize("dof", [2, 4, 6, 10, 26, 122])
@pytest.mark.parametrize("p", [0.001, 0.5, 0.999])
def test_the_exact_lower_quantile_is_scipys(dof, p):
    assert F._chi2_lower(dof, p) == pytest.approx(stats.chi2.ppf(p, dof), rel=1e-9)


def test_the_wilson_hilferty_quantile_is_above_the_exact_one_and_close():
    # even dof (2n - 6 residuals of a window of n >= 4 detections), z = 3.09 for 99.9 %
    worst = 0.0
    for dof in range(2, 200, 2):
        exact = stats.chi2.ppf(stats.norm.cdf(3.09), dof)
        ratio = F._chi2_quantile(dof) / exact
        assert ratio > 1.0, dof  # conservative: a window fit is refused a little less often
        worst = max(worst, ratio - 1.0)
        if dof >= 6:
            assert ratio - 1.0 < 0.01, dof
    assert 0.02 < worst < 0.025  # at 2 dof: 14.13 against 13.82
    assert F._chi2_quantile(0) == math.inf


def test_the_evaluations_two_sigma_share_and_the_noise_medians():
    assert CHI2_3D_2SIGMA == pytest.approx(stats.chi2.cdf(4.0, 3), rel=1e-14)
    assert innovation.RAYLEIGH_MEDIAN == pytest.approx(math.sqrt(stats.chi2.ppf(0.5, 2)),
                                                       rel=1e-14)
    assert confirm._HALF_NORMAL_MEDIAN == pytest.approx(stats.norm.ppf(0.75), rel=1e-14)


@pytest.mark.parametrize("dof", range(1, 14))
def test_the_residual_tests_threshold_is_chi2_at_type_as_level(dof):
    """``innovation.chi2_threshold`` (the N-view residual test, ``stereo.residual_refused``):
    the χ² quantile at type A's 5σ level ``exp(-25/2)``, 25 at 2 dof; its closed-form
    survival function is scipy's."""
    p = innovation.REFUSAL_PROBABILITY
    assert p == pytest.approx(stats.chi2.sf(25.0, 2), rel=1e-12)
    assert innovation.chi2_threshold(dof) == pytest.approx(stats.chi2.isf(p, dof), rel=1e-10)
    for x in (0.3, 2.0, 7.3, 21.4, 60.0):
        assert innovation.chi2_survival(x, dof) == pytest.approx(stats.chi2.sf(x, dof),
                                                                  rel=1e-10)


def test_the_refusal_noise_quartile_is_rayleighs():
    # the lower quartile of ‖N(0, I₂)‖: √(χ²₂ quartile)
    assert stereo.RAYLEIGH_QUARTILE == pytest.approx(math.sqrt(stats.chi2.ppf(0.25, 2)),
                                                     rel=1e-14)


def test_smooths_rejection_bound_is_its_quantile():
    """``smooth``'s fit rejects a detection beyond √(χ²₂'s 1 - 1e-4 quantile) σ (the filter's
    gate's level)."""
    from pslog.estimation import trajectory as T

    assert T._END_JUMP_SCALED ** 2 == pytest.approx(stats.chi2.ppf(1 - 1e-4, 2), rel=1e-9)
    assert T._END_JUMP_SCALED ** 2 == pytest.approx(F.FilterOptions().gate, abs=0.05)
