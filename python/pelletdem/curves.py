"""Measured stress-deformation curves in SI units: the :class:`Curve` type and its statistics.

A :class:`Curve` holds one or more replicates of a diametral-compression curve
(sigma_1 in Pa against dL/D) or a compaction curve (sigma_z in Pa against dh/h0), with
their mean curve (:meth:`Curve.mean_curve`) and, for diametral curves, each replicate's
peak (:meth:`Curve.peak`). Reading and writing curve files is
:mod:`pelletdem.curve_files`; :mod:`pelletdem.measured` re-exports both.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Iterable, Mapping, NamedTuple

import numpy as np

__all__ = [
    "CURVE_KINDS",
    "Curve",
    "MeanCurve",
    "Peak",
    "check_curve_kind",
    "concat_curves",
    "interp_curve",
    "nanmean",
    "replicate_groups",
    "sample_sd",
]

CURVE_KINDS: tuple[str, ...] = ("diametral", "compaction")


def check_curve_kind(kind) -> str:
    """``kind`` itself if it is one of :data:`CURVE_KINDS`; ValueError naming them otherwise."""
    if kind not in CURVE_KINDS:
        raise ValueError(f"kind must be one of {list(CURVE_KINDS)}; got {kind!r}")
    return kind


def _frozen_array(values, dtype) -> np.ndarray:
    arr = np.array(values, dtype=dtype)  # a copy, so freezing it cannot affect the caller
    arr.setflags(write=False)
    return arr


def interp_curve(x, y, at) -> np.ndarray:
    """Linear interpolation of a curve ``y(x)`` at the points ``at``; NaN outside.

    ``x`` must be non-decreasing; points with equal ``x`` (sensor resolution) are
    averaged first so that the result does not depend on their order. Units pass
    through: ``y`` and the result share them, ``x`` and ``at`` share theirs.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    at = np.asarray(at, dtype=float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"x and y must be 1-D of equal length; got shapes {x.shape} and {y.shape}")
    if x.size == 0:
        return np.full(at.shape, np.nan)
    if np.any(np.diff(x) < 0):
        raise ValueError("x must be non-decreasing")
    ux, inverse = np.unique(x, return_inverse=True)
    uy = np.bincount(inverse, weights=y) / np.bincount(inverse)
    return np.interp(at, ux, uy, left=np.nan, right=np.nan)


def sample_sd(values, axis=None) -> np.ndarray:
    """Sample SD (ddof = 1, as for the paper's replicate SDs) ignoring NaN; NaN below 2 values.

    Same unit as ``values``; reduced over ``axis`` (all values when None).
    """
    values = np.asarray(values, dtype=float)
    n = np.sum(np.isfinite(values), axis=axis)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices: the answer is NaN
        mean = np.nanmean(values, axis=axis, keepdims=True)
        ss = np.nansum((values - mean) ** 2, axis=axis)
    return np.where(n >= 2, np.sqrt(ss / np.maximum(n - 1, 1)), np.nan)


