"""Searching the parameters: :func:`scan` (a grid) and :func:`fit` (a few runs).

:func:`scan` runs a grid (like the paper's (E_b, sigma_c) maps, Fig. 14) on an executor.
:func:`fit` needs fewer runs. Its default method, ``"scaling"``, is a Gauss-Newton
iteration in log space on a local affine model of ln(outputs) against ln(parameters), whose
slopes start at the exponents of the paper's scaling laws and are refitted, by weighted
ridge regression towards those exponents, to every run made so far (a 400-particle
pellet's sigma_f scatters by a few % between nearby bond laws, so slopes from two
neighbouring runs alone would be noise):

* a bond breaks at the strain sigma_c / E_b, so the deformation at failure goes as
  dL_f/D ~ sigma_c / E_b (exponents +1, -1), and the peak force as E_b times that strain,
  sigma_f ~ sigma_c (exponents +1, 0): at fixed E_b sigma_f grows about linearly with
  sigma_c (Figs. 12-14), so after one run at (E_b, sigma_c) the next sigma_c is
  sigma_c * sigma_f,target / sigma_f,sim and E_b follows from dL_f/D;
* the response depends on the bond only through E_b r_b^2 and sigma_c r_b^2 (Fig. 12b;
  NOTES item 3), so the exponents in r_b are twice the sum of those in E_b and sigma_c;
* with k2/k1 fixed (the restitution, eq. 8) the compaction of linear contacts depends on
  sigma_z / k1, so d ln BD / d ln k1 = -d ln BD / d ln sigma_z, read off the loading curve
  of the first run: no finite-difference run is needed for k1 (or p_y) either.

The failure of a simulated pellet is the first peak of sigma_1(dL/D) after which the
(lightly smoothed) curve falls by 10% (:func:`pelletdem.worker.failure_point`): a small
pellet can break and then load up again as the plates crush it. A test that ends before such
a fall yields bounds of sigma_f and dL_f/D, not values (``peaked`` = 0): such a run is scored
as if its peak came at 1.5 x the end of the test
(:data:`pelletdem.objectives.CENSORED_DLF_FACTOR`), and its values count a thousand times
less in the local model, whose slopes then stay at the scaling law's. Scans score such runs
the same way. A parameter no scaling law covers gets one finite-difference run.
Steps are limited to a factor 4 per parameter and per iteration and projected on the
bounds; a step that does not improve halves the step limit. The fit stops when the rms
z-score is below ``tol`` (default 0.5: within half a measured SD), after ``max_runs``
parameter points, or when the next step would change no parameter by more than
``min_step`` (2%). ``method="nelder-mead"`` runs scipy's Nelder-Mead on the loss in log
space instead (more runs; use it for a curve criterion or parameters with no scaling law).

Both run their points through an :class:`pelletdem.execution.Evaluator` (run cache,
executors, retries) and score them with :mod:`pelletdem.objectives`; the least-squares
pieces of the fit are :mod:`pelletdem.optimize`'s. Units: SI (Pa, m, N/m, kg/m^3).
"""
from __future__ import annotations

import itertools
import math
import os
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from .engine import BondLaw
from .execution import Evaluator, open_executor, with_relaxed_dir
from .metrics import DEFAULT_REL_SD_FLOOR
from .objectives import Targets, as_targets, effective_outputs, mean_outputs, score
from .optimize import bounded_fd_step, levenberg_step, local_affine_model, nelder_mead_in_box
from .run_cache import RunCache
from .runs import (
    PARAMETERS,
    RunSetup,
    RunSpec,
    bound_signs,
    check_names,
    check_positive,
    parameter_unit,
    parse_bounds,
    run_setup,
)
from .worker import run_point

__all__ = ["SCALING_EXPONENTS", "ScanResult", "scan", "FitResult", "fit"]

_MPA = 1e6

#: d ln(output) / d ln(parameter) from the paper's scaling laws (see the module docstring).
#: None: read off the run's own compaction curve (d ln BD / d ln sigma_z).
SCALING_EXPONENTS: Dict[str, Dict[str, Optional[float]]] = {
    "sigma_f": {"sigma_c": 1.0, "E_b": 0.0, "tau_c": 0.0, "r_b": 2.0},
    "dLf_D": {"sigma_c": 1.0, "E_b": -1.0, "tau_c": 0.0, "r_b": 0.0},
    "bulk_density": {"k1": None, "p_y": None, "sigma_z": None},
}


