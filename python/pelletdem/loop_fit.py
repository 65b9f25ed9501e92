"""Fitting a model to measured data on its emulator (:mod:`pelletdem.loop_emulator`).

The misfit of observation i at parameters u (a position in the model's box) starts from

    t_i(u) = (mu_i(u) - y_i) / sqrt(s_i^2 + m_i^2 + v_i(u))

with y_i the measured mean and s_i its standard error (replicate SD / sqrt(n)), mu_i and v_i
the emulated ensemble mean and its variance, and m_i the standard error of the model's own
ensemble mean over its packings (the pellet's scatter between packings, which a mean over k of
them keeps at SD / sqrt(k)). An SD from five replicates is itself uncertain (a fifth of such
estimates fall below 0.6 of the true SD), so t_i is a Welch t statistic, not a normal score:
with the Welch-Satterthwaite degrees of freedom it is turned into the normal score z_i of the
same tail probability (:func:`welch_z`), and chi2 = sum z_i^2 behaves as a chi-square under
noise. chi2 = sum z_i^2 is minimised by scipy.optimize.least_squares
(trust region, bounded to the box) from several starts: the given one and the design points
that fit best. The parameters' standard errors come from the Jacobian at the optimum, turned
into relative errors on log axes: (J^T J)^-1 in the box's units when the misfits are
independent, and the sandwich (J^T J)^-1 J^T R J (J^T J)^-1 when observations that share a
pellet's packing have correlated misfits R (:mod:`pelletdem.loop_noise`): a lucky packing is
strong along its whole curve, and counting its points as independent evidence would make the
errors too small. The correlation enters only there, linearly: inverting a correlation
estimated from tens of packings would amplify its noise. Profile intervals widen by the same
factor (their chi2 threshold times the ratio of sandwich to plain variance).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence

import numpy as np

from .loop_data import Dataset
from .loop_emulator import Emulator

__all__ = ["EmulatedFit", "welch_z", "misfit", "fit_emulated", "profile_grid", "profile"]

#: Degrees of freedom of an SD pooled over a whole design (many packings at many points).
POOLED_DOF = 1e3


@dataclass
class EmulatedFit:
    """A model fitted on its emulator: ``params`` (every simulator parameter, SI), ``u`` (the
    fitted position in the box), ``z`` (misfits of the observations, -), ``chi2``, ``se``
    (standard error of each fitted parameter: relative, i.e. of ln(value), on log axes and in
    the parameter's unit on linear ones), ``cov`` (covariance in the box's units) and the
    number of observations ``n``."""

    params: Dict[str, float]
    u: np.ndarray
    z: np.ndarray
    chi2: float
    se: Dict[str, float]
    cov: np.ndarray
    n: int

    @property
    def chi2_per_point(self) -> float:
        """chi2 / n."""
        return self.chi2 / max(self.n, 1)

    relative: Dict[str, bool] = field(default_factory=dict)
    profiles: Dict[str, tuple] = field(default_factory=dict)
    #: Per parameter, the sandwich variance over the plain one (>= 1): how much correlated
    #: misfits widen its interval, profile intervals included.
    widen: Dict[str, float] = field(default_factory=dict)
    #: d z / d u at the optimum (observations x parameters), for errors taken afterwards.
    jac: Optional[np.ndarray] = None
    #: The fitted position's covariance over the fit packings left out in turn (unit box
    #: squared, :mod:`pelletdem.loop_jackknife`); None when not measured.
    jackknife: Optional[np.ndarray] = None
    #: Per profiled parameter, the whole position (unit box) where its profile's chi2 is
    #: lowest: where a fit that is only a local minimum of its emulator is left for.
    profile_best: Dict[str, np.ndarray] = field(default_factory=dict)

    def below_fit(self, name: str) -> float:
        """How far (chi2) the lowest point of ``name``'s profile lies below the fit itself; 0
        when it does not (or ``name`` was not profiled). A fit that is the emulator's global
        minimum has 0 up to the optimiser's tolerance: more means a better minimum elsewhere."""
        if name not in self.profiles:
            return 0.0
        return max(0.0, self.chi2 - float(np.min(self.profiles[name][1])))

    def interval(self, name: str, k: float = 2.0) -> tuple:
        """(low, high) of parameter ``name`` (SI): where its profile's chi2 stays within k^2
        (times :attr:`widen`) of the minimum when it was profiled (:func:`profile`), else +-k
        standard errors."""
        if name in self.profiles:
            level = float(np.min(self.profiles[name][1])) + k * k * self.widen.get(name, 1.0)
            return _profile_interval(*self.profiles[name], level)
        v, s = self.params[name], self.se.get(name, float("nan"))
        if not math.isfinite(s):
            return (float("nan"), float("nan"))
        if self.relative.get(name, True):
            return (v * math.exp(-k * s), v * math.exp(k * s))
        return (v - k * s, v + k * s)