def nanmean(values, axis=None) -> np.ndarray:
    """Mean ignoring NaN, without numpy's warning for an all-NaN slice (whose mean is NaN).

    Same unit as ``values``; reduced over ``axis`` (all values when None).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices: the answer is NaN
        return np.nanmean(values, axis=axis)


class MeanCurve(NamedTuple):
    """Replicates interpolated on a common grid.

    ``x`` the grid (-), ``mean`` and ``sd`` the mean and sample SD of ``y`` over the
    replicates covering each grid point (Pa; SD NaN where fewer than 2 do), ``n`` how
    many replicates cover each point.
    """

    x: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    n: np.ndarray


@dataclass(frozen=True, eq=False)
class Peak:
    """Peak of each replicate of a diametral curve (the paper's Table 3 quantities).

    ``replicate`` ids; ``sigma_f`` tensile strength = the maximum sigma_1 (Pa) and
    ``dLf_D`` the deformation at which it is first reached (-), one per replicate;
    the ``*_mean`` / ``*_sd`` properties give mean and sample SD over replicates
    (SD NaN for a single replicate).
    """

    replicate: tuple[str, ...]
    sigma_f: np.ndarray
    dLf_D: np.ndarray

    @property
    def sigma_f_mean(self) -> float:
        """Mean tensile strength over the replicates, Pa."""
        return float(np.mean(self.sigma_f))

    @property
    def sigma_f_sd(self) -> float:
        """Sample SD of the tensile strength over the replicates, Pa (NaN for one)."""
        return float(sample_sd(self.sigma_f))

    @property
    def dLf_D_mean(self) -> float:
        """Mean deformation at failure over the replicates (-)."""
        return float(np.mean(self.dLf_D))

    @property
    def dLf_D_sd(self) -> float:
        """Sample SD of the deformation at failure over the replicates (-; NaN for one)."""
        return float(sample_sd(self.dLf_D))


@dataclass(frozen=True, eq=False)
class Curve:
    """A measured stress-deformation curve, possibly several replicates, in SI units.

    ``x``: dimensionless deformation (dL/D for ``kind="diametral"``, dh/h0 for
    ``kind="compaction"``). ``y``: stress in Pa (sigma_1 of eq. 4, or the compaction
    pressure sigma_z). ``replicate``: one string id per point. ``metadata``:
    ``key -> value`` pairs from the file's ``#`` header plus what the loader derived
    (``diameter_m``, ``height_m`` for test-machine exports). ``source``: the file it
    was read from (not part of equality). Arrays are stored read-only.
    """

    x: np.ndarray
    y: np.ndarray
    replicate: np.ndarray | None = None
    kind: str = "diametral"
    metadata: Mapping[str, object] = field(default_factory=dict)
    source: str | None = None

    def __post_init__(self):
        check_curve_kind(self.kind)
        x = _frozen_array(self.x, float)
        y = _frozen_array(self.y, float)
        if x.ndim != 1 or x.shape != y.shape:
            raise ValueError(f"x and y must be 1-D of equal length; got shapes {x.shape} and {y.shape}")
        rep = np.full(x.shape, "1") if self.replicate is None else [str(r).strip() for r in self.replicate]
        rep = _frozen_array(rep, str)
        if rep.shape != x.shape:
            raise ValueError(f"replicate must have one id per point; got {rep.shape} for {x.shape} points")
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)
        object.__setattr__(self, "replicate", rep)
        object.__setattr__(self, "metadata", dict(self.metadata))

    def __eq__(self, other):
        if not isinstance(other, Curve):
            return NotImplemented
        return (self.kind == other.kind and np.array_equal(self.x, other.x)
                and np.array_equal(self.y, other.y) and np.array_equal(self.replicate, other.replicate)
                and dict(self.metadata) == dict(other.metadata))

    __hash__ = None  # mutable-looking (arrays): not hashable

    def __len__(self) -> int:
        return int(self.x.size)

    @property
    def replicates(self) -> tuple[str, ...]:
        """Replicate ids in order of first appearance."""
        return tuple(replicate_groups(self.replicate))

    def select(self, replicate) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of one replicate (x dimensionless, y in Pa)."""
        idx = replicate_groups(self.replicate).get(str(replicate))
        if idx is None:
            raise ValueError(f"replicate must be one of {list(self.replicates)}; got {replicate!r}")
        return self.x[idx], self.y[idx]

    def per_replicate(self):
        """Yield (replicate id, x, y) for each replicate, in order of first appearance."""
        for rid, idx in replicate_groups(self.replicate).items():
            yield rid, self.x[idx], self.y[idx]

    def common_range(self) -> tuple[float, float]:
        """The x interval covered by every replicate (lo > hi if there is none)."""
        spans = [(xs.min(), xs.max()) for _, xs, _ in self.per_replicate()]
        return float(max(s[0] for s in spans)), float(min(s[1] for s in spans))

    def mean_curve(self, grid=None) -> MeanCurve:
        """Interpolate each replicate on ``grid`` (-) and average.

        Default grid: 101 points over the x range covered by every replicate. Grid
        points outside a replicate's range do not count for that replicate (see
        ``MeanCurve.n``). Returns :class:`MeanCurve` (stress in Pa).
        """
        if grid is None:
            lo, hi = self.common_range()
            if lo > hi:
                raise ValueError("the replicates share no x range; pass an explicit grid")
            grid = np.linspace(lo, hi, 101)
        grid = np.asarray(grid, dtype=float)
        stack = np.vstack([interp_curve(xs, ys, grid) for _, xs, ys in self.per_replicate()])
        n = np.sum(np.isfinite(stack), axis=0)
        return MeanCurve(grid, nanmean(stack, axis=0), sample_sd(stack, axis=0), n)

    def peak(self) -> Peak:
        """Tensile strength sigma_f (Pa) and dL_f/D (-) of each replicate.

        Only for diametral curves: the peak of sigma_1 is the failure point of eq. 4.
        """
        if self.kind != "diametral":
            raise ValueError(f"peak() applies to diametral curves; this curve is {self.kind!r}")
        ids, sig, dl = [], [], []
        for rid, xs, ys in self.per_replicate():
            ids.append(rid)
            i = int(np.argmax(ys))  # first maximum: failure is where the peak is reached
            sig.append(ys[i])
            dl.append(xs[i])
        return Peak(tuple(ids), np.asarray(sig), np.asarray(dl))


def replicate_groups(replicate: np.ndarray) -> dict[str, np.ndarray]:
    """Row indices (ints) of each replicate id of ``replicate``, in order of first appearance."""
    groups: dict[str, list[int]] = {}
    for i, rid in enumerate(replicate):
        groups.setdefault(str(rid), []).append(i)
    return {k: np.asarray(v, dtype=int) for k, v in groups.items()}


def concat_curves(curves: Iterable[Curve]) -> Curve:
    """Join single-pellet curves (e.g. one test-machine export each) into one Curve.

    All must share ``kind``; replicate ids must not repeat across curves (load each
    file with its own ``replicate=`` id). Metadata is kept only where all agree.
    """
    curves = list(curves)
    if not curves:
        raise ValueError("curves is empty")
    kinds = {c.kind for c in curves}
    if len(kinds) != 1:
        raise ValueError(f"curves must share one kind; got {sorted(kinds)}")
    seen: set[str] = set()
    for c in curves:
        clash = seen.intersection(c.replicates)
        if clash:
            raise ValueError(f"replicate ids {sorted(clash)} repeat across curves; "
                             "load each file with a distinct replicate=")
        seen.update(c.replicates)
    common = {k: v for k, v in curves[0].metadata.items() if all(c.metadata.get(k) == v for c in curves)}
    return Curve(np.concatenate([c.x for c in curves]), np.concatenate([c.y for c in curves]),
                 np.concatenate([c.replicate for c in curves]), curves[0].kind, common)
