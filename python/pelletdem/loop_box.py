"""The ends of a model's box: a fit pinned at one, and a wider box that lets it go.

A fitted base parameter at an end of its box (within :data:`EDGE` of it, in the box's unit
coordinates) is not a fit: the data want a value the box does not allow, the emulated chi2
there is the box's minimum, not the data's, and its interval is cut by the box. The loop widens
the baseline's box at such an end (:func:`widened`: by half the box's width, on the axis's own
scale) and fits again, reusing every point already simulated (:func:`rebox`); what is still
pinned after that is said in the verdict (:func:`pinned_note`).
"""
from __future__ import annotations

import math
from typing import List, Sequence, Tuple

import numpy as np

from .loop_emulator import Axis, Space
from .loop_models import ModelFit

__all__ = ["EDGE", "pinned", "widened", "rebox", "pinned_list", "pinned_note"]

#: A fitted position this close to an end of the unit box (-) is pinned there.
EDGE = 0.01


def pinned(mf: ModelFit, names: Sequence[str]) -> List[Tuple[Axis, str]]:
    """(axis, 'lower' or 'upper') of each of ``names`` whose fitted value in ``mf`` is at an
    end of its box."""
    out = []
    for axis, u in zip(mf.space.axes, mf.fit.u):
        if axis.name not in names:
            continue
        if u <= EDGE:
            out.append((axis, "lower"))
        elif u >= 1.0 - EDGE:
            out.append((axis, "upper"))
    return out


def _wider(axis: Axis, end: str) -> Axis:
    """``axis`` with its ``end`` moved out by half its width (a factor sqrt(hi / lo) on a log
    axis); a linear axis that starts at or above zero does not go below it."""
    if axis.log:
        f = math.sqrt(axis.hi / axis.lo)
        lo, hi = (axis.lo / f, axis.hi) if end == "lower" else (axis.lo, axis.hi * f)
    else:
        w = 0.5 * (axis.hi - axis.lo)
        lo, hi = (axis.lo - w, axis.hi) if end == "lower" else (axis.lo, axis.hi + w)
        if axis.lo >= 0.0:
            lo = max(lo, 0.0)
    return Axis(axis.name, lo, hi, axis.log)


def widened(space: Space, ends: Sequence[Tuple[Axis, str]]) -> Space:
    """``space`` with each (axis, end) of ``ends`` moved out (see the module docstring); the
    same box when none can move (a linear axis pinned at zero)."""
    move = {a.name: end for a, end in ends}
    return Space(tuple(_wider(a, move[a.name]) if a.name in move else a for a in space.axes), space.fixed)


def rebox(mf: ModelFit, space: Space) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The design of ``mf`` (U, Y, SE) as points of ``space``, a box of the same axes with other
    bounds: the simulations already made, to join the new box's emulator."""
    U = mf.emulator.U
    cols = [[new.to_unit(old.from_unit(float(u))) for u in U[:, k]]
            for k, (old, new) in enumerate(zip(mf.space.axes, space.axes))]
    return np.array(cols, float).T.reshape(len(U), space.dim), mf.emulator.Y, mf.emulator.SE


def pinned_list(ends: Sequence[Tuple[Axis, str]], mf: ModelFit) -> str:
    """"E_b = 2e+08 is at the upper end of its box [2e+07, 2e+08]; ..." for ``ends``."""
    return "; ".join(f"{a.name} = {mf.fit.params[a.name]:.4g} is at the {end} end of its box [{a.lo:.4g}, {a.hi:.4g}]"
                     for a, end in ends)


def pinned_note(ends: Sequence[Tuple[Axis, str]], mf: ModelFit) -> str:
    """What the report says of parameters still pinned at an end of their box ('' if none)."""
    if not ends:
        return ""
    return pinned_list(ends, mf) + ": the data ask for a value the box does not allow, and the fit there is the box's"
