"""Closing the loop with measured data: fit, find the residual, trace it to an effect the
model lacks, add the effect, and report the error before and after.

The procedure (:func:`close_loop`):

1. **Baseline fit.** The paper's model with the chosen base parameters (e.g. E_b and
   sigma_c, per material or shared) is fitted to the *fit* observations by Levenberg-Marquardt
   on z-scores, in log space, with forward-difference Jacobians (every simulation goes through
   the calibration cache, so repeated points cost nothing).
2. **Residual.** The model's own scatter is measured first (``model_jitter``: the base
   parameters raised and lowered by 0.1%; a DEM pellet then breaks its bonds in another order)
   and added to the replicate SDs in quadrature, so that a chaotic model's jitter is not taken
   for a missing effect. :func:`pelletdem.residuals.describe`: per point, per part of the curve (toe,
   rise, peak, post-peak; compaction below and above dh/h0 = 0.75), per condition, and tests
   for structure (chi-square against the replicate SD, runs along the curves, trends with
   pressure and moisture). A residual consistent with noise ends the loop: nothing is added.
3. **Trace.** Each candidate of :data:`pelletdem.effects.EFFECTS` is switched on at its probe
   strength on top of the fitted baseline (one simulation per condition): the change of the
   predictions, in z units, is its *measured signature*. The part of the residual that
   re-fitting the base parameters cannot remove (orthogonal to the baseline Jacobian) is
   projected on the part of each signature that the base parameters cannot mimic; the
   squared cosine of that angle is the fraction of the structured residual the effect can
   explain to first order. An effect whose best strength would be negative while it only
   works one way explains nothing. Candidates are ranked by that fraction (to two digits);
   among equals, effects of the diametral test come before compaction effects, since they
   branch off the cached relaxed pellets and cost a fraction of a refit that needs new ones.
4. **Refit and choose.** The best ``refit_top`` candidates (explaining at least
   ``min_explained``) are refitted with their parameter free, starting from the best point of
   a profile over the effect's strength (``profile_points`` values across its bounds, each
   with the base parameters moved by one Gauss-Newton step). Each is scored on the
   *held-out* observations (other pressures, moisture contents or replicates, never used in
   a fit) and on the fit data with a penalty of ln(n) per added parameter (BIC). A candidate
   is accepted when its penalised fit error falls, its held-out chi-square falls by at least
   ``min_heldout_gain`` (default 30%), and the refitted residual is no longer structured. If
   none is accepted the loop says "no candidate explains this residual"; if two are accepted
   and the runner-up's held-out error is within ``clear_margin`` of the best's, the loop says
   no candidate wins clearly and adds nothing.
5. **Report.** :func:`pelletdem.loop_report.write_report` (and ``pelletdem loop``) writes the
   errors before and after, on fit and held-out data, the residual plots and the ranking.

The data are :mod:`pelletdem.loop_data`'s, the simulators :mod:`pelletdem.loop_simulators`'s
and the fits :func:`pelletdem.loop_fit.fit_model`.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence

import numpy as np

from .effects import EFFECTS, Effect
from .loop_data import Condition, Dataset
from .loop_fit import FitState, fit_model, zscores, zscores_many
from .loop_simulators import Simulator
from .optimize import bounded_parameters, chi_square, gauss_newton_step, orthogonal_part
from .residuals import DEFAULT_ALPHA, ResidualSummary, describe

__all__ = ["Candidate", "LoopResult", "close_loop", "profile_start"]

_MPA = 1e6


@dataclass
class Candidate:
    """One effect as the loop saw it: ``explained`` (fraction of the structured residual its
    signature explains to first order, 0-1), ``linear_strength`` (the first-order best value),
    refit results (``fit``, ``fit_residual``), held-out chi-square ``heldout_chi2``,
    penalised fit error ``bic``, whether it was ``accepted`` and ``why``."""

    effect: Effect
    explained: float
    linear_strength: float
    signature: Optional[np.ndarray] = None
    fit: Optional[FitState] = None
    fit_residual: Optional[ResidualSummary] = None
    heldout_chi2: float = math.nan
    heldout_z: Optional[np.ndarray] = None
    bic: float = math.nan
    accepted: bool = False
    why: str = ""


@dataclass
class LoopResult:
    """Everything :func:`close_loop` found. ``chosen``: the effect added (None when none was);
    ``verdict``: the sentence that sums it up; ``errors``: model -> {fit/held-out chi2 per
    point, rms z, RRMSE}; ``baseline``/``final``: fits; ``residual_before``/``after``;
    ``candidates`` ranked; ``n_simulations``; ``wall_time_s``."""

    fit_data: Dataset
    heldout_data: Dataset
    baseline: FitState
    residual_before: ResidualSummary
    heldout_before: np.ndarray
    candidates: List[Candidate]
    chosen: Optional[str]
    verdict: str
    final: FitState
    residual_after: ResidualSummary
    heldout_after: np.ndarray
    errors: Dict[str, Dict[str, float]]
    n_simulations: int
    wall_time_s: float
    log: List[str] = field(default_factory=list)

    def table(self) -> str:
        """The before/after errors as a Markdown table."""
        rows = ["| model | fit: chi2/n | fit: RRMSE | held-out: chi2/n | held-out: RRMSE |",
                "|---|---|---|---|---|"]
        for name, e in self.errors.items():
            rows.append(f"| {name} | {e['fit_chi2_per_point']:.2f} | {e['fit_rrmse']:.3f} | "
                        f"{e['heldout_chi2_per_point']:.2f} | {e['heldout_rrmse']:.3f} |")
        return "\n".join(rows)


def _residual(data: Dataset, z: np.ndarray, n_params: int, alpha: float) -> ResidualSummary:
    curves: Dict[str, List[int]] = {}
    for i, o in enumerate(data.observations):
        if o.curve:
            curves.setdefault(o.curve, []).append(i)
    for name, idx in curves.items():
        curves[name] = sorted(idx, key=lambda i: data.observations[i].x)
    conds = data.conditions
    levels = {"sigma_z [MPa]": {c.label: c.sigma_z / _MPA for c in conds},
              "mc [%]": {c.label: c.mc for c in conds}}
    return describe(z, parts=[o.part if o.part != "scalar" else o.quantity for o in data.observations],
                    conditions=[o.condition.label for o in data.observations],
                    curves={k: np.array(v) for k, v in curves.items()}, levels=levels,
                    groups={"material": {c.label: c.material for c in conds}}, n_params=n_params,
                    alpha=alpha)


def _rrmse(data: Dataset, z: np.ndarray) -> float:
    pred = data.values + z * data.sds
    v = data.values
    ok = np.abs(v) > 0
    return float(np.sqrt(np.mean(((pred[ok] - v[ok]) / v[ok]) ** 2)))


def _model_jitter(sim: Simulator, data: Dataset, params: Mapping[str, float], names: Sequence[str],
                  rel: float = 1e-3) -> np.ndarray:
    """The model's own scatter per observation (its unit): predictions at the base parameters
    all raised and all lowered by ``rel``. A smooth model changes by ~rel there; a DEM pellet
    breaks its bonds in another order and its curve jitters by as much as a new packing would.
    Half the squared difference, pooled over each curve (condition and quantity), estimates
    the jitter's variance."""
    up = {**params, **{k: params[k] * (1 + rel) for k in names}}
    down = {**params, **{k: params[k] * (1 - rel) for k in names}}
    zu, zd = zscores_many(sim, [up, down], data)
    d = (zu - zd) * data.sds
    d = np.where(np.isfinite(d), d, 0.0)
    out = np.zeros(len(data))
    groups: Dict[tuple, List[int]] = {}
    for i, o in enumerate(data.observations):
        groups.setdefault((o.condition, o.quantity), []).append(i)
    for idx in groups.values():
        out[idx] = math.sqrt(float(np.mean(d[idx] ** 2)) / 2.0)
    return out


