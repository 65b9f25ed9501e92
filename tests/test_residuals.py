"""Residual description (pelletdem.residuals): the structure tests on z-scores with known answers."""
import numpy as np
import pytest

from pelletdem.residuals import describe, runs_test


def test_runs_test_counts_runs_and_matches_textbook_moments():
    r, e, var = runs_test([1, 1, -1, -1, -1, 1, -1, 1])
    assert r == 5
    n1, n2, n = 4, 4, 8
    assert e == pytest.approx(1 + 2 * n1 * n2 / n)
    assert var == pytest.approx(2 * n1 * n2 * (2 * n1 * n2 - n) / (n * n * (n - 1)))
    assert np.isnan(runs_test([1, 1, 1])[0])


def _describe(z, n_curves=4, **kw):
    n = len(z)
    per = n // n_curves
    curves = {f"c{k}": np.arange(k * per, (k + 1) * per) for k in range(n_curves)}
    conds = [f"c{i // per}" for i in range(n)]
    return describe(z, parts=["rise"] * n, conditions=conds, curves=curves, **kw)


def test_white_noise_is_not_structured():
    rng = np.random.default_rng(0)
    false_alarms = sum(_describe(rng.standard_normal(48)).structured for _ in range(200))
    assert false_alarms <= 6  # alpha = 0.01 family-wise: ~2 of 200 expected


def test_a_shape_error_is_found_by_the_runs_test():
    x = np.linspace(0, 1, 12)
    z = np.tile(1.2 * np.sin(2 * np.pi * x), 4)  # small per point, but smooth along each curve
    s = _describe(z)
    assert s.structured and s.p_runs < 1e-3 and s.autocorr > 0.5


def test_a_level_error_is_found_by_chi_square_and_a_trend_by_regression():
    rng = np.random.default_rng(1)
    s = _describe(rng.standard_normal(48) + 3.0)
    assert s.structured and s.p_chi2 < 1e-10
    z = np.concatenate([rng.standard_normal(12) * 0.3 + m for m in (-1.5, -0.5, 0.5, 1.5)])
    s = _describe(z, levels={"sigma_z [MPa]": {"c0": 60, "c1": 80, "c2": 100, "c3": 120}})
    slope, p = s.trends["sigma_z [MPa]"]
    assert slope == pytest.approx(3.0 / 60, rel=0.2) and p < 0.01


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="one entry per observation"):
        describe([0.0, 1.0], parts=["a"], conditions=["c", "c"], curves={})
    with pytest.raises(ValueError, match="finite"):
        describe([np.nan], parts=["a"], conditions=["c"], curves={})
    with pytest.raises(ValueError, match="alpha"):
        describe([0.0], parts=["a"], conditions=["c"], curves={}, alpha=2.0)
