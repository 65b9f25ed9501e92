"""Measured data for the loop: conditions, observations, datasets (pelletdem.loop_data)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pelletdem.loop import DIAMETRAL_GRID, Condition, Dataset, Observation


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


def test_standard_error_and_degrees_of_freedom_follow_the_replicates():
    c = Condition(60e6)
    d = Dataset([Observation(c, "sigma_f", math.nan, 1e6, 1e5, n=4), Observation(c, "dLf_D", math.nan, 0.1, 0.01, n=1)])
    assert d.standard_errors[0] == pytest.approx(1e5 / 2)
    assert d.standard_errors[1] == pytest.approx(0.01)
    assert list(d.dofs) == [3.0, 1.0]


def test_split_keeps_the_held_out_conditions_apart():
    obs = [Observation(Condition(s), "sigma_f", math.nan, 1e6, 1e5, 5) for s in (60e6, 90e6, 120e6)]
    fit, held = Dataset(obs).split(lambda c: c.sigma_z == 90e6)
    assert [c.sigma_z for c in fit.conditions] == [60e6, 120e6] and [c.sigma_z for c in held.conditions] == [90e6]
    fit, held = Dataset(obs).split(lambda c: False)
    assert held is None and len(fit) == 3
    with pytest.raises(ValueError, match="held out"):
        Dataset(obs).split(lambda c: True)


def test_conditions_pressed_from_the_same_packings_stay_grouped_in_their_parts():
    c60, c90, c120 = (Condition(s) for s in (60e6, 90e6, 120e6))
    obs = [Observation(c, "sigma_f", math.nan, 1e6, 1e5, 5) for c in (c60, c90, c120)]
    d = Dataset(obs, same_packings=((c60, c90, c120),))
    assert d.packings_shared(c60, c120) and not Dataset(obs).packings_shared(c60, c120)
    assert Dataset(obs).packings_shared(c60, c60)
    fit, held = d.split(lambda c: c == c90)
    assert fit.same_packings == ((c60, c120),) and held.same_packings == ()
    assert d.subset(lambda o: o.condition == c60).same_packings == ()
    with pytest.raises(ValueError, match="more than one group"):
        Dataset(obs, same_packings=((c60, c90), (c90, c120)))
    with pytest.raises(ValueError, match="same_packings: each group"):
        Dataset(obs, same_packings=("60 MPa",))


def test_paper_dataset_has_every_variant():
    d = Dataset.from_paper()
    assert len(d.conditions) == 12
    assert len(d) == 36
    oak = [o for o in d.observations if o.condition == Condition(120e6, 8.0, "oak") and o.quantity == "sigma_f"]
    assert oak[0].value == pytest.approx(1.346e6) and oak[0].sd == pytest.approx(0.068e6)
    with pytest.raises(ValueError, match="material"):
        Dataset.from_paper(materials=["teak"])


def _curve(scales, x_f=0.06, top=0.15):
    from pelletdem.measured import Curve

    x = np.linspace(0, top, 300)
    reps = [(x, s * 1e5 * (x / x_f) * np.exp(1 - x / x_f), str(k)) for k, s in enumerate(scales)]
    return Curve(np.concatenate([r[0] for r in reps]), np.concatenate([r[1] for r in reps]),
                 np.concatenate([[r[2]] * len(x) for r in reps]))


def test_dataset_from_curves_samples_the_grid_from_the_toe_past_the_peak():
    d = Dataset.from_curves({Condition(60e6): _curve((1.0, 1.05, 0.95))})
    pts = [o for o in d.observations if o.quantity == "sigma_1"]
    xs = np.array([o.x for o in pts])
    assert np.allclose(xs / 0.06, DIAMETRAL_GRID, rtol=0.02)
    # no point near dL/D = 0 where sigma_1 is tiny and its relative error meaningless
    assert min(o.value for o in pts) > 0.3 * max(o.value for o in pts)
    assert {o.part for o in pts} == {"toe", "rise", "peak", "post-peak"}
    sf = [o for o in d.observations if o.quantity == "sigma_f"][0]
    assert sf.value == pytest.approx(1e5, rel=0.01) and sf.sd == pytest.approx(5e3, rel=0.05) and sf.n == 3


def test_dataset_from_curves_refuses_curves_without_a_peak():
    with pytest.raises(ValueError, match="no peak"):
        Dataset.from_curves({Condition(60e6): _curve((1.0, 1.1), x_f=0.06, top=0.02)})
    with pytest.raises(ValueError, match="points"):
        Dataset.from_curves({Condition(60e6): _curve((1.0, 1.1))}, points=1)
