"""The packings' correlation between observations (pelletdem.loop_noise).

Analytic answers first: a one-factor correlation (one packing's luck shared by a condition's
observations) is recovered from simulated packings, the data's part of the misfits'
covariance is correlated within a condition only, and conditions the estimate never saw
borrow the nearest fit condition's correlation.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from pelletdem.loop_data import Condition, Dataset, Observation
from pelletdem.loop_noise import PackingNoise

C60, C90, C120 = Condition(60e6), Condition(90e6), Condition(120e6)
LOADINGS = np.array([0.9, 0.85, 0.7, 0.6, -0.5, 0.3])


def _curve(cond, m=6, n=5, sd=0.1):
    xs = np.linspace(0.02, 0.12, m)
    return [Observation(cond, "sigma_1", float(x), 1e6 * (1 + 10 * x), sd * 1e6 * (1 + 10 * x), n, "rise") for x in xs]


def _factor(lam):
    R = np.outer(lam, lam)
    np.fill_diagonal(R, 1.0)
    return R


def _members(R, sd_rel, g, k, rng, mean=1e6):
    """g design points x k packings of m positive observations, relative scatter sd_rel with
    correlation R (in ln)."""
    L = np.linalg.cholesky(R)
    e = rng.standard_normal((g, k, len(R))) @ L.T * sd_rel
    level = rng.uniform(0.5, 2.0, (g, 1, 1))  # every design point its own level
    return mean * level * np.exp(e)


def test_estimate_recovers_a_one_factor_correlation():
    rng = np.random.default_rng(1)
    data = Dataset(_curve(C60))
    noise = PackingNoise.estimate(data, _members(_factor(LOADINGS), 0.05, 200, 4, rng))
    assert noise.dof == pytest.approx(600)
    assert np.max(np.abs(noise.corr - _factor(LOADINGS))) < 0.08


def test_the_conditions_are_estimated_apart():
    rng = np.random.default_rng(6)
    data = Dataset(_curve(C60) + _curve(C120))
    R = np.kron(np.ones((2, 2)), _factor(LOADINGS))  # the design's packings are shared
    noise = PackingNoise.estimate(data, _members(R + 1e-9 * np.eye(12), 0.05, 200, 4, rng))
    assert np.allclose(noise.corr[:6, 6:], 0.0)
    assert np.max(np.abs(noise.corr[6:, 6:] - _factor(LOADINGS))) < 0.08


def test_estimate_weights_the_points_near_the_fit():
    rng = np.random.default_rng(2)
    data = Dataset(_curve(C60))
    near = _members(_factor(LOADINGS), 0.05, 100, 4, rng)
    far = _members(np.eye(6), 0.5, 100, 4, rng)
    w = np.r_[np.ones(100), np.full(100, 1e-9)]
    noise = PackingNoise.estimate(data, np.concatenate([near, far]), w)
    assert np.max(np.abs(noise.corr - _factor(LOADINGS))) < 0.1
    assert noise.dof == pytest.approx(300, rel=0.01)


def test_failed_points_are_left_out_and_too_few_packings_mean_independence():
    rng = np.random.default_rng(3)
    data = Dataset(_curve(C60))
    V = _members(_factor(LOADINGS), 0.05, 50, 4, rng)
    V[0, 1, 2] = np.nan
    assert PackingNoise.estimate(data, V).dof == pytest.approx(49 * 3)
    one = PackingNoise.estimate(data, V[:, :1])
    assert one.keys == ()
    assert np.allclose(one.misfit_correlation(data, np.ones(len(data))), np.eye(len(data)))
    with pytest.raises(ValueError, match="do not match"):
        PackingNoise.estimate(data, V[:, :, :3])


def test_the_data_part_is_correlated_within_a_condition_only_and_keeps_its_own_noise():
    R = _factor(LOADINGS)
    data = Dataset(_curve(C60) + _curve(C120))
    noise = PackingNoise([(o.condition, o.quantity, round(o.x, 12)) for o in data.observations],
                         np.kron(np.eye(2), R), 1e3)
    # a model without scatter of its own: all of the covariance is the data's
    C = noise.covariance(data, np.zeros(len(data)), 0.5 * data.sds)
    se2 = data.standard_errors ** 2
    assert np.allclose(np.diag(C), se2)
    assert np.allclose(C[:6, 6:], 0.0)
    # half of the replicate SD is the packings' (correlated), the rest measurement noise
    assert C[0, 1] == pytest.approx(0.25 * math.sqrt(se2[0] * se2[1]) * R[0, 1])
    # with the model's packing scatter as large as the data's, the misfits follow R
    corr = noise.misfit_correlation(data, data.standard_errors, data.sds)
    assert np.allclose(corr[:6, :6], R)


def test_a_held_out_condition_borrows_the_nearest_fit_conditions_correlation():
    fit = Dataset(_curve(C60) + _curve(C120))
    R = np.kron(np.eye(2), _factor(LOADINGS))
    noise = PackingNoise([(o.condition, o.quantity, round(o.x, 12)) for o in fit.observations], R, 1e3)
    assert np.allclose(noise.correlation(Dataset(_curve(C90, m=6))), _factor(LOADINGS))
    # two held-out conditions are not tied to each other through their counterparts
    both = noise.correlation(Dataset(_curve(C90) + _curve(Condition(100e6))))
    assert np.allclose(both[:6, 6:], 0.0) and np.allclose(both[6:, 6:], _factor(LOADINGS))
    # an observation with no counterpart is independent of the rest
    odd = Dataset(_curve(C90, m=3) + [Observation(C90, "bulk_density", float("nan"), 500.0, 5.0, 5)])
    assert np.allclose(noise.correlation(odd)[3, :3], 0.0)


def test_the_shared_packings_correlation_between_conditions_is_estimated():
    """The design presses the same packings in every condition: a packing's luck runs
    through both, and `shared` recovers that (within the conditions the one factor, between
    them the sampled coefficients), while `corr` keeps the conditions apart."""
    rng = np.random.default_rng(7)
    data = Dataset(_curve(C60) + _curve(C120))
    R = np.kron(np.array([[1.0, 0.8], [0.8, 1.0]]), _factor(LOADINGS))
    np.fill_diagonal(R, 1.0)
    noise = PackingNoise.estimate(data, _members(R, 0.05, 300, 4, rng))
    assert np.allclose(noise.corr[:6, 6:], 0.0)
    assert np.max(np.abs(noise.shared - R)) < 0.1
    assert np.min(np.linalg.eigvalsh(noise.shared)) > -1e-9
    assert np.allclose(np.diag(noise.shared), 1.0)
    # unrelated conditions: the sampled coefficients shrink to (nearly) nothing
    apart = PackingNoise.estimate(data, _members(np.kron(np.eye(2), _factor(LOADINGS)), 0.05, 300, 4, rng))
    assert np.max(np.abs(apart.shared[:6, 6:])) < 0.1


def test_the_model_part_is_shared_between_conditions_and_the_data_part_only_where_the_data_say_so():
    data = Dataset(_curve(C60) + _curve(C120))
    keys = [(o.condition, o.quantity, round(o.x, 12)) for o in data.observations]
    F = _factor(LOADINGS)
    shared = np.kron(np.array([[1.0, 0.8], [0.8, 1.0]]), F)
    np.fill_diagonal(shared, 1.0)
    noise = PackingNoise(keys, np.kron(np.eye(2), F), 1e3, shared)
    assert np.allclose(noise.correlation(data)[:6, 6:], 0.0)
    assert np.allclose(noise.correlation(data, lambda a, b: True), shared)
    se = data.standard_errors
    # a laboratory's data (other pellets per condition): only the model's part is tied
    C = noise.covariance(data, se, data.sds)
    assert np.allclose(C[:6, 6:], np.outer(se[:6], se[6:]) * shared[:6, 6:])
    # synthetic data pressed from the same packings at both pressures: the data's part too
    same = Dataset(data.observations, same_packings=((C60, C120),))
    C2 = noise.covariance(same, se, same.sds)
    assert np.allclose(C2[:6, 6:], 2.0 * np.outer(se[:6], se[6:]) * shared[:6, 6:])
    assert np.allclose(C2[:6, :6], C[:6, :6]) and np.allclose(np.diag(C2), np.diag(C))
    # a held-out condition borrows its counterpart's block and is tied to nothing else
    held = Dataset(_curve(C60) + _curve(C90), same_packings=((C60, C90),))
    Rh = noise.correlation(held, held.packings_shared)
    assert np.allclose(Rh[:6, 6:], 0.0) and np.allclose(Rh[6:, 6:], F)


def test_correlated_conditions_widen_a_shared_parameters_interval():
    """Two conditions that measure one shift through the same packings are not two
    independent measurements: the sandwich variance of the shift, with misfits correlated
    r between the conditions, is (1 + r) / 2 of one condition's against 1 / 2 for
    independent ones."""
    data = Dataset([Observation(C60, "bulk_density", float("nan"), 600.0, 5.0, 5),
                    Observation(C120, "bulk_density", float("nan"), 700.0, 5.0, 5)])
    keys = [(o.condition, o.quantity, math.nan) for o in data.observations]
    r = 0.7
    noise = PackingNoise(keys, np.eye(2), 1e3, np.array([[1.0, r], [r, 1.0]]))
    corr = noise.misfit_correlation(data, data.standard_errors, data.sds)
    # equal data and model parts; the data's (other pellets) are independent between conditions
    assert corr[0, 1] == pytest.approx(r / 2.0)
    J = np.ones((2, 1))
    plain = np.linalg.inv(J.T @ J)
    sandwich = plain @ J.T @ corr @ J @ plain
    assert float(sandwich[0, 0] / plain[0, 0]) == pytest.approx(1.0 + r / 2.0)
