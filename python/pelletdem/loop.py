"""Closing the loop with measured data (issue 6): fit, find the residual, trace it to an effect
the model lacks, add the effect, and report the error before and after.

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

Data: :class:`Dataset` of :class:`Observation` s (a measured value, its replicate SD, where it
lies on which curve of which :class:`Condition`); built from the paper's tables
(:meth:`Dataset.from_paper`), from measured curves (:meth:`Dataset.from_curves`) or made by
:func:`synthetic_dataset` with a hidden effect. Simulators: :class:`EngineSimulator` runs the
C++ pellet through the calibration's run cache and executors; :class:`FunctionSimulator`
wraps any Python function (used by fast tests with an analytic model).
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .effects import EFFECTS, Effect
from .metrics import DEFAULT_REL_SD_FLOOR
from .residuals import DEFAULT_ALPHA, ResidualSummary, describe

__all__ = [
    "Condition", "Observation", "Dataset", "Prediction", "Simulator", "FunctionSimulator",
    "EngineSimulator", "FitState", "Candidate", "LoopResult", "fit_model", "close_loop",
    "synthetic_dataset", "QUANTITIES", "DIAMETRAL_PARTS", "COMPACTION_SPLIT",
]

#: Observable quantities: name -> (unit, meaning).
QUANTITIES: Dict[str, Tuple[str, str]] = {
    "sigma_1": ("Pa", "diametral stress P/(pi R h) at x = dL/D (eq. 4), a curve point"),
    "sigma_z": ("Pa", "compaction pressure at x = dh/h0, a curve point"),
    "sigma_f": ("Pa", "tensile strength (peak of sigma_1)"),
    "dLf_D": ("-", "deformation at failure"),
    "bulk_density": ("kg/m^3", "bulk density of the relaxed pellet"),
}
#: Parts of a diametral curve by x / (dL_f/D): toe below 0.4, rise to 0.85, peak to 1.15.
DIAMETRAL_PARTS = ((0.4, "toe"), (0.85, "rise"), (1.15, "peak"), (math.inf, "post-peak"))
#: Compaction curves split at this dh/h0 (the paper's model fits only below it).
COMPACTION_SPLIT = 0.75
_MPA = 1e6


# --------------------------------------------------------------------------------------
# Data
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Condition:
    """One experimental variant: compaction pressure ``sigma_z`` (Pa), moisture content ``mc``
    (%), ``material`` (a name, '' when there is one)."""

    sigma_z: float
    mc: float = 8.0
    material: str = ""

    def __post_init__(self):
        if not (isinstance(self.sigma_z, (int, float)) and math.isfinite(self.sigma_z) and 1e5 <= self.sigma_z <= 1e9):
            raise ValueError(f"sigma_z = {self.sigma_z!r} is out of range: allowed 1e5 <= sigma_z <= 1e9 Pa")
        if not (isinstance(self.mc, (int, float)) and math.isfinite(self.mc) and 0 <= self.mc <= 100):
            raise ValueError(f"mc = {self.mc!r} is out of range: allowed 0 <= mc <= 100 %")
        if not isinstance(self.material, str):
            raise ValueError(f"material = {self.material!r} must be a string")

    @property
    def label(self) -> str:
        """E.g. 'oak MC 8% 120 MPa'."""
        head = f"{self.material} " if self.material else ""
        return f"{head}MC {self.mc:g}% {self.sigma_z / _MPA:g} MPa"


@dataclass(frozen=True)
class Observation:
    """One measured number: ``quantity`` (see :data:`QUANTITIES`) of ``condition``, at ``x``
    (dL/D or dh/h0 for curve points, NaN for scalars), mean ``value`` and replicate ``sd`` in
    the quantity's SI unit, ``n`` replicates, and the ``part`` of the curve it lies on."""

    condition: Condition
    quantity: str
    x: float
    value: float
    sd: float
    n: int = 1
    part: str = "scalar"

    def __post_init__(self):
        if self.quantity not in QUANTITIES:
            raise ValueError(f"quantity = {self.quantity!r}: allowed {sorted(QUANTITIES)}")
        if not math.isfinite(self.value):
            raise ValueError(f"{self.quantity} of {self.condition.label}: value must be finite")
        if not (math.isfinite(self.sd) and self.sd >= 0):
            raise ValueError(f"{self.quantity} of {self.condition.label}: sd = {self.sd} must be finite and >= 0")
        if self.quantity in ("sigma_1", "sigma_z") and not math.isfinite(self.x):
            raise ValueError(f"a {self.quantity} curve point needs a finite x")

    @property
    def curve(self) -> str:
        """Name of the curve the point lies on ('' for scalars)."""
        return f"{self.condition.label} {self.quantity}" if self.quantity in ("sigma_1", "sigma_z") else ""

    @property
    def effective_sd(self) -> float:
        """The SD used in z-scores: the replicate SD floored at 1% of |value| (same unit)."""
        return max(self.sd, DEFAULT_REL_SD_FLOOR * abs(self.value), 1e-300)


