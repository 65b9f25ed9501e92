"""Which candidate effect could explain the residual, and what these data could have revealed.

**Screening** (:func:`screen`). Each candidate is switched on at its probe strength on top of
the fitted model and simulated on the fit seeds, the same packings as the model's own
prediction there, so the difference d is the effect's signature, not packing luck. With the
residual r and d weighted by each observation's SD (data standard error and the model's own
in quadrature), and both made orthogonal to what the fitted parameters can already do (the
emulator's Jacobian), the effect at strength a d lowers chi2 by at most (r.d)^2 / |d|^2 (the
*gain*, to first order; an effect that only acts one way gains nothing where the residual asks
for the other). Candidates are ranked by gain; the best are fitted in full.

**Detection power** (:func:`detection_power`). Had the data carried the effect at strength s,
chi2 would drop by a noncentral chi-square of one degree of freedom with noncentrality
lambda(s) ~ |d_perp|^2 (x(s) / x(probe))^2, x the effect's size (its strength's distance from
off; 1 / strength for effects that grow as the strength falls, such as a Weibull modulus). The
strength at which the acceptance threshold is passed with probability 0.8 is what these data
can reveal; the replicates (or the model's packings) that would reveal the probe strength
follow from how lambda grows as the data's (or the model's) standard errors shrink. Where
the fitted parameters can do most of an effect's signature (:data:`ABSORBED_NOTE`), the
statement says which parameter: data that carry the effect may be fitted by moving that
parameter instead (a ductile bond read as a stronger one), and the linear bound is then
optimistic.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Mapping, Optional, Sequence

import numpy as np
from scipy import stats
from scipy.optimize import brentq

from .effects import Effect
from .loop_data import Dataset
from .loop_models import ModelFit, unit_jacobian
from .loop_simulators import Simulator

__all__ = ["Screen", "Power", "screen", "detection_power", "lambda_for_power", "ABSORBED_NOTE"]

#: A power statement says that the fitted parameters can mimic the effect where they can do
#: at least this fraction of its signature (first order, weighted).
ABSORBED_NOTE = 0.75


@dataclass
class Screen:
    """One candidate's screening: ``gain`` (first-order chi2 drop, -), ``strength`` (its
    first-order best strength, SI, clipped to the effect's bounds), ``lam_probe`` (|d_perp|^2:
    the chi2 drop the probe strength would give, -), ``d_perp`` (weighted signature orthogonal
    to the fitted parameters), ``absorbed`` (the fraction of the weighted signature's square
    that the fitted parameters can do as well, to first order, -) and ``absorber`` (the fitted
    parameter most aligned with it), ``skipped`` (why it was not screened, '' when it was)."""

    effect: Effect
    gain: float = 0.0
    strength: float = math.nan
    lam_probe: float = 0.0
    d_perp: Optional[np.ndarray] = None
    skipped: str = ""
    absorbed: float = 0.0
    absorber: str = ""


def _size(e: Effect, s: float) -> float:
    """The effect's size at strength s: distance from off, or 1/s when it grows as s falls."""
    if e.stronger == "lower":
        return 1.0 / s if s > 0 else math.inf
    return abs(s - e.off)


def _strength(e: Effect, x: float, sign: float = 1.0) -> float:
    """The strength of size x (inverse of :func:`_size`)."""
    if e.stronger == "lower":
        return 1.0 / x if x > 0 else math.inf
    return e.off + sign * x


def weights(mf: ModelFit, data: Dataset) -> np.ndarray:
    """Each observation's SD in the misfit (its unit): data SE and the model's SE in
    quadrature."""
    return np.sqrt(data.standard_errors ** 2 + mf.emulator.noise() ** 2)


def _perp(J: np.ndarray, v: np.ndarray) -> np.ndarray:
    if J.size == 0:
        return v
    q, _ = np.linalg.qr(J)
    return v - q @ (q.T @ v)