def profile_start(sim: Simulator, data: Dataset, base: FitState, eff: Effect,
                  base_bounds: Mapping[str, Sequence[float]], linear: float, points: int) -> Dict[str, float]:
    """Start of a refit: the effect's strength on a grid over its bounds (``points`` values,
    plus the first-order estimate ``linear``, in the effect's unit), each with the base
    parameters moved by one Gauss-Newton step on the baseline's Jacobian; the best of all
    these points, as {name: value} (SI) for the base parameters and the effect's. A DEM
    objective is too rough for a local fit to find a strength from far away.

    A strength at which every prediction equals the baseline's (the effect never acts: a
    plate yield stress no contact reaches) is left out, with its step, while another strength
    is usable: a refit started there has no gradient in the effect's parameter, and the
    baseline's own step, which any such point gets, would win whenever the baseline is not
    quite at its minimum."""
    pars = bounded_parameters(base_bounds)
    grid = list(np.geomspace(eff.lo, eff.hi, points) if eff.log else np.linspace(eff.lo, eff.hi, points))
    grid.append(min(max(linear, eff.lo * (1.01 if eff.log else 1.0)), eff.hi))
    first = [{**base.params, **eff.settings(v)} for v in grid]
    zs = zscores_many(sim, first, data)
    inactive = [bool(np.all(np.isfinite(z))) and np.allclose(z, base.z, rtol=1e-12, atol=1e-12) for z in zs]
    second, second_inactive = [], []
    for pset, z, off in zip(first, zs, inactive):
        if not np.all(np.isfinite(z)) or base.jacobian.size == 0:
            continue
        du = gauss_newton_step(base.jacobian, z)
        q = dict(pset)
        for p, d in zip(pars, np.clip(du, -0.7, 0.7)):
            q[p.name] = p.to_v(p.clip_u(p.to_u(pset[p.name]) + d))
        second.append(q)
        second_inactive.append(off)
    tried = first + second
    chis = np.array([chi_square(z) for z in zs + zscores_many(sim, second, data)])
    off = np.array(inactive + second_inactive)
    if np.any(~off & np.isfinite(chis)):
        chis = np.where(off, np.inf, chis)
    best = tried[int(np.argmin(chis))]
    return {k: best[k] for k in list(base_bounds) + [eff.param]}