def _diametral_part(x: float, x_f: float) -> str:
    for bound, name in DIAMETRAL_PARTS:
        if x < bound * x_f:
            return name
    return DIAMETRAL_PARTS[-1][1]


@dataclass
class Dataset:
    """Observations, in a fixed order, with the conditions they cover."""

    observations: List[Observation]
    name: str = "data"

    def __post_init__(self):
        self.observations = list(self.observations)
        if not self.observations:
            raise ValueError("a Dataset needs at least one observation")
        for o in self.observations:
            if not isinstance(o, Observation):
                raise ValueError(f"observations must be Observation objects, got {type(o).__name__}")

    def __len__(self) -> int:
        return len(self.observations)

    @property
    def conditions(self) -> List[Condition]:
        """The conditions, in order of first appearance."""
        return list(dict.fromkeys(o.condition for o in self.observations))

    @property
    def values(self) -> np.ndarray:
        """Measured values (SI units of each quantity)."""
        return np.array([o.value for o in self.observations])

    @property
    def sds(self) -> np.ndarray:
        """Effective SDs used in z-scores."""
        return np.array([o.effective_sd for o in self.observations])

    def with_model_sd(self, model_sd: Sequence[float]) -> "Dataset":
        """A copy whose SDs also carry the model's own scatter: sd = sqrt(sd^2 + model_sd^2)
        per observation (same unit)."""
        model_sd = np.asarray(model_sd, float)
        if model_sd.shape != (len(self),) or not np.all(np.isfinite(model_sd)) or np.any(model_sd < 0):
            raise ValueError("model_sd must be one finite value >= 0 per observation")
        return Dataset([dataclasses.replace(o, sd=float(math.hypot(o.sd, m)))
                        for o, m in zip(self.observations, model_sd)], self.name)

    def subset(self, keep: Callable[[Observation], bool], name: Optional[str] = None) -> "Dataset":
        """The observations for which ``keep(observation)`` is true."""
        obs = [o for o in self.observations if keep(o)]
        if not obs:
            raise ValueError("the subset is empty")
        return Dataset(obs, name or self.name)

    def split(self, held_out: Callable[[Condition], bool]) -> Tuple["Dataset", "Dataset"]:
        """(fit, held-out): observations of conditions for which ``held_out(condition)`` is
        false, and true. Both must be non-empty."""
        fit = [o for o in self.observations if not held_out(o.condition)]
        held = [o for o in self.observations if held_out(o.condition)]
        if not fit or not held:
            raise ValueError(f"the split leaves {len(fit)} fit and {len(held)} held-out observations; "
                             "both need at least one")
        return Dataset(fit, self.name + " (fit)"), Dataset(held, self.name + " (held out)")

    @classmethod
    def from_paper(cls, materials: Optional[Sequence[str]] = None,
                   quantities: Sequence[str] = ("sigma_f", "dLf_D", "bulk_density")) -> "Dataset":
        """The paper's measurements of the 12 variants (Table 3's sigma_f and dL_f/D, Table 2's
        pellet bulk density), as scalar observations with their SDs (5 replicates each)."""
        from .measured import variants

        bad = set(quantities) - {"sigma_f", "dLf_D", "bulk_density"}
        if bad:
            raise ValueError(f"quantities {sorted(bad)}: the paper's tables give sigma_f, dLf_D, bulk_density")
        vs = variants()
        if materials is not None:
            known = {v.material for v in vs}
            for m in materials:
                if m not in known:
                    raise ValueError(f"material {m!r}: allowed {sorted(known)}")
            vs = [v for v in vs if v.material in materials]
        obs = []
        for v in vs:
            c = Condition(float(v.sigma_z), float(v.mc_percent), v.material)
            src = {"sigma_f": (v.sigma_f, v.sigma_f_sd), "dLf_D": (v.dLf_D, v.dLf_D_sd),
                   "bulk_density": (v.bd_pellet, v.bd_pellet_sd)}
            for q in quantities:
                val, sd = src[q]
                if math.isfinite(val):
                    obs.append(Observation(c, q, float("nan"), float(val), float(sd), 5))
        return cls(obs, "paper (Tables 2, 3)")

    @classmethod
    def from_curves(cls, curves: Mapping[Condition, object], points: int = 12,
                    scalars: bool = True, name: str = "curves") -> "Dataset":
        """Observations from measured curves (:class:`pelletdem.measured.Curve`, with
        replicates) per condition: ``points`` points of each mean curve on an even grid of x,
        with the replicates' SD, labelled by part; for diametral curves also sigma_f and
        dL_f/D of the replicates (``scalars``)."""
        if not isinstance(points, int) or not 3 <= points <= 500:
            raise ValueError(f"points = {points!r} is out of range: allowed 3 <= points <= 500")
        obs = []
        for cond, curve in curves.items():
            if not isinstance(cond, Condition):
                raise ValueError("curves must be keyed by Condition")
            lo, hi = curve.common_range()
            if not lo < hi:
                raise ValueError(f"{cond.label}: the replicates share no x range")
            grid = np.linspace(lo + 0.02 * (hi - lo), hi, points)
            mc = curve.mean_curve(grid)
            nrep = len(curve.replicates)
            if curve.kind == "diametral":
                pk = curve.peak()
                x_f = pk.dLf_D_mean
                for x, m, s in zip(mc.x, mc.mean, mc.sd):
                    obs.append(Observation(cond, "sigma_1", float(x), float(m), float(np.nan_to_num(s)), nrep,
                                           _diametral_part(x, x_f)))
                if scalars:
                    obs.append(Observation(cond, "sigma_f", float("nan"), pk.sigma_f_mean,
                                           float(np.nan_to_num(pk.sigma_f_sd)), nrep))
                    obs.append(Observation(cond, "dLf_D", float("nan"), pk.dLf_D_mean,
                                           float(np.nan_to_num(pk.dLf_D_sd)), nrep))
            else:
                split = COMPACTION_SPLIT if hi > COMPACTION_SPLIT else float(np.quantile(grid, 0.75))
                for x, m, s in zip(mc.x, mc.mean, mc.sd):
                    obs.append(Observation(cond, "sigma_z", float(x), float(m), float(np.nan_to_num(s)), nrep,
                                           "compaction-low" if x < split else "compaction-high"))
        return cls(obs, name)