def _profile_interval(values: np.ndarray, chi2: np.ndarray, level: float) -> tuple:
    """(low, high): where the profile ``chi2`` over the grid ``values`` (ascending) last
    crosses ``level`` on either side, interpolated between grid points (in ln(value) when all
    values are positive, as the grid is spaced); a grid end when it stays below. A profile
    with two dips below the level gets the interval spanning both."""
    values, chi2 = np.asarray(values, float), np.asarray(chi2, float)
    x = np.log(values) if np.all(values > 0) else values
    inside = np.flatnonzero(chi2 <= level)
    if len(inside) == 0:
        inside = np.array([int(np.argmin(chi2))])
    ends = []
    for i, step in ((int(inside[0]), -1), (int(inside[-1]), 1)):
        j = i + step
        if 0 <= j < len(x) and chi2[j] > chi2[i]:
            f = (level - chi2[i]) / (chi2[j] - chi2[i])
            ends.append(x[i] + f * (x[j] - x[i]))
        else:
            ends.append(x[i])
    lo, hi = min(ends), max(ends)
    if np.all(values > 0):
        lo, hi = math.exp(lo), math.exp(hi)
    return (float(lo), float(hi))


def welch_z(diff, se_a, dof_a, se_b, dof_b) -> np.ndarray:
    """Normal scores (-) of differences ``diff`` between two means whose standard errors
    ``se_a``, ``se_b`` (diff's unit) were estimated with ``dof_a``, ``dof_b`` degrees of
    freedom: the Welch t statistic diff / sqrt(se_a^2 + se_b^2) mapped to the normal score of
    the same two-sided tail probability under Student's t with the Welch-Satterthwaite
    degrees of freedom. Arrays broadcast."""
    from scipy import stats

    diff = np.asarray(diff, float)
    a, b = np.asarray(se_a, float) ** 2, np.asarray(se_b, float) ** 2
    t = diff / np.sqrt(a + b)
    dof = (a + b) ** 2 / (a * a / np.maximum(dof_a, 1.0) + b * b / np.maximum(dof_b, 1.0) + 1e-300)
    dof = np.clip(dof, 1.0, 1e6)
    # the upper tail, computed where it is accurate, then its normal score
    p = stats.t.sf(np.abs(t), dof)
    return np.sign(t) * stats.norm.isf(np.maximum(p, 1e-300))


def misfit(emulator: Emulator, data: Dataset, u: np.ndarray) -> np.ndarray:
    """z_i(u) of every observation of ``data`` (in the emulator's output order) at unit
    position ``u`` (-)."""
    mean, var = emulator.predict(np.asarray(u, float)[None, :])
    model_se = np.sqrt(emulator.noise() ** 2 + var[0])
    return welch_z(mean[0] - data.values, data.standard_errors, data.dofs, model_se, POOLED_DOF)


def fit_emulated(emulator: Emulator, data: Dataset, start: Optional[Sequence[float]] = None,
                 starts: int = 3, corr: Optional[np.ndarray] = None) -> EmulatedFit:
    """Minimise chi2 of ``data`` over ``emulator``'s box (see the module docstring), from
    ``start`` (unit position; default the box's centre) and the ``starts`` best design points.
    ``corr``: the correlation of the misfits (-, :mod:`pelletdem.loop_noise`), which turns
    the standard errors into sandwich ones. The data's observations must be the emulator's
    outputs, in order."""
    from scipy.optimize import least_squares

    d = emulator.space.dim
    if len(data) != emulator.n_outputs:
        raise ValueError(f"{len(data)} observations for an emulator of {emulator.n_outputs} outputs")
    x0s: List[np.ndarray] = [np.clip(np.asarray(start, float), 0.0, 1.0) if start is not None else np.full(d, 0.5)]
    # the design points that fit the data best, as seen through the emulator's own mean there
    z_design = [float(np.sum(misfit(emulator, data, u) ** 2)) for u in emulator.U]
    for k in np.argsort(z_design)[:starts]:
        x0s.append(emulator.U[k])
    best = None
    for x0 in x0s:
        res = least_squares(lambda u: misfit(emulator, data, u), x0, bounds=(np.zeros(d), np.ones(d)),
                            method="trf", x_scale=0.1, diff_step=1e-4, max_nfev=200)
        if best is None or res.cost < best.cost:
            best = res
    u = best.x
    z = misfit(emulator, data, u)
    J = best.jac
    try:
        plain = np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        plain = np.full((d, d), np.nan)
    cov = plain if corr is None else plain @ (J.T @ np.asarray(corr, float) @ J) @ plain
    se, relative, widen = {}, {}, {}
    for k, a in enumerate(emulator.space.axes):
        s = math.sqrt(max(cov[k, k], 0.0)) if np.isfinite(cov[k, k]) else float("nan")
        se[a.name] = s * a.relative_scale()
        relative[a.name] = a.log
        ok = np.isfinite(cov[k, k]) and np.isfinite(plain[k, k]) and plain[k, k] > 0
        widen[a.name] = max(1.0, float(cov[k, k] / plain[k, k])) if ok else 1.0
    return EmulatedFit(emulator.space.params(u), u, z, float(np.sum(z ** 2)), se, cov, len(z), relative,
                       widen=widen, jac=J)


