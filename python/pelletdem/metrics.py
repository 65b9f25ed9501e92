"""Fit quality of a simulation against measurements.

* :func:`rrmse` is eq. 16 of the paper,
  RRMSE = sqrt(mean(((exp - dem) / exp)^2)), on paired arrays.
* :func:`rrmse_curve` applies it to two curves sampled at different x, by
  interpolating the simulated curve at the measured x.
* :func:`rrmse_replicates` does so per measured replicate, and reports the replicate
  spread so that a fit can be judged against the scatter between pellets.
* :func:`sd_weighted_error` scores scalar targets (sigma_f, dL_f/D, bulk density)
  in units of the measured SD.

All RRMSE values and z-scores are dimensionless; inputs may be in any unit as long
as measured and simulated share it (the package uses Pa for stress).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .curves import Curve, interp_curve, nanmean, sample_sd

__all__ = [
    "MIN_OVERLAP",
    "DEFAULT_MIN_FRACTION_OF_PEAK",
    "DEFAULT_REL_SD_FLOOR",
    "rrmse",
    "rrmse_curve",
    "rrmse_replicates",
    "ReplicateRRMSE",
    "sd_weighted_error",
    "ZScores",
]

# The simulated curve must cover at least this fraction of the measured x range.
MIN_OVERLAP = 0.5
# Eq. 16 divides by the measured stress, which is zero at the start of every curve;
# points below this fraction of the measured peak would dominate the sum with the
# relative error of a near-zero number. The paper does not say how it treated them.
DEFAULT_MIN_FRACTION_OF_PEAK = 0.05
# SD floor of sd_weighted_error, as a fraction of |measured mean|: no DEM run
# reproduces a quantity better than ~1% (packing-seed scatter), so a measurement
# more precise than that (e.g. pycnometry, SD 0.02%) should not dominate the score.
DEFAULT_REL_SD_FLOOR = 0.01


def _as_1d(name: str, values) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D; got shape {arr.shape}")
    return arr


def _check_finite(name: str, arr: np.ndarray, labels=None) -> None:
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        i = int(bad[0])
        idx = i if labels is None else int(labels[i])
        raise ValueError(f"{name}[{idx}] is {float(arr[i])!r}; NaN and inf are not allowed")


def _check_same_shape(a_name, a, b_name, b) -> None:
    if a.shape != b.shape:
        raise ValueError(f"shape mismatch: {a_name} has shape {a.shape}, {b_name} has shape {b.shape}")


def _rrmse(measured: np.ndarray, simulated: np.ndarray, labels=None) -> float:
    """Eq. 16 on checked arrays; ``labels`` maps positions to the caller's indices."""
    _check_finite("measured", measured, labels)
    _check_finite("simulated", simulated, labels)
    if measured.size == 0:
        raise ValueError("no points to compare (empty arrays)")
    zero = np.flatnonzero(measured == 0.0)
    if zero.size:
        idx = int(zero[0]) if labels is None else int(labels[zero[0]])
        raise ValueError(f"measured[{idx}] is 0; eq. 16 divides by the measured value")
    rel = (measured - simulated) / measured
    return float(math.sqrt(np.mean(rel * rel)))


def rrmse(measured, simulated) -> float:
    """Relative root-mean-square error, eq. 16 of the paper (dimensionless).

    RRMSE = sqrt((1/n) sum(((measured_i - simulated_i) / measured_i)^2)).
    ``measured`` and ``simulated`` are paired samples in the same unit (e.g. Pa).
    Raises ValueError on a shape mismatch, an empty input, NaN/inf (naming the
    index) or a zero measured value (naming the index).
    """
    m = _as_1d("measured", measured)
    s = _as_1d("simulated", simulated)
    _check_same_shape("measured", m, "simulated", s)
    return _rrmse(m, s)


def _checked_curve(prefix: str, x, y) -> tuple[np.ndarray, np.ndarray]:
    xa = _as_1d(f"{prefix}_x", x)
    ya = _as_1d(f"{prefix}_y", y)
    _check_same_shape(f"{prefix}_x", xa, f"{prefix}_y", ya)
    _check_finite(f"{prefix}_x", xa)
    _check_finite(f"{prefix}_y", ya)
    return xa, ya


def _overlap_fraction(lo: float, hi: float, slo: float, shi: float) -> float:
    """Fraction of [lo, hi] inside [slo, shi]; for a single point, 1 if covered."""
    if hi == lo:
        return 1.0 if slo <= lo <= shi else 0.0
    return max(0.0, min(hi, shi) - max(lo, slo)) / (hi - lo)


