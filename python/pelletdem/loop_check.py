"""The models' errors on fresh packings (the check seeds): chi2 and RRMSE (eq. 16) of all the
data, and the scatter of a change of either between the check packings (a jackknife), which
tells a gain from the packings' luck."""
from __future__ import annotations

import math
from typing import Callable, Dict, Mapping, Optional

import numpy as np

from .loop_data import Condition, Dataset
from .loop_models import ModelFit, chi2_of, ensemble_z
from .loop_simulators import Ensemble

__all__ = ["model_errors", "rrmse_all", "check_rrmse", "without_packing", "jackknife_se", "rrmse_rise_se",
           "check_chi2_se", "check_chi2", "held_chi2"]


def _rrmse(ensembles, data: Optional[Dataset]) -> float:
    # eq. 16 over data's observations against the ensembles' means; nan without data
    if data is None:
        return math.nan
    rel = []
    for o in data.observations:
        m, _ = ensembles[o.condition].mean_se(o)
        rel.append((m - o.value) / o.value if o.value else math.nan)
    rel = np.asarray(rel, float)
    return float(np.sqrt(np.nanmean(rel ** 2)))


def model_errors(mf: ModelFit, fit_data: Dataset, heldout: Optional[Dataset]) -> Dict[str, float]:
    """The errors the report tabulates, on the check seeds: chi2 per point (-) and RRMSE (-,
    eq. 16) of the fit and of the held-out data (nan without held-out data)."""
    n_h = len(heldout) if heldout is not None else 0
    return {"fit_chi2_per_point": chi2_of(mf.z_check_fit) / len(fit_data),
            "fit_rrmse": _rrmse(mf.check, fit_data),
            "heldout_chi2_per_point": chi2_of(mf.z_check_held) / n_h if n_h else math.nan,
            "heldout_rrmse": _rrmse(mf.check, heldout)}


def rrmse_all(check: Mapping[Condition, Ensemble], fit_data: Dataset, heldout: Optional[Dataset]) -> float:
    """RRMSE (-, eq. 16) of the fit and held-out data together, under the ensembles ``check``."""
    n_f, n_h = len(fit_data), len(heldout) if heldout is not None else 0
    sq = n_f * _rrmse(check, fit_data) ** 2 + (n_h * _rrmse(check, heldout) ** 2 if n_h else 0.0)
    return math.sqrt(sq / (n_f + n_h))


def check_rrmse(mf: ModelFit, fit_data: Dataset, heldout: Optional[Dataset]) -> float:
    """RRMSE (eq. 16) of all the data (fit and held-out conditions) on the check seeds."""
    return rrmse_all(mf.check, fit_data, heldout)


def without_packing(check: Mapping[Condition, Ensemble], j: int) -> Dict[Condition, Ensemble]:
    """The ensembles ``check`` without their ``j``-th packing."""
    return {c: Ensemble(e.seeds[:j] + e.seeds[j + 1:], e.members[:j] + e.members[j + 1:]) for c, e in check.items()}


def jackknife_se(before: ModelFit, after: ModelFit, stat: Callable[[Mapping[Condition, Ensemble]], float]) -> float:
    """Standard error of stat(after) - stat(before) over the check packings: the jackknife,
    leaving each packing out of both models' means in turn. It measures the packings' part of
    the difference, not the data's noise, which the two models share; where both models have
    the same pellets (an effect of the diametral test) their packings' scatter cancels in
    part, where a compaction effect made new pellets it does not. 0 with fewer than three
    packings (no tolerance)."""
    k = min(len(e.members) for e in (*before.check.values(), *after.check.values()))
    if k < 3:
        return 0.0
    d = np.array([stat(without_packing(after.check, j)) - stat(without_packing(before.check, j)) for j in range(k)])
    d = d[np.isfinite(d)]
    if len(d) < 3:
        return 0.0
    return float(math.sqrt((len(d) - 1) / len(d) * np.sum((d - d.mean()) ** 2)))


def rrmse_rise_se(before: ModelFit, after: ModelFit, fit_data: Dataset, heldout: Optional[Dataset]) -> float:
    """Standard error (-) of the rise of the check packings' RRMSE (eq. 16, all the data) from
    ``before`` to ``after`` (both checked on the same packing seeds): :func:`jackknife_se`."""
    return jackknife_se(before, after, lambda check: rrmse_all(check, fit_data, heldout))


def check_chi2_se(before: ModelFit, after: ModelFit, fit_data: Dataset, heldout: Optional[Dataset]) -> float:
    """Standard error (-) of the change of the check packings' chi2 (all the data) from
    ``before`` to ``after``: :func:`jackknife_se`. A compaction effect checked on new pellets
    can lower that chi2 by luck of the packings; this says by how much."""
    def chi2(check):
        held = chi2_of(ensemble_z(check, heldout)) if heldout is not None else 0.0
        return chi2_of(ensemble_z(check, fit_data)) + held

    return jackknife_se(before, after, chi2)


def check_chi2(mf: ModelFit) -> float:
    """chi2 of all the data on the check seeds."""
    held = chi2_of(mf.z_check_held) if mf.z_check_held is not None else 0.0
    return chi2_of(mf.z_check_fit) + held


def held_chi2(mf: ModelFit) -> float:
    """chi2 of the held-out data on the check seeds (0 without held-out data)."""
    return chi2_of(mf.z_check_held) if mf.z_check_held is not None else 0.0
