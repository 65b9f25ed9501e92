"""The discrepancy loop (pelletdem.loop).

Fast tests drive the loop's logic with an analytic pellet (a closed-form sigma_1(dL/D) with
three switchable effects): it must name a hidden effect it knows, add nothing to data with
no effect, and say "no candidate explains this residual" when the effect is outside its
library. The slow tests do the same with the C++ engine on the 'tiny' pellet (see docs/loop.md for the
measured margins).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pelletdem import loop
from pelletdem.effects import EFFECTS, Effect
from pelletdem.loop import Condition, Dataset, FunctionSimulator, Observation, Prediction
from pelletdem.loop_selection import profile_start

FIT = [Condition(60e6), Condition(120e6)]
HELD = [Condition(90e6)]

# An analytic pellet: peak S = 1e3 sigma_c (sigma_z / 120 MPa), failure at x_f = sigma_c / E_b,
# shape t exp(1 - t) up to t = x / x_f = 1, exp(-3 (t - 1)) after. Three effects switch on through law-style names.
TOY_LIBRARY = {e.name: e for e in (
    Effect("toe", "contact.plate_yield_stress", "Pa", 0.01, 1.0, 0.2, True, 0.0, "diametral",
           "toe shift", "stress too high at small dL/D"),
    Effect("tail", "bond.softening", "-", 0.05, 5.0, 0.5, True, 0.0, "diametral",
           "slow decline after the peak", "post-peak too low"),
    Effect("trend", "bond.overlap_radius_gain", "-", 0.05, 5.0, 0.5, True, 0.0, "diametral",
           "strength rises faster with pressure", "sigma_f trend with sigma_z"),
)}


def toy(params, c: Condition) -> Prediction:
    E, sc = params["E_b"], params["sigma_c"]
    shift = 0.02 * params.get("contact.plate_yield_stress", 0.0)
    tail = params.get("bond.softening", 0.0)
    gain = params.get("bond.overlap_radius_gain", 0.0)
    wiggle = params.get("bond.kt_ratio", 1.0) - 1.0  # outside the library
    x_f0 = sc / E
    S = 1e3 * sc * (c.sigma_z / 120e6) * (c.sigma_z / 90e6) ** gain
    x = np.linspace(0, 3 * x_f0 + shift, 400)
    t = np.maximum(x - shift, 0) / x_f0
    g = t * np.exp(1 - t)
    post = t > 1
    g[post] = np.exp(-3.0 * (t[post] - 1) / (1 + 2 * tail))  # brittle unless softened
    g = g * (1 + wiggle * np.sin(4 * np.pi * np.minimum(t, 1.0)) * (t < 1))
    y = S * g
    k = int(np.argmax(y))
    return Prediction(curve=(x, y), scalars={"sigma_f": float(y[k]), "dLf_D": float(x[k])})


TRUTH = {"E_b": 100e6, "sigma_c": 8e6}
START = {"E_b": 70e6, "sigma_c": 10e6}
BOUNDS = {"E_b": (1e6, 1e10), "sigma_c": (1e5, 1e9)}


def run_toy(extra, seed=1):
    sim = FunctionSimulator(toy)
    data = loop.synthetic_dataset(sim, {**TRUTH, **extra}, FIT + HELD, noise=0.02, points=14,
                                  quantities=("sigma_1", "sigma_f", "dLf_D"), seed=seed)
    return loop.close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD, library=TOY_LIBRARY,
                           fd_step=0.01, max_iter=10, refit_iter=10)


@pytest.mark.parametrize("name,extra", [("toe", {"contact.plate_yield_stress": 0.5}),
                                        ("tail", {"bond.softening": 1.0}),
                                        ("trend", {"bond.overlap_radius_gain": 1.0})])
def test_loop_names_the_hidden_effect(name, extra):
    res = run_toy(extra)
    assert res.residual_before.structured
    assert res.candidates[0].effect.name == name
    assert res.chosen == name, res.verdict
    before, after = res.errors["baseline"], res.errors[f"baseline + {name}"]
    assert after["heldout_chi2_per_point"] < 0.3 * before["heldout_chi2_per_point"]
    assert not res.residual_after.structured


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_loop_adds_nothing_without_an_effect(seed):
    res = run_toy({}, seed=seed)
    assert res.chosen is None
    assert not res.residual_before.structured
    assert "nothing to explain" in res.verdict


def test_loop_says_so_when_the_effect_is_outside_its_library():
    res = run_toy({"bond.kt_ratio": 1.3})
    assert res.residual_before.structured
    assert res.chosen is None
    assert res.verdict == "no candidate explains this residual"


def test_candidates_that_explain_equally_are_refitted_cheapest_first():
    # The same toe shift under two names: one said to act in compaction (new pellets per
    # strength), listed first, and one in the diametral test. Their signatures are identical,
    # so with one refit the cheaper, diametral one must be the one refitted.
    toe = TOY_LIBRARY["toe"]
    twin = dataclasses.replace(toe, name="toe_in_compaction", stage="compaction")
    sim = FunctionSimulator(toy)
    data = loop.synthetic_dataset(sim, {**TRUTH, "contact.plate_yield_stress": 0.5}, FIT + HELD,
                                  noise=0.02, points=14, quantities=("sigma_1", "sigma_f", "dLf_D"), seed=1)
    res = loop.close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD,
                          library={twin.name: twin, "toe": toe}, fd_step=0.01, max_iter=10,
                          refit_iter=10, refit_top=1)
    first, second = res.candidates[:2]
    assert round(first.explained, 2) == round(second.explained, 2) > 0.05
    assert first.effect.name == "toe" and first.fit is not None
    assert second.fit is None  # not refitted
    assert res.chosen == "toe", res.verdict


def test_loop_refuses_a_split_without_held_out_data():
    sim = FunctionSimulator(toy)
    data = loop.synthetic_dataset(sim, TRUTH, FIT, noise=0.02)
    with pytest.raises(ValueError, match="held_out"):
        loop.close_loop(sim, data, BOUNDS, START, library=TOY_LIBRARY)
    with pytest.raises(ValueError, match="held-out"):
        loop.close_loop(sim, data, BOUNDS, START, held_out=lambda c: False, library=TOY_LIBRARY)
    with pytest.raises(ValueError, match="min_heldout_gain"):
        loop.close_loop(sim, data, BOUNDS, START, held_out=lambda c: c == FIT[0], min_heldout_gain=2.0)


def test_fit_model_damps_its_step_until_chi2_falls():
    # sigma_f = 1 + 0.5 sin(3 ln(E_b / E_true)) MPa, from ln(E_b / E_true) = 0.45: the
    # Gauss-Newton step is -1.49 (clipped to -1), and the steps damped by up to 1.25 all land past
    # the dip, worse than the start; the fourth (1 / 2.25) is the first to improve. A fit that
    # gives up after three tries stays at the start (as it did on the paper's data).
    e_true = 50e6

    def model(params, c):
        u = math.log(params["E_b"] / e_true)
        return Prediction(scalars={"sigma_f": 1e6 * (1 + 0.5 * math.sin(3 * u))})

    data = Dataset([Observation(Condition(120e6), "sigma_f", math.nan, 1e6, 1e4, n=5)])
    fs = loop.fit_model(FunctionSimulator(model), data, {"E_b": (1e6, 1e10)},
                        {"E_b": e_true * math.exp(0.45)}, max_iter=20, fd_step=1e-4)
    assert fs.params["E_b"] == pytest.approx(e_true, rel=1e-3)


def test_profile_leaves_out_strengths_where_the_effect_never_acts():
    """A cap (like a plate yield stress) that no load reaches above p = 1: there every
    prediction is the baseline's. The data have no effect and the baseline is 20 % off its
    minimum, so an inactive strength plus the baseline's own Gauss-Newton step would score best;
    the profile must start the refit where the effect acts (p < 1), or the refit has no
    gradient in p. Fails when the inactive points are kept."""

    def model(params, c):
        a = max(0.0, 1.0 - params.get("contact.plate_yield_stress", 10.0)) * c.sigma_z / 120e6
        sc, e = params["sigma_c"], params["E_b"]
        return Prediction(scalars={"sigma_f": 1e3 * sc * (1 - 0.5 * a), "dLf_D": sc / e * (1 + 0.5 * a)})

    sim = FunctionSimulator(model)
    obs = []
    for c in FIT:
        pred = model(TRUTH, c)
        obs += [Observation(c, q, math.nan, v, 0.01 * v, n=5) for q, v in pred.scalars.items()]
    data = Dataset(obs)
    base = loop.fit_model(sim, data, BOUNDS, {"E_b": 1.2 * TRUTH["E_b"], "sigma_c": 0.8 * TRUTH["sigma_c"]},
                          max_iter=0)
    cap = Effect("cap", "contact.plate_yield_stress", "Pa", 0.01, 10.0, 0.2, True, 0.0, "diametral",
                 "a cap no load reaches above 1", "")
    st = profile_start(sim, data, base, cap, BOUNDS, 5.0, 5)
    assert st["contact.plate_yield_stress"] < 1.0


def test_fit_model_recovers_known_parameters():
    sim = FunctionSimulator(toy)
    data = loop.synthetic_dataset(sim, TRUTH, FIT, noise=0.01, points=14, quantities=("sigma_1", "sigma_f"))
    fs = loop.fit_model(sim, data, BOUNDS, START, max_iter=10)
    assert fs.params["E_b"] == pytest.approx(TRUTH["E_b"], rel=0.05)
    assert fs.params["sigma_c"] == pytest.approx(TRUTH["sigma_c"], rel=0.05)
    with pytest.raises(ValueError, match="outside its bounds"):
        loop.fit_model(sim, data, BOUNDS, {"E_b": 1.0, "sigma_c": 1e6})


def test_observation_and_condition_validation():
    with pytest.raises(ValueError, match="sigma_z"):
        Condition(float("nan"))
    with pytest.raises(ValueError, match="mc"):
        Condition(60e6, mc=-1)
    with pytest.raises(ValueError, match="quantity"):
        Observation(Condition(60e6), "strength", math.nan, 1.0, 0.1)
    with pytest.raises(ValueError, match="sd"):
        Observation(Condition(60e6), "sigma_f", math.nan, 1.0, -0.1)
    with pytest.raises(ValueError, match="finite x"):
        Observation(Condition(60e6), "sigma_1", math.nan, 1.0, 0.1)
    o = Observation(Condition(60e6), "sigma_f", math.nan, 1e6, 0.0)
    assert o.effective_sd == pytest.approx(1e4)  # floored at 1% of the value


def test_paper_dataset_has_every_variant():
    d = Dataset.from_paper()
    assert len(d.conditions) == 12
    assert len(d) == 36
    oak = [o for o in d.observations if o.condition == Condition(120e6, 8.0, "oak") and o.quantity == "sigma_f"]
    assert oak[0].value == pytest.approx(1.346e6) and oak[0].sd == pytest.approx(0.068e6)
    with pytest.raises(ValueError, match="material"):
        Dataset.from_paper(materials=["teak"])


def test_dataset_from_curves_labels_the_parts():
    from pelletdem.measured import Curve

    x = np.linspace(0, 0.15, 200)
    reps = []
    for k, s in enumerate((1.0, 1.05, 0.95)):
        reps.append((x, s * 1e5 * (x / 0.06) * np.exp(1 - x / 0.06), str(k)))
    curve = Curve(np.concatenate([r[0] for r in reps]), np.concatenate([r[1] for r in reps]),
                  np.concatenate([[r[2]] * len(x) for r in reps]))
    d = Dataset.from_curves({Condition(60e6): curve}, points=20)
    parts = {o.part for o in d.observations if o.quantity == "sigma_1"}
    assert parts == {"toe", "rise", "peak", "post-peak"}
    sf = [o for o in d.observations if o.quantity == "sigma_f"][0]
    assert sf.value == pytest.approx(1e5, rel=0.01) and sf.sd == pytest.approx(5e3, rel=0.05)


def test_shipped_library_has_at_least_five_effects_in_the_engine():
    import pelletdem as pd

    assert len(EFFECTS) >= 5
    for e in EFFECTS.values():
        law = pd.ContactLaw() if e.param.startswith("contact.") else pd.BondLaw()
        for k, v in e.settings(e.probe).items():
            setattr(law, k.split(".", 1)[1], v)
        law.to_core()  # every probe is a valid engine law


# --------------------------------------------------------------------------------------
# The engine (slow): hidden effects in 'tiny' pellets
# --------------------------------------------------------------------------------------

ENGINE_BOND = {"youngs_modulus": 30e6, "sigma_c": 9e6, "tau_c": 9e6}
ENGINE_BOUNDS = {"E_b": (1e6, 1e9), "sigma_c": (1e5, 1e8)}
ENGINE_START = {"E_b": 22e6, "sigma_c": 11e6}


def engine_loop(extra, tmp_path, held=(90e6,), fit=(60e6, 120e6)):
    """The configuration of `pelletdem loop --synthetic ...` (see docs/loop.md):
    sigma_1 at 14 points of each curve, 3 % noise on 5 replicates, start 30 % off the truth."""
    from pelletdem.engine import BondLaw

    conds = [Condition(s) for s in fit + held]
    with loop.EngineSimulator("tiny", bond=BondLaw(**ENGINE_BOND), max_dLD=0.15, executor=None, max_workers=2,
                              cache_dir=tmp_path / "cache") as sim:
        truth = {"E_b": ENGINE_BOND["youngs_modulus"], "sigma_c": ENGINE_BOND["sigma_c"], **extra}
        data = loop.synthetic_dataset(sim, truth, conds, noise=0.03, points=14, quantities=("sigma_1",), seed=5)
        return loop.close_loop(sim, data, ENGINE_BOUNDS, ENGINE_START, held_out=lambda c: c.sigma_z in held,
                               max_iter=4, refit_iter=5, refit_top=3)


# Measured 2026-12-02 (docs/loop.md): at the 'tiny' size the current build names
# plate_crushing (XPASS) but not the other two: the pellet's own jitter (6-7 % of sigma_1)
# exceeds the data's 3 % noise and the baseline absorbs much of an effect into E_b and sigma_c.
# Kept as expected failures (not strict), so that progress shows up as XPASS.
@pytest.mark.slow
@pytest.mark.xfail(reason="known: the tiny-size engine loop misses these hidden effects (docs/loop.md)", strict=False)
@pytest.mark.parametrize("name,extra", [("plate_crushing", {"contact.plate_yield_stress": 1.5e5}),
                                        ("overlap_bond_radius", {"bond.overlap_radius_gain": 5.0}),
                                        ("weibull_strength", {"bond.weibull_modulus": 2.0})])
def test_engine_loop_names_the_hidden_effect(name, extra, tmp_path):
    res = engine_loop(extra, tmp_path)
    assert res.chosen == name, res.verdict + "\n" + "\n".join(res.log)
    before, after = res.errors["baseline"], res.errors[f"baseline + {name}"]
    assert after["heldout_chi2_per_point"] < 0.5 * before["heldout_chi2_per_point"]


@pytest.mark.slow
def test_engine_loop_control_adds_nothing(tmp_path):
    res = engine_loop({}, tmp_path)
    assert res.chosen is None, res.verdict


@pytest.mark.slow
def test_engine_loop_outside_library_is_not_explained(tmp_path):
    res = engine_loop({"contact.mu": 0.1}, tmp_path)
    assert res.chosen is None, res.verdict


def test_report_is_written_with_its_figures(tmp_path):
    from pelletdem.loop_report import write_report

    res = run_toy({"bond.softening": 1.0})
    path = write_report(res, str(tmp_path / "rep"))
    text = open(path).read()
    assert "Error before and after" in text and res.verdict in text
    assert "baseline + tail" in text
    for png in ("loop_fit.png", "loop_residual.png", "loop_ranking.png"):
        assert (tmp_path / "rep" / png).stat().st_size > 1000


def test_loop_cli_rejects_bad_arguments_before_any_work():
    from pelletdem.loop_cli import _synthetic_truth

    assert _synthetic_truth("none") == {}
    assert _synthetic_truth("bond_softening=2") == {"bond.softening": 2.0}
    assert _synthetic_truth("hardening")["contact.hardening_exponent"] == 2.0
    assert _synthetic_truth("contact.mu=0.1") == {"contact.mu": 0.1}
    for bad in ("teleportation", "contact.mu", "x.y=1"):
        with pytest.raises(ValueError, match="--synthetic"):
            _synthetic_truth(bad)
