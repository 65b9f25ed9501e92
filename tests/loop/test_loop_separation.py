"""How well data separate two fitted models: D, the chance of naming the right one, and the
replicates that would make it sure."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pelletdem.loop import Condition, Dataset, Prediction
from pelletdem.loop_data import Observation
from pelletdem.loop_separation import SURE, chance_right, replicates_factor, separation, statement
from pelletdem.loop_simulators import Ensemble

C60, C120 = Condition(60e6), Condition(120e6)
# SE of the means: 5e4 / sqrt(4) = 2.5e4 Pa and 10 / sqrt(4) = 5 kg/m^3
DATA = Dataset([Observation(C60, "sigma_f", math.nan, 1.0e6, 5e4, 4),
                Observation(C120, "bulk_density", math.nan, 600.0, 10.0, 4)])


def _ensemble(cond, seeds, sigma_f, density):
    return Ensemble(tuple(seeds), tuple(Prediction(scalars={"sigma_f": s, "bulk_density": d})
                                        for s, d in zip(sigma_f, density)))


def _models(offsets_a, offsets_b, seeds_a=(0, 1, 2, 3), seeds_b=(0, 1, 2, 3), delta=(5e4, 10.0)):
    a = {c: _ensemble(c, seeds_a, 1.0e6 + 1e5 * np.asarray(offsets_a), 600.0 + 20 * np.asarray(offsets_a))
         for c in (C60, C120)}
    b = {c: _ensemble(c, seeds_b, 1.0e6 + delta[0] + 1e5 * np.asarray(offsets_b),
                      600.0 + delta[1] + 20 * np.asarray(offsets_b)) for c in (C60, C120)}
    return a, b


def test_models_apart_by_a_known_amount_on_the_same_packings():
    # the packings' luck is common to both (paired), so it cancels: D = (5e4/2.5e4)^2 + (10/5)^2
    a, b = _models([-1.0, 0.5, 1.5, -1.0], [-1.0, 0.5, 1.5, -1.0])
    assert separation(a, b, DATA) == pytest.approx(8.0, rel=1e-9)
    assert separation(b, a, DATA) == pytest.approx(8.0, rel=1e-9)


def test_the_packings_noise_does_not_count_as_separation():
    # the same model on other packings: the means differ by the packings' luck alone, which
    # the estimate's own variance removes: most often none is left (P(chi2_1 < 1) = 0.68), and
    # on average well under what the raw squared difference would claim
    rng = np.random.default_rng(3)
    d = [separation(*_models(rng.normal(size=4), rng.normal(size=4), (0, 1, 2, 3), (4, 5, 6, 7), (0.0, 0.0)),
                    DATA) for _ in range(400)]
    raw = 2 * 2 * (1e5 / 2.5e4) ** 2 / 4  # sum of E[(mean_a - mean_b)^2] / s^2 over both observations
    assert np.median(d) == 0.0 and np.mean(d) < 0.6 * raw


def test_a_failed_prediction_is_left_out():
    a, b = _models([0.0] * 4, [0.0] * 4)
    a[C60] = Ensemble((0, 1, 2, 3), tuple(Prediction(ok=False, error="x") for _ in range(4)))
    assert separation(a, b, DATA) == pytest.approx(4.0, rel=1e-9)


def test_the_chance_of_naming_the_right_model_matches_a_simulated_laboratory():
    # truth A, rival B = A + Delta; the data are A + noise; the nearer model (lower chi2) is named
    rng = np.random.default_rng(0)
    s = np.array([1.0, 2.0, 0.5])
    for delta in ([0.4, 0.0, 0.1], [1.0, 1.0, 0.5], [2.0, 3.0, 0.0]):
        delta = np.asarray(delta)
        d = float(np.sum((delta / s) ** 2))
        eta = rng.normal(size=(20000, 3)) * s
        right = np.sum((eta / s) ** 2, axis=1) < np.sum(((eta - delta) / s) ** 2, axis=1)
        assert right.mean() == pytest.approx(chance_right(d), abs=0.01)


def test_how_many_replicates_would_make_the_choice_sure():
    assert chance_right(0.0) == 0.5
    assert chance_right(SURE) == pytest.approx(0.95, abs=1e-9)
    assert replicates_factor(SURE) == pytest.approx(1.0)
    assert replicates_factor(SURE / 4) == pytest.approx(4.0)
    assert replicates_factor(0.0) == math.inf
    # D grows with the replicates: n * factor replicates bring it to SURE
    assert chance_right(SURE / 4 * replicates_factor(SURE / 4)) == pytest.approx(0.95, abs=1e-9)


def test_the_sentence_says_what_would_tell_them_apart():
    assert "no number of replicates" in statement("a", "b", 0.0)
    s = statement("a", "b", SURE / 4)
    assert "a and b predict 2.7 apart" in s and "name it only 79 %" in s and "x4 the replicates" in s
    assert "decided" not in s
    s = statement("a", "b", 2 * SURE)
    assert "replicates" not in s and "what ties them is how each was fitted" in s
    s = statement("a", "b", 71.1, 8, 6.2, 9.3)
    assert "on the 8 fresh packings that decided, b's chi2 is 6.2 above a's" in s and "scatter of 9.3" in s