def screen(sim: Simulator, mf: ModelFit, candidates: Sequence[Effect], data: Dataset,
           seeds: Sequence[int]) -> List[Screen]:
    """Screen ``candidates`` on top of the fitted model ``mf`` against ``data`` (the fit data)
    on the packings ``seeds`` (the fit seeds); ranked by gain, the skipped last."""
    sigma = weights(mf, data)
    mu_b = np.array([mf.direct[o.condition].mean_se(o)[0] for o in data.observations])
    r = (data.values - mu_b) / sigma
    J = unit_jacobian(mf, data) / sigma[:, None]
    r_perp = _perp(J, r)
    out, probes = [], []
    for e in candidates:
        if e.needs and len({getattr(c, e.needs) for c in data.conditions}) < 2:
            out.append(Screen(e, skipped=f"needs {e.needs} to vary in the fit data"))
            continue
        probes.append(e)
    params = [dict(mf.fit.params, **e.settings(e.probe)) for e in probes]
    preds = sim.predict_many(params, data.conditions, tuple(seeds))
    for e, p in zip(probes, preds):
        mu_p = np.array([p[o.condition].mean_se(o)[0] for o in data.observations])
        if not np.all(np.isfinite(mu_p)):
            out.append(Screen(e, skipped="its probe's simulation failed"))
            continue
        d = (mu_p - mu_b) / sigma
        d_perp = _perp(J, d)
        dd = float(d_perp @ d_perp)
        absorbed, absorber = _absorbed(J, d, d_perp, mf.space.names)
        if dd <= 0:
            out.append(Screen(e, skipped="its probe changes nothing the data measure"))
            continue
        a = float(r_perp @ d_perp) / dd
        two_sided = e.lo < e.off < e.hi
        allowed = a > 0 or (two_sided and a < 0)
        gain = a * a * dd if allowed else 0.0
        x = _size(e, e.probe) * abs(a) if allowed else 0.0
        s = _strength(e, x, 1.0 if a >= 0 else -1.0) if allowed else e.off
        s = float(np.clip(s, e.lo, e.hi)) if math.isfinite(s) else e.hi
        out.append(Screen(e, gain, s, dd, d_perp, absorbed=absorbed, absorber=absorber))
    return sorted(out, key=lambda s: (bool(s.skipped), -s.gain))


def _absorbed(J: np.ndarray, d: np.ndarray, d_perp: np.ndarray, names: Sequence[str]):
    """(fraction of |d|^2 inside the span of J's columns, the column most aligned with d)."""
    full = float(d @ d)
    if full <= 0 or J.size == 0:
        return 0.0, ""
    frac = min(1.0, max(0.0, 1.0 - float(d_perp @ d_perp) / full))
    norms = np.linalg.norm(J, axis=0)
    cos2 = [(float(J[:, k] @ d) ** 2 / (norms[k] ** 2 * full)) if norms[k] > 0 else 0.0 for k in range(J.shape[1])]
    return frac, names[int(np.argmax(cos2))]


def lambda_for_power(threshold: float, power: float = 0.8) -> float:
    """The noncentrality at which a chi-square of one degree of freedom passes ``threshold``
    with probability ``power``."""
    f = lambda lam: stats.ncx2.sf(threshold, 1, lam) - power  # noqa: E731
    return float(brentq(f, 1e-9, 1e4))


@dataclass
class Power:
    """What the data could reveal of one effect: ``detectable`` (the strength passed with
    probability 0.8, SI; NaN when no strength in the effect's range is), ``replicates`` and
    ``packings`` (what would reveal the probe strength: replicates per condition with the
    model as it is, or the model's packings with the data as they are; None when that alone
    cannot), and ``statement``, the sentence in the report."""

    effect: str
    detectable: float
    replicates: Optional[int]
    packings: Optional[int]
    statement: str


