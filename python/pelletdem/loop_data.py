"""The discrepancy loop's data: measured :class:`Observation` s of :class:`Condition` s,
collected in a :class:`Dataset`.

An observation is one measured number (a value, its replicate SD, where it lies on which
curve of which condition). A dataset is built from the paper's tables
(:meth:`Dataset.from_paper`), from measured curves (:meth:`Dataset.from_curves`) or made by
:func:`pelletdem.loop_simulators.synthetic_dataset` with a hidden effect. Values are in the SI unit of each quantity
(:data:`QUANTITIES`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .metrics import DEFAULT_REL_SD_FLOOR

__all__ = ["split_material", "QUANTITIES", "DIAMETRAL_PARTS", "DIAMETRAL_GRID", "COMPACTION_SPLIT", "Condition",
           "Observation", "Dataset", "diametral_part"]

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
#: Where a diametral curve is sampled, in fractions of its dL_f/D: from the toe, where sigma_1
#: is already a quarter of the way up (near dL/D = 0 it is ~1 kPa and its relative error
#: meaningless), to half again past the failure.
DIAMETRAL_GRID = (0.25, 0.5, 0.75, 1.0, 1.25, 1.5)
#: Compaction curves split at this dh/h0 (the paper's model fits only below it).
COMPACTION_SPLIT = 0.75
_MPA = 1e6


def split_material(name: str) -> Tuple[str, str]:
    """(root, material) of a parameter name: ``E_b[oak]`` acts on oak's conditions only, as E_b;
    a name without brackets is shared by every material (material '')."""
    root, bracket, rest = name.partition("[")
    return (root, rest.rstrip("]")) if bracket else (name, "")


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
        """The replicate SD floored at 1% of |value| (same unit): no measurement is better."""
        return max(self.sd, DEFAULT_REL_SD_FLOOR * abs(self.value), 1e-300)

    @property
    def standard_error(self) -> float:
        """The standard error of the measured mean, effective_sd / sqrt(n) (same unit): what
        a model's mean is compared with."""
        return self.effective_sd / math.sqrt(max(self.n, 1))


def diametral_part(x: float, x_f: float) -> str:
    """The part of a diametral curve (DIAMETRAL_PARTS) that x = dL/D lies in, for a curve
    that fails at x_f (-)."""
    for bound, name in DIAMETRAL_PARTS:
        if x < bound * x_f:
            return name
    return DIAMETRAL_PARTS[-1][1]


