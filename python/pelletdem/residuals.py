"""Describing a fit's residual: where it is, and whether it is structure or noise.

The residual of observation i is its z-score, z_i = (simulated_i - measured_i) / sd_i, with
sd_i the replicate SD of the measurement (floored at 1% of the value, as in
:mod:`pelletdem.metrics`). If the model explains the data up to replicate scatter the z_i are
independent with unit variance; three tests look for what noise cannot do:

* chi-square: sum z_i^2 against chi^2 with n - p degrees of freedom (p fitted parameters):
  a residual larger than the replicates' spread;
* runs (Wald-Wolfowitz) along each curve: too few sign changes of z along dL/D or dh/h0
  means the model misses a shape, not a level; the curves' run counts are pooled into one
  normal statistic; the pooled lag-1 autocorrelation is reported beside it;
* trends across conditions: the mean z of each condition regressed on compaction pressure
  and on moisture content (when there are at least three conditions and two levels), and a
  one-way ANOVA of the conditions' mean z between materials.

The residual is called structured when any test's p-value falls below ``alpha`` divided by
the number of tests run (Bonferroni).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np
from scipy import stats

__all__ = ["ResidualSummary", "describe", "runs_test", "DEFAULT_ALPHA"]

#: Family-wise significance level of the structure tests.
DEFAULT_ALPHA = 0.01


@dataclass
class ResidualSummary:
    """What :func:`describe` found (z-scores are dimensionless).

    ``z``: per observation. ``by_part``: part -> (count, mean z, rms z). ``by_condition``:
    condition label -> (count, mean z, rms z). ``chi2``, ``dof``, ``p_chi2``; ``runs_z``,
    ``p_runs`` (None without curves), ``autocorr`` (pooled lag-1); ``trends``: variable ->
    (slope of mean z per unit, p-value); ``structured`` and ``reasons`` (which tests fired).
    """

    z: np.ndarray
    by_part: Dict[str, tuple]
    by_condition: Dict[str, tuple]
    chi2: float
    dof: int
    p_chi2: float
    runs_z: Optional[float]
    p_runs: Optional[float]
    autocorr: Optional[float]
    trends: Dict[str, tuple] = field(default_factory=dict)
    structured: bool = False
    reasons: List[str] = field(default_factory=list)

    @property
    def rms(self) -> float:
        """Root-mean-square z-score."""
        return float(np.sqrt(np.mean(self.z ** 2))) if len(self.z) else float("nan")

    def lines(self) -> List[str]:
        """A short human-readable account (for reports and the CLI)."""
        out = [f"rms z = {self.rms:.2f} over {len(self.z)} points; chi2 = {self.chi2:.1f} on {self.dof} dof "
               f"(p = {self.p_chi2:.2g})"]
        if self.p_runs is not None:
            out.append(f"runs test along the curves: z = {self.runs_z:.2f} (p = {self.p_runs:.2g}); "
                       f"lag-1 autocorrelation {self.autocorr:.2f}")
        for var, (slope, p) in self.trends.items():
            if var.startswith("group "):
                out.append(f"mean z differs between {var[6:]}s: F = {slope:.3g} (p = {p:.2g})")
            else:
                out.append(f"trend of mean z with {var}: {slope:+.3g} per unit (p = {p:.2g})")
        for part, (n, m, r) in self.by_part.items():
            out.append(f"  {part:>16}: {n:3d} points, mean z {m:+.2f}, rms z {r:.2f}")
        out.append("structured: " + ("yes (" + "; ".join(self.reasons) + ")" if self.structured else "no, "
                                     "consistent with the replicate scatter"))
        return out


def runs_test(signs: Sequence[float]) -> tuple:
    """Wald-Wolfowitz runs of a sign sequence: (runs R, expected E[R], variance Var[R]).

    Zeros are dropped. With n1 positive and n2 negative signs, E[R] = 1 + 2 n1 n2 / n and
    Var[R] = 2 n1 n2 (2 n1 n2 - n) / (n^2 (n - 1)). (nan, nan, nan) when one sign is absent.
    """
    s = np.sign(np.asarray(signs, float))
    s = s[s != 0]
    n1, n2 = int((s > 0).sum()), int((s < 0).sum())
    n = n1 + n2
    if n1 == 0 or n2 == 0 or n < 3:
        return float("nan"), float("nan"), float("nan")
    r = 1 + int((s[1:] != s[:-1]).sum())
    e = 1 + 2.0 * n1 * n2 / n
    var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n * n * (n - 1.0))
    return float(r), e, var


def _group_stats(z: np.ndarray, labels: Sequence[str]) -> Dict[str, tuple]:
    out = {}
    for lab in dict.fromkeys(labels):
        sel = np.array([x == lab for x in labels])
        zz = z[sel]
        out[lab] = (int(sel.sum()), float(zz.mean()), float(np.sqrt(np.mean(zz ** 2))))
    return out


def describe(z, *, parts: Sequence[str], conditions: Sequence[str], curves: Mapping[str, np.ndarray],
             levels: Optional[Mapping[str, Mapping[str, float]]] = None,
             groups: Optional[Mapping[str, Mapping[str, str]]] = None, n_params: int = 0,
             alpha: float = DEFAULT_ALPHA) -> ResidualSummary:
    """Summarise residual z-scores and test them for structure.

    ``z``: one z-score per observation; ``parts`` and ``conditions``: a label per observation
    (part of the curve, condition); ``curves``: curve name -> indices of its observations in
    the order of their x; ``levels``: variable (e.g. 'sigma_z [MPa]', 'mc [%]') -> condition
    label -> value, for the trend tests; ``groups``: categorical variable (e.g. 'material') ->
    condition label -> category, for a one-way ANOVA of the conditions' mean z between
    categories (reported in ``trends`` as (F statistic, p)); ``n_params``: fitted parameters
    (chi-square dof).
    """
    z = np.asarray(z, float)
    if z.ndim != 1 or len(z) != len(parts) or len(z) != len(conditions):
        raise ValueError("z, parts and conditions must have one entry per observation")
    if not np.all(np.isfinite(z)):
        raise ValueError("z must be finite (a simulation that failed cannot be described)")
    if not 0 < alpha < 1:
        raise ValueError(f"alpha = {alpha} must be in (0, 1)")
    n = len(z)
    dof = max(n - int(n_params), 1)
    chi2 = float(np.sum(z ** 2))
    p_chi2 = float(stats.chi2.sf(chi2, dof))
    tests = {"chi-square": p_chi2}

    # runs along each curve, pooled: sum (R - E) / sqrt(sum Var)
    dr, vr, num, den = 0.0, 0.0, 0.0, 0.0
    for idx in curves.values():
        idx = np.asarray(idx, int)
        if len(idx) < 4:
            continue
        r, e, var = runs_test(z[idx])
        if math.isfinite(r):
            dr += r - e
            vr += var
        else:  # one sign along the whole curve: as few runs as there can be
            dr += 1 - (1 + len(idx) / 2.0)
            vr += len(idx) / 4.0
        zc = z[idx] - z[idx].mean()
        num += float(np.sum(zc[1:] * zc[:-1]))
        den += float(np.sum(zc ** 2))
    runs_z = p_runs = autocorr = None
    if vr > 0:
        runs_z = dr / math.sqrt(vr)
        p_runs = float(stats.norm.cdf(runs_z))  # too few runs is the structure we look for
        autocorr = num / den if den > 0 else 0.0
        tests["runs"] = p_runs

    trends = {}
    by_cond = _group_stats(z, conditions)
    for var, lev in (levels or {}).items():
        labs = [c for c in by_cond if c in lev]
        xs = np.array([lev[c] for c in labs], float)
        if len(labs) < 3 or len(np.unique(xs)) < 2:
            continue
        ys = np.array([by_cond[c][1] for c in labs])
        res = stats.linregress(xs, ys)
        p = float(res.pvalue) if math.isfinite(res.pvalue) else 1.0
        trends[var] = (float(res.slope), p)
        tests[f"trend with {var}"] = p

    for var, cats in (groups or {}).items():
        by_cat: Dict[str, List[float]] = {}
        for c, (_, m, _) in by_cond.items():
            if c in cats:
                by_cat.setdefault(cats[c], []).append(m)
        if len(by_cat) < 2 or sum(len(v) for v in by_cat.values()) < len(by_cat) + 2:
            continue
        spread = [v for v in by_cat.values() if len(v) >= 1]
        res = stats.f_oneway(*spread)
        p = float(res.pvalue) if math.isfinite(res.pvalue) else 1.0
        trends["group " + var] = (float(res.statistic), p)
        tests[f"differences between {var}s"] = p

    limit = alpha / len(tests)
    reasons = [f"{name} p = {p:.2g} < {limit:.2g}" for name, p in tests.items() if p < limit]
    return ResidualSummary(z, _group_stats(z, parts), by_cond, chi2, dof, p_chi2, runs_z, p_runs, autocorr,
                           trends, bool(reasons), reasons)
