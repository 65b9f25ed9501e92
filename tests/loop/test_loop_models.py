"""Designs of the loop's models: what a failed design point leaves behind, and a fit that has not
settled when its refinement rounds run out."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pelletdem.loop import Condition, Dataset, FunctionSimulator, Prediction
from pelletdem.loop_box import Axis, Space
from pelletdem.loop_data import Observation
from pelletdem.loop_models import SETTLED, fit_model, simulate_design
from pelletdem.loop_report import model_summary, params_text

COND = Condition(120e6)
DATA = Dataset([Observation(COND, "sigma_f", float("nan"), 1.0e6, 5e4, 5),
                Observation(COND, "bulk_density", float("nan"), 600.0, 5.0, 5)])
SPACE = Space((Axis("E_b", 1e7, 1e9, True), Axis("sigma_c", 1e6, 1e8, True)))


def _pellet(params, cond, seed):
    if params["E_b"] > 5e8:
        return Prediction(ok=False, error="OverlapError: overlap / radius = 1.5 exceeds max_overlap_ratio")
    return Prediction(scalars={"sigma_f": 0.1 * params["sigma_c"] + 1e3 * seed,
                               "bulk_density": 600.0 + 1e-8 * params["E_b"] + seed})


def test_a_failed_design_point_is_left_blank_and_its_reason_kept():
    sim = FunctionSimulator(_pellet, default_seeds=(0, 1, 2))
    U = np.array([[0.2, 0.5], [0.9, 0.5]])  # E_b 2.5e7 and 6.3e8
    errors = []
    _, Y, SE, V = simulate_design(sim, SPACE, DATA, (0, 1, 2), U=U, errors=errors)
    assert np.all(np.isfinite(Y[0])) and np.all(np.isnan(Y[1])) and np.all(np.isnan(V[1]))
    assert len(errors) == 1 and errors[0].startswith("E_b = 6.31e+08") and "OverlapError" in errors[0]


def test_the_fit_says_why_its_design_points_failed():
    sim = FunctionSimulator(_pellet, default_seeds=(0, 1, 2))
    lines = []
    fit_model(sim, SPACE, (), DATA, None, (0, 1, 2), (10, 11, 12), n_design=12, log=lines.append, refine=0)
    failed = [s for s in lines if "design points (" in s]
    assert failed and " 0 failed" not in failed[0]
    why = [s for s in lines if "the first failed design point" in s]
    assert len(why) == 1 and "OverlapError" in why[0] and "E_b = " in why[0]


def test_a_fit_whose_every_point_failed_says_why():
    sim = FunctionSimulator(lambda p, c, s: Prediction(ok=False, error="OverlapError: at 120 MPa"), (0, 1))
    with pytest.raises(RuntimeError, match=r"every design point's simulation failed \(the first: E_b = .*OverlapError"):
        fit_model(sim, SPACE, (), DATA, None, (0, 1), (10, 11), n_design=6, refine=0)


def _wavy_pellet(params, cond, seed):
    # a response too wavy for a 4-point design's emulator to place the optimum at once
    x = math.log10(params["sigma_c"])
    return Prediction(scalars={"sigma_f": 1e6 * (1 + 4 * math.sin(3 * x) ** 2) * 10 ** (x - 7) + 1e3 * seed,
                               "bulk_density": 600.0 + 30 * math.sin(2 * math.log10(params["E_b"])) + seed})


def test_a_fit_still_moving_when_its_rounds_run_out_says_so():
    sim = FunctionSimulator(_wavy_pellet, default_seeds=(0, 1, 2))
    lines = []
    mf = fit_model(sim, SPACE, (), DATA, None, (0, 1, 2), (10, 11, 12), n_design=4, log=lines.append, refine=1)
    assert mf.last_move >= SETTLED and not mf.settled
    assert any("had not settled after 1 refinements" in s for s in lines)
    assert "not settled: the fit still moved" in params_text(mf)
    assert model_summary(mf)["settled"] is False
    # one more round on the same design settles it, and then nothing is said
    lines = []
    mf = fit_model(sim, SPACE, (), DATA, None, (0, 1, 2), (10, 11, 12), n_design=4, log=lines.append, refine=2)
    assert mf.last_move < SETTLED and mf.settled
    assert not any("had not settled" in s for s in lines) and "not settled" not in params_text(mf)


def test_a_fit_without_refinement_has_no_move_to_report():
    sim = FunctionSimulator(_wavy_pellet, default_seeds=(0, 1, 2))
    mf = fit_model(sim, SPACE, (), DATA, None, (0, 1, 2), (10, 11, 12), n_design=4, refine=0)
    assert math.isnan(mf.last_move) and mf.settled


# Two wells along a candidate's strength s (unit axis): the density's misfit is 0 at s = 0.2
# and 3 SE at s = 0.9 (chi2 9 above), with a barrier between; sigma_f pins E_b at any s.
TWO_WELLS = Space((Axis("E_b", 1e7, 1e9, True), Axis("s", 0.0, 1.0, False)))
CONDS = (Condition(60e6), Condition(120e6))
WELL_DATA = Dataset([Observation(c, q, float("nan"), v, se, 5) for c in CONDS
                     for q, v, se in (("sigma_f", 1.0e6, 2e4), ("bulk_density", 600.0, 5.0))])


def _two_wells(params, cond, seed):
    s, x = params["s"], math.log10(params["E_b"]) - 8.0  # x in [-1, 1]
    well = 10.0 * (s - 0.2) * (s - 0.9)
    return Prediction(scalars={"sigma_f": 1e6 * (1.0 + 0.3 * (x - 0.2 * s)) + 10.0 * seed,
                               "bulk_density": 600.0 + 5.0 * (3.0 * well ** 2 + 3.0 * (s - 0.2) / 0.7)
                               + 0.01 * seed})


def _stuck_first(monkeypatch):
    """fit_model's fits held to their start's own basin (no design-point starts): where a
    multistart lands when none of its design points lies in the better basin."""
    import pelletdem.loop_models as lm

    real = lm.fit_emulated
    monkeypatch.setattr(lm, "fit_emulated", lambda emu, data, start=None, starts=3, corr=None:
                        real(emu, data, start, starts=0, corr=corr))


def test_a_fit_the_profile_shows_to_be_a_local_minimum_is_fitted_again_from_the_profiles_best(monkeypatch):
    import pelletdem.loop_models as lm
    from pelletdem.loop_noise import PackingNoise

    _stuck_first(monkeypatch)
    sim = FunctionSimulator(_two_wells, default_seeds=(0, 1, 2))
    args = (sim, TWO_WELLS, ("toy",), WELL_DATA, None, (0, 1, 2), (10, 11, 12))
    kw = dict(start={"E_b": 1e8, "s": 0.9}, n_design=24, refine=2, noise=PackingNoise.independent())
    monkeypatch.setattr(lm, "ESCAPE_CHI2", math.inf)
    stuck = fit_model(*args, **kw).fit
    assert stuck.params["s"] > 0.8 and stuck.below_fit("s") > 5.0  # the profile sees the other well
    monkeypatch.setattr(lm, "ESCAPE_CHI2", 1.0)
    lines = []
    fit = fit_model(*args, log=lines.append, **kw).fit
    assert any("the fit was a local minimum; fitted again from there" in s for s in lines)
    assert abs(fit.params["s"] - 0.2) < 0.05 and fit.chi2 < stuck.chi2 - 5.0
    assert fit.below_fit("s") <= 1.0
    lo, hi = fit.interval("s")
    assert lo < 0.2 < hi and hi < 0.55  # the interval is the good well's, and holds its fit


def test_a_design_gives_every_material_the_same_bonds_and_each_output_its_own_axes():
    from pelletdem.loop_data import Condition, Dataset, Observation
    from pelletdem.loop_emulator import Axis, Space, design
    from pelletdem.loop_models import active_axes, effective_dim, tied_design

    space = Space((Axis("E_b[oak]", 1e8, 1e10), Axis("sigma_c[oak]", 5e6, 5e8), Axis("E_b[pine]", 1e8, 1e10),
                   Axis("sigma_c[pine]", 5e6, 5e8), Axis("k1", 1e4, 1e5)))
    U = tied_design(space, 18)
    assert np.array_equal(U[:, 0], U[:, 2]) and np.array_equal(U[:, 1], U[:, 3])
    assert np.array_equal(U[:, [0, 1, 4]], design(3, 18))  # each material's box as if alone
    assert effective_dim(space) == 3
    oak, pine = Condition(60e6, 8.0, "oak"), Condition(60e6, 8.0, "pine")
    data = Dataset([Observation(oak, "sigma_f", float("nan"), 1e6, 1e5, 5),
                    Observation(pine, "sigma_f", float("nan"), 1e6, 1e5, 5)])
    assert active_axes(space, data) == [(0, 1, 4), (2, 3, 4)]
    # one material (no per-material names): the plain design, every axis active
    one = Space((Axis("E_b", 1e8, 1e10), Axis("sigma_c", 5e6, 5e8)))
    assert np.array_equal(tied_design(one, 12), design(2, 12)) and effective_dim(one) == 2
    assert active_axes(one, data) == [(0, 1), (0, 1)]