# --------------------------------------------------------------------------------------
# Simulators
# --------------------------------------------------------------------------------------

@dataclass
class Prediction:
    """What a model predicts for one condition. ``curve``: (dL/D, sigma_1 Pa) arrays;
    ``compaction``: (dh/h0, sigma_z Pa); ``scalars``: sigma_f (Pa), dLf_D (-), bulk_density
    (kg/m^3). ``ok`` False (with ``error``) when the simulation failed."""

    curve: Optional[Tuple[np.ndarray, np.ndarray]] = None
    compaction: Optional[Tuple[np.ndarray, np.ndarray]] = None
    scalars: Dict[str, float] = field(default_factory=dict)
    ok: bool = True
    error: str = ""

    def value(self, o: Observation) -> float:
        """The prediction of observation ``o`` (NaN when it cannot be made)."""
        if not self.ok:
            return float("nan")
        if o.quantity == "sigma_1" or o.quantity == "sigma_z":
            xy = self.curve if o.quantity == "sigma_1" else self.compaction
            if xy is None or len(xy[0]) == 0:
                return float("nan")
            x, y = np.asarray(xy[0], float), np.asarray(xy[1], float)
            order = np.argsort(x, kind="stable")
            x, y = x[order], y[order]
            if o.x < x[0] or o.x > x[-1]:
                # beyond the simulated range: the nearest end (a short test is a model error)
                return float(y[0] if o.x < x[0] else y[-1])
            return float(np.interp(o.x, x, y))
        return float(self.scalars.get(o.quantity, float("nan")))