@dataclass
class Dataset:
    """Observations, in a fixed order, with the conditions they cover. ``same_packings``:
    groups of conditions whose replicates are the same packings (synthetic pellets pressed
    from one fill to each pressure), so that one packing's luck runs through all of a group;
    a laboratory's pellets of different conditions are other pellets, and no condition is
    grouped (the default)."""

    observations: List[Observation]
    name: str = "data"
    same_packings: Tuple[Tuple[Condition, ...], ...] = ()

    def __post_init__(self):
        self.observations = list(self.observations)
        if not self.observations:
            raise ValueError("a Dataset needs at least one observation")
        for o in self.observations:
            if not isinstance(o, Observation):
                raise ValueError(f"observations must be Observation objects, got {type(o).__name__}")
        conds = set(self.conditions)
        groups = []
        for g in self.same_packings:
            iterable = hasattr(g, "__iter__") and not isinstance(g, (str, bytes))
            if not iterable or not all(isinstance(c, Condition) for c in g):
                raise ValueError(f"same_packings: each group must be a sequence of Conditions, got {g!r}")
            g = tuple(c for c in dict.fromkeys(g) if c in conds)  # a subset keeps what it still holds
            if len(g) >= 2:
                groups.append(g)
        seen = [c for g in groups for c in g]
        if len(seen) != len(set(seen)):
            raise ValueError("same_packings: a condition is in more than one group")
        self.same_packings = tuple(groups)

    def packings_shared(self, a: Condition, b: Condition) -> bool:
        """Whether the replicates of conditions ``a`` and ``b`` are the same packings."""
        return a == b or any(a in g and b in g for g in self.same_packings)

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
        """Effective replicate SDs (each quantity's SI unit)."""
        return np.array([o.effective_sd for o in self.observations])

    @property
    def standard_errors(self) -> np.ndarray:
        """Standard errors of the measured means (each quantity's SI unit)."""
        return np.array([o.standard_error for o in self.observations])

    @property
    def dofs(self) -> np.ndarray:
        """Degrees of freedom of each replicate SD, n - 1 (at least 1)."""
        return np.array([max(o.n - 1, 1) for o in self.observations], float)

    def subset(self, keep: Callable[[Observation], bool], name: Optional[str] = None) -> "Dataset":
        """The observations for which ``keep(observation)`` is true."""
        obs = [o for o in self.observations if keep(o)]
        if not obs:
            raise ValueError("the subset is empty")
        return Dataset(obs, name or self.name, self.same_packings)

    def split(self, held_out: Callable[[Condition], bool]) -> Tuple["Dataset", Optional["Dataset"]]:
        """(fit, held-out): observations of conditions for which ``held_out(condition)`` is
        false, and true (None when no condition is held out). The fit part must be non-empty."""
        fit = [o for o in self.observations if not held_out(o.condition)]
        held = [o for o in self.observations if held_out(o.condition)]
        if not fit:
            raise ValueError("every condition is held out: nothing is left to fit")
        return (Dataset(fit, self.name + " (fit)", self.same_packings),
                Dataset(held, self.name + " (held out)", self.same_packings) if held else None)

    @classmethod
    def from_paper(cls, materials: Optional[Sequence[str]] = None,
                   quantities: Sequence[str] = ("sigma_f", "dLf_D", "bulk_density")) -> "Dataset":
        """The paper's measurements of the 12 variants (Table 3's sigma_f and dL_f/D, Table 2's
        pellet bulk density), as scalar observations with their SDs (5 replicates each)."""
        from .paper_tables import variants

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
    def from_curves(cls, curves: Mapping[Condition, object], points: int = 8, scalars: bool = True,
                    name: str = "curves") -> "Dataset":
        """Observations from measured curves (:class:`pelletdem.measured.Curve`, with
        replicates) per condition, each with the replicates' SD and count. A diametral curve
        gives sigma_1 at :data:`DIAMETRAL_GRID` fractions of its mean dL_f/D (those inside the
        replicates' common range), labelled by part, and (``scalars``) sigma_f and dL_f/D; a
        compaction curve gives sigma_z at ``points`` values of dh/h0 from 0.3 of its range to its
        end. The defaults are ``pelletdem loop --data``'s."""
        if not isinstance(points, int) or not 3 <= points <= 500:
            raise ValueError(f"points = {points!r} is out of range: allowed 3 <= points <= 500")
        obs = []
        for cond, curve in curves.items():
            if not isinstance(cond, Condition):
                raise ValueError("curves must be keyed by Condition")
            lo, hi = curve.common_range()
            if not lo < hi:
                raise ValueError(f"{cond.label}: the replicates share no x range")
            nrep = len(curve.replicates)
            if curve.kind == "diametral":
                pk = curve.peak()
                x_f = pk.dLf_D_mean
                if x_f >= hi - 0.02 * (hi - lo):
                    raise ValueError(f"{cond.label}: the diametral curves reach their maximum at the end of the test "
                                     f"(dL/D = {hi:.3g}): they show no failure, no peak to sample around")
                grid = np.array([f * x_f for f in DIAMETRAL_GRID if lo <= f * x_f <= hi])
                if len(grid) < 2:
                    raise ValueError(f"{cond.label}: the replicates' common range [{lo:.3g}, {hi:.3g}] holds fewer "
                                     f"than 2 of the points {DIAMETRAL_GRID} x dL_f/D = {x_f:.3g}")
                mc = curve.mean_curve(grid)
                for x, m, s in zip(mc.x, mc.mean, mc.sd):
                    obs.append(Observation(cond, "sigma_1", float(x), float(m), float(np.nan_to_num(s)), nrep,
                                           diametral_part(x, x_f)))
                if scalars:
                    obs.append(Observation(cond, "sigma_f", float("nan"), pk.sigma_f_mean,
                                           float(np.nan_to_num(pk.sigma_f_sd)), nrep))
                    obs.append(Observation(cond, "dLf_D", float("nan"), pk.dLf_D_mean,
                                           float(np.nan_to_num(pk.dLf_D_sd)), nrep))
            else:
                grid = np.linspace(lo + 0.3 * (hi - lo), hi, points)
                mc = curve.mean_curve(grid)
                split = COMPACTION_SPLIT if hi > COMPACTION_SPLIT else float(np.quantile(grid, 0.75))
                for x, m, s in zip(mc.x, mc.mean, mc.sd):
                    obs.append(Observation(cond, "sigma_z", float(x), float(m), float(np.nan_to_num(s)), nrep,
                                           "compaction-low" if x < split else "compaction-high"))
        return cls(obs, name)
