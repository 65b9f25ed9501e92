"""What a simulated pellet is scored against (:class:`Targets`) and how (small pure functions).

:func:`diametral_error`: z-scores of the simulated sigma_f and dL_f/D against Table 3's mean
and SD (:func:`pelletdem.metrics.sd_weighted_error`, SD floored at 1% of the mean).
:func:`curve_error`: RRMSE of eq. 16 against a measured sigma_1(dL/D) curve.
:func:`density_error`: z-score of the simulated bulk density (relaxed, or at the end of
compaction) against Table 2. :func:`score` combines them for one :class:`Targets`;
:func:`compaction_targets` pools Table 2 into one density target per pressure.

A diametral test that ends before its failure yields bounds of sigma_f and dL_f/D, not
values (``peaked`` = 0): :func:`effective_outputs` scores such a run as if its peak came at
:data:`CENSORED_DLF_FACTOR` x the end of the test. :func:`mean_outputs` averages a point's
runs over packing seeds.

Units: SI (Pa, kg/m^3; deformations and z-scores dimensionless).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .runs import check_positive

__all__ = [
    "Targets", "diametral_error", "curve_error", "density_error", "score", "compaction_targets",
    "as_targets", "as_variants", "mean_outputs", "effective_outputs", "CENSORED_DLF_FACTOR",
]

_MPA = 1e6


@dataclass(frozen=True)
class Targets:
    """What one simulated pellet is scored against (SI units).

    ``sigma_z``: compaction pressure of the pellet, Pa. ``sigma_f`` / ``sigma_f_sd``: tensile
    strength, Pa; ``dLf_D`` / ``dLf_D_sd``: deformation at failure, -; ``curve``: a measured
    diametral ``measured.Curve`` or an ``(x, y)`` pair (dL/D, sigma_1 in Pa) for eq. 16;
    ``bulk_density`` / ``bulk_density_sd``: kg/m^3 of the pellet ``density_state`` 'relaxed'
    (Table 2's pellets) or 'max' (at the end of compaction). Leave out what is not measured.
    ``mc_percent``: the moisture content (%) the pellet is made at, the contact law's
    ``moisture_content`` for its runs (the moisture effects read it); ``wood_density``: the
    bulk density (kg/m^3) of the wood its particles are cut from, the law's ``wood_density``
    (wood_density_yield reads it). None keeps the law's.
    """

    sigma_z: float
    sigma_f: Optional[float] = None
    sigma_f_sd: float = 0.0
    dLf_D: Optional[float] = None
    dLf_D_sd: float = 0.0
    bulk_density: Optional[float] = None
    bulk_density_sd: float = 0.0
    density_state: str = "relaxed"
    curve: Any = None
    label: str = ""
    mc_percent: Optional[float] = None
    wood_density: Optional[float] = None

    def __post_init__(self):
        check_positive("sigma_z", self.sigma_z, "Pa")
        if self.mc_percent is not None and not (isinstance(self.mc_percent, (int, float))
                                                and 0.0 <= self.mc_percent <= 100.0):
            raise ValueError(f"mc_percent = {self.mc_percent!r} is out of range: allowed 0..100 %")
        if self.wood_density is not None:
            check_positive("wood_density", self.wood_density, "kg/m^3")
        for name in ("sigma_f", "dLf_D", "bulk_density"):
            v = getattr(self, name)
            if v is not None:
                check_positive(name, v, "target")
            sd = getattr(self, name + "_sd")
            try:
                ok = math.isfinite(float(sd)) and float(sd) >= 0
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(f"{name}_sd = {sd!r} must be finite and >= 0")
        if self.density_state not in ("relaxed", "max"):
            raise ValueError(f"density_state = {self.density_state!r}: allowed 'relaxed', 'max'")
        if not (self.diametral or self.bulk_density is not None):
            raise ValueError("a Targets needs sigma_f, dLf_D, a curve or bulk_density")

    def condition_rows(self) -> dict:
        """The contact-law rows of this target's condition, for its runs: ``moisture_content``
        (%) and ``wood_density`` (kg/m^3) where given."""
        rows = {"moisture_content": self.mc_percent, "wood_density": self.wood_density}
        return {k: float(v) for k, v in rows.items() if v is not None}

    @property
    def diametral(self) -> bool:
        """True when a diametral test is needed to score against this target."""
        return self.sigma_f is not None or self.dLf_D is not None or self.curve is not None

    @classmethod
    def from_variant(cls, v, *, diametral: bool = True, density: bool = False, curve=None) -> "Targets":
        """Targets of one of the paper's variants (a ``measured.Variant`` or its key
        (material, mc %, sigma_z MPa)): Table 3's sigma_f and dL_f/D if ``diametral``, Table 2's
        relaxed pellet bulk density if ``density``, and an optional measured ``curve``."""
        from .paper_tables import Variant, variant

        if not isinstance(v, Variant):
            v = variant(*v)
        kw = {}
        if diametral:
            kw.update(sigma_f=v.sigma_f, sigma_f_sd=v.sigma_f_sd, dLf_D=v.dLf_D, dLf_D_sd=v.dLf_D_sd)
        if density:
            kw.update(bulk_density=v.bd_pellet, bulk_density_sd=v.bd_pellet_sd)
        return cls(sigma_z=v.sigma_z, curve=curve, label=v.label, **kw)


def diametral_error(sigma_f: float, dLf_D: float, target: Targets) -> dict:
    """z-scores of a simulated tensile strength ``sigma_f`` (Pa) and deformation at failure
    ``dLf_D`` (-) against the target's mean and SD (SD floored at 1% of the mean, see
    metrics.sd_weighted_error): {'z_sigma_f', 'z_dLf_D'} for the targets given (-)."""
    from .metrics import sd_weighted_error

    out = {}
    for name, sim in (("sigma_f", sigma_f), ("dLf_D", dLf_D)):
        mean = getattr(target, name)
        if mean is not None:
            out["z_" + name] = float(sd_weighted_error(mean, getattr(target, name + "_sd"), sim).z[0])
    return out


def curve_error(dL_D, sigma_1, target: Targets) -> float:
    """RRMSE (eq. 16, -) of a simulated sigma_1(dL/D) curve (dL_D -, sigma_1 Pa) against the
    target's measured curve: the replicates' mean curve for a ``measured.Curve``, the points
    for an (x, y) pair. NaN when the target has no curve."""
    from .metrics import rrmse_curve, rrmse_replicates

    if target.curve is None:
        return float("nan")
    x, y = np.asarray(dL_D, float), np.asarray(sigma_1, float)
    if hasattr(target.curve, "per_replicate"):
        return float(rrmse_replicates(target.curve, x, y).mean_curve)
    mx, my = target.curve
    return float(rrmse_curve(mx, my, x, y))


def density_error(bulk_density: float, target: Targets) -> float:
    """z-score (-) of a simulated bulk density (kg/m^3) against the target's (Table 2), SD
    floored at 1% of the mean. NaN when the target has no density."""
    from .metrics import sd_weighted_error

    if target.bulk_density is None:
        return float("nan")
    return float(sd_weighted_error(target.bulk_density, target.bulk_density_sd, bulk_density).z[0])


def score(outputs: Mapping[str, float], target: Targets, curve: Optional[Mapping] = None) -> dict:
    """All errors of one simulated pellet against ``target``.

    ``outputs``: a run record's outputs (sigma_f Pa, dLf_D, bulk_density_relaxed /
    bulk_density_max kg/m^3); ``curve``: its {dL_D, sigma_1 (Pa)}. Returns z-scores
    (z_sigma_f, z_dLf_D, z_bulk_density, -), their root mean square ``rms_z`` and ``rrmse``
    (eq. 16, NaN without a measured curve).
    """
    out = {}
    if target.diametral and "sigma_f" in outputs:
        out.update(diametral_error(outputs["sigma_f"], outputs["dLf_D"], target))
    if target.bulk_density is not None:
        out["z_bulk_density"] = density_error(outputs["bulk_density_" + target.density_state], target)
    zs = [v for k, v in out.items() if k.startswith("z_")]
    out["rms_z"] = float(math.sqrt(np.mean(np.square(zs)))) if zs else float("nan")
    out["rrmse"] = float("nan")
    if target.curve is not None and curve:
        try:
            out["rrmse"] = curve_error(curve["dL_D"], curve["sigma_1"], target)
        except ValueError:  # too little overlap with the measured curve
            out["rrmse"] = float("inf")
    return out


def compaction_targets(variants=None, state: str = "relaxed", particle_density: Optional[float] = None,
                       by_mc: bool = False, by_material: bool = False) -> List[Targets]:
    """One bulk-density target per compaction pressure, shared by all materials (Table 2).

    For each pressure of ``variants`` (default the 12): the mean of the variants' pellet bulk
    densities (kg/m^3), and as SD sqrt(mean within-variant SD^2 + SD between the variants'
    means^2): one contact law for all woods cannot do better than the spread between them.
    ``particle_density`` (kg/m^3, the model particles'): each variant's density (and SD) is
    first taken to that particle density at the same BD_p / BD_w (Table 2's intact wood), so
    that woods of different densities ask one contact law for one solid fraction; None keeps
    Table 2's densities as they are. ``by_mc``: one target per pressure and moisture content
    (its ``mc_percent`` set), for a contact law whose moisture effect makes wet and dry
    pellets differ; ``by_material``: one per pressure and material (its ``wood_density`` the
    material's BD_w), for a law whose yield depends on the wood's density. False pools them.
    """
    from .paper_tables import variants as all_variants

    vs = as_variants(variants) if variants is not None else all_variants()
    if particle_density is not None:
        check_positive("particle_density", particle_density, "kg/m^3")
    out = []
    keys = sorted({(v.sigma_z, v.mc_percent if by_mc else -1.0, v.material if by_material else "") for v in vs})
    for sz, mc, material in keys:
        group = [v for v in vs if v.sigma_z == sz and mc in (-1.0, v.mc_percent) and material in ("", v.material)]
        scale = np.array([particle_density / v.bd_wood if particle_density is not None else 1.0 for v in group])
        means = np.array([v.bd_pellet for v in group]) * scale
        sds = np.array([v.bd_pellet_sd for v in group]) * scale
        between = float(np.std(means, ddof=1)) if len(means) > 1 else 0.0
        sd = float(math.sqrt(np.mean(sds**2) + between**2))
        at = ", ".join([f"{sz / _MPA:g} MPa", *([f"MC {mc:g} %"] if by_mc else []),
                        *([material] if by_material else [])])
        out.append(Targets(sigma_z=sz, bulk_density=float(means.mean()), bulk_density_sd=sd,
                           density_state=state, label=f"BD at {at} (mean of {len(group)})",
                           mc_percent=float(mc) if by_mc else None,
                           wood_density=group[0].bd_wood if by_material else None))
    return out


def as_variants(variants) -> list:
    """``measured.Variant`` objects from ``variants``: Variants or their keys (material, mc %,
    sigma_z MPa); None gives all 12. ValueError when empty or unknown."""
    from .paper_tables import Variant, variant
    from .paper_tables import variants as all_variants

    if variants is None:
        return all_variants()
    out = []
    for v in variants:
        out.append(v if isinstance(v, Variant) else variant(*v))
    if not out:
        raise ValueError("variants is empty")
    return out


def as_targets(targets) -> List[Targets]:
    """``targets`` as a list: [] for None, [t] for one :class:`Targets`, else the list
    itself; ValueError when empty or holding anything but Targets."""
    if targets is None:
        return []
    if isinstance(targets, Targets):
        return [targets]
    out = list(targets)
    for t in out:
        if not isinstance(t, Targets):
            raise ValueError(f"targets must be Targets objects; got {type(t).__name__}")
    if not out:
        raise ValueError("targets is empty")
    return out


def mean_outputs(records: Sequence[dict]) -> Tuple[dict, dict, bool, str]:
    """The run records of one point (one per seed) as (outputs averaged over the seeds, SI;
    the first record's curve; ok; the first failed record's error). A failed run fails the
    point: ({}, {}, False, error)."""
    bad = [r for r in records if not r["ok"]]
    if bad:
        return {}, {}, False, bad[0]["error"] or "failed"
    keys = set.intersection(*(set(r["outputs"]) for r in records))
    outs = {k: float(np.mean([r["outputs"][k] for r in records])) for k in keys}
    return outs, records[0].get("curve") or {}, True, ""


#: A diametral test that ended before its peak is scored as if the peak came this many times
#: later than the end of the test (its dL_f/D is a lower bound; see the module docstring).
CENSORED_DLF_FACTOR = 1.5


def effective_outputs(outs: Mapping[str, float]) -> dict:
    """Outputs (SI) as scored: dLf_D of a test that ended before its peak (peaked < 1) is taken as
    CENSORED_DLF_FACTOR x the end of the test; the raw value stays under 'dLf_D_end'."""
    out = dict(outs)
    if "dLf_D" in out and out.get("peaked", 1.0) < 1.0:
        out["dLf_D_end"] = out["dLf_D"]
        out["dLf_D"] = out["dLf_D"] * CENSORED_DLF_FACTOR
    return out

