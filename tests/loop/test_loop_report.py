"""The loop's report (pelletdem.loop_report): what it draws and writes."""
from __future__ import annotations

import dataclasses
import functools

from toy_pellet import BOUNDS, START, TRUTH, toy

from pelletdem.loop import Condition, FunctionSimulator, close_loop, synthetic_dataset


def _with_coordination(params, c, seed=0):
    # the toy pellet's coordination number grows with its density, as a relaxed pellet's does
    p = toy(params, c, seed)
    cn = 12.0 * p.scalars["bulk_density"] / 560.0
    return dataclasses.replace(p, scalars={**p.scalars, "coordination_number": cn})


@functools.lru_cache(maxsize=None)
def _loop(conditions, held):
    """The baseline alone on toy data of ``conditions`` (tuples), ``held`` held out; memoised."""
    conditions, held = list(conditions), list(held)
    sim = FunctionSimulator(_with_coordination)
    data = synthetic_dataset(sim, TRUTH, conditions + held, noise=0.02, compaction_points=4,
                             seeds=[1000 + k for k in range(5)], seed=0)
    return close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in held, max_effects=0)


def test_data_of_the_paper_s_variants_get_its_fig_10_with_the_relaxed_pellets(tmp_path):
    from pelletdem.loop_report import _paper_variants, write_report
    from pelletdem.paper_tables import variants

    fit = [Condition(60e6, 8, "oak"), Condition(120e6, 8, "oak")]
    held = [Condition(120e6, 20, "oak")]
    res = _loop(tuple(fit), tuple(held))
    paper = _paper_variants(res)
    oak = {(v.mc_percent, v.sigma_z): v for v in variants() if v.material == "oak"}
    assert paper == {c: oak[(c.mc, c.sigma_z)] for c in fit + held}
    text = open(write_report(res, str(tmp_path), "toy")).read()
    assert (tmp_path / "loop_coordination.png").stat().st_size > 0
    assert "![coordination](loop_coordination.png)" in text and "Fig. 10" in text


def test_conditions_that_are_not_the_paper_s_get_no_fig_10(tmp_path):
    from pelletdem.loop_report import _paper_variants, write_report

    res = _loop((Condition(60e6), Condition(120e6)), (Condition(90e6),))  # no material: not the paper's
    assert _paper_variants(res) == {}
    text = open(write_report(res, str(tmp_path), "toy")).read()
    assert not (tmp_path / "loop_coordination.png").exists() and "coordination" not in text


def test_the_errors_are_reported_by_quantity_and_the_relaxed_pellets_by_condition(tmp_path):
    """Each quantity's chi2/n is the mean of its observations' squared z-scores, its RRMSE eq.
    16 over them; the relaxed pellets' density and CN are the means over the fresh packings."""
    import math

    import numpy as np

    from pelletdem.loop_report import _by_quantity, _relaxed, write_report

    fit = [Condition(60e6, 8, "oak"), Condition(120e6, 8, "oak")]
    held = [Condition(120e6, 20, "oak")]
    res = _loop(tuple(fit), tuple(held))
    table = _by_quantity(res)
    data, z = res.fit_data, res.baseline.z_check_fit
    idx = [k for k, o in enumerate(data.observations) if o.quantity == "bulk_density"]
    pred = [res.baseline.check[data.observations[k].condition].mean_se(data.observations[k])[0] for k in idx]
    rel = [(p - data.observations[k].value) / data.observations[k].value for p, k in zip(pred, idx)]
    row = f"| bulk_density | fit | {len(idx)} | {np.mean(z[idx] ** 2):.2f} | {math.sqrt(np.mean(np.square(rel))):.3f} |"
    assert row in table
    assert {line.split(" | ")[0][2:] for line in table.splitlines()[2:]} == {o.quantity for o in data.observations}
    assert any(line.startswith("| sigma_f | held out |") for line in table.splitlines())
    relaxed = _relaxed(res)
    c = held[0]
    o = next(o for o in res.heldout_data.observations if o.quantity == "bulk_density")
    e = res.baseline.check[c]
    assert (f"| {c.label} | {o.value:.0f} +- {o.sd:.0f} | {e.scalar('bulk_density'):.0f} | "
            f"{e.scalar('coordination_number'):.2f} |") in relaxed
    text = open(write_report(res, str(tmp_path), "toy")).read()
    assert table in text and relaxed in text
