"""Least-squares machinery shared by the calibration's :func:`pelletdem.search.fit` and the
discrepancy loop's :func:`pelletdem.loop_fit.fit_model`.

Both fit a few positive physical parameters (moduli and strengths in Pa, stiffnesses in
N/m, dimensionless gains) to z-scores of simulated against measured values, in log space
within bounds, with simulations too costly and too noisy for a generic optimiser. What
they share lives here:

* :class:`BoundedParameter` / :func:`bounded_parameters`: a parameter's bounds and the
  coordinate ``u`` a fit moves in (``u = ln p`` for positive bounds, ``u = p`` otherwise).
* Finite differences: :func:`bounded_fd_step` (a forward step, taken backwards where it
  would leave the upper bound), :func:`fd_points` and :func:`fd_jacobian`.
* Damped linearised steps: :func:`levenberg_step` (damping ``lam * I``, the calibration's)
  and :func:`marquardt_step` (damping ``lam * diag(J^T J)``, the loop's), the undamped
  :func:`gauss_newton_step`, and :func:`orthogonal_part` (what a Jacobian's columns cannot
  explain).
* :func:`chi_square`, :func:`local_affine_model` (the calibration's noise-tolerant local
  model of log outputs) and :func:`nelder_mead_in_box` (scipy's Nelder-Mead on a box).

The two fits keep their own iterations (a trust-region search on a local model with
scaling-law slopes for the calibration, Levenberg-Marquardt on finite differences for the
loop): they step differently, so one driver for both would change what either computes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, List, Mapping, Optional, Sequence, Tuple

import numpy as np

__all__ = [
    "BoundedParameter", "bounded_parameters", "bounded_fd_step", "fd_points", "fd_jacobian",
    "chi_square", "levenberg_step", "marquardt_step", "gauss_newton_step", "orthogonal_part",
    "local_affine_model", "nelder_mead_in_box",
]


@dataclass(frozen=True)
class BoundedParameter:
    """A fitted parameter ``name`` within [``lo``, ``hi``] (its own unit, SI). ``log``: the fit
    moves in ``u = ln p`` (positive bounds), else in ``u = p``."""

    name: str
    lo: float
    hi: float
    log: bool

    def to_u(self, v: float) -> float:
        """The fit coordinate of value ``v`` (ln v in log space, else v)."""
        return math.log(v) if self.log else v

    def to_v(self, u: float) -> float:
        """The value (the parameter's unit) at fit coordinate ``u``."""
        return math.exp(u) if self.log else u

    def step(self, rel: float) -> float:
        """Finite-difference step in ``u`` for a relative step ``rel`` (-): ``rel`` itself in
        log space, else ``rel`` times half the bounds' width."""
        return rel if self.log else rel * 0.5 * (self.hi - self.lo)

    def clip_u(self, u: float) -> float:
        """``u`` moved into the bounds."""
        return min(max(u, self.to_u(self.lo)), self.to_u(self.hi))


def bounded_parameters(bounds: Mapping[str, Sequence[float]]) -> List[BoundedParameter]:
    """One :class:`BoundedParameter` per ``{name: (lo, hi)}`` entry (the parameter's unit),
    in log space when lo > 0. ValueError naming the parameter for bounds that are not
    finite numbers with lo < hi."""
    out = []
    for name, b in bounds.items():
        try:
            lo, hi = float(b[0]), float(b[1])
        except (TypeError, ValueError, IndexError):
            raise ValueError(f"bounds of {name!r} must be (lo, hi); got {b!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"bounds of {name!r} = {b!r}: need finite lo < hi")
        out.append(BoundedParameter(name, lo, hi, lo > 0))
    return out


def bounded_fd_step(u: float, h: float, upper: float) -> float:
    """The signed finite-difference step from ``u``: ``+h`` when ``u + h`` stays at or below
    ``upper``, else ``-h`` (same unit as ``u``)."""
    return h if u + h <= upper else -h


def fd_points(u: np.ndarray, params: Sequence[BoundedParameter], rel_step: float) -> List[np.ndarray]:
    """The points of a forward-difference Jacobian at ``u``: one per parameter, its
    coordinate moved by ``params[k].step(rel_step)`` (backwards at the upper bound)."""
    shifted = []
    for k, p in enumerate(params):
        du = u.copy()
        du[k] = u[k] + bounded_fd_step(u[k], p.step(rel_step), p.to_u(p.hi))
        shifted.append(du)
    return shifted


def fd_jacobian(u: np.ndarray, shifted: Sequence[np.ndarray], z0: np.ndarray,
                zs: Sequence[np.ndarray]) -> np.ndarray:
    """dz/du by forward differences: ``zs[k]`` are the residuals at ``shifted[k]``
    (:func:`fd_points`), ``z0`` those at ``u``. A column entry that is not finite (a failed
    simulation) is 0. Shape (len(z0), len(shifted))."""
    cols = []
    for k, (du, zk) in enumerate(zip(shifted, zs)):
        col = (zk - z0) / (du[k] - u[k])
        cols.append(np.where(np.isfinite(col), col, 0.0))
    return np.array(cols).T if cols else np.zeros((len(z0), 0))


def chi_square(z: np.ndarray) -> float:
    """Sum of squared z-scores (-); inf when any is not finite (a failed prediction)."""
    return float(np.sum(z ** 2)) if np.all(np.isfinite(z)) else math.inf


def levenberg_step(A: np.ndarray, r: np.ndarray, lam: float) -> np.ndarray:
    """The step dx minimising |r + A dx|^2 + lam |dx|^2: -(A^T A + lam I)^-1 A^T r (units of
    1 / A's columns times r's)."""
    return -np.linalg.solve(A.T @ A + lam * np.eye(A.shape[1]), A.T @ r)


def marquardt_step(JtJ: np.ndarray, g: np.ndarray, lam: float) -> np.ndarray:
    """The Levenberg-Marquardt step from the normal equations ``JtJ`` = J^T J and gradient
    ``g`` = J^T z: -(JtJ + lam diag(JtJ + 1e-12))^-1 g, each coordinate damped in
    proportion to its own curvature."""
    return np.linalg.solve(JtJ + lam * np.diag(np.diag(JtJ) + 1e-12), -g)


def gauss_newton_step(J: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The undamped least-squares step du with J du ~ -z (minimum norm where J is
    rank-deficient)."""
    du, *_ = np.linalg.lstsq(J, -z, rcond=None)
    return du


def orthogonal_part(J: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The part of ``v`` that no combination of J's columns reproduces (the least-squares
    residual of v on J); ``v`` itself for an empty J."""
    if J.size == 0:
        return v
    coef, *_ = np.linalg.lstsq(J, v, rcond=None)
    return v - J @ coef


def local_affine_model(xs: np.ndarray, ys: np.ndarray, xb: np.ndarray, prior: np.ndarray, ridge: float,
                       width: float, censored: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Affine model y ~ a + J (x - xb) of the log outputs near xb, by weighted least squares
    over the evaluated points (weight exp(-|x - xb|^2 / 2 width^2)) with J pulled towards the
    scaling-law ``prior`` (ridge). Censored values (bounds, not measurements; a boolean array
    shaped like ``ys``) count a thousand times less, so they anchor the model only where
    nothing better is known. ``xs`` (points x parameters) and ``xb`` are log parameters,
    ``ys`` (points x outputs) log outputs, ``width`` in the units of x. Returns (a, J)."""
    n = xs.shape[1]
    dx = xs - xb
    w = np.exp(-np.sum(dx * dx, axis=1) / (2.0 * width * width))
    X = np.hstack([np.ones((len(xs), 1)), dx])           # [intercept, slopes]
    R = np.diag([1e-9] + [ridge] * n)                      # ridge on the slopes only
    a, J = np.zeros(ys.shape[1]), np.zeros((ys.shape[1], n))
    for i in range(ys.shape[1]):
        wi = w if censored is None else w * np.where(censored[:, i], 1e-3, 1.0)
        lhs = X.T @ (wi[:, None] * X) + R
        rhs = X.T @ (wi * ys[:, i]) + R @ np.concatenate([[0.0], prior[i]])
        coef = np.linalg.solve(lhs, rhs)
        a[i], J[i] = coef[0], coef[1:]
    return a, J


def nelder_mead_in_box(loss: Callable[[np.ndarray], float], lo: np.ndarray, hi: np.ndarray, x0: np.ndarray,
                       tol: float, max_evals: int) -> str:
    """scipy's Nelder-Mead on ``loss(x)`` for x in the box [lo, hi], searched in coordinates
    scaled to the box, from ``x0`` with an initial simplex 15% of the box wide. Stops at the
    first loss <= ``tol`` or after ``max_evals`` calls (a non-finite loss counts as 1e6).
    Returns scipy's message, or 'loss <= tol ...'. The caller keeps the points it evaluated."""
    from scipy.optimize import minimize

    span = hi - lo

    class _Done(Exception):
        pass

    def f(u):
        v = loss(lo + np.clip(u, 0, 1) * span)
        if v <= tol:
            raise _Done
        return v if math.isfinite(v) else 1e6

    u0 = (x0 - lo) / span
    simplex = [u0]
    for j in range(len(x0)):
        u = u0.copy()
        u[j] = u[j] + 0.15 if u[j] + 0.15 <= 1 else u[j] - 0.15
        simplex.append(u)
    try:
        res = minimize(f, u0, method="Nelder-Mead", bounds=[(0, 1)] * len(x0),
                       options={"maxfev": max_evals, "initial_simplex": np.array(simplex),
                                "xatol": 0.005, "fatol": 0.01})
        return str(res.message)
    except _Done:
        return f"loss <= tol {tol}"
