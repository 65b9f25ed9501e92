"""A smooth surrogate of the stochastic pellet: a Gaussian-process emulator over the parameters.

The fits never take finite differences of single noisy simulations (a 0.1 % change of a bond
parameter breaks the bonds in another order). Instead each model is simulated once on a
space-filling design of its parameters (a scrambled Sobol sequence, :func:`design`), every
design point on the same packings; one Gaussian process per observed number (scikit-learn,
an anisotropic squared-exponential kernel plus a noise term, with each point's own standard
error from the packings' spread as known noise) then predicts the ensemble mean and its
uncertainty anywhere in the box (:meth:`Emulator.predict`). Fits, Jacobians, profiles and
detection power are all taken on the emulator.

Parameters live in a box (:class:`Space`): each axis (:class:`Axis`) maps its physical range
to [0, 1], in log space for positive ranges spanning a factor (E_b, sigma_c, most effect
strengths) and linearly otherwise. Positive outputs are emulated in log space, so their
relative scatter is what the noise term sees.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

__all__ = ["Axis", "Space", "design", "Emulator"]


@dataclass(frozen=True)
class Axis:
    """One fitted parameter: ``name`` (a simulator parameter), bounds ``lo`` < ``hi`` (SI) and
    whether it lives in log space (``log``; needs lo > 0)."""

    name: str
    lo: float
    hi: float
    log: bool = True

    def __post_init__(self):
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.lo < self.hi):
            raise ValueError(f"{self.name}: bounds ({self.lo}, {self.hi}) must be finite with lo < hi")
        if self.log and self.lo <= 0:
            raise ValueError(f"{self.name}: a log-space axis needs lo > 0, got {self.lo}")

    def to_unit(self, v: float) -> float:
        """Physical value (SI) -> position in [0, 1] (outside for values out of bounds)."""
        if self.log:
            return (math.log(v) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo))
        return (v - self.lo) / (self.hi - self.lo)

    def from_unit(self, u: float) -> float:
        """Position in [0, 1] -> physical value (SI)."""
        if self.log:
            return math.exp(math.log(self.lo) + u * (math.log(self.hi) - math.log(self.lo)))
        return self.lo + u * (self.hi - self.lo)

    def relative_scale(self) -> float:
        """d ln(value) / du for log axes, (hi - lo) for linear ones: turns a unit-space
        standard error into a relative (log) or absolute one."""
        return math.log(self.hi / self.lo) if self.log else self.hi - self.lo


@dataclass(frozen=True)
class Space:
    """The box of a model's fitted parameters, with the parameters held fixed (``fixed``, SI)."""

    axes: Tuple[Axis, ...]
    fixed: Tuple[Tuple[str, float], ...] = ()

    @property
    def names(self) -> List[str]:
        """The fitted parameters' names, in axis order."""
        return [a.name for a in self.axes]

    @property
    def dim(self) -> int:
        """Number of fitted parameters."""
        return len(self.axes)

    def params(self, u: Sequence[float]) -> Dict[str, float]:
        """Every simulator parameter (SI) at unit position ``u`` (fixed ones included)."""
        out = dict(self.fixed)
        out.update({a.name: a.from_unit(float(x)) for a, x in zip(self.axes, u)})
        return out

    def unit(self, params: Mapping[str, float]) -> np.ndarray:
        """Unit position of ``params`` (the fitted names must be in it)."""
        return np.array([a.to_unit(float(params[a.name])) for a in self.axes])

    def with_axis(self, axis: Axis, fixed: Mapping[str, float] = ()) -> "Space":
        """This box with one more axis (a candidate effect's strength) and more fixed values."""
        return Space(self.axes + (axis,), tuple(dict(self.fixed, **dict(fixed)).items()))