# --------------------------------------------------------------------------------------
# Problems: parameter point -> runs -> residuals
# --------------------------------------------------------------------------------------

@dataclass
class _Point:
    params: dict
    records: List[dict]
    scores: List[dict]
    outputs: List[dict]
    ok: bool
    error: str
    loss: float
    rms_z: float
    rrmse: float
    residual: np.ndarray   # weighted log-ratios, ~z
    weight: np.ndarray
    names: List[str]
    slopes: np.ndarray     # d ln BD / d ln sigma_z of the loading curve, per residual
    censored: np.ndarray   # residuals that are bounds (diametral test ended before the peak)


class _Problem:
    """Parameter point -> the runs its targets need (x seeds) -> scores and residuals."""

    def __init__(self, names, targets: List[Targets], setup: RunSetup, criterion: str, fixed=None):
        self.names = list(names)
        self.targets = targets
        self.setup = setup
        self.fixed = dict(fixed or {})
        if criterion == "auto":
            diam = [t for t in targets if t.diametral]
            criterion = "rrmse" if diam and all(t.curve is not None for t in diam) else "z"
        if criterion not in ("z", "rrmse"):
            raise ValueError(f"criterion = {criterion!r}: allowed 'auto', 'z', 'rrmse'")
        self.criterion = criterion

    def specs(self, params: Mapping[str, float]) -> List[List[RunSpec]]:
        p = {**self.fixed, **params}
        return [[self.setup.spec(p, t.sigma_z, s, t.diametral, t.condition_rows()) for s in self.setup.seeds]
                for t in self.targets]

    def evaluate(self, params: Mapping[str, float], ev: Evaluator) -> _Point:
        groups = self.specs(params)
        flat = ev.run_all([s for g in groups for s in g])
        recs, k = [], 0
        for g in groups:
            recs.append(flat[k:k + len(g)])
            k += len(g)
        scores, outputs, res, wts, names, slopes, censored = [], [], [], [], [], [], []
        ok, err = True, ""
        for t, rs in zip(self.targets, recs):
            outs, curve, good, e = mean_outputs(rs)
            outputs.append(outs)
            if not good:
                ok, err = False, e
                scores.append({})
                continue
            outs = effective_outputs(outs)
            sc = score(outs, t, curve)
            scores.append(sc)
            for name, out_name in (("sigma_f", "sigma_f"), ("dLf_D", "dLf_D"),
                                   ("bulk_density", "bulk_density_" + t.density_state)):
                mean = getattr(t, name)
                if mean is None:
                    continue
                # the SD of metrics.sd_weighted_error (floored at 1% of the mean), so that
                # w * ln(sim / mean) ~ z for small errors
                w = mean / max(getattr(t, name + "_sd"), DEFAULT_REL_SD_FLOOR * mean)
                res.append(w * math.log(max(outs[out_name], 1e-300) / mean))
                wts.append(w)
                names.append(name)
                slopes.append(outs.get("dlnbd_dlnsigma", float("nan")))
                # a diametral test that ended before sigma_1 fell past its peak gives lower
                # bounds of sigma_f and dL_f/D, not values
                censored.append(name != "bulk_density" and outs.get("peaked", 1.0) < 1.0)
        if ok:
            zs = [v for s in scores for k, v in s.items() if k.startswith("z_")]
            rms_z = float(math.sqrt(np.mean(np.square(zs)))) if zs else float("nan")
            rr = [s["rrmse"] for s in scores if not math.isnan(s.get("rrmse", float("nan")))]
            rrmse = float(np.mean(rr)) if rr else float("nan")
            loss = rrmse if self.criterion == "rrmse" else rms_z
        else:
            rms_z = rrmse = loss = float("inf")
        return _Point(dict(params), [r for rs in recs for r in rs], scores, outputs, ok, err, loss,
                      rms_z, rrmse, np.asarray(res), np.asarray(wts), names, np.asarray(slopes),
                      np.asarray(censored, dtype=bool))

    def prior_jacobian(self, point: _Point) -> np.ndarray:
        """d ln(output) / d ln(param) from SCALING_EXPONENTS; NaN where no law applies."""
        J = np.full((len(point.names), len(self.names)), np.nan)
        slopes = point.slopes
        for i, out in enumerate(point.names):
            law = SCALING_EXPONENTS.get(out, {})
            for j, p in enumerate(self.names):
                if p not in law:
                    continue
                e = law[p]
                if e is None:  # compaction: BD depends on sigma_z / k1
                    s = slopes[i]
                    e = s if p == "sigma_z" else -s
                J[i, j] = e
        # diametral outputs do not depend on k1 / p_y / sigma_z by any law we know; bulk
        # density does not depend on bond parameters at all (exactly 0: bonds come later).
        for i, out in enumerate(point.names):
            for j, p in enumerate(self.names):
                if out == "bulk_density" and p in ("E_b", "sigma_c", "tau_c", "r_b"):
                    J[i, j] = 0.0
        return J


