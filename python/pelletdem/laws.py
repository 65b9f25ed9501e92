"""The contact law (eq. 5-11) and the parallel bond law (eq. 12-15) as Python dataclasses.

Every parameter is one row of its law's table in C++ (``cpp/include/pelletdem/params.hpp``:
name, type, default, allowed range, unit, doc); the candidate effects' rows come from their
own headers (``cpp/include/pelletdem/effects/``). The fields, defaults and docstrings of
:class:`ContactLaw` and :class:`BondLaw` are made from those tables when the module is
imported, and ``to_core()`` checks the values in C++ against the same rows, so a parameter is
written once. ``ContactLaw.rows()`` and ``BondLaw.rows()`` return the tables.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, List

from . import _core

__all__ = ["ContactLaw", "BondLaw", "ParamRow", "law_rows", "allowed_values"]

ParamRow = _core.ParamRow


def law_rows(core_params) -> List[Any]:
    """The parameter rows of a law's C++ struct (``_core.ContactLawParams`` or ``BondParams``):
    each has name, type ('double' or 'bool'), default, lo, hi, check, unit, label, lanes, doc."""
    return list(core_params.rows())


def allowed_values(row) -> str:
    """The allowed values of a row, as a person reads them."""
    unit = "" if row.unit == "-" else f" {row.unit}"
    if row.type == "bool":
        return "True or False"
    hi = "" if row.hi >= 1e299 else f" <= {row.hi:g}{unit}"
    return {
        "positive": f"> 0{unit}" + (f", in [{row.lo:g}, {row.hi:g}]{unit}" if row.lo > 0 or hi else ""),
        "nonnegative": f">= 0{unit}" + (f", <= {row.hi:g}{unit}" if hi else ""),
        "zero_or_range": f"0 (off) or {row.lo:g} to {row.hi:g}{unit}",
        "whole_range": f"a whole number from {row.lo:g} to {row.hi:g}",
    }.get(row.check, f"{row.lo:g} to {row.hi:g}{unit}")


def _docstring(summary: str, rows) -> str:
    lines = [summary, "", "Fields (SI units; default; allowed values):", ""]
    for r in rows:
        default = bool(r.default) if r.type == "bool" else f"{r.default:g}"
        unit = "" if r.unit == "-" else f", {r.unit}"
        lines.append(f"- ``{r.name}``{unit}: {r.doc} (default {default}; {allowed_values(r)}).")
    return "\n".join(lines)


def _to_core(self):
    """The C++ parameter struct, checked against the law's table (ParameterError naming the
    field and its allowed range, or TypeError for a value of the wrong type)."""
    core = self._core_type()
    for r in self.rows():
        value = getattr(self, r.name)
        if r.type == "double":
            if isinstance(value, (str, bytes)) or isinstance(value, complex):
                raise TypeError(f"{r.name} must be a real number, got {value!r}")
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise TypeError(f"{r.name} must be a real number, got {value!r}") from None
        setattr(core, r.name, value)
    core.validate()
    return core


def _law_class(name: str, core_type, summary: str, namespace: dict):
    rows = law_rows(core_type)
    specs = []
    for r in rows:
        typ = bool if r.type == "bool" else float
        default = bool(r.default) if typ is bool else float(r.default)
        meta = {"unit": r.unit, "doc": r.doc, "lo": r.lo, "hi": r.hi, "check": r.check}
        specs.append((r.name, typ, dataclasses.field(default=default, metadata=meta)))
    ns = dict(namespace)
    ns["to_core"] = _to_core
    ns["_core_type"] = staticmethod(core_type)
    ns["rows"] = classmethod(lambda cls: law_rows(core_type))
    cls = dataclasses.make_dataclass(name, specs, namespace=ns)
    cls.__module__ = __name__
    cls.__qualname__ = name
    cls.__doc__ = _docstring(summary, rows)
    cls.rows.__func__.__doc__ = "The law's parameter table: one ParamRow per field, in field order."
    return cls


def _restitution(self) -> float:
    """Coefficient of restitution e = sqrt(k1/k2) (eq. 8), dimensionless."""
    return math.sqrt(self.k1 / self.k2)


ContactLaw: Any = _law_class(
    "ContactLaw", _core.ContactLawParams,
    "Parameters of the paper's contact law (eq. 5-11) and its candidate effects, SI units.",
    {"restitution": property(_restitution)})

BondLaw: Any = _law_class(
    "BondLaw", _core.BondParams,
    "Parallel-bond parameters (eq. 12-15) and the bonds' candidate effects, SI units.", {})

