"""Contact-law rows fitted beside k1 in the compaction fit (:func:`pelletdem.search.fit`):
a yield effect's strength, positive or negative (log space of its magnitude), given back by
a stand-in pellet whose k1 follows the effect's law."""
from __future__ import annotations

import dataclasses
import math

import pytest

from pelletdem import calibrate as C
from test_calibrate import power_law_runner


def _yield_factor_problem(factor, off, truth, conditions):
    """A stand-in pellet whose k1 is k1 * factor(contact law) (k2 = 4 k1, the effect's row set to
    ``off`` before the power-law stand-in runs), and density targets at ``conditions`` (Targets
    keyword arguments, each at 60 and 120 MPa) made by it with the parameters ``truth``."""
    def runner(spec):
        c = spec.preset.contact
        k1 = c.k1 * factor(c)
        return power_law_runner(dataclasses.replace(spec, preset=spec.preset.with_(
            contact=dataclasses.replace(c, k1=k1, k2=4 * k1, **off))))

    targets = []
    for cond in conditions:
        for sz in (60e6, 120e6):
            t = C.Targets(sigma_z=sz, bulk_density=1.0, bulk_density_sd=5.0, **cond)
            out = runner(C.make_spec(truth, sigma_z=sz, diametral=False, contact=t.condition_rows()))["outputs"]
            targets.append(dataclasses.replace(t, bulk_density=out["bulk_density_relaxed"]))
    return runner, targets


def test_a_contact_rows_strength_is_fitted_beside_k1():
    """A yield effect's strength fitted with k1: a pellet whose density follows the effect's
    law, k1 (rho_w / 680)^n, gives back k1 and n from the densities of two woods at two
    pressures."""
    runner, targets = _yield_factor_problem(
        lambda c: (c.wood_density / c.wood_density_reference) ** c.wood_density_yield, {"wood_density_yield": 0.0},
        {"k1": 5e4, "contact.wood_density_yield": 2.0}, [{"wood_density": 500.0}, {"wood_density": 700.0}])
    res = C.fit({"k1": (1e4, 2e5, 1e5), "contact.wood_density_yield": (0.3, 5.0, 1.0)}, targets, runner=runner,
                max_runs=20, tol=0.05)
    assert res.params["k1"] == pytest.approx(5e4, rel=0.05)
    assert res.params["contact.wood_density_yield"] == pytest.approx(2.0, rel=0.05)
    assert C.make_spec({"contact.wood_density_yield": 1.5}).preset.contact.wood_density_yield == 1.5
    with pytest.raises(ValueError, match="contact.no_such_row"):
        C.make_spec({"contact.no_such_row": 1.0})
    with pytest.raises(ValueError, match="contact.wood_density_yield"):
        C.fit({"contact.wood_density_yield": (-1.0, 2.0)}, targets, runner=runner)


def test_a_negative_strength_is_fitted_in_log_space_of_its_magnitude():
    """moisture_yield's c < 0 (wetter pellets looser) fitted beside k1, its bounds both negative:
    a pellet whose k1 follows k1 exp(-c (MC - 8)) gives back k1 and c = -0.04 from wet and dry
    densities at two pressures; bounds that straddle zero are refused, naming the row."""
    runner, targets = _yield_factor_problem(
        lambda c: math.exp(-c.moisture_yield * (c.moisture_content - c.moisture_reference)), {"moisture_yield": 0.0},
        {"k1": 5e4, "contact.moisture_yield": -0.04}, [{"mc_percent": 8.0}, {"mc_percent": 20.0}])
    res = C.fit({"k1": (1e4, 2e5, 1e5), "contact.moisture_yield": (-0.2, -0.005)}, targets, runner=runner,
                max_runs=20, tol=0.05)
    assert res.params["k1"] == pytest.approx(5e4, rel=0.05)
    assert res.params["contact.moisture_yield"] == pytest.approx(-0.04, rel=0.05)
    assert (res.history["contact.moisture_yield"] < 0).all()
    with pytest.raises(ValueError, match="contact.moisture_yield.*both < 0"):
        C.fit({"contact.moisture_yield": (-0.1, 0.1)}, targets, runner=runner)
    with pytest.raises(ValueError, match="'k1'.*must both be > 0"):
        C.fit({"k1": (-1.0, -0.5)}, targets, runner=runner)