# --------------------------------------------------------------------------------------
# Scan
# --------------------------------------------------------------------------------------

@dataclass
class ScanResult:
    """A finished scan.

    ``runs``: one row per run (parameters in SI, seed, sigma_z Pa, target label, outputs,
    errors, ok, error, cached, key). ``points``: one row per parameter point (outputs averaged
    over seeds, ``rms_z``, ``rrmse``, ``loss`` over all targets). ``best``: the parameters of
    the lowest loss (empty without targets). ``n_simulations``: runs executed now;
    ``n_cached``: runs read from the cache; ``n_relaxations``: relaxed pellets computed now;
    ``wall_time_s``: s. ``n_retried``: runs tried again after a failed attempt (a worker
    died or the runner raised); ``failures``: the runs that failed again ({key, error,
    attempts}; their rows in ``runs`` have ok False and the error text), ``n_failed`` of them.
    """

    runs: Any
    points: Any
    best: dict
    n_simulations: int
    n_cached: int
    n_relaxations: int
    wall_time_s: float
    n_retried: int = 0
    n_failed: int = 0
    failures: list = field(default_factory=list)


def _grid(param_grid: Mapping[str, Sequence[float]]) -> Tuple[List[str], List[dict]]:
    if not isinstance(param_grid, Mapping) or not param_grid:
        raise ValueError("param_grid must be a non-empty mapping {name: [values]}")
    for name in param_grid:
        parameter_unit(name)  # PARAMETERS, 'seed' or a contact-law row
    names = list(param_grid)
    axes = []
    for n in names:
        vals = param_grid[n]
        vals = [vals] if np.ndim(vals) == 0 else list(vals)
        if not vals:
            raise ValueError(f"param_grid[{n!r}] is empty")
        for v in vals:
            try:
                f = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"param_grid[{n!r}] holds {v!r}, not a number") from None
            if not math.isfinite(f) or (f <= 0 and n != "seed") or (n == "seed" and f < 0):
                raise ValueError(f"param_grid[{n!r}] holds {v!r}: values must be finite and > 0")
        axes.append(vals)
    return names, [dict(zip(names, combo)) for combo in itertools.product(*axes)]


