"""Fitting a simulator's parameters to a dataset: :func:`fit_model`.

Levenberg-Marquardt on the z-scores of the observations (:func:`zscores`: prediction minus
measured value, over the effective SD), in log space for positive parameters, with
forward-difference Jacobians whose columns are predicted together
(:meth:`pelletdem.loop_simulators.Simulator.predict_many`). The steps and finite
differences are :mod:`pelletdem.optimize`'s, shared with the calibration's fit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Mapping, Optional, Sequence

import numpy as np

from .loop_data import Dataset
from .loop_simulators import Simulator
from .optimize import bounded_parameters, chi_square, fd_jacobian, fd_points, marquardt_step

__all__ = ["FitState", "zscores", "zscores_many", "fit_model"]


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


def zscores_many(sim: Simulator, params_list: Sequence[Mapping[str, float]], data: Dataset) -> List[np.ndarray]:
    """z-scores (-) of ``data`` under each parameter set (SI), predicted together: (predicted -
    measured) / effective SD per observation, NaN where a prediction could not be made."""
    out = []
    for preds in sim.predict_many(list(params_list), data.conditions):
        pred = np.array([preds[o.condition].value(o) for o in data.observations])
        z = (pred - data.values) / data.sds
        out.append(np.where(np.isfinite(z), z, np.nan))
    return out


def zscores(sim: Simulator, params: Mapping[str, float], data: Dataset) -> np.ndarray:
    """z-scores (-) of ``data`` under ``params`` (SI); see :func:`zscores_many`."""
    return zscores_many(sim, [params], data)[0]


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
    pars = bounded_parameters(bounds)
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
        return zscores(sim, params_of(uu), data)

    def jac(uu, z0):
        nonlocal n_eval
        shifted = fd_points(uu, pars, fd_step)
        n_eval += len(shifted)
        return fd_jacobian(uu, shifted, z0, zscores_many(sim, [params_of(d) for d in shifted], data))

    z = evaluate(u)
    chi = chi_square(z)
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
            step = marquardt_step(A, g, lam)
            step = np.clip(step, -1.0, 1.0) if all(p.log for p in pars) else step
            un = np.array([p.clip_u(x) for p, x in zip(pars, u + step)])
            if np.allclose(un, u):
                break
            zn = evaluate(un)
            cn = chi_square(zn)
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

