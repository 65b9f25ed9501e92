"""How well a data set can tell two fitted models apart.

Two candidates that both pass every gate (for example two laws of the unloading stiffness)
are told apart by which of them lies nearer the measured means. Let the two models' means
differ by Delta_i at observation i, whose measured mean has standard error s_i. Then

    D = sum_i Delta_i^2 / s_i^2

is the chi2 (in the data's standard errors) that separates them. If one of them is the truth,
the other's chi2 exceeds it by D - 2 sum_i Delta_i eta_i / s_i^2 for measurement errors eta_i:
on average D, with a standard deviation 2 sqrt(D). So the data name the right one of the two
with probability Phi(sqrt(D) / 2), and since D grows in proportion to the replicates (s_i^2
falls as 1/n), n D* / D replicates name it with probability 0.95, D* = (2 z_0.95)^2 = 10.8.

Delta_i is estimated from the two models' predictions on the same fresh packings: the mean of
the paired differences, less its own variance (the packings' noise would otherwise add to D).

D is between the two fitted models. Each fit carries its own packings' luck, so neither need
be the truth: where D is large and the two still tie on fresh packings, the fits, not the
data's noise, tie them, and more replicates would not help.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from .loop_data import Dataset
from .loop_simulators import Ensemble

__all__ = ["SURE", "separation", "chance_right", "replicates_factor", "statement"]

#: D at which the data name the right one of two models 19 times in 20: (2 z_0.95)^2.
SURE = (2.0 * 1.6448536269514722) ** 2


def separation(a: Mapping, b: Mapping, data: Dataset) -> float:
    """D (-): the squared difference between the means of two models' ensembles
    ({Condition: Ensemble}, on the same packings where they share them) over the squared
    standard errors of ``data``'s means, summed over ``data``'s observations, each less the
    variance of its estimate (so unbiased, then floored at 0 in total). Observations either
    model failed to predict are left out."""
    total = 0.0
    for o, s in zip(data.observations, data.standard_errors):
        ea, eb = a[o.condition], b[o.condition]
        d, var = _difference(ea, eb, o)
        if math.isfinite(d) and math.isfinite(var) and s > 0:
            total += (d * d - var) / (s * s)
    return max(total, 0.0)


def _difference(ea: Ensemble, eb: Ensemble, o) -> tuple:
    """Mean difference of two ensembles at observation ``o`` and its variance: paired over the
    packings they share, unpaired otherwise."""
    va, vb = ea.values(o), eb.values(o)
    if tuple(ea.seeds) == tuple(eb.seeds) and len(va) > 1:
        diff = va - vb
        if not np.all(np.isfinite(diff)):
            return math.nan, math.nan
        return float(np.mean(diff)), float(np.var(diff, ddof=1) / len(diff))
    (ma, sa), (mb, sb) = ea.mean_se(o), eb.mean_se(o)
    return ma - mb, sa * sa + sb * sb


def chance_right(d: float) -> float:
    """Probability (-) that data separating two models by ``d`` (:func:`separation`) name the
    right one, when one of them is the truth: Phi(sqrt(d) / 2)."""
    return 0.5 * (1.0 + math.erf(math.sqrt(max(d, 0.0)) / 2.0 / math.sqrt(2.0)))


def replicates_factor(d: float) -> float:
    """How many times the data's replicates would name the right one of two models separated
    by ``d`` 19 times in 20 (:data:`SURE` / d: below 1 where these data already do; inf when
    d is 0)."""
    return SURE / d if d > 0 else math.inf


def statement(added: str, rival: str, d: float, k: int = 0, diff: float = math.nan,
              scatter: float = math.nan) -> str:
    """The report's sentence on two candidates that fit as well, separated by ``d``; with
    ``k`` > 0, also the chi2 by which the ``rival`` trails on the ``k`` fresh packings that
    decided (``diff``) and that difference's scatter between them (``scatter``)."""
    out = (f"{added} and {rival} predict {d:.1f} apart in chi2 (their mean predictions on the same fresh packings, "
           "in the data's standard errors, less the packings' noise)")
    if d <= 0:
        out += ": they predict the same here, and no number of replicates of these conditions would tell them apart"
    elif d < SURE:
        out += (f": even were one of them the truth, data like these would name it only {100 * chance_right(d):.0f} % "
                f"of the time, and x{_times(replicates_factor(d))} the replicates 19 times in 20")
    else:
        out += (": data like these could tell these two fitted models apart, so what ties them is how each was "
                "fitted (each fit carries its own packings' luck), not the data's noise")
    if k > 0:
        out += (f"; on the {k} fresh packings that decided, {rival}'s chi2 is {diff:.1f} above {added}'s, with a "
                f"scatter of {scatter:.1f} between the packings")
    return out


def _times(r: float) -> str:
    return f"{r:.0f}" if r >= 10 else f"{r:.2g}"