def design(dim: int, n: int, seed: int = 0) -> np.ndarray:
    """``n`` points of a scrambled Sobol sequence in [0, 1]^dim (the first n of the next power
    of two, so the first 2^k are balanced), the same for the same (dim, n, seed)."""
    from scipy.stats import qmc

    if not (isinstance(n, int) and 2 <= n <= 4096):
        raise ValueError(f"n = {n!r} design points is out of range: allowed 2 <= n <= 4096")
    m = int(math.ceil(math.log2(n)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pts = qmc.Sobol(dim, scramble=True, seed=seed).random_base2(m)
    return pts[:n]


class _GP:
    """One fitted Gaussian process, kept as the arrays its prediction needs: the latent mean
    and variance at many points in a few array operations (scikit-learn's own predict costs
    a millisecond of overhead per call, and a fit calls it thousands of times)."""

    def __init__(self, gp):
        k = gp.kernel_
        self.kernel = k
        self.c = float(k.k1.k1.constant_value)
        self.ls = np.atleast_1d(np.asarray(k.k1.k2.length_scale, float))
        self.X = gp.X_train_ / self.ls
        self.alpha = np.asarray(gp.alpha_, float).ravel()
        self.L = gp.L_
        self.y_mean = float(np.ravel(gp._y_train_mean)[0])
        self.y_std = float(np.ravel(gp._y_train_std)[0])

    def predict(self, U: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Latent mean and variance (the white noise left out) at rows of ``U``."""
        from scipy.linalg import solve_triangular

        Z = U / self.ls
        d2 = np.sum(Z * Z, 1)[:, None] + np.sum(self.X * self.X, 1)[None, :] - 2.0 * Z @ self.X.T
        Ks = self.c * np.exp(-0.5 * np.maximum(d2, 0.0))
        mean = Ks @ self.alpha * self.y_std + self.y_mean
        V = solve_triangular(self.L, Ks.T, lower=True, check_finite=False)
        var = np.maximum(self.c - np.sum(V * V, 0), 0.0) * self.y_std ** 2
        return mean, var


class Emulator:
    """Gaussian-process emulators of ``m`` observed numbers over a :class:`Space`.

    ``U``: (n, d) design positions in [0, 1]; ``Y``: (n, m) ensemble means at them; ``SE``:
    (n, m) their standard errors (from the packings' spread). Rows with a NaN (a failed
    simulation) are left out per output. ``warm``: an emulator of the same outputs on fewer
    points (the design before a refinement), whose hyperparameters start this one's.
    ``active``: per output, the axes it depends on (None: all): an output of one material
    does not move with another material's bonds, so its process is fitted over its own axes
    only, and a design that gives every material the same bonds covers each of them.
    :meth:`predict` gives the emulated mean and its
    variance at new positions, in the outputs' units.
    """

    def __init__(self, space: Space, U: np.ndarray, Y: np.ndarray, SE: np.ndarray,
                 warm: Optional["Emulator"] = None, active: Optional[Sequence[Sequence[int]]] = None):
        self.space = space
        self.U = np.atleast_2d(np.asarray(U, float))
        self.Y = np.atleast_2d(np.asarray(Y, float))
        self.SE = np.atleast_2d(np.asarray(SE, float))
        n, m = self.Y.shape
        if self.U.shape != (n, space.dim) or self.SE.shape != (n, m):
            raise ValueError(f"design {self.U.shape}, outputs {self.Y.shape} and errors {self.SE.shape} disagree")
        every = tuple(range(space.dim))
        self.active = [every] * m if active is None else [tuple(int(i) for i in a) for a in active]
        if len(self.active) != m or any(not a or not set(a) <= set(every) for a in self.active):
            raise ValueError(f"active: one non-empty list of axes (0..{space.dim - 1}) per output ({m}) is needed")
        if warm is not None and (warm.n_outputs != m or warm.space.dim != space.dim or warm.active != self.active):
            warm = None
        self._gps: List[Optional[_GP]] = []
        self._log: List[bool] = []
        self._const: List[Optional[Tuple[float, float]]] = []
        for j in range(m):
            self._fit_one(j, warm._gps[j] if warm is not None else None)

    def _fit_one(self, j: int, warm: Optional["_GP"]) -> None:
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import RBF, WhiteKernel
        from sklearn.gaussian_process.kernels import ConstantKernel as C

        ok = np.isfinite(self.Y[:, j]) & np.isfinite(self.SE[:, j])
        y, se, U = self.Y[ok, j], self.SE[ok, j], self._columns(self.U[ok], j)
        use_log = bool(len(y) and np.all(y > 0))
        self._log.append(use_log)
        if len(y) < 3:
            raise ValueError(f"output {j}: fewer than 3 design points simulated successfully")
        t = np.log(y) if use_log else y
        te = se / y if use_log else se
        scale = float(np.std(t)) or 1.0
        if np.ptp(t) < 1e-12 * max(1.0, abs(float(np.mean(t)))):
            # a constant output (e.g. a density that no fitted parameter changes)
            self._gps.append(None)
            self._const.append((float(np.mean(t)), float(np.mean(te ** 2)) + float(np.var(t))))
            return
        d = len(self.active[j])
        if warm is not None:
            # a refinement: start from the hyperparameters the last design found
            kernel, restarts = warm.kernel, 0
        else:
            kernel = (C(1.0, (1e-3, 1e3)) * RBF(length_scale=[0.5] * d, length_scale_bounds=(0.15, 20.0))
                      + WhiteKernel(1e-4, (1e-8, 1.0)))
            restarts = 1
        gp = GaussianProcessRegressor(kernel=kernel, alpha=(te / scale) ** 2 + 1e-10, normalize_y=True,
                                      n_restarts_optimizer=restarts, random_state=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gp.fit(U, t)
        self._gps.append(_GP(gp))
        self._const.append(None)

    def _columns(self, U: np.ndarray, j: int) -> np.ndarray:
        # all axes: U itself, not a copy, whose other memory layout would change the last bits
        a = self.active[j]
        return U if len(a) == self.space.dim else U[:, list(a)]

    @property
    def n_outputs(self) -> int:
        """Number of emulated numbers."""
        return self.Y.shape[1]

    def predict(self, U: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Emulated means (p, m) and their variances (p, m) at unit positions ``U`` (p, d), in
        the outputs' units: the latent mean's uncertainty, without the packings' noise."""
        U = np.atleast_2d(np.asarray(U, float))
        p, m = U.shape[0], self.n_outputs
        mean, var = np.empty((p, m)), np.empty((p, m))
        for j, gp in enumerate(self._gps):
            if gp is None:
                mu, v = self._const[j]
                mu, v = np.full(p, mu), np.full(p, v)
            else:
                mu, v = gp.predict(self._columns(U, j))
            if self._log[j]:
                e = np.exp(mu)
                mean[:, j], var[:, j] = e, e * e * v
            else:
                mean[:, j], var[:, j] = mu, v
        return mean, var

    def noise(self) -> np.ndarray:
        """Each output's typical standard error of an ensemble mean over the design (its unit):
        the packings' scatter the design points carry, as a fraction of the mean for positive
        outputs times the output's mean."""
        out = np.empty(self.n_outputs)
        for j in range(self.n_outputs):
            y, se = self.Y[:, j], self.SE[:, j]
            ok = np.isfinite(y) & np.isfinite(se)
            if self._log[j]:
                out[j] = float(np.sqrt(np.mean((se[ok] / y[ok]) ** 2)) * np.mean(y[ok]))
            else:
                out[j] = float(np.sqrt(np.mean(se[ok] ** 2)))
        return out
