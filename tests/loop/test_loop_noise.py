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
