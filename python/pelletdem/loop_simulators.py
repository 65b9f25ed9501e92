"""Simulators for the discrepancy loop: parameters and packings -> predictions per condition.

A DEM pellet is one draw from a distribution: another packing (seed) breaks its bonds in
another order. So a simulator predicts each condition on a list of packings, and an
:class:`Ensemble` holds those predictions: for an observation it gives the mean over the
packings and its standard error from their spread (:meth:`Ensemble.mean_se`). The loop
evaluates every parameter set on the same packings (common random numbers), so differences
between parameter sets are paired.

:class:`EngineSimulator` runs the C++ pellet through the calibration's run cache,
relaxed-pellet reuse and executors (:mod:`pelletdem.runs`, :mod:`pelletdem.execution`);
:class:`FunctionSimulator` wraps a Python function of (parameters, condition, seed) (fast tests
with an analytic pellet, and users' own surrogate models).
"""
from __future__ import annotations

import contextlib
import dataclasses
import inspect
import math
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .engine import BondLaw
from .execution import Evaluator, open_executor, with_relaxed_dir
from .loop_data import Condition, Observation, split_material
from .run_cache import RunCache
from .runs import check_names, check_positive, make_spec, run_setup
from .worker import run_point

__all__ = ["Prediction", "Ensemble", "Simulator", "FunctionSimulator", "EngineSimulator", "CONDITION_ROWS",
           "refuse_condition_rows"]

# make_spec's base names and the law fields they set
_ALIASES = (("E_b", "youngs_modulus"), ("sigma_c", "sigma_c"), ("tau_c", "tau_c"), ("r_b", "radius"), ("k1", "k1"),
            ("p_y", "k1"))


@dataclass
class Prediction:
    """What a model predicts for one condition on one packing. ``curve``: (dL/D, sigma_1 Pa)
    arrays; ``compaction``: (dh/h0, sigma_z Pa); ``scalars``: sigma_f (Pa), dLf_D (-),
    bulk_density (kg/m^3), coordination_number (-), peaked (1.0 when the diametral test passed
    its peak). ``ok`` False (with ``error``) when the simulation failed."""

    curve: Optional[Tuple[np.ndarray, np.ndarray]] = None
    compaction: Optional[Tuple[np.ndarray, np.ndarray]] = None
    scalars: Dict[str, float] = field(default_factory=dict)
    ok: bool = True
    error: str = ""

    def value(self, o: Observation) -> float:
        """The prediction of observation ``o`` in its SI unit (NaN when it cannot be made)."""
        if not self.ok:
            return float("nan")
        if o.quantity in ("sigma_1", "sigma_z"):
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


@dataclass
class Ensemble:
    """One condition's predictions on several packings (``seeds``, one Prediction each)."""

    seeds: Tuple[int, ...]
    members: Tuple[Prediction, ...]

    @property
    def ok(self) -> bool:
        """True when every packing's simulation succeeded."""
        return all(m.ok for m in self.members)

    @property
    def error(self) -> str:
        """The first failed packing's error ('' when none failed)."""
        return next((m.error for m in self.members if not m.ok), "")

    def values(self, o: Observation) -> np.ndarray:
        """Observation ``o`` predicted on each packing (its SI unit)."""
        return np.array([m.value(o) for m in self.members], float)

    def mean_se(self, o: Observation) -> Tuple[float, float]:
        """The mean over the packings of observation ``o`` and the standard error of that
        mean, SD / sqrt(k) (0 for one packing), both in the observation's SI unit."""
        v = self.values(o)
        if not np.all(np.isfinite(v)):
            return float("nan"), float("nan")
        return float(v.mean()), (float(v.std(ddof=1) / math.sqrt(len(v))) if len(v) > 1 else 0.0)

    def scalar(self, name: str) -> float:
        """A scalar output averaged over the packings (NaN when missing)."""
        v = [m.scalars.get(name, float("nan")) for m in self.members]
        return float(np.mean(v)) if v else float("nan")