def _curve_points(measured_x, measured_y, sim_x, sim_y, x_range, min_fraction_of_peak):
    """Measured points to compare and the simulated values there.

    Returns (indices into the measured arrays, measured y, simulated y).
    """
    mx, my = _checked_curve("measured", measured_x, measured_y)
    sx, sy = _checked_curve("sim", sim_x, sim_y)
    if sx.size < 2:
        raise ValueError(f"the simulated curve needs at least 2 points; got {sx.size}")
    back = np.flatnonzero(np.diff(sx) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise ValueError(f"sim_x must be non-decreasing; sim_x[{i}] = {float(sx[i])!r} < "
                         f"sim_x[{i - 1}] = {float(sx[i - 1])!r}")
    keep = np.ones(mx.size, dtype=bool)
    if x_range is not None:
        lo, hi = (float(v) for v in x_range)
        if not lo < hi:
            raise ValueError(f"x_range must be (lo, hi) with lo < hi; got {x_range!r}")
        keep &= (mx >= lo) & (mx <= hi)
    if not keep.any():
        raise ValueError(f"no measured points inside x_range {x_range!r}")
    lo, hi = float(mx[keep].min()), float(mx[keep].max())
    frac = _overlap_fraction(lo, hi, float(sx[0]), float(sx[-1]))
    if frac < MIN_OVERLAP:
        raise ValueError(
            f"the simulated curve (x from {sx[0]:.4g} to {sx[-1]:.4g}) covers only {100 * frac:.0f}% of the "
            f"measured x range [{lo:.4g}, {hi:.4g}]; at least {100 * MIN_OVERLAP:.0f}% overlap is required")
    if min_fraction_of_peak < 0:
        raise ValueError(f"min_fraction_of_peak must be >= 0; got {min_fraction_of_peak!r}")
    if min_fraction_of_peak > 0:
        keep &= my >= min_fraction_of_peak * float(my[keep].max())
    keep &= (mx >= sx[0]) & (mx <= sx[-1])  # compare only where the simulation exists
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        raise ValueError("no measured points left to compare after the x_range, coverage and "
                         "peak-fraction cuts")
    return idx, my[idx], interp_curve(sx, sy, mx[idx])


def rrmse_curve(measured_x, measured_y, sim_x, sim_y, x_range=None, *,
                min_fraction_of_peak: float = DEFAULT_MIN_FRACTION_OF_PEAK) -> float:
    """Eq. 16 between a measured curve and a simulated one sampled at other x.

    ``measured_x``, ``sim_x``: deformation (dimensionless dL/D or dh/h0);
    ``measured_y``, ``sim_y``: stress in one unit (Pa). The simulated curve (x
    non-decreasing) is interpolated linearly at the measured x; measured points are
    used only where

    * they lie inside ``x_range = (lo, hi)`` when given,
    * the simulated curve covers them (no extrapolation), and
    * the measured stress is at least ``min_fraction_of_peak`` (default 0.05) times
      the largest measured stress in the range, because eq. 16 divides by the
      measured stress and the toe of the curve (stress ~ 0) would dominate. Pass 0
      to use every point (a zero measured stress then raises).

    Raises ValueError if the simulated x span covers less than 50% (MIN_OVERLAP) of
    the measured x range, on NaN/inf, and on shape mismatches. Returns the RRMSE (-).
    """
    idx, m, s = _curve_points(measured_x, measured_y, sim_x, sim_y, x_range, min_fraction_of_peak)
    return _rrmse(m, s, labels=idx)


@dataclass(frozen=True, eq=False)
class ReplicateRRMSE:
    """RRMSE (eq. 16, dimensionless) of one simulation against replicated measurements.

    ``replicate``: ids; ``per_replicate``: RRMSE against each replicate; ``mean`` and
    ``sd``: their mean and sample SD (the spread of the score over replicates, NaN SD
    for one replicate); ``mean_curve``: RRMSE against the replicates' mean curve;
    ``noise_floor``: mean over replicates of each replicate's RRMSE against that mean
    curve, i.e. what a perfect model of the mean would score on single pellets (NaN
    for one replicate).
    """

    replicate: tuple[str, ...]
    per_replicate: np.ndarray
    mean: float
    sd: float
    mean_curve: float
    noise_floor: float


def _noise_floor(stack: np.ndarray, mean: np.ndarray, min_fraction_of_peak: float) -> float:
    """Mean RRMSE of the replicates (rows of ``stack``) against their mean curve."""
    if stack.shape[0] < 2:
        return math.nan
    scores = []
    for row in stack:
        keep = row >= min_fraction_of_peak * row.max()  # same toe cut as rrmse_curve
        if min_fraction_of_peak == 0:
            keep[:] = True
        scores.append(_rrmse(row[keep], mean[keep]))
    return float(np.mean(scores))


def rrmse_replicates(measured: Curve, sim_x, sim_y, *, x_range=None, grid=None,
                     min_fraction_of_peak: float = DEFAULT_MIN_FRACTION_OF_PEAK) -> ReplicateRRMSE:
    """Score a simulated curve against every replicate of a measured :class:`Curve`.

    ``measured``: a Curve (x dimensionless, y in Pa) with one or more replicates;
    ``sim_x`` (-), ``sim_y`` (Pa): the simulated curve. Each replicate is scored with
    :func:`rrmse_curve` (same ``x_range`` and ``min_fraction_of_peak``; an
    insufficient overlap names the replicate). The mean curve is
    ``measured.mean_curve(grid)`` (default: 101 points over the x range shared by
    all replicates), restricted to grid points covered by every replicate.
    Returns :class:`ReplicateRRMSE` (all values dimensionless).
    """
    ids, scores = [], []
    for rid, xs, ys in measured.per_replicate():
        try:
            scores.append(rrmse_curve(xs, ys, sim_x, sim_y, x_range,
                                      min_fraction_of_peak=min_fraction_of_peak))
        except ValueError as exc:
            raise ValueError(f"replicate {rid!r}: {exc}") from exc
        ids.append(rid)
    scores_arr = np.asarray(scores)
    mc = measured.mean_curve(grid)
    full = mc.n == len(ids)  # the mean jumps where a replicate ends: use full coverage only
    if full.sum() < 2:
        raise ValueError("fewer than 2 grid points are covered by every replicate; pass a grid inside their "
                         f"common x range {measured.common_range()}")
    mean_score = rrmse_curve(mc.x[full], mc.mean[full], sim_x, sim_y, x_range,
                             min_fraction_of_peak=min_fraction_of_peak)
    stack = np.vstack([interp_curve(xs, ys, mc.x[full]) for _, xs, ys in measured.per_replicate()])
    return ReplicateRRMSE(
        replicate=tuple(ids),
        per_replicate=scores_arr,
        mean=float(nanmean(scores_arr)),
        sd=float(sample_sd(scores_arr)),
        mean_curve=mean_score,
        noise_floor=_noise_floor(stack, mc.mean[full], min_fraction_of_peak),
    )


class ZScores(NamedTuple):
    """Result of :func:`sd_weighted_error`.

    ``z``: (simulated - measured_mean) / sd_used per target (-); ``rms``:
    sqrt(mean(z^2)) (-); ``sd_used``: the SD after the floor, in the targets' units.
    """

    z: np.ndarray
    rms: float
    sd_used: np.ndarray


def sd_weighted_error(measured_mean, measured_sd, simulated, *, rel_sd_floor: float = DEFAULT_REL_SD_FLOOR,
                      abs_sd_floor: float = 0.0) -> ZScores:
    """z-scores of simulated scalar targets against measured mean +- SD.

    Each argument is a scalar or a 1-D array, one entry per target (e.g. sigma_f in
    Pa, dL_f/D in -, bulk density in kg/m3; each target's mean, SD and simulated
    value share a unit, targets may differ). z_i = (simulated_i - mean_i) / sd_i with
    sd_i = max(measured_sd_i, rel_sd_floor * |mean_i|, abs_sd_floor).

    The floor (default 1% of |mean|, DEFAULT_REL_SD_FLOOR) avoids division by a zero
    SD and stops a target measured far more precisely than any DEM run can match
    (pycnometry: SD 0.02% of the mean) from dominating the score. Raises ValueError
    on shape mismatch, NaN/inf, negative SD, or an SD that is still 0 after the floor
    (mean 0 and SD 0 with no ``abs_sd_floor``). ``abs_sd_floor`` is in the targets'
    unit, so use it only with one kind of target.
    """
    mean = _as_1d("measured_mean", measured_mean)
    sd = _as_1d("measured_sd", measured_sd)
    sim = _as_1d("simulated", simulated)
    _check_same_shape("measured_mean", mean, "measured_sd", sd)
    _check_same_shape("measured_mean", mean, "simulated", sim)
    for name, arr in (("measured_mean", mean), ("measured_sd", sd), ("simulated", sim)):
        _check_finite(name, arr)
    if mean.size == 0:
        raise ValueError("no targets (empty arrays)")
    if rel_sd_floor < 0 or abs_sd_floor < 0:
        raise ValueError(f"SD floors must be >= 0; got rel_sd_floor={rel_sd_floor!r}, "
                         f"abs_sd_floor={abs_sd_floor!r}")
    negative = np.flatnonzero(sd < 0)
    if negative.size:
        i = int(negative[0])
        raise ValueError(f"measured_sd[{i}] is {float(sd[i])!r}; an SD cannot be negative")
    used = np.maximum.reduce([sd, rel_sd_floor * np.abs(mean), np.full(sd.shape, float(abs_sd_floor))])
    zero = np.flatnonzero(used == 0)
    if zero.size:
        i = int(zero[0])
        raise ValueError(f"target {i}: SD is 0 even after the floor (mean 0, SD 0); pass abs_sd_floor > 0")
    z = (sim - mean) / used
    return ZScores(z, float(math.sqrt(np.mean(z * z))), used)
