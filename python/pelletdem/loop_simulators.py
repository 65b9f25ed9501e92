"""Simulators for the discrepancy loop: parameters -> a :class:`Prediction` per condition.

:class:`Simulator` is the interface the loop's fits call (:meth:`Simulator.predict`, and
:meth:`Simulator.predict_many` for a Jacobian's columns at once). :class:`EngineSimulator`
runs the C++ pellet through the calibration's run cache, relaxed-pellet reuse and executors
(:mod:`pelletdem.runs`, :mod:`pelletdem.execution`); :class:`FunctionSimulator` wraps any
Python function (used by fast tests with an analytic model, and for surrogate models).
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .engine import BondLaw
from .execution import Evaluator, open_executor, with_relaxed_dir
from .loop_data import COMPACTION_SPLIT, Condition, Dataset, Observation, diametral_part
from .run_cache import RunCache
from .runs import make_spec, run_setup
from .worker import run_point

__all__ = ["Prediction", "Simulator", "FunctionSimulator", "EngineSimulator", "synthetic_dataset"]


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
        return make_spec(base, preset=self.setup.preset, sigma_z=cond.sigma_z, seed=seed, bond=law,
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
                obs.append(Observation(c, "sigma_1", float(xi), m, s, replicates, diametral_part(xi, x_f)))
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