class Simulator:
    """Predicts observations from parameters. Subclasses implement :meth:`predict`."""

    def predict(self, params: Mapping[str, float], conditions: Sequence[Condition]) -> Dict[Condition, Prediction]:
        """Predictions for each condition under ``params`` (base names, ``contact.x``, ``bond.x``)."""
        raise NotImplementedError

    def predict_many(self, params_list: Sequence[Mapping[str, float]],
                     conditions: Sequence[Condition]) -> List[Dict[Condition, Prediction]]:
        """:meth:`predict` for several parameter sets (a simulator with workers runs them
        all at once: a Jacobian's columns in parallel)."""
        return [self.predict(p, conditions) for p in params_list]

    @property
    def n_simulations(self) -> int:
        """Simulations run so far (cache hits not counted)."""
        return 0

    def close(self) -> None:
        """Release workers (no-op by default)."""


class FunctionSimulator(Simulator):
    """A simulator from a Python function ``fn(params, condition) -> Prediction`` (for analytic
    test models and for users' own surrogate models)."""

    def __init__(self, fn: Callable[[Mapping[str, float], Condition], Prediction]):
        if not callable(fn):
            raise ValueError("fn must be callable")
        self.fn = fn
        self._n = 0
        self._memo: Dict[tuple, Prediction] = {}

    def predict(self, params, conditions):
        """Calls ``fn`` once per new (params, condition); repeated calls are memoised."""
        key0 = tuple(sorted((k, float(v)) for k, v in params.items()))
        out = {}
        for c in conditions:
            key = (key0, c)
            if key not in self._memo:
                self._n += 1
                self._memo[key] = self.fn(dict(params), c)
            out[c] = self._memo[key]
        return out

    @property
    def n_simulations(self) -> int:
        """Function evaluations (memo hits not counted)."""
        return self._n


class EngineSimulator(Simulator):
    """The C++ pellet: fill -> compact (condition's sigma_z) -> ... -> diametral test, through
    the calibration's run cache, relaxed-pellet reuse and executors (:mod:`pelletdem.runs`,
    :mod:`pelletdem.execution`).

    ``preset``: name or Preset; ``bond``: base BondLaw; ``contact``: ContactLaw field
    overrides; ``seeds``: packings averaged per condition; ``max_dLD``: end of the test;
    ``executor``/``max_workers``: as in :func:`pelletdem.calibrate.scan` ('serial' runs here);
    ``cache_dir``: run cache directory (resumable); ``relaxed_dir``: relaxed-pellet checkpoints.
    Parameters: base names of :data:`pelletdem.calibrate.PARAMETERS`, optionally per material
    as ``name[material]``, and any ``contact.<field>`` / ``bond.<field>``. The condition's
    moisture content is passed to the bond law (``bond.moisture_content``).
    """

    def __init__(self, preset="tiny", *, bond=None, contact: Optional[Mapping[str, float]] = None,
                 seeds: Sequence[int] = (0,), max_dLD: Optional[float] = None, executor="serial",
                 max_workers: Optional[int] = None, cache_dir=None, relaxed_dir=None):
        from .engine import BondLaw
        from .execution import Evaluator, open_executor, with_relaxed_dir
        from .run_cache import RunCache
        from .runs import make_spec, run_setup
        from .worker import run_point

        self._make_spec = make_spec
        self.setup = run_setup(preset, bond if bond is not None else BondLaw(), dict(contact or {}),
                               seeds, max_dLD)
        self._stack = contextlib.ExitStack()
        ex = self._stack.enter_context(open_executor(executor, max_workers))
        runner = with_relaxed_dir(run_point, relaxed_dir)
        self.evaluator = Evaluator(RunCache(cache_dir), ex, runner)

    def close(self) -> None:
        """Shut the executor down."""
        self._stack.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @property
    def n_simulations(self) -> int:
        """Simulations run now (the cache's hits are not counted)."""
        return self.evaluator.n_run

    def _spec(self, params: Mapping[str, float], cond: Condition, seed: int):
        base, contact, bond = {}, dict(self.setup.contact or {}), {}
        for name, v in params.items():
            if name.startswith("contact."):
                contact[name[8:]] = v
            elif name.startswith("bond."):
                bond[name[5:]] = v
            elif "[" in name:
                root, _, group = name.partition("[")
                if group.rstrip("]") == cond.material:
                    base[root] = v
            else:
                base[name] = v
        law = dataclasses.replace(self.setup.bond, **bond, moisture_content=float(cond.mc))
        return self._make_spec(base, preset=self.setup.preset, sigma_z=cond.sigma_z, seed=seed, bond=law,
                               contact=contact, max_dLD=self.setup.max_dLD)

    def predict(self, params, conditions):
        """Run (or fetch from the cache) every (condition, seed) and average over seeds."""
        return self.predict_many([params], conditions)[0]

    def predict_many(self, params_list, conditions):
        """All parameter sets' runs submitted together, so the workers share them out."""
        specs = [(k, c, self._spec(p, c, s)) for k, p in enumerate(params_list) for c in conditions
                 for s in self.setup.seeds]
        recs = self.evaluator.run_all([s for _, _, s in specs])
        out = []
        for k in range(len(params_list)):
            d = {}
            for c in conditions:
                d[c] = _prediction_from_records([r for (kk, cc, _), r in zip(specs, recs) if kk == k and cc == c])
            out.append(d)
        return out