def scan(param_grid: Mapping[str, Sequence[float]], targets=None, *, preset="tiny",
         sigma_z: float = 120e6, seeds=(0,), bond: Optional[BondLaw] = None,
         contact: Optional[Mapping[str, Any]] = None, max_dLD: Optional[float] = None,
         diametral: bool = True, criterion: str = "auto",
         cache_dir: Optional[Union[str, os.PathLike]] = None, executor=None,
         max_workers: Optional[int] = None, runner: Callable[[RunSpec], dict] = run_point,
         relaxed_dir: Optional[Union[str, os.PathLike]] = None) -> ScanResult:
    """Run every combination of ``param_grid`` ({name: values}, SI, names from
    :data:`PARAMETERS` plus 'seed') and score it against ``targets``.

    ``targets``: a :class:`Targets`, a list of them (each at its own sigma_z), or None to only
    run at ``sigma_z`` (Pa; a compaction-only run when ``diametral`` is False). ``seeds``: the
    packing seeds each point is run with (outputs averaged). ``preset``, ``bond`` (base
    BondLaw), ``contact`` (ContactLaw overrides), ``max_dLD``: see :func:`make_spec`.
    ``cache_dir``: where run records live (resume by pointing at it again; None: memory only).
    ``executor``: None (a spawn ProcessPoolExecutor of ``max_workers``), 'serial', a
    concurrent.futures.Executor, or a distributed.Client. ``runner``: the function run per
    RunSpec (default :func:`run_point`; replace it for tests). ``relaxed_dir``: a directory all
    workers can reach where relaxed pellets are kept as checkpoints, so a worker (or a later
    session) that lacks one in memory loads it instead of compacting again (None: memory
    only). Returns :class:`ScanResult`.
    """
    import pandas as pd

    t0 = time.perf_counter()
    names, points = _grid(param_grid)
    tg = as_targets(targets)
    setup = run_setup(preset, bond, contact, seeds, max_dLD)
    if not tg:
        tg = [None]
    cache = RunCache(cache_dir)
    specs, index = [], []
    for pi, p in enumerate(points):
        for ti, t in enumerate(tg):
            sz = t.sigma_z if t is not None else sigma_z
            dia = t.diametral if t is not None else diametral
            seed_list = [p["seed"]] if "seed" in p else setup.seeds
            for s in seed_list:
                specs.append(setup.spec({k: v for k, v in p.items() if k != "seed"}, sz, s, dia,
                                        t.condition_rows() if t is not None else None))
                index.append((pi, ti, s))
    with open_executor(executor, max_workers) as ex:
        ev = Evaluator(cache, ex, with_relaxed_dir(runner, relaxed_dir), relaxed_shared=relaxed_dir is not None)
        records = ev.run_all(specs)
    crit = _Problem([], tg, setup, criterion).criterion if tg[0] is not None else "z"
    rows = []
    for (pi, ti, s), spec, rec in zip(index, specs, records):
        t = tg[ti]
        row = {**points[pi], "seed": s, "sigma_z": spec.sigma_z, "target": t.label if t else "",
               "ok": rec["ok"], "error": rec["error"], "cached": rec.get("cached", False), "key": rec["key"]}
        row.update(rec["outputs"])
        if t is not None and rec["ok"]:
            row.update(score(effective_outputs(rec["outputs"]), t, rec.get("curve")))
        rows.append(row)
    runs = pd.DataFrame(rows)
    prows = []
    for pi, p in enumerate(points):
        prow = dict(p)
        zs, rr, ok = [], [], True
        for ti, t in enumerate(tg):
            recs = [records[k] for k, (a, b, _) in enumerate(index) if a == pi and b == ti]
            outs, curve, good, err = mean_outputs(recs)
            ok &= good
            suffix = "" if len(tg) == 1 else f"@{(t.sigma_z if t else sigma_z) / _MPA:g}MPa#{ti}"
            for k in ("sigma_f", "dLf_D", "peaked", "bulk_density_relaxed", "bulk_density_max",
                      "coordination_number_relaxed", "coordination_number_relaxed_bulk"):
                if k in outs:
                    prow[k + suffix] = outs[k]
            if t is not None and good:
                sc = score(effective_outputs(outs), t, curve)
                for k, v in sc.items():
                    prow[k + suffix] = v
                zs += [v for k, v in sc.items() if k.startswith("z_")]
                if not math.isnan(sc["rrmse"]):
                    rr.append(sc["rrmse"])
        prow["ok"] = ok
        if tg[0] is not None:
            prow["rms_z"] = float(math.sqrt(np.mean(np.square(zs)))) if ok and zs else float("inf")
            prow["rrmse"] = float(np.mean(rr)) if ok and rr else (float("nan") if ok else float("inf"))
            prow["loss"] = prow["rrmse"] if crit == "rrmse" else prow["rms_z"]
        prows.append(prow)
    pts = pd.DataFrame(prows)
    best = {}
    if tg[0] is not None and len(pts) and np.isfinite(pts["loss"]).any():
        b = pts.loc[pts["loss"].idxmin()]
        best = {n: float(b[n]) for n in names}
    st = ev.stats()
    return ScanResult(runs=runs, points=pts, best=best, n_simulations=st["n_simulations"],
                      n_cached=st["n_cached"], n_relaxations=st["n_relaxations"],
                      wall_time_s=time.perf_counter() - t0, n_retried=st["n_retried"],
                      n_failed=st["n_failed"], failures=st["failures"])


