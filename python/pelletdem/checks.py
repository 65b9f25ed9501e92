"""Checks of plain input values: each returns the value as the engine wants it or raises
ParameterError naming the parameter and what is allowed, before any work starts."""
from __future__ import annotations

import math

import numpy as np

from ._core import ParameterError

__all__ = ["finite", "positive", "integer", "vec3"]


def finite(name: str, value) -> float:
    """`value` as a finite float, or ParameterError naming `name`."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(v):
        raise ParameterError(f"{name} = {v} must be finite")
    return v


def positive(name: str, value, unit: str) -> float:
    """`value` (in `unit`) as a finite float > 0, or ParameterError naming `name`."""
    if not (isinstance(value, (int, float, np.floating)) and not isinstance(value, bool)
            and math.isfinite(value) and value > 0):
        raise ParameterError(f"{name} = {value!r} {unit} must be a finite number > 0")
    return float(value)


def integer(name: str, value, lo: int, hi: int) -> int:
    """`value` as an int in [lo, hi] (a float with no fraction is taken), or ParameterError."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise ParameterError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    if not lo <= int(value) <= hi:
        raise ParameterError(f"{name} = {value} is out of range: allowed {lo} <= {name} <= {hi}")
    return int(value)


def vec3(name: str, value) -> tuple:
    """Three finite floats, or ParameterError naming `name`."""
    try:
        items = list(value)
    except TypeError:
        raise ParameterError(f"{name} must have 3 components, got {value!r}") from None
    if len(items) != 3 or isinstance(value, (str, bytes)):
        raise ParameterError(f"{name} must have 3 components, got {value!r}")
    return tuple(finite(name, v) for v in items)
