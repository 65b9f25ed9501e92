"""Forward selection on data made like a laboratory's (pelletdem.loop_selection).

The analytic pellet of toy_pellet.py scatters between packings as the DEM pellet does; the
data's five replicates come from packings no fit uses, with 2 % noise, and 90 MPa is held
out. The loop must name a hidden effect it knows and recover its strength, add nothing to
data without one, say "no candidate explains" an effect outside its library, and not let a
compaction-stage effect win by re-packing.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from toy_pellet import BOUNDS, FIT, HELD, LIBRARY, START, TRUTH, toy

from conftest import toy_loop
from pelletdem.loop import FunctionSimulator, Prediction, close_loop, synthetic_dataset
from pelletdem.loop_selection import SCALAR_BREAK_DROP, SCALAR_REACH, unfailed

HIDDEN = {"toe": 0.5, "tail": 1.0, "trend": 1.0, "springback": 10.0}


@pytest.mark.parametrize("name", sorted(HIDDEN))
@pytest.mark.parametrize("draw", [0, 1])
def test_loop_names_the_hidden_effect_and_recovers_its_strength(name, draw):
    e = LIBRARY[name]
    res = toy_loop(e.settings(HIDDEN[name]), draw)
    assert res.chosen[:1] == [name], res.verdict + "\n" + "\n".join(res.log)
    model = res.steps[0].trials[[t.effect.name for t in res.steps[0].trials].index(name)].model
    # the profile's 3-sigma interval (the 2-sigma one's coverage rate over many draws is what
    # benchmarks/bench_loop_acceptance.py measures; two draws cannot)
    lo, hi = model.fit.interval(e.param, k=3.0)
    assert lo <= HIDDEN[name] <= hi, (lo, hi)
    before, after = res.errors["baseline"], res.errors[f"baseline + {name}"]
    assert after["fit_rrmse"] < before["fit_rrmse"]
    # the held-out conditions do not get worse beyond their noise (the loop's own rule)
    n_held = len(res.heldout_data)
    assert after["heldout_chi2_per_point"] <= before["heldout_chi2_per_point"] + 2 * math.sqrt(2 * n_held) / n_held


@pytest.mark.parametrize("draw", [0, 1, 2, 3])
def test_loop_adds_nothing_without_an_effect(draw):
    res = toy_loop({}, draw)
    assert res.chosen == [], res.verdict + "\n" + "\n".join(res.log)
    assert res.final is res.baseline
    assert res.errors["baseline"]["heldout_chi2_per_point"] < 2.5


@pytest.mark.parametrize("draw", [0, 1])
def test_an_effect_outside_the_library_is_not_explained(draw):
    res = toy_loop({"bond.kt_ratio": 1.3}, draw)
    assert res.chosen == [] and res.verdict == "no candidate explains this residual", "\n".join(res.log)
    assert res.errors["baseline"]["fit_chi2_per_point"] > 3  # there was something to explain
    assert set(res.power) == set(LIBRARY)  # and the report says what could have been seen


def test_a_compaction_effect_does_not_win_by_repacking():
    # With every candidate fitted in full, the compaction-stage one (which re-draws the
    # packings at every strength, as a DEM compaction does) may lower the fit's chi2 by luck;
    # the check on fresh packings must refuse it on data without an effect.
    for draw in (0, 1):
        res = toy_loop({}, draw, screen_threshold=0.0, screen_top=4)
        assert res.chosen == [], "\n".join(res.log)


def test_every_step_is_reported():
    res = toy_loop(LIBRARY["tail"].settings(1.0), 0)
    first = res.steps[0]
    assert first.model is res.baseline and first.added == "tail"
    assert [s.effect.name for s in first.screens][0] == "tail"
    assert all(math.isfinite(s.gain) for s in first.screens if not s.skipped)
    assert res.steps[-1].added is None
    assert "baseline + tail" in res.table()
    assert res.n_simulations > 0 and res.wall_time_s > 0
    # each round says what the data could reveal on top of its own model
    second = res.steps[1]
    assert second.screens and set(first.powers) >= {s.effect.name for s in second.screens}
    assert any(first.powers[k].statement != p.statement for k, p in second.powers.items())
    assert res.power == {**first.powers, **second.powers}


def test_the_report_shows_each_round_s_own_power(tmp_path):
    from pelletdem.loop_report import write_report

    res = toy_loop(LIBRARY["tail"].settings(1.0), 0)
    text = open(write_report(res, str(tmp_path), "toy")).read()
    for st in res.steps:
        for p in st.powers.values():
            assert p.statement in text


def test_bad_arguments_are_refused_before_any_simulation():
    sim = FunctionSimulator(toy)
    data = synthetic_dataset(sim, TRUTH, FIT + HELD, noise=0.02)
    n0 = sim.n_simulations
    for kw, match in (({"fit_seeds": (0, 1), "check_seeds": (1, 2)}, "disjoint"), ({"alpha": 0.0}, "alpha"),
                      ({"min_check_gain": 1.5}, "min_check_gain"), ({"max_effects": -1}, "max_effects")):
        with pytest.raises(ValueError, match=match):
            close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD, library=LIBRARY, **kw)
    with pytest.raises(ValueError, match="E_b"):
        close_loop(sim, data, {"E_b": (1e9, 1e6)}, None, library=LIBRARY)
    with pytest.raises(ValueError, match="start"):
        close_loop(sim, data, BOUNDS, {"E_b": 1.0, "sigma_c": 8e6}, library=LIBRARY)
    with pytest.raises(ValueError, match="held out"):
        close_loop(sim, data, BOUNDS, START, held_out=lambda c: True, library=LIBRARY)
    assert sim.n_simulations == n0


class WindowedToy(FunctionSimulator):
    """The toy pellet seen through a diametral test that ends at ``max_dLD``: past its end
    the curve is cut, and a pellet that has not failed by then has not peaked."""

    def __init__(self, max_dLD):
        self.max_dLD = max_dLD
        super().__init__(self._run)

    def _run(self, params, c, seed):
        p = toy(params, c, seed)
        x, y = p.curve
        keep = x <= self.max_dLD
        k = int(np.argmax(y[keep]))
        peaked = 1.0 if p.scalars["dLf_D"] <= self.max_dLD else 0.0
        return Prediction(curve=(x[keep], y[keep]), compaction=p.compaction,
                          scalars=dict(p.scalars, sigma_f=float(y[keep][k]), dLf_D=float(x[keep][k]), peaked=peaked))

    def widen(self, max_dLD):
        self.max_dLD = max_dLD
        self._memo.clear()


def test_a_window_shorter_than_the_data_is_widened_before_the_fit():
    # the data (a laboratory's) break near dL/D = 0.08 and reach 0.12; the model's test ends at 0.05
    data = synthetic_dataset(WindowedToy(0.5), TRUTH, FIT + HELD, noise=0.02, compaction_points=4)
    sim = WindowedToy(0.05)
    res = close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD, library=LIBRARY, max_effects=0)
    assert sim.max_dLD > 0.12
    assert any("the tests run to dL/D" in line for line in res.log)
    assert not unfailed(res.baseline, res.fit_data)
    assert res.baseline.fit.params["E_b"] == pytest.approx(TRUTH["E_b"], rel=0.2)
    # asked for no effect, it says it tried none, not that none explains the residual
    assert res.verdict == "nothing added: no candidate was tried (max_effects = 0)"


def test_a_fitted_model_that_does_not_fail_gets_a_wider_window():
    # data without curve points past dL/D 0.02 (their dL_f/D is not given): the window first
    # holds them, but the model fitted to them does not fail inside it
    full = synthetic_dataset(WindowedToy(0.5), TRUTH, FIT + HELD, noise=0.02, compaction_points=4)
    data = full.subset(lambda o: o.quantity not in ("dLf_D",) and not (o.quantity == "sigma_1" and o.x > 0.02))
    sim = WindowedToy(0.03)
    res = close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD, library=LIBRARY, max_effects=0)
    assert sim.max_dLD > 0.03
    assert any("does not fail within the test window" in line for line in res.log)


def test_data_of_failures_alone_get_a_window_either_side_of_them_and_tests_that_end_at_the_break():
    # the paper's Table 3: sigma_f and dL_f/D, no curve; a window at 1.1 dL_f/D would cut off
    # the half of the model's packings that fail later than the mean
    full = synthetic_dataset(WindowedToy(0.5), TRUTH, FIT + HELD, noise=0.02, compaction_points=4)
    data = full.subset(lambda o: o.quantity != "sigma_1")
    reach = max(o.value for o in data.observations if o.quantity == "dLf_D")
    sim = WindowedToy(0.5)
    drops = []
    sim.end_at_break = drops.append
    res = close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD, library=LIBRARY, max_effects=0)
    assert sim.max_dLD == pytest.approx(SCALAR_REACH * reach) and drops == [SCALAR_BREAK_DROP]
    assert any("no curve: each test ends once its force has fallen" in line for line in res.log)
    assert not unfailed(res.baseline, res.fit_data)


def test_synthetic_data_refuse_replicates_that_do_not_break():
    # a simulator that cannot test further (tests/loop/test_loop_synthetic.py: one that can is
    # widened until its replicates break)
    sim = WindowedToy(0.03)
    sim.widen = None
    with pytest.raises(ValueError, match="do not fail within"):
        synthetic_dataset(sim, TRUTH, FIT, noise=0.02)


def test_a_simulator_that_cannot_widen_says_so_in_the_verdict():
    data = synthetic_dataset(WindowedToy(0.5), TRUTH, FIT + HELD, noise=0.02)
    sim = WindowedToy(0.05)
    sim.widen = None  # a simulator that cannot widen its window
    res = close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD, library=LIBRARY, max_effects=0)
    assert "beyond the simulated test window" in res.verdict


def test_the_report_says_how_much_shared_packings_widen_the_errors(tmp_path):
    from pelletdem.loop_report import write_report

    res = toy_loop({}, 0)
    widen = res.baseline.fit.widen
    assert set(widen) == set(BOUNDS) and min(widen.values()) >= 1.0
    text = open(write_report(res, str(tmp_path), "toy")).read()
    assert "share their pellets' packings" in text
    assert "variances x" + ", x".join(f"{widen[a]:.2f}" for a in BOUNDS) in text


def test_candidates_the_data_cannot_tell_apart_are_both_named(tmp_path):
    # a twin of the hidden effect (the same law under another name) fits exactly as well: the
    # loop adds one and says the other is as good, in the verdict and the report
    import dataclasses

    from pelletdem.loop_report import write_report
    from pelletdem.loop_separation import statement

    library = {"trend": LIBRARY["trend"], "twin": dataclasses.replace(LIBRARY["trend"], name="twin")}
    sim = FunctionSimulator(toy)
    data = synthetic_dataset(sim, {**TRUTH, **LIBRARY["trend"].settings(HIDDEN["trend"])}, FIT + HELD,
                             noise=0.02, compaction_points=4, seeds=[1000 + k for k in range(5)], seed=0)
    res = close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD, library=library)
    assert res.chosen == ["trend"], "\n".join(res.log)
    assert res.steps[0].rivals == ["twin"]
    assert res.verdict.startswith("added trend (twin fits as well: these data do not tell them apart)")
    text = open(write_report(res, str(tmp_path), "toy")).read()
    assert "these data do not tell them apart; trend was added" in text
    # the same law fitted twice predicts nearly the same: the data cannot separate them
    d = res.steps[0].separations["twin"]
    assert 0.0 <= d < 1.0
    assert statement("trend", "twin", d) in text
    # a clear winner has no rival
    assert toy_loop(LIBRARY["trend"].settings(HIDDEN["trend"]), 0).steps[0].rivals == []


def test_a_candidate_that_cannot_join_the_added_effect_is_not_tried_with_it():
    # the engine refuses two laws of the unloading stiffness at once: once one is added, the
    # other is left out of the next round (not simulated, which would stop the loop)
    from pelletdem.effects import EFFECTS

    sat = EFFECTS["saturating_unloading"]
    library = {"springback": LIBRARY["springback"], "saturating": sat}
    sim = FunctionSimulator(toy)
    data = synthetic_dataset(sim, {**TRUTH, **LIBRARY["springback"].settings(HIDDEN["springback"])}, FIT + HELD,
                             noise=0.02, compaction_points=4, seeds=[1000 + k for k in range(5)], seed=0)
    res = close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD, library=library)
    assert res.chosen == ["springback"], "\n".join(res.log)
    assert any(line.startswith("saturating is not tried with springback: two effects that shape the unloading")
               for line in res.log), "\n".join(res.log)


def test_a_candidate_the_model_sets_or_its_laws_refuse_is_not_tried():
    """A candidate whose row the base model sets (a --set) is part of it already, and one the
    laws refuse beside the model (two laws of the unloading stiffness, say) would stop the loop
    at its first simulation: both are named in the log and left out; the others are screened."""
    class Sim(FunctionSimulator):
        def base_rows(self):  # an effect's row set at its "off" value leaves it a candidate
            return {"contact.unloading_growth": 5.0, "bond.softening": 0.0}

        def refusal(self, params, conditions):
            return "the toe's law is refused here" if "contact.plate_yield_stress" in params else ""

    sim = Sim(toy)
    data = synthetic_dataset(sim, {**TRUTH, **LIBRARY["trend"].settings(HIDDEN["trend"])}, FIT + HELD,
                             noise=0.02, compaction_points=4, seeds=[1000 + k for k in range(5)], seed=0)
    res = close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD, library=LIBRARY, max_effects=1)
    log = "\n".join(res.log)
    assert "springback is not tried: the model sets contact.unloading_growth itself" in log, log
    assert "toe is not tried with the model: the toe's law is refused here" in log, log
    screened = {sc.effect.name for sc in res.steps[0].screens}
    assert screened == {"tail", "trend"}, log
    assert res.chosen == ["trend"], log


def test_the_engine_simulator_names_the_rows_it_sets_and_what_its_laws_refuse():
    from pelletdem.engine import BondLaw
    from pelletdem.loop import Condition, EngineSimulator

    conds = [Condition(60e6), Condition(120e6)]
    with EngineSimulator("tiny", contact={"plastic_stiffness_ratio": 50.0}, bond=BondLaw(softening=1.0)) as sim:
        assert sim.base_rows() == {"contact.plastic_stiffness_ratio": 50.0, "bond.softening": 1.0}
        assert "two effects that shape the unloading" in sim.refusal({"contact.unloading_growth": 5.0}, conds)
        assert sim.refusal({"E_b": 1e8, "contact.hardening": 1.0}, conds) == ""
        assert sim.n_simulations == 0


def test_a_base_parameter_pinned_at_its_box_is_let_go():
    """The data's E_b (100 MPa) lies above the box (30-70 MPa): the baseline's fit is pinned at
    the upper end, so the box is widened there and the fit lands on the truth, with nothing
    added to a model without an effect."""
    sim = FunctionSimulator(toy)
    data = synthetic_dataset(sim, TRUTH, FIT + HELD, noise=0.02, compaction_points=4,
                             seeds=[1000 + k for k in range(5)], seed=0)
    res = close_loop(sim, data, {"E_b": (30e6, 70e6), "sigma_c": BOUNDS["sigma_c"]}, {"E_b": 50e6, "sigma_c": 10e6},
                     held_out=lambda c: c in HELD, library=LIBRARY)
    log = "\n".join(res.log)
    assert "E_b = 7e+07 is at the upper end of its box" in log, log
    axis = res.baseline.space.axes[0]
    assert axis.name == "E_b" and axis.hi > TRUTH["E_b"]
    assert res.baseline.fit.params["E_b"] == pytest.approx(TRUTH["E_b"], rel=0.1)
    assert res.chosen == [] and "end of its box" not in res.verdict


def test_a_parameter_the_box_cannot_reach_is_said_in_the_verdict():
    """sigma_c (8 MPa, the curve's height) far above its box (3-4 MPa): two widenings do not
    reach it (two log lines), and the verdict says where it is pinned (its log line and the
    verdict's own)."""
    sim = FunctionSimulator(toy)
    data = synthetic_dataset(sim, TRUTH, FIT + HELD, noise=0.02, compaction_points=4,
                             seeds=[1000 + k for k in range(5)], seed=0)
    res = close_loop(sim, data, {"E_b": BOUNDS["E_b"], "sigma_c": (3e6, 4e6)}, {"E_b": 70e6, "sigma_c": 3.5e6},
                     held_out=lambda c: c in HELD, library=LIBRARY, max_effects=0)
    assert sum("sigma_c = " in line and "at the upper end of its box" in line for line in res.log) == 4, \
        "\n".join(res.log)
    assert "sigma_c = " in res.verdict and "is at the upper end of its box" in res.verdict
    first = 4e6 * (4 / 3) ** 0.5
    assert res.baseline.space.axes[1].hi == pytest.approx(first * (first / 3e6) ** 0.5)


def test_each_gate_refuses_on_its_own():
    """A candidate passing every other gate is refused by the one it fails; the RRMSE gate
    refuses a candidate whose chi2 fell everywhere it was counted but whose relative error
    rose (a precise density fitted at the curves' cost)."""
    from pelletdem.loop_selection import Gates, judge

    g = Gates(threshold=10.0, n_check=40, n_held=13, min_check_gain=0.25)
    before = (120.0, 30.0, 0.15)          # chi2 all, chi2 held out, RRMSE on fresh packings
    good = (60.0, 20.0, 0.08)
    ok, why = judge(g, 25.0, before, good)
    assert ok and "120.0 -> 60.0" in why and "held out 30.0 -> 20.0" in why and "RRMSE 0.150 -> 0.080" in why
    # the fit test: one chi2 unit short of the threshold
    ok, why = judge(g, 9.0, before, good)
    assert not ok and "below the threshold 10.0" in why
    # fresh packings: needs max(4, 0.25 * (120 - 40)) = 20; a fall of 19 is not enough
    ok, why = judge(g, 25.0, before, (101.0, 20.0, 0.08))
    assert not ok and "needed to fall by 20.0" in why
    # held out: a rise beyond 2 sqrt(2 * 13) = 10.2 is refused, one of 10 is not
    ok, why = judge(g, 25.0, before, (60.0, 40.3, 0.08))
    assert not ok and "does not carry over" in why
    assert judge(g, 25.0, before, (60.0, 40.0, 0.08))[0]
    # RRMSE: every chi2 gate passed, relative error up; with no scatter any rise is refused,
    # with the rise's scatter between packings only one beyond twice it
    ok, why = judge(g, 25.0, before, (60.0, 20.0, 0.151))
    assert not ok and "RRMSE on fresh packings rose 0.150 -> 0.151" in why
    assert judge(g, 25.0, before, (60.0, 20.0, 0.159), rrmse_se=0.005)[0]
    ok, why = judge(g, 25.0, before, (60.0, 20.0, 0.161), rrmse_se=0.005)
    assert not ok and "twice its scatter between packings (0.005)" in why
    # fresh packings' scatter: a fall of 60 is refused where its scatter is 60, not below
    ok, why = judge(g, 25.0, before, good, chi2_se=60.0)
    assert not ok and "within its scatter between packings (60.0)" in why
    ok, why = judge(g, 25.0, before, good, chi2_se=59.9)
    assert ok and "120.0 -> 60.0 (its fall's scatter 59.9)" in why
    # without held-out conditions the held-out gate does not apply
    g0 = Gates(threshold=10.0, n_check=27, n_held=0, min_check_gain=0.25)
    ok, why = judge(g0, 25.0, (120.0, 0.0, 0.15), (60.0, 0.0, 0.08))
    assert ok and "held out" not in why


def test_the_candidate_added_is_the_best_on_fresh_packings():
    """Between accepted candidates the fresh packings decide; one the emulated fit preferred,
    or one within a chi2 of 2 there, is named beside it; a clear winner on both has none."""
    from pelletdem.effects import EFFECTS
    from pelletdem.loop_selection import Trial, pick

    def trial(name, drop, after):
        return Trial(EFFECTS[name], None, drop, 77.0, after, True, "")

    # in-sample the saturating law fitted better (46.2 against 40.0); on fresh packings the
    # growing one did (22.3 against 26.1)
    added, rivals = pick([trial("saturating_unloading", 46.2, 26.1), trial("unloading_growth", 40.0, 22.3)])
    assert added.effect.name == "unloading_growth" and rivals == ["saturating_unloading"]
    # better on both: no rival
    added, rivals = pick([trial("saturating_unloading", 30.0, 26.1), trial("unloading_growth", 40.0, 22.3)])
    assert added.effect.name == "unloading_growth" and rivals == []
    # within 2 on fresh packings: a rival whichever the fit preferred
    added, rivals = pick([trial("hardening", 30.0, 23.9), trial("unloading_growth", 40.0, 22.3)])
    assert added.effect.name == "unloading_growth" and rivals == ["hardening"]
    assert pick([]) == (None, [])
    # better on both by 3.8, but the two models' difference scatters by 2 between packings
    # (each checked on its own pellets): within twice that, a rival; with 1.8, not
    better = [trial("saturating_unloading", 30.0, 26.1), trial("unloading_growth", 40.0, 22.3)]
    assert pick(better, lambda a, b: 2.0)[1] == ["saturating_unloading"]
    assert pick(better, lambda a, b: 1.8)[1] == []


def test_the_rrmse_rise_scatter_is_a_jackknife_over_the_check_packings():
    """The same model checked twice rises by 0 with scatter 0; another model's rise has the
    jackknife's scatter, worked here by hand from the leave-one-out RRMSEs."""
    from types import SimpleNamespace

    from pelletdem.loop_check import rrmse_all, rrmse_rise_se, without_packing

    sim = FunctionSimulator(toy)
    data = synthetic_dataset(sim, TRUTH, FIT + HELD, noise=0.02, compaction_points=4,
                             seeds=[1000 + k for k in range(5)], seed=0)
    fit_data, held = data.split(lambda c: c in HELD)
    seeds = (100, 101, 102, 103)
    a = SimpleNamespace(check=sim.predict(START, FIT + HELD, seeds))
    b = SimpleNamespace(check=sim.predict(TRUTH, FIT + HELD, seeds))
    assert rrmse_rise_se(a, a, fit_data, held) == 0.0
    d = np.array([rrmse_all(without_packing(b.check, j), fit_data, held)
                  - rrmse_all(without_packing(a.check, j), fit_data, held) for j in range(4)])
    se = rrmse_rise_se(a, b, fit_data, held)
    assert se > 0 and se == pytest.approx(math.sqrt(3 / 4 * np.sum((d - d.mean()) ** 2)), rel=1e-12)
    # fewer than three packings: no tolerance
    two = SimpleNamespace(check=sim.predict(TRUTH, FIT + HELD, seeds[:2]))
    assert rrmse_rise_se(two, two, fit_data, held) == 0.0


def test_the_rrmse_rise_scatter_of_one_observation_is_the_standard_error_of_a_mean():
    """One observation predicted above its measured value on every packing: RRMSE is (mean -
    v) / v, linear in the packings' mean, and the jackknife of a mean is exactly the standard
    error of the mean, SD(b - a) / sqrt(k) / v, with b - a the packings' paired rises."""
    from types import SimpleNamespace

    from pelletdem.loop import Condition, Dataset, Observation
    from pelletdem.loop_check import rrmse_rise_se
    from pelletdem.loop_simulators import Ensemble

    cond = Condition(60e6)
    v = 1.0e6
    data = Dataset([Observation(cond, "sigma_f", float("nan"), v, 0.05e6, 5)])
    a = np.array([1.30e6, 1.10e6, 1.25e6, 1.40e6, 1.15e6])
    b = np.array([1.50e6, 1.20e6, 1.60e6, 1.45e6, 1.35e6])

    def model(values):
        members = tuple(Prediction(scalars={"sigma_f": float(x)}) for x in values)
        return SimpleNamespace(check={cond: Ensemble(tuple(range(len(values))), members)})

    rise = b - a
    expected = rise.std(ddof=1) / math.sqrt(len(rise)) / v
    assert rrmse_rise_se(model(a), model(b), data, None) == pytest.approx(expected, rel=1e-12)
    # a rise common to every packing has no scatter: the data's noise is shared by both models
    assert rrmse_rise_se(model(a), model(a + 0.2e6), data, None) == pytest.approx(0.0, abs=1e-12)


def test_new_pellets_make_the_fresh_chi2_scatter_more_than_the_same_pellets_do():
    """The jackknife of the fresh packings' chi2: an effect of the diametral test keeps the
    baseline's pellets and its change scatters little between packings; a compaction effect
    of the same size on the data makes new pellets (the toy re-draws its packings, as the DEM
    does), and its change scatters with them."""
    from types import SimpleNamespace

    from pelletdem.loop_check import check_chi2_se, without_packing
    from pelletdem.loop_models import chi2_of, ensemble_z

    sim = FunctionSimulator(toy)
    data = synthetic_dataset(sim, TRUTH, FIT + HELD, noise=0.02, compaction_points=4,
                             seeds=[1000 + k for k in range(5)], seed=0)
    fit_data, held = data.split(lambda c: c in HELD)
    seeds = tuple(100 + k for k in range(6))

    def model(extra):
        return SimpleNamespace(check=sim.predict({**TRUTH, **extra}, FIT + HELD, seeds))

    base = model({})
    same = model(LIBRARY["toe"].settings(0.05))
    new = model(LIBRARY["springback"].settings(0.1))
    assert check_chi2_se(base, base, fit_data, held) == 0.0
    paired, unpaired = check_chi2_se(base, same, fit_data, held), check_chi2_se(base, new, fit_data, held)
    assert 0 < paired < unpaired / 3, (paired, unpaired)

    def chi2(check):
        return chi2_of(ensemble_z(check, fit_data)) + chi2_of(ensemble_z(check, held))

    d = np.array([chi2(without_packing(new.check, j)) - chi2(without_packing(base.check, j)) for j in range(6)])
    assert unpaired == pytest.approx(math.sqrt(5 / 6 * np.sum((d - d.mean()) ** 2)), rel=1e-12)


def test_an_inconclusive_check_is_extended_to_as_many_packings_again():
    """The extra packings follow the check packings and skip any fit or check packing; the
    model checked on them keeps its first packings' predictions and adds the new ones."""
    import dataclasses
    from types import SimpleNamespace

    from pelletdem.loop_models import ensemble_z, with_more_check_packings
    from pelletdem.loop_selection import _more_check_seeds

    @dataclasses.dataclass
    class Fitted:  # the fields of a ModelFit that with_more_check_packings reads and replaces
        check: dict
        fit: object
        z_check_fit: object = None
        z_check_held: object = None

    assert _more_check_seeds((0, 1, 2, 3), (100, 101, 102, 103)) == (104, 105, 106, 107)
    assert _more_check_seeds((5, 7), (4, 6)) == (8, 9)
    sim = FunctionSimulator(toy)
    data = synthetic_dataset(sim, TRUTH, FIT + HELD, noise=0.02, compaction_points=4,
                             seeds=[1000 + k for k in range(5)], seed=0)
    fit_data, held = data.split(lambda c: c in HELD)
    first = Fitted(sim.predict(TRUTH, FIT + HELD, (100, 101, 102, 103)), SimpleNamespace(params=dict(TRUTH)))
    more = with_more_check_packings(sim, first, (104, 105, 106, 107), fit_data, held)
    whole = sim.predict(TRUTH, FIT + HELD, tuple(range(100, 108)))
    o = fit_data.observations[0]
    for c in FIT + HELD:
        assert more.check[c].seeds == tuple(range(100, 108))
        assert np.array_equal(more.check[c].values(o), whole[c].values(o))
    np.testing.assert_array_equal(more.z_check_fit, ensemble_z(whole, fit_data))
    np.testing.assert_array_equal(more.z_check_held, ensemble_z(whole, held))