class Simulator:
    """Predicts observations from parameters on given packings. Subclasses implement
    :meth:`predict_many`."""

    #: Packings a prediction is averaged over when no seeds are given.
    default_seeds: Tuple[int, ...] = (0,)

    def predict(self, params: Mapping[str, float], conditions: Sequence[Condition],
                seeds: Optional[Sequence[int]] = None) -> Dict[Condition, Ensemble]:
        """Predictions for each condition under ``params`` (base names, ``contact.x``,
        ``bond.x``, SI) on the packings ``seeds`` (default :attr:`default_seeds`)."""
        return self.predict_many([params], conditions, seeds)[0]

    def predict_many(self, params_list: Sequence[Mapping[str, float]], conditions: Sequence[Condition],
                     seeds: Optional[Sequence[int]] = None) -> List[Dict[Condition, Ensemble]]:
        """:meth:`predict` for several parameter sets (a simulator with workers runs them all
        at once)."""
        raise NotImplementedError

    @property
    def n_simulations(self) -> int:
        """Simulations run so far (cache hits not counted)."""
        return 0

    def same_relaxation(self, a: Mapping[str, float], b: Mapping[str, float],
                        conditions: Sequence[Condition]) -> bool:
        """Whether the parameter sets ``a`` and ``b`` (SI) run from the same relaxed pellets
        (fill to relaxation) at every condition and packing, so that a design may let two of
        its points share one. False where the simulator cannot tell."""
        return False

    def base_rows(self) -> Dict[str, float]:
        """The law rows its base model sets itself ({'contact.x': v, 'bond.y': w}, SI; a
        manifest's or ``--set`` values): a candidate effect whose row is among them is part of
        the model already. None known by default."""
        return {}

    def refusal(self, params: Mapping[str, float], conditions: Sequence[Condition]) -> str:
        """Why ``params`` (SI) cannot run at ``conditions`` (the laws' own checks, before any
        simulation: two laws of the unloading stiffness at once, for instance); "" when they
        can, and by default."""
        return ""

    def close(self) -> None:
        """Release workers (no-op by default)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


#: The widest diametral test window (dL/D) a simulator is widened to.
MAX_WINDOW = 0.5


def next_window(sim: Simulator) -> Optional[float]:
    """The end of ``sim``'s diametral test after one widening (x 1.5, at most
    :data:`MAX_WINDOW`), or None where it cannot widen (no ``widen`` method, or already at
    MAX_WINDOW): a test that ended before its pellet broke shows no failure."""
    end = getattr(sim, "max_dLD", math.nan)
    if getattr(sim, "widen", None) is None or not end < MAX_WINDOW:
        return None
    return min(MAX_WINDOW, 1.5 * end)


class FunctionSimulator(Simulator):
    """A simulator from a Python function ``fn(params, condition, seed) -> Prediction`` (a
    function of (params, condition) is taken too: it then predicts the same on every packing).
    Repeated calls are memoised. ``packing_params``: the parameters that change the packing
    itself, as a compaction parameter does in the DEM (None: not known); two parameter sets
    that agree on them share their packings (:meth:`same_relaxation`)."""

    def __init__(self, fn: Callable[..., Prediction], default_seeds: Sequence[int] = (0,),
                 packing_params: Optional[Sequence[str]] = None):
        if not callable(fn):
            raise ValueError("fn must be callable")
        self.packing_params = None if packing_params is None else tuple(packing_params)
        try:
            n_args = len(inspect.signature(fn).parameters)
        except (TypeError, ValueError):
            n_args = 3
        self.fn = fn if n_args >= 3 else (lambda p, c, s: fn(p, c))
        self.default_seeds = tuple(int(s) for s in default_seeds)
        self._n = 0
        self._memo: Dict[tuple, Prediction] = {}

    def same_relaxation(self, a, b, conditions) -> bool:
        """Whether ``a`` and ``b`` agree on every one of :attr:`packing_params` (False where
        those are not known)."""
        if self.packing_params is None:
            return False
        return all(float(a.get(p, math.nan)) == float(b.get(p, math.nan)) or (p not in a and p not in b)
                   for p in self.packing_params)

    def predict_many(self, params_list, conditions, seeds=None):
        """Calls ``fn`` once per new (params, condition, seed)."""
        seeds = tuple(self.default_seeds if seeds is None else seeds)
        out = []
        for params in params_list:
            key0 = tuple(sorted((k, float(v)) for k, v in params.items()))
            d = {}
            for c in conditions:
                members = []
                for s in seeds:
                    key = (key0, c, s)
                    if key not in self._memo:
                        self._n += 1
                        self._memo[key] = self.fn(dict(params), c, s)
                    members.append(self._memo[key])
                d[c] = Ensemble(seeds, tuple(members))
            out.append(d)
        return out

    @property
    def n_simulations(self) -> int:
        """Function evaluations (memo hits not counted)."""
        return self._n


#: Law rows each condition sets: its moisture content, its material's wood density.
CONDITION_ROWS = {"contact.moisture_content": "moisture content (mc)",
                  "contact.wood_density": "material's particle density (BD_w)"}


def refuse_condition_rows(names, flag: str = "") -> None:
    """ValueError when one of ``names`` is a row each condition sets (:data:`CONDITION_ROWS`)."""
    for n in names:
        if n in CONDITION_ROWS:
            raise ValueError(f"{flag + ' ' if flag else ''}{n} is set by each condition's {CONDITION_ROWS[n]}: "
                             "do not set or fit it")


class EngineSimulator(Simulator):
    """The C++ pellet: fill -> compact (the condition's sigma_z) -> ... -> diametral test,
    through the calibration's run cache, relaxed-pellet reuse and executors
    (:mod:`pelletdem.runs`, :mod:`pelletdem.execution`).

    ``preset``: name or Preset; ``bond``: base BondLaw; ``contact``: ContactLaw field
    overrides; ``seeds``: the default packings; ``max_dLD``: end of the test; ``break_drop``:
    end the test once the plate force has fallen to this fraction of its peak (0: off; the
    failure and the first part of the fall are what the data show); ``executor`` /
    ``max_workers``: as in :func:`pelletdem.calibrate.scan` ('serial' runs here);
    ``cache_dir``: run cache directory (resumable); ``relaxed_dir``: relaxed-pellet
    checkpoints. Parameters: base names of :data:`pelletdem.calibrate.PARAMETERS`, optionally
    per material as ``name[material]``, and any ``contact.<field>`` / ``bond.<field>``. The
    condition's moisture content is the contact law's (``contact.moisture_content``), which the
    bonds take too. ``particle_density``: {material: the particles' density, kg/m^3} for
    conditions of those materials (others keep the preset's): the pellet's mechanics are
    quasi-static (the mass is scaled for the time step), so a material's density changes the
    bulk density its relaxed packing has, not the packing: the predicted bulk density is the
    simulated one times the material's density over the preset's, and one relaxed pellet serves
    every material, unless the yield depends on the wood's density (``contact.wood_density_yield``
    not 0): the condition's ``contact.wood_density`` is then its material's density, and each
    material relaxes its own pellets.
    """

    def __init__(self, preset="tiny", *, bond=None, contact: Optional[Mapping[str, float]] = None,
                 seeds: Sequence[int] = (0,), max_dLD: Optional[float] = None, break_drop: float = 0.0,
                 executor="serial", max_workers: Optional[int] = None, cache_dir=None, relaxed_dir=None,
                 particle_density: Optional[Mapping[str, float]] = None):
        self.setup = run_setup(preset, bond if bond is not None else BondLaw(), dict(contact or {}),
                               tuple(seeds), max_dLD)
        self._density = {str(m): check_positive(f"particle_density[{m}]", v, "kg/m^3")
                         for m, v in (particle_density or {}).items()}
        self._density_factor = {m: v / self.setup.preset.density for m, v in self._density.items()}
        if break_drop:
            self.end_at_break(break_drop)
        self.default_seeds = tuple(int(s) for s in seeds)
        self._stack = contextlib.ExitStack()
        ex = self._stack.enter_context(open_executor(executor, max_workers))
        runner = with_relaxed_dir(run_point, relaxed_dir)
        self.evaluator = Evaluator(RunCache(cache_dir), ex, runner, relaxed_shared=relaxed_dir is not None)

    def close(self) -> None:
        """Shut the executor down."""
        self._stack.close()

    @property
    def max_dLD(self) -> float:
        """The end of the diametral test, dL/D (-)."""
        return float(self.setup.max_dLD if self.setup.max_dLD is not None else self.setup.preset.max_dLD)

    def widen(self, max_dLD: float) -> None:
        """Run later diametral tests to ``max_dLD`` (-): further for a test that ended before its
        peak, shorter where the data stop sooner."""
        self.setup = dataclasses.replace(self.setup, max_dLD=float(max_dLD))

    def end_at_break(self, drop: float) -> None:
        """End later diametral tests once the plate force has fallen to ``drop`` (0 < drop < 1)
        of its peak: where only the failure is measured, the rest of a test costs time."""
        if not 0.0 < drop < 1.0:
            raise ValueError(f"break_drop = {drop!r} is out of range: allowed 0 < break_drop < 1")
        self.setup = dataclasses.replace(self.setup, preset=self.setup.preset.with_(break_drop=float(drop)))

    @property
    def n_simulations(self) -> int:
        """Simulations run now (the cache's hits are not counted)."""
        return self.evaluator.n_run

    def base_rows(self) -> Dict[str, float]:
        """The contact-law rows given to it (``contact=``) and the bond law's fields that differ
        from :class:`BondLaw`'s defaults, as {'contact.x': v, 'bond.y': w} (SI)."""
        rows = {f"contact.{k}": v for k, v in (self.setup.contact or {}).items()}
        default = BondLaw()
        for f in dataclasses.fields(BondLaw):
            if getattr(self.setup.bond, f.name) != getattr(default, f.name):
                rows[f"bond.{f.name}"] = getattr(self.setup.bond, f.name)
        return rows

    def refusal(self, params, conditions) -> str:
        """The laws' refusal of ``params`` at any of ``conditions`` (their runs' specs are made,
        nothing is simulated); "" when every one can run."""
        try:
            for c in conditions:
                self._spec(params, c, self.default_seeds[0])
        except ValueError as err:
            return str(err)
        return ""

    def same_relaxation(self, a, b, conditions) -> bool:
        """Whether ``a`` and ``b`` (SI) give the same relaxed pellets: the same relax key of
        their runs (:attr:`pelletdem.runs.RunSpec.relax_key`) at every condition."""
        seed = self.default_seeds[0]
        return all(self._spec(a, c, seed).relax_key == self._spec(b, c, seed).relax_key for c in conditions)

    def _spec(self, params: Mapping[str, float], cond: Condition, seed: int):
        base, contact, bond = {}, dict(self.setup.contact or {}), {}
        for name, v in params.items():
            if name.startswith("contact."):
                contact[name[8:]] = v
            elif name.startswith("bond."):
                bond[name[5:]] = v
            elif "[" in name:
                root, group = split_material(name)
                if group == cond.material:
                    base[root] = v
            else:
                base[name] = v
        refuse_condition_rows([*params, *(f"contact.{k}" for k in contact)])
        contact["moisture_content"] = float(cond.mc)
        if dataclasses.replace(self.setup.preset.contact, **contact).to_core().wood_density_acts():
            if cond.material not in self._density:
                raise ValueError(f"the wood's density acts (wood_density_yield) but material {cond.material!r} "
                                 f"has no particle_density: give one (kg/m^3) for each of the data's materials")
            contact["wood_density"] = self._density[cond.material]
        for alias, fld in _ALIASES:
            if alias in base and fld in (contact if fld in ("k1",) else bond):
                raise ValueError(f"{alias} and {'contact' if fld == 'k1' else 'bond'}.{fld} both set: give one")
        spec = make_spec(base, preset=self.setup.preset, sigma_z=cond.sigma_z, seed=seed, bond=self.setup.bond,
                         contact=contact, max_dLD=self.setup.max_dLD)
        check_names(bond, {f.name: f for f in dataclasses.fields(BondLaw)}, "bond law field")
        # the law's own fields last: make_spec's aliases (sigma_c sets tau_c) must not undo them
        law = dataclasses.replace(spec.bond, **bond)
        law.to_core()
        return dataclasses.replace(spec, bond=law)

    def predict_many(self, params_list, conditions, seeds=None):
        """Every (parameter set, condition, packing) run (or fetched from the cache) together,
        so the workers share them out."""
        seeds = tuple(self.default_seeds if seeds is None else seeds)
        specs = [(k, c, s, self._spec(p, c, s)) for k, p in enumerate(params_list) for c in conditions
                 for s in seeds]
        recs = self.evaluator.run_all([sp for _, _, _, sp in specs])
        by_key = {(k, c, s): rec for (k, c, s, _), rec in zip(specs, recs)}
        return [{c: Ensemble(seeds, tuple(_prediction(by_key[(k, c, s)], self._density_factor.get(c.material, 1.0))
                                          for s in seeds)) for c in conditions}
                for k in range(len(params_list))]


def _prediction(rec: dict, density_factor: float = 1.0) -> Prediction:
    """One run record (pelletdem.worker.run_point) as a Prediction; ``density_factor``: the
    material's particle density over the simulated one (-)."""
    if not rec["ok"]:
        return Prediction(ok=False, error=rec.get("error") or "failed")
    outs = rec["outputs"]
    sc = {key: float(outs.get(out, float("nan"))) for key, out in (
        ("sigma_f", "sigma_f"), ("dLf_D", "dLf_D"), ("bulk_density", "bulk_density_relaxed"),
        ("coordination_number", "coordination_number_relaxed_bulk"), ("peaked", "peaked"))}
    sc["bulk_density"] *= density_factor
    curve = rec.get("curve") or {}
    comp = rec.get("compaction_curve") or {}
    return Prediction((np.asarray(curve.get("dL_D", []), float), np.asarray(curve.get("sigma_1", []), float)),
                      (np.asarray(comp.get("dh_h0", []), float), np.asarray(comp.get("sigma_z", []), float)), sc)
