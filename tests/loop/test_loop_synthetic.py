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
    with pytest.raises(ValueError, match="no replicate packings given for MC 8% 120 MPa"):
        synthetic_dataset(sim, TRUTH, FIT, seeds={FIT[0]: (1000, 1001)})
    with pytest.raises(ValueError, match="at least 2"):
        synthetic_dataset(sim, TRUTH, FIT, seeds={FIT[0]: (1000, 1001), FIT[1]: (1002,)})


def test_each_condition_can_have_its_own_replicate_packings():
    seen = {}
    sim = FunctionSimulator(lambda p, c, s: (seen.setdefault(c, set()).add(s), toy(p, c, s))[1])
    seeds = {FIT[0]: (1000, 1001, 1002), FIT[1]: (1500, 1501, 1502)}
    d = synthetic_dataset(sim, TRUTH, FIT, seeds=seeds, noise=0.0)
    assert seen == {c: set(s) for c, s in seeds.items()}
    assert all(o.n == 3 for o in d.observations)
    # other packings per condition are other pellets; one sequence for all is the same pellets
    assert d.same_packings == ()
    assert synthetic_dataset(sim, TRUTH, FIT, noise=0.0).same_packings == (tuple(FIT),)
    linked = {FIT[0]: (1000, 1001), FIT[1]: (1001, 1002)}
    assert set(synthetic_dataset(sim, TRUTH, FIT, seeds=linked, noise=0.0).same_packings[0]) == set(FIT)


def test_a_moisture_effect_is_hidden_in_data_of_two_moisture_contents_from_other_pellets():
    from pelletdem.effects import EFFECTS
    from pelletdem.loop_cli import SYNTHETIC_MOISTURE, synthetic_design, synthetic_truth

    conds, held, seeds = synthetic_design(synthetic_truth("moisture_bonds"), 2)
    assert [(c.sigma_z, c.mc) for c in conds] == list(SYNTHETIC_MOISTURE) and held == (conds[-1],)
    assert held[0].mc == 20.0 and held[0].sigma_z == 60e6
    dry = [s for c, s in seeds.items() if c.mc == 8.0]
    wet = [s for c, s in seeds.items() if c.mc == 20.0]
    assert dry[0] == tuple(s + 20 for s in DATA_SEEDS) and not set(dry[0]) & set(wet[0])
    assert not (set(wet[0]) | set(dry[0])) & (set(FIT_SEEDS) | set(CHECK_SEEDS))
    # the same design for its control (the coefficient at 0)
    assert synthetic_design(synthetic_truth("bond.moisture_coefficient=0"), 2)[0] == conds
    # every other effect: three pressures at MC 8 %, the replicates those of before
    assert synthetic_design(synthetic_truth("moisture_yield"), 2)[0] == conds
    for name in set(EFFECTS) - {"moisture_bonds", "moisture_yield", "wood_density_yield"}:
        c, h, s = synthetic_design(synthetic_truth(name), 1)
        assert [x.sigma_z for x in c] == [60e6, 120e6, 90e6] and {x.mc for x in c} == {8.0}
        assert h == (c[-1],) and set(s.values()) == {tuple(k + 10 for k in DATA_SEEDS)}
    # an effect between woods cannot hide in data of one material: said, not run
    with pytest.raises(ValueError, match="materials"):
        synthetic_truth("wood_density_yield")


def test_the_command_lines_synthetic_data_hide_the_truth_in_the_draws_packings():
    from pelletdem.loop_cli import SYNTHETIC_BOND, synthetic_data, synthetic_design, synthetic_truth

    seen = set()
    sim = FunctionSimulator(lambda p, c, s: (seen.add(s), toy(p, c, s))[1])
    truth = synthetic_truth("none")
    data, hidden = synthetic_data(sim, truth, 3, noise=0.0)
    conds, _, seeds = synthetic_design(truth, 3)
    assert hidden == {"E_b": SYNTHETIC_BOND["youngs_modulus"], "sigma_c": SYNTHETIC_BOND["sigma_c"]}
    assert seen == set(seeds[conds[0]]) and {o.condition for o in data.observations} == set(conds)
    # without noise each number is the truth's mean over the draw's replicate packings
    o = next(o for o in data.observations if o.quantity == "sigma_f")
    assert o.value == pytest.approx(sim.predict(hidden, [o.condition], seeds[o.condition])[o.condition].mean_se(o)[0])
    # another draw: other packings, other numbers
    assert synthetic_data(sim, truth, 4, noise=0.0)[0].values[0] != data.values[0]


class _Window(FunctionSimulator):
    """The toy pellet behind a test window: a replicate fails inside it only from dL/D
    ``needs`` on (a ductile pellet), as the engine's tests end at max_dLD."""

    def __init__(self, needs):
        self.max_dLD, self.needs = 0.2, needs
        super().__init__(self._run)

    def widen(self, max_dLD):
        self.max_dLD = max_dLD
        self._memo.clear()  # a longer test is another simulation, as in the engine's cache key

    def _run(self, p, c, s):
        pred = toy(p, c, s)
        pred.scalars["peaked"] = 1.0 if self.max_dLD >= self.needs else 0.0
        return pred


def test_a_replicate_that_has_not_broken_is_tested_further():
    sim = _Window(needs=0.4)
    d = synthetic_dataset(sim, TRUTH, FIT, noise=0.02)
    assert sim.max_dLD == pytest.approx(0.2 * 1.5 * 1.5)  # widened twice, as a laboratory tests on
    assert any(o.quantity == "sigma_f" for o in d.observations)
    with pytest.raises(ValueError, match="do not fail within the diametral test window"):
        synthetic_dataset(_Window(needs=0.6), TRUTH, FIT, noise=0.02)  # not even at dL/D 0.5