#: Half-width of the fine part of a profile, in the fitted parameter's standard errors.
PROFILE_FINE_REACH = 4.5
#: Positions in the fine part of a profile.
PROFILE_FINE_POINTS = 31


def profile_grid(u: float, sd: float, n: int = 41) -> np.ndarray:
    """Unit positions (ascending, in [0, 1]) at which a profile is evaluated: ``n`` across the
    whole axis, the fitted position ``u`` itself, and :data:`PROFILE_FINE_POINTS` within
    :data:`PROFILE_FINE_REACH` of the fit's standard error ``sd`` (unit box) either side.
    The fine part matters where the data pin a strength down to less than a coarse cell: an
    interval read by straight lines between coarse points of a convex profile cuts each
    crossing short (with the crossing at 2 sd and a cell of h, at 4 sd^2 / h instead of 2 sd)."""
    grid = [np.linspace(0.0, 1.0, n), [u]]
    if math.isfinite(sd) and sd > 0:
        grid.append(u + sd * np.linspace(-PROFILE_FINE_REACH, PROFILE_FINE_REACH, PROFILE_FINE_POINTS))
    return np.unique(np.clip(np.concatenate(grid), 0.0, 1.0))


def profile(emulator: Emulator, data: Dataset, fit: EmulatedFit, name: str, n: int = 41) -> EmulatedFit:
    """The chi2 profile of parameter ``name``: chi2 minimised over the other parameters (on the
    emulator, from the fitted position) at the positions of :func:`profile_grid` (``n`` across
    its axis, finer near the fit). Stored in ``fit.profiles[name]`` as (values SI, chi2),
    where :meth:`EmulatedFit.interval` reads it: a weakly constrained strength gets the
    lopsided interval its data allow rather than a symmetric standard error; the whole
    position of its lowest point in ``fit.profile_best[name]``. Returns ``fit``."""
    from scipy.optimize import least_squares

    names = emulator.space.names
    k = names.index(name)
    d = emulator.space.dim
    others = [j for j in range(d) if j != k]
    var = float(fit.cov[k, k])
    grid = profile_grid(float(fit.u[k]), math.sqrt(var) if var > 0 else float("nan"), n)
    n = len(grid)
    chi2 = np.empty(n)
    order = np.argsort(np.abs(grid - fit.u[k]))  # outwards from the fit, each start the nearest done
    done: Dict[int, np.ndarray] = {}
    for i in order:
        near = min(done, key=lambda j: abs(grid[j] - grid[i])) if done else None
        x0 = done[near] if near is not None else fit.u[others]

        def z(v, i=i):
            u = np.empty(d)
            u[k], u[others] = grid[i], v
            return misfit(emulator, data, u)

        if others:
            res = least_squares(z, x0, bounds=(np.zeros(len(others)), np.ones(len(others))), method="trf",
                                x_scale=0.1, diff_step=1e-4, max_nfev=60)
            done[i], chi2[i] = res.x, float(np.sum(res.fun ** 2))
        else:
            done[i], chi2[i] = x0, float(np.sum(z(x0) ** 2))
    axis = emulator.space.axes[k]
    fit.profiles[name] = (np.array([axis.from_unit(g) for g in grid]), chi2)
    best = int(np.argmin(chi2))
    fit.profile_best[name] = np.empty(d)
    fit.profile_best[name][k], fit.profile_best[name][others] = grid[best], done[best]
    return fit