def _mean_curve(curves: Sequence[Tuple[np.ndarray, np.ndarray]], points: int = 200):
    curves = [(np.asarray(x, float), np.asarray(y, float)) for x, y in curves if len(x)]
    if not curves:
        return None
    if len(curves) == 1:
        return curves[0]
    lo, hi = max(x.min() for x, _ in curves), min(x.max() for x, _ in curves)
    grid = np.linspace(lo, hi, points)
    ys = [np.interp(grid, x[np.argsort(x, kind="stable")], y[np.argsort(x, kind="stable")]) for x, y in curves]
    return grid, np.mean(ys, axis=0)


def _prediction_from_records(recs: Sequence[dict]) -> Prediction:
    bad = [r for r in recs if not r["ok"]]
    if bad:
        return Prediction(ok=False, error=bad[0].get("error") or "failed")
    sc = {}
    for key, out in (("sigma_f", "sigma_f"), ("dLf_D", "dLf_D"), ("bulk_density", "bulk_density_relaxed")):
        vals = [r["outputs"].get(out, float("nan")) for r in recs]
        sc[key] = float(np.mean(vals))
    curve = _mean_curve([(r["curve"].get("dL_D", []), r["curve"].get("sigma_1", [])) for r in recs])
    comp = _mean_curve([(r["compaction_curve"].get("dh_h0", []), r["compaction_curve"].get("sigma_z", []))
                        for r in recs])
    return Prediction(curve, comp, sc)


# --------------------------------------------------------------------------------------
# Fitting
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Par:
    name: str
    lo: float
    hi: float
    log: bool

    def to_u(self, v: float) -> float:
        return math.log(v) if self.log else v

    def to_v(self, u: float) -> float:
        return math.exp(u) if self.log else u

    def step(self, rel: float) -> float:  # finite-difference step in u
        return rel if self.log else rel * 0.5 * (self.hi - self.lo)

    def clip_u(self, u: float) -> float:
        return min(max(u, self.to_u(self.lo)), self.to_u(self.hi))


