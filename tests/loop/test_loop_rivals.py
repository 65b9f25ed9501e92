"""Candidates that fit as well on the check packings are checked again on as many more, and
the lower chi2 there decides."""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, Optional

import numpy as np

from pelletdem.loop import Condition, Dataset, FunctionSimulator, Prediction
from pelletdem.loop_check import check_chi2
from pelletdem.loop_data import Observation
from pelletdem.loop_models import ensemble_z
from pelletdem.loop_selection import Trial, _rivals_on_more_packings, pick

COND = Condition(120e6)
DATA = Dataset([Observation(COND, "sigma_f", math.nan, 1.0e6, 5e4, 5),
                Observation(COND, "bulk_density", math.nan, 600.0, 5.0, 5)])
CHECK, MORE = (10, 11, 12, 13), (14, 15, 16, 17)
# each law's sigma_f offset from the truth (Pa) on each packing: on the first four the true
# law "a" had bad luck and the biased law "b" (4e4 Pa off) good luck; on the next four neither
LUCK = {"a": dict(zip(CHECK + MORE, (2.9e4, 3.1e4, 3.0e4, 3.0e4, -3.0e4, -2.9e4, -3.1e4, -3.0e4))),
        "b": dict(zip(CHECK + MORE, (0.1e4, -0.1e4, 0.0, 0.0, 4.1e4, 3.9e4, 4.0e4, 4.0e4)))}


def _pellet(params, cond, seed):
    law = "a" if params["law"] == 0 else "b"
    return Prediction(scalars={"sigma_f": 1.0e6 + LUCK[law][seed], "bulk_density": 600.0 + 0.1 * (seed % 3)})


@dataclass
class _Fitted:  # the parts of a ModelFit the rivals' check reads
    fit: Any
    check: dict
    z_check_fit: np.ndarray
    z_check_held: Optional[np.ndarray]


def _trial(sim, name, law):
    check = sim.predict({"law": law}, [COND], CHECK)
    model = _Fitted(SimpleNamespace(params={"law": law}), check, ensemble_z(check, DATA), None)
    return Trial(SimpleNamespace(name=name), model, 20.0, 60.0, check_chi2(model), True, "accepted")


def test_a_tie_on_the_check_packings_is_decided_on_more():
    sim = FunctionSimulator(_pellet, default_seeds=CHECK)
    a, b = _trial(sim, "a", 0), _trial(sim, "b", 1)
    first, rivals = pick([a, b])
    assert first is b and rivals == ["a"]  # the biased law looks better on the lucky packings
    lines = []
    added, rivals, seps, notes = _rivals_on_more_packings(sim, [b, a], MORE, DATA, None, lines.append)
    assert added is a  # as fitted and checked before: the next round compares like with like
    assert len(next(iter(added.model.check.values())).seeds) == 4
    assert notes == lines and "checked again on 8 packings" in notes[0] and notes[0].endswith("a is the lower")
    # b trails a by less than 2 on 8 packings: still named beside it, with how far apart they are
    assert rivals == ["b"] and set(seps) == {"b"} and seps["b"] > 0
    assert "a and b predict" in notes[1] and "on the 8 fresh packings that decided" in notes[1]