# --------------------------------------------------------------------------------------
# Fit
# --------------------------------------------------------------------------------------

@dataclass
class FitResult:
    """A finished fit.

    ``params``: best parameters (SI). ``loss``: its loss (rms z-score, or RRMSE with the
    'rrmse' criterion); ``rms_z``, ``rrmse``: both measures at the best point (-).
    ``outputs``: the simulated outputs at the best point, one dict per target (SI).
    ``scores``: the errors per target. ``history``: one row per parameter point tried
    (parameters, outputs, errors, ok). ``converged``: the loss reached ``tol``;
    ``message``: why the fit stopped. ``n_points``: parameter points evaluated;
    ``n_simulations`` / ``n_cached`` / ``n_relaxations``: runs executed / read from the cache /
    relaxations done; ``wall_time_s``: s. ``method``: 'scaling' or 'nelder-mead'.
    ``n_retried`` / ``n_failed``: runs tried again after a failed attempt / that failed again
    (their points have ok False and the error text in ``history``).
    """

    params: dict
    loss: float
    rms_z: float
    rrmse: float
    outputs: list
    scores: list
    history: Any
    converged: bool
    message: str
    n_points: int
    n_simulations: int
    n_cached: int
    n_relaxations: int
    wall_time_s: float
    method: str
    targets: list = field(default_factory=list)
    n_retried: int = 0
    n_failed: int = 0


def _history_row(names, point: _Point, targets) -> dict:
    row = {n: point.params[n] for n in names}
    for i, (_, outs, sc) in enumerate(zip(targets, point.outputs, point.scores)):
        sfx = "" if len(targets) == 1 else f"#{i}"
        for k in ("sigma_f", "dLf_D", "peaked", "sigma_f_max", "dLf_D_max", "bulk_density_relaxed",
                  "bulk_density_max", "coordination_number_relaxed", "coordination_number_relaxed_bulk"):
            if k in outs:
                row[k + sfx] = outs[k]
        for k, v in sc.items():
            row[k + sfx] = v
    row.update(ok=point.ok, error=point.error, loss=point.loss, rms_z=point.rms_z, rrmse=point.rrmse)
    return row


def _scaling_search(problem: _Problem, ev: Evaluator, names, values: Callable, lo, hi, x0, tol, max_runs, max_step,
                    min_step, log: Callable) -> Tuple[List[_Point], str, bool]:
    """Gauss-Newton in log space on a local affine model of the log outputs whose slopes start
    at the scaling-law exponents and are refitted to every run so far (noise-tolerant)."""
    pts: List[_Point] = []
    xs: List[np.ndarray] = []

    def run(x):
        p = problem.evaluate(values(x), ev)
        pts.append(p)
        xs.append(np.array(x, dtype=float))
        log(p)
        return p

    def logs(p: _Point) -> np.ndarray:  # ln(sim / measured) per residual
        return p.residual / p.weight

    x = np.clip(x0, lo, hi)
    cur = run(x)
    if not cur.ok:
        return pts, f"the start point failed: {cur.error}", False
    if cur.loss <= tol:
        return pts, f"loss {cur.loss:.3g} <= tol {tol} at the start point", True
    prior = problem.prior_jacobian(cur)
    # parameters no scaling law covers: one finite-difference run each
    for j in range(len(names)):
        col = prior[:, j]
        if np.all(np.isfinite(col)) and np.any(col != 0):
            continue
        if len(pts) >= max_runs:
            return pts, "max_runs reached while probing parameters without a scaling law", False
        h = bounded_fd_step(x[j], math.log(1.3), hi[j])
        xp = x.copy()
        xp[j] += h
        p = run(xp)
        if not p.ok:
            return pts, f"finite-difference run for {names[j]!r} failed: {p.error}", False
        prior[:, j] = (logs(p) - logs(cur)) / h
    prior = np.nan_to_num(prior)
    good = lambda: [k for k, p in enumerate(pts) if p.ok]  # noqa: E731
    ib = min(good(), key=lambda k: pts[k].loss)
    radius = max_step
    while len(pts) < max_runs:
        best, xb = pts[ib], xs[ib]
        if best.loss <= tol:
            return pts, f"loss {best.loss:.3g} <= tol {tol}", True
        g = good()
        a, J = local_affine_model(np.array([xs[k] for k in g]), np.array([logs(pts[k]) for k in g]), xb, prior,
                            ridge=0.01, width=math.log(2.0),
                            censored=np.array([pts[k].censored for k in g]))
        W = best.weight
        A = W[:, None] * J
        r = W * a  # weighted model residual at xb
        lam = 1e-6 * max(float(np.trace(A.T @ A)), 1e-12)
        try:
            dx = levenberg_step(A, r, lam)
        except np.linalg.LinAlgError:
            return pts, "singular Jacobian", False
        dx = dx / max(1.0, float(np.max(np.abs(dx))) / radius)
        xn = np.clip(xb + dx, lo, hi)
        if float(np.max(np.abs(xn - xb))) < min_step:
            at_bound = np.any((np.abs(xn - lo) < 1e-12) | (np.abs(xn - hi) < 1e-12))
            why = "the bounds stop the step" if at_bound else "the model's optimum is within min_step of the best point"
            return pts, f"{why}; best loss {best.loss:.3g}", bool(best.loss <= tol)
        p = run(xn)
        if p.ok and p.loss < best.loss:
            ib = len(pts) - 1
            radius = min(max_step, 1.5 * radius)
        else:
            radius = 0.5 * float(np.max(np.abs(xn - xb)))
            if radius < min_step:
                return pts, (f"no better point within a {100 * (math.exp(min_step) - 1):.0f}% step; "
                             f"best loss {best.loss:.3g}"), bool(best.loss <= tol)
    best = pts[ib]
    ok = best.loss <= tol
    return pts, (f"loss {best.loss:.3g} <= tol {tol}" if ok else f"max_runs = {max_runs} reached"), ok