def detection_power(sc: Screen, mf: ModelFit, data: Dataset, threshold: float, n_replicates: int,
                    n_packings: int) -> Power:
    """The detection power of the screened candidate ``sc`` (see the module docstring) given
    the acceptance ``threshold`` on the chi2 drop and the data's and the model's current
    replicates and packings."""
    e = sc.effect
    if sc.skipped or sc.d_perp is None:
        return Power(e.name, math.nan, None, None, f"{e.name}: not screened ({sc.skipped})")
    lam80 = lambda_for_power(threshold)
    x_probe = _size(e, e.probe)
    x80 = x_probe * math.sqrt(lam80 / sc.lam_probe)
    s80 = _strength(e, x80)
    inside = e.lo <= s80 <= e.hi if math.isfinite(s80) else False
    unit = "" if e.unit == "-" else f" {e.unit}"
    pname = e.param.split(".", 1)[1]
    if e.stronger == "lower":
        statement = (f"{e.name}: {pname} above {s80:.3g}{unit} cannot be told from none with these data"
                     if inside else f"{e.name}: no {pname} in [{e.lo:g}, {e.hi:g}] could be told from none")
    else:
        statement = (f"{e.name}: {pname} below {s80:.3g}{unit} cannot be told from none with these data"
                     if inside else f"{e.name}: no {pname} in [{e.lo:g}, {e.hi:g}] could be told from none")
    # lambda at the probe as the data's (model's) variance shrinks with more replicates (packings)
    s2 = data.standard_errors ** 2
    m2 = mf.emulator.noise() ** 2
    d2 = sc.d_perp ** 2 * (s2 + m2)

    def lam(rep_factor: float, pack_factor: float) -> float:
        return float(np.sum(d2 / (s2 / rep_factor + m2 / pack_factor)))

    reps = packs = None
    for n in range(n_replicates, 10 * n_replicates + 1):
        if lam(n / n_replicates, 1.0) >= lam80:
            reps = n
            break
    for k in range(n_packings, 16 * n_packings + 1):
        if lam(1.0, k / n_packings) >= lam80:
            packs = k
            break
    more = []
    if reps is not None and reps > n_replicates:
        more.append(f"{reps} replicates per condition")
    if packs is not None and packs > n_packings:
        more.append(f"{packs} model packings")
    if sc.lam_probe >= lam80:
        statement += f"; its probe strength ({e.probe:g}{unit}) would be seen"
    elif more:
        statement += f"; to see its probe strength ({e.probe:g}{unit}): " + " or ".join(more)
    else:
        statement += f"; its probe strength ({e.probe:g}{unit}) stays out of reach of 10x the replicates " \
                     "or 16x the packings"
    if sc.absorbed >= ABSORBED_NOTE:
        # the statement is first-order at the fitted model; an effect the fitted parameters
        # can mimic is taken up by them before it leaves a residual
        statement += (f"; {100 * sc.absorbed:.0f} % of its signature at the probe is what the fitted parameters "
                      f"can do as well (most of all {sc.absorber}): data that carry it may be fitted by moving "
                      f"{sc.absorber} instead, so this bound is optimistic")
    return Power(e.name, s80 if inside else math.nan, reps, packs, statement)


def screens_table(screens: Sequence[Screen], powers: Mapping[str, Power]) -> str:
    """The screening as a Markdown table."""
    rows = ["| effect | stage | gain (chi2) | first-order strength | mimicked by the fit "
            "| what the data could reveal |",
            "|---|---|---|---|---|---|"]
    for s in screens:
        p: Optional[Power] = powers.get(s.effect.name)
        if s.skipped:
            rows.append(f"| {s.effect.name} | {s.effect.stage} | - | - | - | {s.skipped} |")
        else:
            mimic = f"{100 * s.absorbed:.0f} % ({s.absorber})" if s.absorber else "-"
            rows.append(f"| {s.effect.name} | {s.effect.stage} | {s.gain:.1f} | {s.strength:.3g} | {mimic} | "
                        f"{p.statement if p else ''} |")
    return "\n".join(rows)


__all__ += ["weights", "screens_table"]
