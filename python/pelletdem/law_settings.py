"""Law parameters set by name: ``contact.X=V`` and ``bond.X=V``, checked against the laws'
parameter tables (:meth:`pelletdem.laws.ContactLaw.rows`, :meth:`pelletdem.laws.BondLaw.rows`).

The command line's ``--set`` (``pelletdem run``, ``calibrate``, ``loop``) and a loop data
manifest's ``[model] set`` go through :func:`parse_setting`: a name that is no row of its law,
a value that is not a number (or true/false for a switch) or one outside the row's allowed
range is refused with the name, the unit and the range, before any work.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Dict, Iterable, Mapping, Tuple

from .laws import BondLaw, ContactLaw

__all__ = ["LAWS", "parse_setting", "parse_settings", "apply_settings"]

#: The laws that can be set by name: prefix -> law class.
LAWS = {"contact": ContactLaw, "bond": BondLaw}


def _rows(law: str):
    return {r.name: r for r in LAWS[law].rows()}


def _value(text, row, where: str):
    if row.type == "bool":
        t = str(text).strip().lower()
        if t in ("true", "1", "yes", "on"):
            return True
        if t in ("false", "0", "no", "off"):
            return False
        raise ValueError(f"{where}: {text!r} is not a switch value (true or false)")
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: {text!r} is not a number ({row.unit})") from None
    if not math.isfinite(v) or not row.lo <= v <= row.hi:
        raise ValueError(f"{where} = {text!r} is out of range: allowed {row.lo:g} <= {row.name} <= {row.hi:g} "
                         f"({row.unit})")
    return v


def parse_setting(text: str, value=None) -> Tuple[str, object]:
    """('contact.X' or 'bond.X', value) from ``"contact.X=V"`` (or the name and a separate
    ``value``), checked against the law's parameter table; ValueError naming what is wrong."""
    if value is None:
        if "=" not in str(text):
            raise ValueError(f"--set {text!r}: expected contact.NAME=VALUE or bond.NAME=VALUE")
        text, _, value = str(text).partition("=")
    name = str(text).strip()
    law, _, field = name.partition(".")
    if law not in LAWS or not field:
        raise ValueError(f"--set {name!r}: a law parameter is contact.NAME or bond.NAME")
    rows = _rows(law)
    if field not in rows:
        raise ValueError(f"--set {name!r}: no such {law} law parameter; allowed {sorted(rows)}")
    return name, _value(value, rows[field], name)


def parse_settings(items: Iterable) -> Dict[str, object]:
    """{name: value} from ``--set`` strings or (name, value) pairs; a name given twice is an
    error."""
    out: Dict[str, object] = {}
    for it in items or ():
        name, v = parse_setting(*it) if isinstance(it, tuple) else parse_setting(it)
        if name in out:
            raise ValueError(f"--set {name} given twice")
        out[name] = v
    return out


def apply_settings(contact: ContactLaw, bond: BondLaw, settings: Mapping[str, object]) -> Tuple[ContactLaw, BondLaw]:
    """Copies of ``contact`` and ``bond`` with ``settings`` ({'contact.X': v, 'bond.Y': w})
    applied and checked by the engine."""
    c = {k[8:]: v for k, v in settings.items() if k.startswith("contact.")}
    b = {k[5:]: v for k, v in settings.items() if k.startswith("bond.")}
    contact, bond = dataclasses.replace(contact, **c), dataclasses.replace(bond, **b)
    contact.to_core()
    bond.to_core()
    return contact, bond
