"""Fitting on the emulator, and the Welch scores it minimises (pelletdem.loop_fit)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from pelletdem.loop import Condition, Dataset, Observation
from pelletdem.loop_emulator import Axis, Emulator, Space, design
from pelletdem.loop_fit import fit_emulated, profile, welch_z


def test_welch_z_is_the_t_statistic_when_both_errors_are_well_known():
    z = welch_z([0.0, 1.0, -3.0], [1.0, 1.0, 1.0], 1e6, [0.0, 0.0, 0.0], 1e6)
    assert z == pytest.approx([0.0, 1.0, -3.0], abs=1e-4)


def test_welch_z_discounts_a_difference_measured_against_a_five_replicate_sd():
    # t = 3 with 4 degrees of freedom has the tail of z = 2.25, not 3
    z = float(welch_z(3.0, 1.0, 4, 0.0, 1e6))
    assert z == pytest.approx(stats.norm.isf(stats.t.sf(3.0, 4)), rel=1e-6)
    assert 2.0 < z < 2.5
    # Welch-Satterthwaite: two equal errors with 4 dof each give 8 dof
    assert float(welch_z(3.0, 1.0, 4, 1.0, 4)) == pytest.approx(stats.norm.isf(stats.t.sf(3.0 / math.sqrt(2), 8)))


def test_welch_z_squared_sums_to_a_chi_square_under_noise():
    rng = np.random.default_rng(1)
    n, reps = 4000, 5
    x = rng.standard_normal((n, reps))
    se = x.std(axis=1, ddof=1) / math.sqrt(reps)
    z = welch_z(x.mean(axis=1), se, reps - 1, 0.0, 1e6)
    assert np.mean(z ** 2) == pytest.approx(1.0, abs=0.08)  # the raw t^2 would average 2


def _emulator_and_data(truth_u, noise=0.01):
    """An emulator of sigma_f = 1 MPa exp(u0 - 0.3 u1) and dL_f/D = 0.05 (1 + u1 - 0.5 u0),
    and data made at ``truth_u``."""
    space = Space((Axis("E_b", 1e7, 1e9), Axis("sigma_c", 1e6, 1e8)))
    f = lambda U: np.column_stack([1e6 * np.exp(U[:, 0] - 0.3 * U[:, 1]),  # noqa: E731
                                   0.05 * (1 + U[:, 1] - 0.5 * U[:, 0])])
    U = design(2, 20)
    Y = f(U)
    emu = Emulator(space, U, Y, Y * 0.005)
    y = f(np.atleast_2d(truth_u))[0]
    c = Condition(120e6)
    data = Dataset([Observation(c, "sigma_f", math.nan, y[0], noise * y[0] * math.sqrt(5), 5),
                    Observation(c, "dLf_D", math.nan, y[1], noise * y[1] * math.sqrt(5), 5)])
    return space, emu, data


def test_fit_emulated_recovers_the_parameters_and_their_uncertainty():
    truth = np.array([0.3, 0.6])
    space, emu, data = _emulator_and_data(truth)
    fit = fit_emulated(emu, data, start=[0.8, 0.1])
    assert fit.u == pytest.approx(truth, abs=0.01)
    assert fit.chi2 < 1e-3
    p = space.params(truth)
    for name in ("E_b", "sigma_c"):
        lo, hi = fit.interval(name)
        assert lo < p[name] < hi
        assert 0 < fit.se[name] < 0.2  # relative (log axes)


def test_fit_emulated_needs_the_emulators_outputs():
    _, emu, data = _emulator_and_data(np.array([0.5, 0.5]))
    with pytest.raises(ValueError, match="outputs"):
        fit_emulated(emu, Dataset(data.observations[:1]))


def test_correlated_misfits_widen_the_errors_by_the_sandwich():
    # two observations of one pellet: correlated misfits carry less than two independent ones
    space, emu, data = _emulator_and_data(np.array([0.3, 0.6]))
    plain = fit_emulated(emu, data, start=[0.8, 0.1])
    same = fit_emulated(emu, data, start=[0.8, 0.1], corr=np.eye(2))
    assert same.widen == pytest.approx({"E_b": 1.0, "sigma_c": 1.0})
    assert np.allclose(same.cov, plain.cov)
    R = np.array([[1.0, 0.8], [0.8, 1.0]])
    corr = fit_emulated(emu, data, start=[0.8, 0.1], corr=R)
    assert corr.u == pytest.approx(plain.u, abs=1e-6)  # the fit itself does not change
    for name in ("E_b", "sigma_c"):
        assert corr.widen[name] >= 1.0
        assert corr.se[name] == pytest.approx(plain.se[name] * math.sqrt(corr.widen[name]), rel=1e-6)
    assert max(corr.widen.values()) > 1.2
    lo, hi = corr.interval("E_b")
    lo0, hi0 = plain.interval("E_b")
    assert lo <= lo0 and hi >= hi0


def _linear_one_parameter(sd_unit: float):
    """An emulator of one observation y = u (unit box, linear axis) and data at u = 0.4 with a
    standard error of ``sd_unit``: chi2(u) = ((u - 0.4) / sd_unit)^2 exactly, so the 2-sigma
    interval is 0.4 +- 2 sd_unit of the box."""
    space = Space((Axis("c", 0.0, 1.0, log=False),))
    U = np.linspace(0.0, 1.0, 12)[:, None]
    emu = Emulator(space, U, U.copy(), np.full_like(U, 1e-9))
    data = Dataset([Observation(Condition(120e6), "bulk_density", math.nan, 0.4, sd_unit * 1e3, 1_000_000)])
    return emu, data


@pytest.mark.parametrize("sd_unit", [0.001, 0.003, 0.05])
def test_a_profile_interval_is_the_parabolas_whatever_the_coarse_grid(sd_unit):
    # the coarse grid's cells are 0.025 of the box: an interval of a few thousandths lies
    # inside one, and straight lines between its points would cut it short
    emu, data = _linear_one_parameter(sd_unit)
    fit = profile(emu, data, fit_emulated(emu, data, start=[0.5]), "c")
    assert fit.u[0] == pytest.approx(0.4, abs=0.05 * sd_unit)
    assert fit.se["c"] == pytest.approx(sd_unit, rel=0.02)
    lo, hi = fit.interval("c")
    assert lo == pytest.approx(0.4 - 2 * sd_unit, abs=0.03 * sd_unit)
    assert hi == pytest.approx(0.4 + 2 * sd_unit, abs=0.03 * sd_unit)
    lo3, hi3 = fit.interval("c", k=3.0)
    assert hi3 - lo3 == pytest.approx(6 * sd_unit, rel=0.03)