def _pars(bounds: Mapping[str, Sequence[float]]) -> List[_Par]:
    out = []
    for name, b in bounds.items():
        try:
            lo, hi = float(b[0]), float(b[1])
        except (TypeError, ValueError, IndexError):
            raise ValueError(f"bounds of {name!r} must be (lo, hi); got {b!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"bounds of {name!r} = {b!r}: need finite lo < hi")
        out.append(_Par(name, lo, hi, lo > 0))
    return out


@dataclass
class FitState:
    """A fitted model: ``params`` (all, SI), ``free`` (names fitted), ``z`` (z-scores of the
    fit observations), ``chi2``, ``jacobian`` (dz/du, u = ln p for positive parameters),
    ``iterations``, ``n_evaluations`` (parameter points tried)."""

    params: Dict[str, float]
    free: List[str]
    z: np.ndarray
    chi2: float
    jacobian: np.ndarray
    iterations: int
    n_evaluations: int


def _zscores_many(sim: Simulator, params_list: Sequence[Mapping[str, float]], data: Dataset) -> List[np.ndarray]:
    out = []
    for preds in sim.predict_many(list(params_list), data.conditions):
        pred = np.array([preds[o.condition].value(o) for o in data.observations])
        z = (pred - data.values) / data.sds
        out.append(np.where(np.isfinite(z), z, np.nan))
    return out


def _zscores(sim: Simulator, params: Mapping[str, float], data: Dataset) -> np.ndarray:
    return _zscores_many(sim, [params], data)[0]


def _chi2(z: np.ndarray) -> float:
    return float(np.sum(z ** 2)) if np.all(np.isfinite(z)) else math.inf


def fit_model(sim: Simulator, data: Dataset, bounds: Mapping[str, Sequence[float]],
              start: Mapping[str, float], fixed: Optional[Mapping[str, float]] = None, *,
              max_iter: int = 4, tol: float = 0.01, fd_step: float = 0.1,
              log: Optional[Callable[[str], None]] = None) -> FitState:
    """Levenberg-Marquardt fit of the parameters in ``bounds`` ((lo, hi), SI; positive
    bounds are fitted in log space) to ``data``, from ``start``, with ``fixed`` parameters
    held. Forward-difference Jacobians (step ``fd_step`` in ln p for positive parameters:
    10% by default, wide enough to see through a DEM pellet's run-to-run jitter). Stops after
    ``max_iter`` iterations or when chi-square improves by less than ``tol`` (relative), or
    when 8 ever more damped steps (damping x5 each) all fail to lower it.
    """
    pars = _pars(bounds)
    fixed = dict(fixed or {})
    for p in pars:
        if p.name not in start:
            raise ValueError(f"start has no value for {p.name!r}")
        v = float(start[p.name])
        if not p.lo <= v <= p.hi:
            raise ValueError(f"start {p.name} = {v} is outside its bounds [{p.lo}, {p.hi}]")
    if not isinstance(max_iter, int) or max_iter < 0:
        raise ValueError(f"max_iter = {max_iter!r} must be an integer >= 0")
    if not (isinstance(fd_step, (int, float)) and 1e-6 <= fd_step <= 1):
        raise ValueError(f"fd_step = {fd_step!r} is out of range: allowed 1e-6 <= fd_step <= 1")
    say = log or (lambda s: None)
    u = np.array([p.to_u(float(start[p.name])) for p in pars])
    n_eval = 0

    def params_of(uu):
        d = dict(fixed)
        d.update({p.name: p.to_v(x) for p, x in zip(pars, uu)})
        return d

    def evaluate(uu):
        nonlocal n_eval
        n_eval += 1
        return _zscores(sim, params_of(uu), data)

    def jac(uu, z0):
        nonlocal n_eval
        shifted = []
        for k, p in enumerate(pars):
            h = p.step(fd_step)
            du = uu.copy()
            du[k] = uu[k] + h if uu[k] + h <= p.to_u(p.hi) else uu[k] - h
            shifted.append(du)
        n_eval += len(shifted)
        cols = []
        for k, (du, zk) in enumerate(zip(shifted, _zscores_many(sim, [params_of(d) for d in shifted], data))):
            col = (zk - z0) / (du[k] - uu[k])
            cols.append(np.where(np.isfinite(col), col, 0.0))
        return np.array(cols).T if cols else np.zeros((len(z0), 0))

    z = evaluate(u)
    chi = _chi2(z)
    if not math.isfinite(chi):
        raise RuntimeError("the start point's simulations failed; choose another start")
    J = jac(u, z) if pars else np.zeros((len(z), 0))
    lam = 1e-2
    it = 0
    for it in range(1, max_iter + 1):
        if not pars:
            break
        g = J.T @ z
        A = J.T @ J
        improved = False
        # Up to 8 tries, the damping x5 each (to ~4e3 x its value): a pellet's response is far
        # from linear, and the first Gauss-Newton steps from a poor start can overshoot by a
        # factor of several (seen on the paper's data: three tries, all worse, stopped the fit
        # where it started).
        for _ in range(8):
            step = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), -g)
            step = np.clip(step, -1.0, 1.0) if all(p.log for p in pars) else step
            un = np.array([p.clip_u(x) for p, x in zip(pars, u + step)])
            if np.allclose(un, u):
                break
            zn = evaluate(un)
            cn = _chi2(zn)
            say(f"    try (damping {lam:.3g}): chi2 = {cn:.2f}")
            if cn < chi:
                improved = True
                rel = (chi - cn) / max(chi, 1e-300)
                u, z, chi = un, zn, cn
                lam = max(lam / 3, 1e-4)
                break
            lam *= 5
        say(f"  iteration {it}: chi2 = {chi:.2f} " + ", ".join(f"{p.name} = {p.to_v(x):.4g}" for p, x in zip(pars, u)))
        if not improved or rel < tol:
            break
        J = jac(u, z)
    return FitState(params_of(u), [p.name for p in pars], z, chi, J, it, n_eval)


# --------------------------------------------------------------------------------------
# The loop
# --------------------------------------------------------------------------------------

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


def _orth(J: np.ndarray, v: np.ndarray) -> np.ndarray:
    if J.size == 0:
        return v
    coef, *_ = np.linalg.lstsq(J, v, rcond=None)
    return v - J @ coef


