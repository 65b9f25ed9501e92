"""Laboratory-like synthetic data (pelletdem.loop_synthetic)."""
from __future__ import annotations

import numpy as np
import pytest
from toy_pellet import FIT, TRUTH, toy

from pelletdem.loop import CHECK_SEEDS, DATA_SEEDS, FIT_SEEDS, FunctionSimulator, synthetic_dataset


def test_replicates_come_from_packings_no_fit_or_check_uses():
    assert not set(DATA_SEEDS) & (set(FIT_SEEDS) | set(CHECK_SEEDS))
    seen = []
    sim = FunctionSimulator(lambda p, c, s: (seen.append(s), toy(p, c, s))[1])
    d = synthetic_dataset(sim, TRUTH, FIT, noise=0.02, compaction_points=4)
    assert set(seen) == set(DATA_SEEDS)
    assert all(o.n == len(DATA_SEEDS) for o in d.observations)
    assert {o.quantity for o in d.observations} == {"sigma_1", "sigma_z", "sigma_f", "dLf_D", "bulk_density"}


def test_noise_and_packings_make_the_replicate_sd():
    sim = FunctionSimulator(toy)
    quiet = synthetic_dataset(sim, TRUTH, FIT, noise=0.0)
    noisy = synthetic_dataset(sim, TRUTH, FIT, noise=0.2, seed=3)
    sf = lambda d: np.array([o.sd / o.value for o in d.observations if o.quantity == "sigma_f"])  # noqa: E731
    assert np.all(sf(quiet) > 0.01)  # the packings alone scatter (5 % in the toy)
    assert np.mean(sf(noisy)) > 2 * np.mean(sf(quiet))
    again = synthetic_dataset(sim, TRUTH, FIT, noise=0.2, seed=3)
    assert np.array_equal(noisy.values, again.values)


def test_bad_arguments_are_refused_before_any_simulation():
    sim = FunctionSimulator(lambda p, c, s: pytest.fail("simulated"))
    with pytest.raises(ValueError, match="noise"):
        synthetic_dataset(sim, TRUTH, FIT, noise=-0.1)
    with pytest.raises(ValueError, match="seeds"):
        synthetic_dataset(sim, TRUTH, FIT, seeds=[1])
    with pytest.raises(ValueError, match="quantities"):
        synthetic_dataset(sim, TRUTH, FIT, quantities=("porosity",))
