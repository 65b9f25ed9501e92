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