def _model_jitter(sim: Simulator, data: Dataset, params: Mapping[str, float], names: Sequence[str],
                  rel: float = 1e-3) -> np.ndarray:
    """The model's own scatter per observation (its unit): predictions at the base parameters
    all raised and all lowered by ``rel``. A smooth model changes by ~rel there; a DEM pellet
    breaks its bonds in another order and its curve jitters by as much as a new packing would.
    Half the squared difference, pooled over each curve (condition and quantity), estimates
    the jitter's variance."""
    up = {**params, **{k: params[k] * (1 + rel) for k in names}}
    down = {**params, **{k: params[k] * (1 - rel) for k in names}}
    zu, zd = _zscores_many(sim, [up, down], data)
    d = (zu - zd) * data.sds
    d = np.where(np.isfinite(d), d, 0.0)
    out = np.zeros(len(data))
    groups: Dict[tuple, List[int]] = {}
    for i, o in enumerate(data.observations):
        groups.setdefault((o.condition, o.quantity), []).append(i)
    for idx in groups.values():
        out[idx] = math.sqrt(float(np.mean(d[idx] ** 2)) / 2.0)
    return out


def _profile_start(sim: Simulator, data: Dataset, base: FitState, eff: Effect,
                   base_bounds: Mapping[str, Sequence[float]], linear: float, points: int) -> Dict[str, float]:
    """Start of a refit: the effect's strength on a grid over its bounds (plus the first-order
    estimate), each with the base parameters moved by one Gauss-Newton step on the baseline's
    Jacobian; the best of all these points. A DEM objective is too rough for a local fit to
    find a strength from far away.

    A strength at which every prediction equals the baseline's (the effect never acts: a
    plate yield stress no contact reaches) is left out, with its step, while another strength
    is usable: a refit started there has no gradient in the effect's parameter, and the
    baseline's own step, which any such point gets, would win whenever the baseline is not
    quite at its minimum."""
    pars = _pars(base_bounds)
    grid = list(np.geomspace(eff.lo, eff.hi, points) if eff.log else np.linspace(eff.lo, eff.hi, points))
    grid.append(min(max(linear, eff.lo * (1.01 if eff.log else 1.0)), eff.hi))
    first = [{**base.params, **eff.settings(v)} for v in grid]
    zs = _zscores_many(sim, first, data)
    inactive = [bool(np.all(np.isfinite(z))) and np.allclose(z, base.z, rtol=1e-12, atol=1e-12) for z in zs]
    second, second_inactive = [], []
    for pset, z, off in zip(first, zs, inactive):
        if not np.all(np.isfinite(z)) or base.jacobian.size == 0:
            continue
        du, *_ = np.linalg.lstsq(base.jacobian, -z, rcond=None)
        q = dict(pset)
        for p, d in zip(pars, np.clip(du, -0.7, 0.7)):
            q[p.name] = p.to_v(p.clip_u(p.to_u(pset[p.name]) + d))
        second.append(q)
        second_inactive.append(off)
    tried = first + second
    chis = np.array([_chi2(z) for z in zs + _zscores_many(sim, second, data)])
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
            say(f"model jitter (base parameters +-0.1%): rms {np.sqrt(np.mean((jit / np.maximum(np.abs(both.values), 1e-300)) ** 2)):.3f} "
                "of the measured values, added to the SDs in quadrature")
            # The SDs changed, so the chi-square did: the baseline is refitted with them, as
            # every candidate will be, or a candidate would win by the refit alone.
            say("baseline refitted with those SDs")
            base = fit_model(sim, fit_data, base_bounds, base.params, fixed, max_iter=max_iter, fd_step=fd_step,
                             log=say)
    res0 = _residual(fit_data, base.z, k0, alpha)
    for s in res0.lines():
        say("  " + s)
    z_held0 = _zscores(sim, base.params, heldout_data)
    chi_held0 = _chi2(z_held0)
    bic0 = base.chi2 + k0 * math.log(n_fit)
    say(f"held-out: chi2/n = {chi_held0 / len(heldout_data):.2f} on {len(heldout_data)} points")

    candidates: List[Candidate] = []
    chosen, verdict, final, res_final, z_held_final = None, "", base, res0, z_held0
    if not res0.structured:
        verdict = ("the baseline's residual is consistent with the replicate scatter: "
                   "nothing to explain, no effect added")
    else:
        r_perp = _orth(base.jacobian, base.z)
        conds = fit_data.conditions
        usable = [e for e in library.values() if not (e.needs and len({getattr(c, e.needs) for c in conds}) < 2)]
        probes = _zscores_many(sim, [{**base.params, **e.settings(e.probe)} for e in usable], fit_data)
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
            s_perp = _orth(base.jacobian, sig)
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
            st = _profile_start(sim, fit_data, base, eff, base_bounds, c.linear_strength, profile_points)
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
            c.heldout_z = _zscores(sim, c.fit.params, heldout_data)
            c.heldout_chi2 = _chi2(c.heldout_z)
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
                "heldout_chi2_per_point": _chi2(zh) / len(heldout_data), "heldout_rrmse": _rrmse(heldout_data, zh),
                "n_params": float(len(fs.free))}

    errors = {"baseline": errs(base, z_held0)}
    if chosen is not None:
        errors[f"baseline + {chosen}"] = errs(final, z_held_final)
    return LoopResult(fit_data, heldout_data, base, res0, z_held0, candidates, chosen, verdict, final, res_final,
                      z_held_final, errors, sim.n_simulations, time.perf_counter() - t0, lines)


