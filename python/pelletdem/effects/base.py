"""What a candidate effect declares to the discrepancy loop: its parameter, the bounds and
probe of its strength, the stage after which it acts and the residual signature it leaves."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Mapping, Sequence

from ..laws import BondLaw, ContactLaw

__all__ = ["Effect", "clash"]

_LAWS = {"contact": ContactLaw, "bond": BondLaw}


@dataclass(frozen=True)
class Effect:
    """One candidate effect.

    ``param``: the law field it sets (``contact.x`` or ``bond.x``, a row of that law's table);
    ``unit``: its unit (checked against the row's). ``lo``, ``hi``: fit bounds; ``probe``: the
    strength at which its signature is measured; ``log``: fitted in log space (positive
    strengths); ``off``: the value that switches it off (the row's default). ``fixed``: other
    law fields set with it (e.g. an exponent). ``needs``: condition attribute that must vary in
    the data for the effect to be seen (``"mc"`` for moisture), or ``""``. ``stage``: where it
    acts ('compaction' effects need a new relaxation per value, 'diametral' ones branch off the
    relaxed pellet). ``signature``: the residual it leaves, for the report. ``stronger``:
    'higher' when the effect grows with its strength, 'lower' when it grows as the strength
    falls (a Weibull modulus: a small modulus is a wide spread).
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
    stronger: str = "higher"

    def __post_init__(self):
        law, _, fname = self.param.partition(".")
        if law not in _LAWS:
            raise ValueError(f"effect {self.name}: param {self.param!r} must start with 'contact.' or 'bond.'")
        rows = {r.name: r for r in _LAWS[law].rows()}
        for p in (self.param, *self.fixed):
            plaw, _, pname = p.partition(".")
            if plaw not in _LAWS or pname not in {r.name for r in _LAWS[plaw].rows()}:
                raise ValueError(f"effect {self.name}: {p!r} is no row of a law's table")
        row = rows[fname]
        if self.unit != row.unit:
            raise ValueError(f"effect {self.name}: unit {self.unit!r} but the row {self.param} says {row.unit!r}")
        if self.off != row.default:
            raise ValueError(f"effect {self.name}: off = {self.off} but the row {self.param} defaults to {row.default}")
        if not self.lo < self.hi or not self.lo <= self.probe <= self.hi:
            raise ValueError(f"effect {self.name}: need lo < hi and lo <= probe <= hi")
        if self.log and self.lo <= 0:
            raise ValueError(f"effect {self.name}: a log-space parameter needs lo > 0")
        if self.stage not in ("compaction", "diametral"):
            raise ValueError(f"effect {self.name}: stage must be 'compaction' or 'diametral'")
        if self.stronger not in ("higher", "lower"):
            raise ValueError(f"effect {self.name}: stronger must be 'higher' or 'lower'")

    def settings(self, value: float) -> Dict[str, float]:
        """The law fields to set for strength ``value`` (its param plus the fixed ones)."""
        return {self.param: float(value), **{k: float(v) for k, v in self.fixed.items()}}


def clash(effects: Sequence[Effect]) -> str:
    """Why ``effects`` cannot be on together, each at its probe strength, as the laws' own
    checks say it (two laws of the unloading stiffness, for instance); "" when they can."""
    fields: Dict[str, Dict[str, float]] = {law: {} for law in _LAWS}
    for e in effects:
        for p, v in e.settings(e.probe).items():
            law, _, name = p.partition(".")
            fields[law][name] = v
    try:
        for law, kw in fields.items():
            _LAWS[law](**kw).to_core()
    except ValueError as err:
        return str(err)
    return ""
