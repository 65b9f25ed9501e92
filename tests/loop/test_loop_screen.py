"""Screening candidates and the detection power of the data (pelletdem.loop_screen)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from toy_pellet import FIT, LIBRARY, TRUTH, toy

from pelletdem.loop import FIT_SEEDS, FunctionSimulator, synthetic_dataset
from pelletdem.loop_emulator import Axis, Space
from pelletdem.loop_models import fit_model
from pelletdem.loop_screen import detection_power, lambda_for_power, screen


def test_lambda_for_power_is_the_noncentrality_that_passes_the_threshold():
    for thr in (3.84, 9.1):
        lam = lambda_for_power(thr, 0.8)
        assert stats.ncx2.sf(thr, 1, lam) == pytest.approx(0.8, abs=1e-6)
    # the textbook value: 5 % two-sided test, 80 % power -> (1.96 + 0.84)^2 = 7.85
    assert lambda_for_power(stats.chi2.isf(0.05, 1), 0.8) == pytest.approx(7.85, abs=0.02)


def _baseline(extra, replicates=5):
    sim = FunctionSimulator(toy)
    data = synthetic_dataset(sim, {**TRUTH, **extra}, FIT, noise=0.02, compaction_points=4,
                             seeds=list(range(1000, 1000 + replicates)))
    space = Space((Axis("E_b", 30e6, 300e6), Axis("sigma_c", 3e6, 30e6)))
    return sim, data, fit_model(sim, space, (), data, None, FIT_SEEDS, (100, 101, 102, 103))


@pytest.mark.parametrize("name", ["toe", "tail", "trend"])
def test_screen_ranks_the_hidden_effect_first(name):
    e = LIBRARY[name]
    sim, data, mf = _baseline(e.settings(2 * e.probe))
    ranked = screen(sim, mf, list(LIBRARY.values()), data, FIT_SEEDS)
    assert ranked[0].effect.name == name
    assert ranked[0].gain > 20 and ranked[0].gain > 5 * ranked[1].gain
    assert e.lo <= ranked[0].strength <= e.hi


def test_screen_gives_nothing_to_an_effect_that_acts_the_wrong_way():
    # the toy's softening only slows the fall after the peak; data whose fall is faster than
    # the model's cannot be explained by it, whatever its strength
    sim, data, mf = _baseline({})
    faster = [o for o in data.observations]
    for k, o in enumerate(faster):
        if o.part == "post-peak":
            faster[k] = type(o)(o.condition, o.quantity, o.x, 0.7 * o.value, o.sd, o.n, o.part)
    data2 = type(data)(faster)
    tail = [s for s in screen(sim, mf, [LIBRARY["tail"]], data2, FIT_SEEDS)][0]
    assert tail.gain == 0.0


def test_detection_power_falls_with_more_replicates_and_names_what_would_help():
    e = LIBRARY["toe"]
    sim, data, mf = _baseline({})
    sc = screen(sim, mf, [e], data, FIT_SEEDS)[0]
    thr = 9.1
    p5 = detection_power(sc, mf, data, thr, 5, len(FIT_SEEDS))
    assert e.lo < p5.detectable < e.hi
    # at the detectable strength the noncentrality is the one with 80 % power
    lam = sc.lam_probe * (p5.detectable / e.probe) ** 2
    assert stats.ncx2.sf(thr, 1, lam) == pytest.approx(0.8, abs=0.01)
    assert "cannot be told from none" in p5.statement
    if sc.lam_probe < lambda_for_power(thr):
        assert p5.replicates is None or p5.replicates > 5
        assert p5.packings is None or p5.packings > len(FIT_SEEDS)
    # with 20 replicates the same effect is seen at a smaller strength
    _, data20, mf20 = _baseline({}, replicates=20)
    sc20 = screen(sim, mf20, [e], data20, FIT_SEEDS)[0]
    p20 = detection_power(sc20, mf20, data20, thr, 20, len(FIT_SEEDS))
    assert p20.detectable < p5.detectable or math.isnan(p5.detectable)
    assert np.isfinite(p20.detectable)


def test_power_names_the_parameter_that_can_mimic_an_effect():
    # an "effect" that is nothing but a stronger bond: sigma_c does all of it
    def stronger(params, c, seed=0):
        p = dict(params)
        p["sigma_c"] = p["sigma_c"] * (1.0 + p.pop("bond.softening", 0.0))
        return toy(p, c, seed)

    e = LIBRARY["tail"]
    sim = FunctionSimulator(stronger)
    data = synthetic_dataset(sim, TRUTH, FIT, noise=0.02, compaction_points=4, seeds=list(range(1000, 1005)))
    space = Space((Axis("E_b", 30e6, 300e6), Axis("sigma_c", 3e6, 30e6)))
    mf = fit_model(sim, space, (), data, None, FIT_SEEDS, (100, 101, 102, 103))
    sc = screen(sim, mf, [e], data, FIT_SEEDS)[0]
    assert sc.absorbed > 0.75 and sc.absorber == "sigma_c"  # first order: the probe is sigma_c x 1.5
    p = detection_power(sc, mf, data, 9.1, 5, len(FIT_SEEDS))
    assert "can do as well (most of all sigma_c)" in p.statement
    # the toy's pressure trend is more its own than the base parameters'
    _, data0, mf0 = _baseline({})
    sc0 = screen(FunctionSimulator(toy), mf0, [LIBRARY["trend"]], data0, FIT_SEEDS)[0]
    assert 0.0 <= sc0.absorbed < 0.6
    assert "can do as well" not in detection_power(sc0, mf0, data0, 9.1, 5, len(FIT_SEEDS)).statement