def close_loop(sim: Simulator, data: Dataset, base_bounds: Mapping[str, Sequence[float]],
               start: Mapping[str, float], *, held_out: Optional[Callable[[Condition], bool]] = None,
               heldout_data: Optional[Dataset] = None, library: Optional[Mapping[str, Effect]] = None,
               fixed: Optional[Mapping[str, float]] = None, refit_top: int = 3, min_explained: float = 0.05,
               min_heldout_gain: float = 0.3, clear_margin: float = 0.1, alpha: float = DEFAULT_ALPHA,
               max_iter: int = 6, refit_iter: int = 5, fd_step: float = 0.1, profile_points: int = 5,
               model_jitter: bool = True,
               log: Optional[Callable[[str], None]] = None) -> LoopResult:
    """Fit the baseline, describe its residual, rank the candidate effects, refit the best,
    choose by held-out error with a parameter penalty, and return a :class:`LoopResult`.

    ``data`` with ``held_out`` (a predicate on conditions) is split into fit and held-out
    parts; or pass ``heldout_data`` separately. ``base_bounds``: the baseline's free
    parameters ((lo, hi) in SI), ``start`` their start values; ``fixed``: parameters held.
    ``library``: the candidates (default :data:`pelletdem.effects.EFFECTS`). See the module
    docstring for the thresholds ``min_explained``, ``min_heldout_gain``, ``clear_margin``.
    """
    t0 = time.perf_counter()
    lines: List[str] = []

    def say(s: str) -> None:
        lines.append(s)
        if log is not None:
            log(s)

    for name, v, lo, hi in (("refit_top", refit_top, 1, 20), ("max_iter", max_iter, 0, 50),
                            ("refit_iter", refit_iter, 0, 50), ("profile_points", profile_points, 2, 50)):
        if not isinstance(v, int) or not lo <= v <= hi:
            raise ValueError(f"{name} = {v!r} is out of range: allowed {lo} <= {name} <= {hi}")
    for name, v in (("min_explained", min_explained), ("min_heldout_gain", min_heldout_gain),
                    ("clear_margin", clear_margin), ("alpha", alpha)):
        if not (isinstance(v, (int, float)) and 0 < v < 1):
            raise ValueError(f"{name} = {v!r} is out of range: allowed 0 < {name} < 1")
    if heldout_data is None:
        if held_out is None:
            raise ValueError("give held_out (a predicate on conditions) or heldout_data: the loop "
                             "chooses by the error on data not used in the fit")
        fit_data, heldout_data = data.split(held_out)
    else:
        fit_data = data
    library = dict(EFFECTS if library is None else library)
    fixed = dict(fixed or {})
    n_fit = len(fit_data)

    say(f"baseline fit of {list(base_bounds)} to {n_fit} points ({len(fit_data.conditions)} conditions)")
    base = fit_model(sim, fit_data, base_bounds, start, fixed, max_iter=max_iter, fd_step=fd_step, log=say)
    k0 = len(base.free)
    if model_jitter:
        both = Dataset(fit_data.observations + heldout_data.observations, data.name)
        jit = _model_jitter(sim, both, base.params, list(base_bounds))
        if np.any(jit > 0):
            both = both.with_model_sd(jit)
            fit_data = Dataset(both.observations[:n_fit], fit_data.name)
            heldout_data = Dataset(both.observations[n_fit:], heldout_data.name)
            rel = np.sqrt(np.mean((jit / np.maximum(np.abs(both.values), 1e-300)) ** 2))
            say(f"model jitter (base parameters +-0.1%): rms {rel:.3f} "
                "of the measured values, added to the SDs in quadrature")
            # The SDs changed, so the chi-square did: the baseline is refitted with them, as
            # every candidate will be, or a candidate would win by the refit alone.
            say("baseline refitted with those SDs")
            base = fit_model(sim, fit_data, base_bounds, base.params, fixed, max_iter=max_iter, fd_step=fd_step,
                             log=say)
    res0 = _residual(fit_data, base.z, k0, alpha)
    for s in res0.lines():
        say("  " + s)
    z_held0 = zscores(sim, base.params, heldout_data)
    chi_held0 = chi_square(z_held0)
    bic0 = base.chi2 + k0 * math.log(n_fit)
    say(f"held-out: chi2/n = {chi_held0 / len(heldout_data):.2f} on {len(heldout_data)} points")

    candidates: List[Candidate] = []
    chosen, verdict, final, res_final, z_held_final = None, "", base, res0, z_held0
    if not res0.structured:
        verdict = ("the baseline's residual is consistent with the replicate scatter: "
                   "nothing to explain, no effect added")
    else:
        r_perp = orthogonal_part(base.jacobian, base.z)
        conds = fit_data.conditions
        usable = [e for e in library.values() if not (e.needs and len({getattr(c, e.needs) for c in conds}) < 2)]
        probes = zscores_many(sim, [{**base.params, **e.settings(e.probe)} for e in usable], fit_data)
        zprobe = {e.name: z for e, z in zip(usable, probes)}
        for eff in library.values():
            if eff.name not in zprobe:
                candidates.append(Candidate(eff, 0.0, eff.off, why=f"the fit data have one {eff.needs} level"))
                continue
            zp = zprobe[eff.name]
            if not np.all(np.isfinite(zp)):
                candidates.append(Candidate(eff, 0.0, eff.off, why="simulation failed at the probe strength"))
                continue
            sig = zp - base.z
            s_perp = orthogonal_part(base.jacobian, sig)
            ss = float(s_perp @ s_perp)
            rr = float(r_perp @ r_perp)
            if ss <= 1e-12 * max(rr, 1e-300):
                candidates.append(Candidate(eff, 0.0, eff.off, sig, why="no signature beyond the base parameters"))
                continue
            a = -float(r_perp @ s_perp) / ss  # best multiple of the probe's signature
            frac = (float(r_perp @ s_perp) ** 2) / (ss * rr) if rr > 0 else 0.0
            strength = eff.off + a * (eff.probe - eff.off)
            why = ""
            if a <= 0 and eff.off == 0.0 and eff.lo >= 0:
                frac, why = 0.0, "its signature points the other way"
            candidates.append(Candidate(eff, frac, strength, sig, why=why))
        # Ranked by the fraction explained as printed (two digits); candidates tied there are
        # refitted cheapest first: a 'diametral' effect branches off the cached relaxed
        # pellets, a 'compaction' one needs new pellets for every strength it tries.
        candidates.sort(key=lambda c: (-round(c.explained, 2), c.effect.stage != "diametral"))
        say("candidate signatures (fraction of the structured residual explained to first order):")
        for c in candidates:
            say(f"  {c.effect.name:>20}: {c.explained:.2f}  {c.why}")

        tried = [c for c in candidates if c.explained >= min_explained][:refit_top]
        for c in tried:
            eff = c.effect
            bounds = dict(base_bounds)
            bounds[eff.param] = (eff.lo, eff.hi)
            st = profile_start(sim, fit_data, base, eff, base_bounds, c.linear_strength, profile_points)
            x0 = st[eff.param]
            fx = dict(fixed)
            fx.update({k: v for k, v in eff.settings(x0).items() if k != eff.param})
            say(f"refit with {eff.name} from {eff.param} = {x0:.4g} (best of a {profile_points}-point profile)")
            try:
                c.fit = fit_model(sim, fit_data, bounds, st, fx, max_iter=refit_iter, fd_step=fd_step, log=say)
            except RuntimeError as e:
                c.why = f"refit failed: {e}"
                continue
            c.fit_residual = _residual(fit_data, c.fit.z, len(c.fit.free), alpha)
            c.heldout_z = zscores(sim, c.fit.params, heldout_data)
            c.heldout_chi2 = chi_square(c.heldout_z)
            c.bic = c.fit.chi2 + len(c.fit.free) * math.log(n_fit)
            gain = 1.0 - c.heldout_chi2 / chi_held0 if chi_held0 > 0 else 0.0
            if not c.bic < bic0:
                c.why = f"penalised fit error not lower (BIC {c.bic:.1f} vs {bic0:.1f})"
            elif not gain >= min_heldout_gain:
                c.why = (f"held-out chi2 changes by {-100 * gain:+.0f}% (needs to fall by "
                         f"{100 * min_heldout_gain:.0f}%)")
            elif c.fit_residual.structured:
                c.why = "the refitted residual is still structured (" + "; ".join(c.fit_residual.reasons) + ")"
            else:
                c.accepted = True
                c.why = f"held-out chi2 -{100 * gain:.0f}%, BIC {bic0:.1f} -> {c.bic:.1f}, residual now noise"
            say(f"  {eff.name}: {c.why}")
        ok = sorted([c for c in tried if c.accepted], key=lambda c: c.heldout_chi2)
        if not ok:
            verdict = "no candidate explains this residual"
        elif len(ok) > 1 and ok[1].heldout_chi2 <= (1 + clear_margin) * ok[0].heldout_chi2:
            verdict = (f"no candidate wins clearly ({ok[0].effect.name} and {ok[1].effect.name} "
                       f"explain the residual equally well on held-out data): no effect added")
        else:
            best = ok[0]
            chosen, final, res_final, z_held_final = best.effect.name, best.fit, best.fit_residual, best.heldout_z
            verdict = (f"added {best.effect.name} ({best.effect.param} = "
                       f"{best.fit.params[best.effect.param]:.4g} {best.effect.unit}): {best.why}")
    say("verdict: " + verdict)

    def errs(fs: FitState, zh: np.ndarray) -> Dict[str, float]:
        return {"fit_chi2_per_point": fs.chi2 / n_fit, "fit_rrmse": _rrmse(fit_data, fs.z),
                "heldout_chi2_per_point": chi_square(zh) / len(heldout_data), "heldout_rrmse": _rrmse(heldout_data, zh),
                "n_params": float(len(fs.free))}

    errors = {"baseline": errs(base, z_held0)}
    if chosen is not None:
        errors[f"baseline + {chosen}"] = errs(final, z_held_final)
    return LoopResult(fit_data, heldout_data, base, res0, z_held0, candidates, chosen, verdict, final, res_final,
                      z_held_final, errors, sim.n_simulations, time.perf_counter() - t0, lines)

