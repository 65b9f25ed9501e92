"""The library of candidate effects the discrepancy loop (:mod:`pelletdem.loop`) can add.

Each effect is an optional part of the C++ contact or bond law (off by default, so the
baseline is the paper's model) with one fitted parameter, and comes with the residual
signature it leaves when the data carry it and the model does not. The loop measures each
signature numerically (one simulation per condition at a probe strength) and ranks the
candidates by how much of the residual it explains; the text here is what a person reads.

Parameter names are ``contact.<field>`` (a :class:`~pelletdem.engine.ContactLaw` field) or
``bond.<field>`` (a :class:`~pelletdem.engine.BondLaw` field), so any simulator that knows
those laws can switch the effect on.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Mapping, Tuple

__all__ = ["Effect", "EFFECTS", "effect_names"]


@dataclass(frozen=True)
class Effect:
    """One candidate effect.

    ``param``: the law field it sets (``contact.x`` or ``bond.x``); ``unit``: its unit.
    ``lo``, ``hi``: fit bounds; ``probe``: the strength at which its signature is measured;
    ``log``: fitted in log space (positive strengths); ``off``: the value that switches it
    off (the baseline's). ``fixed``: other law fields set with it (e.g. an exponent).
    ``needs``: condition attribute that must vary in the data for the effect to be seen
    (``"mc"`` for moisture), or ``""``. ``stage``: where it acts ('compaction' effects need a
    new relaxation per value, 'diametral' ones branch off the relaxed pellet).
    ``signature``: the residual it leaves, for the report.
    """

    name: str
    param: str
    unit: str
    lo: float
    hi: float
    probe: float
    log: bool
    off: float
    stage: str
    description: str
    signature: str
    fixed: Mapping[str, float] = field(default_factory=dict)
    needs: str = ""

    def __post_init__(self):
        if not (self.param.startswith("contact.") or self.param.startswith("bond.")):
            raise ValueError(f"effect {self.name}: param {self.param!r} must start with 'contact.' or 'bond.'")
        if not self.lo < self.hi or not self.lo <= self.probe <= self.hi:
            raise ValueError(f"effect {self.name}: need lo < hi and lo <= probe <= hi")
        if self.log and self.lo <= 0:
            raise ValueError(f"effect {self.name}: a log-space parameter needs lo > 0")
        if self.stage not in ("compaction", "diametral"):
            raise ValueError(f"effect {self.name}: stage must be 'compaction' or 'diametral'")

    def settings(self, value: float) -> Dict[str, float]:
        """The law fields to set for strength ``value`` (its param plus the fixed ones)."""
        return {self.param: float(value), **{k: float(v) for k, v in self.fixed.items()}}


EFFECTS: Dict[str, Effect] = {e.name: e for e in (
    Effect("hardening", "contact.hardening", "-", 0.05, 200.0, 5.0, True, 0.0, "compaction",
           "loading stiffness grows with overlap: k1 (1 + h (delta/r*)^2)",
           "compaction curve too soft above dh/h0 ~ 0.75 (the paper's own residual): the "
           "simulated sigma_z falls below the measured at the end of compaction; relaxed "
           "density too high, the more so at the higher pressure",
           fixed={"contact.hardening_exponent": 2.0}),
    Effect("unloading_growth", "contact.unloading_growth", "-", 0.1, 500.0, 10.0, True, 0.0, "compaction",
           "unloading stiffness grows with plastic flattening: k2 (1 + g delta0/r*) (Luding)",
           "relaxed pellets spring back too much: simulated relaxed density (and coordination "
           "number) below the measured, more so at the higher pressure; the loading branch of "
           "the compaction curve is untouched"),
    Effect("plate_crushing", "contact.plate_yield_stress", "Pa", 2.0e4, 5.0e7, 3.0e5, True, 0.0, "diametral",
           "particles crush where the plates touch the pellet: plate contact force capped at p pi r^2",
           "toe of sigma_1(dL/D): simulated stress too high at small dL/D, the rise starts "
           "late in the data; failure at larger dL_f/D with nearly the same peak"),
    Effect("weibull_strength", "bond.weibull_modulus", "-", 1.0, 30.0, 2.5, True, 0.0, "diametral",
           "bond strengths spread as a Weibull distribution of modulus m (mean kept)",
           "weak bonds break early: the rise bends over before the peak, the peak is lower "
           "and rounder, and the fall after it gentler; small m is a wide spread"),
    Effect("bond_softening", "bond.softening", "-", 0.05, 20.0, 1.5, True, 0.0, "diametral",
           "bonds soften before they break: capacity falls to zero at (1 + s) times the peak strain",
           "the curve keeps rising past the brittle model's peak: higher sigma_f at larger "
           "dL_f/D and a slow, ductile decline after the peak"),
    Effect("overlap_bond_radius", "bond.overlap_radius_gain", "-", 0.05, 100.0, 3.0, True, 0.0, "diametral",
           "bond radius grows with the contact's plastic flattening: r_b (1 + g delta0/r*)",
           "strength rises with compaction pressure faster than the model's: simulated "
           "sigma_f too high at low sigma_z and too low at high sigma_z (a trend across "
           "pressures, invisible within one pressure)"),
    Effect("moisture_bonds", "bond.moisture_coefficient", "1/%", -0.2, 0.2, 0.03, False, 0.0, "diametral",
           "bond stiffness and strength scale as exp(-c (MC - 8 %))",
           "a trend of the strength residual with moisture content (wetter pellets weaker or "
           "stronger than the model says), the same at every pressure",
           needs="mc"),
)}


def effect_names() -> Tuple[str, ...]:
    """Names of the shipped candidate effects, in library order."""
    return tuple(EFFECTS)