def _nelder_mead(problem: _Problem, ev: Evaluator, values: Callable, lo, hi, x0, tol, max_runs, log):
    pts: List[_Point] = []

    def loss(x):
        p = problem.evaluate(values(x), ev)
        pts.append(p)
        log(p)
        return p.loss

    msg = nelder_mead_in_box(loss, lo, hi, x0, tol, max_runs)
    best = min(pts, key=lambda p: p.loss)
    return pts, msg, best.loss <= tol


def fit(params: Mapping[str, Sequence[float]], targets, *, start: Optional[Mapping[str, float]] = None,
        method: str = "scaling", tol: float = 0.5, max_runs: int = 10, max_step: float = 4.0,
        min_step: float = 1.02,
        preset="tiny", seeds=(0,), bond: Optional[BondLaw] = None, fixed: Optional[Mapping[str, float]] = None,
        contact: Optional[Mapping[str, Any]] = None, max_dLD: Optional[float] = None,
        criterion: str = "auto", cache_dir: Optional[Union[str, os.PathLike]] = None, executor="serial",
        max_workers: Optional[int] = None, runner: Callable[[RunSpec], dict] = run_point,
        relaxed_dir: Optional[Union[str, os.PathLike]] = None,
        verbose: bool = False, evaluator: Optional[Evaluator] = None) -> FitResult:
    """Fit ``params`` ({name: (lo, hi)} or {name: (lo, hi, start)}, SI, names from
    :data:`PARAMETERS`, or a contact-law row ``contact.<field>``) so the simulations match
    ``targets`` (a :class:`Targets` or a list, each at its own sigma_z).

    ``method``: 'scaling' (default: log-space Gauss-Newton started from the paper's scaling
    laws, see the module docstring; 3-6 runs for (E_b, sigma_c)) or 'nelder-mead' (scipy, in
    log space scaled to the bounds). ``start``: start values (default the bounds' third entry,
    else their geometric mean). ``tol``: stop when the loss is at most this (rms z-score, -;
    or RRMSE with criterion 'rrmse'). ``max_runs``: most parameter points to evaluate (each is
    one run per target and seed). ``max_step``: the largest factor a parameter changes by in
    one step; ``min_step`` the smallest worth a run (default 1.02: a 400-particle pellet's
    sigma_f scatters by a few % between nearby bond laws). ``fixed``: parameters held at a
    value (SI). ``seeds``: packing seeds averaged per point. ``criterion``: 'z' (rms z of
    sigma_f, dL_f/D, bulk density), 'rrmse' (eq. 16 on the targets' curves; the scaling
    steps still use the z residuals, the best point is picked by RRMSE) or 'auto' (rrmse when
    every diametral target has a curve). ``executor``: 'serial' by default (a fit is
    sequential; the relaxed pellet stays in this process), or as in
    :func:`scan`, as are ``cache_dir``, ``runner`` and ``relaxed_dir``. ``evaluator``: an
    :class:`pelletdem.execution.Evaluator` to run on instead (its cache and executor, shared
    with other fits; ``cache_dir``, ``executor``, ``max_workers``, ``runner`` and
    ``relaxed_dir`` are then not used; the result counts only this fit's runs). Returns
    :class:`FitResult`. Bad names, reversed bounds or NaN raise
    ValueError naming the parameter.
    """
    import pandas as pd

    t0 = time.perf_counter()
    if method not in ("scaling", "nelder-mead"):
        raise ValueError(f"method = {method!r}: allowed 'scaling', 'nelder-mead'")
    names, lo, hi, x0 = parse_bounds(params, start)
    signs = bound_signs(params)

    def values(x) -> Dict[str, float]:  # a point's parameters (SI) from its coordinates
        return {n: float(sg * math.exp(v)) for n, sg, v in zip(names, signs, x)}
    if fixed:
        for n, v in fixed.items():
            if not n.startswith("contact."):
                check_names([n], PARAMETERS, "fixed parameter")
            unit = parameter_unit(n)
            if n in names:
                raise ValueError(f"parameter {n!r} is both fitted and fixed")
            check_positive(n, v, unit)
    check_positive("tol", tol, "-")
    check_positive("max_step", max_step, "-")
    check_positive("min_step", min_step, "-")
    if not 1 < min_step < max_step:
        raise ValueError(f"min_step = {min_step!r} and max_step = {max_step!r} must be factors with "
                         "1 < min_step < max_step")
    if isinstance(max_runs, bool) or not isinstance(max_runs, (int, np.integer)) or max_runs < 1:
        raise ValueError(f"max_runs = {max_runs!r} must be an integer >= 1")
    tg = as_targets(targets)
    if not tg:
        raise ValueError("targets is empty: nothing to fit against")
    setup = run_setup(preset, bond, contact, seeds, max_dLD)
    problem = _Problem(names, tg, setup, criterion, fixed)
    problem.specs(values(x0))  # validate before running

    def log(p: _Point):
        if verbose:
            ps = ", ".join(f"{n}={p.params[n]:.4g}" for n in names)
            tag = " + ".join(t.label for t in tg if t.label) or "fit"
            print(f"[{tag}] {ps}: loss={p.loss:.3g} rms_z={p.rms_z:.3g}" + ("" if p.ok else f" FAILED {p.error}"),
                  flush=True)

    def go(ev):
        if method == "scaling":
            return _scaling_search(problem, ev, names, values, lo, hi, x0, tol, max_runs, math.log(max_step),
                                   math.log(min_step), log)
        return _nelder_mead(problem, ev, values, lo, hi, x0, tol, max_runs, log)

    if evaluator is not None:
        ev = evaluator
        before = ev.stats()
        pts, msg, conv = go(ev)
    else:
        with open_executor(executor, max_workers) as ex:
            ev = Evaluator(RunCache(cache_dir), ex, with_relaxed_dir(runner, relaxed_dir),
                           relaxed_shared=relaxed_dir is not None)
            before = ev.stats()
            pts, msg, conv = go(ev)
    after = ev.stats()
    good = [p for p in pts if p.ok]
    best = min(good, key=lambda p: p.loss) if good else pts[-1]
    hist = pd.DataFrame([_history_row(names, p, tg) for p in pts])
    return FitResult(params=dict(best.params), loss=best.loss, rms_z=best.rms_z, rrmse=best.rrmse,
                     outputs=best.outputs, scores=best.scores, history=hist, converged=bool(conv),
                     message=msg, n_points=len(pts),
                     n_simulations=after["n_simulations"] - before["n_simulations"],
                     n_cached=after["n_cached"] - before["n_cached"],
                     n_relaxations=after["n_relaxations"] - before["n_relaxations"],
                     wall_time_s=time.perf_counter() - t0, method=method, targets=tg,
                     n_retried=after["n_retried"] - before["n_retried"],
                     n_failed=after["n_failed"] - before["n_failed"])