# --------------------------------------------------------------------------------------
# Synthetic data with a hidden effect
# --------------------------------------------------------------------------------------

def synthetic_dataset(sim: Simulator, truth: Mapping[str, float], conditions: Sequence[Condition], *,
                      noise: float = 0.05, replicates: int = 5, points: int = 12,
                      quantities: Sequence[str] = ("sigma_1", "sigma_f", "dLf_D", "bulk_density"),
                      compaction_points: int = 0, seed: int = 0, name: str = "synthetic") -> Dataset:
    """"Measured" data made by ``sim`` with parameters ``truth`` (which may switch on any
    effect, in the library or not), with Gaussian noise of relative SD ``noise`` per replicate
    (curve points: relative to the curve's peak), ``replicates`` replicates averaged, so the
    reported SD is the replicates' sample SD. ``points`` points per diametral curve from
    0.1 to 1.6 x its failure point (within the simulated range); ``compaction_points`` on the
    compaction curve (0: none). Nothing in the returned Dataset says which effect made it.
    """
    if not (isinstance(noise, (int, float)) and 0 <= noise < 1):
        raise ValueError(f"noise = {noise!r} is out of range: allowed 0 <= noise < 1")
    if not isinstance(replicates, int) or not 2 <= replicates <= 100:
        raise ValueError(f"replicates = {replicates!r} is out of range: allowed 2 <= replicates <= 100")
    rng = np.random.default_rng(seed)
    preds = sim.predict(dict(truth), list(conditions))
    obs = []

    def noisy(mean: float, scale: float) -> Tuple[float, float]:
        draws = mean + noise * scale * rng.standard_normal(replicates)
        return float(draws.mean()), float(draws.std(ddof=1))

    for c in conditions:
        p = preds[c]
        if not p.ok:
            raise RuntimeError(f"the truth's simulation of {c.label} failed: {p.error}")
        x_f = p.scalars.get("dLf_D", float("nan"))
        if "sigma_1" in quantities and p.curve is not None:
            x, y = np.asarray(p.curve[0]), np.asarray(p.curve[1])
            top = float(np.max(y))
            hi = min(1.6 * x_f, float(x.max()))
            for xi in np.linspace(0.1 * x_f, hi, points):
                m, s = noisy(float(np.interp(xi, x, y)), top)
                obs.append(Observation(c, "sigma_1", float(xi), m, s, replicates, _diametral_part(xi, x_f)))
        if compaction_points and p.compaction is not None:
            x, y = np.asarray(p.compaction[0]), np.asarray(p.compaction[1])
            order = np.argsort(x)
            x, y = x[order], y[order]
            top = float(np.max(y))
            for xi in np.linspace(0.3 * x.max(), x.max(), compaction_points):
                m, s = noisy(float(np.interp(xi, x, y)), top)
                obs.append(Observation(c, "sigma_z", float(xi), m, s, replicates,
                                       "compaction-low" if xi < COMPACTION_SPLIT else "compaction-high"))
        for q in ("sigma_f", "dLf_D", "bulk_density"):
            if q in quantities and math.isfinite(p.scalars.get(q, float("nan"))):
                v = p.scalars[q]
                m, s = noisy(v, abs(v))
                obs.append(Observation(c, q, float("nan"), m, s, replicates))
    return Dataset(obs, name)
