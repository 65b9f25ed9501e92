"""The ends of a model's box (pelletdem.loop_box): a fit pinned at one, a wider box, and the
points already simulated carried into it."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from pelletdem.loop_box import pinned, pinned_note, rebox, widened
from pelletdem.loop_emulator import Axis, Space

SPACE = Space((Axis("E_b", 2e7, 2e8, True), Axis("gain", 0.0, 1.0, False)))


def _model(u, U=None):
    """The parts of a ModelFit these functions read."""
    U = np.zeros((0, 2)) if U is None else U
    return SimpleNamespace(space=SPACE, fit=SimpleNamespace(u=np.asarray(u, float), params=SPACE.params(u)),
                           emulator=SimpleNamespace(U=U, Y=np.ones((len(U), 3)), SE=np.ones((len(U), 3))))


def test_a_fit_within_one_percent_of_an_end_is_pinned_there():
    assert pinned(_model([0.995, 0.5]), ["E_b", "gain"]) == [(SPACE.axes[0], "upper")]
    assert pinned(_model([0.5, 0.005]), ["E_b", "gain"]) == [(SPACE.axes[1], "lower")]
    assert pinned(_model([0.5, 0.005]), ["E_b"]) == []  # only the names asked about
    assert pinned(_model([0.02, 0.98]), ["E_b", "gain"]) == []


def test_an_end_moves_out_by_half_the_box_on_the_axis_own_scale():
    up = widened(SPACE, [(SPACE.axes[0], "upper")]).axes[0]
    assert (up.lo, up.hi) == (2e7, pytest.approx(2e8 * math.sqrt(10)))
    down = widened(SPACE, [(SPACE.axes[0], "lower")]).axes[0]
    assert (down.lo, down.hi) == (pytest.approx(2e7 / math.sqrt(10)), 2e8)
    lin = widened(SPACE, [(SPACE.axes[1], "upper")]).axes[1]
    assert (lin.lo, lin.hi) == (0.0, 1.5)
    # a linear axis that starts at zero stays there: nothing to widen
    assert widened(SPACE, [(SPACE.axes[1], "lower")]) == SPACE


def test_the_points_already_simulated_keep_their_values_in_the_wider_box():
    U = np.array([[0.0, 0.0], [0.5, 0.25], [1.0, 1.0]])
    m = _model([1.0, 0.5], U)
    new = widened(SPACE, pinned(m, ["E_b", "gain"]))
    U2, Y, SE = rebox(m, new)
    for a, b in zip(U, U2):
        assert new.params(b) == pytest.approx(SPACE.params(a))
    assert U2[:, 0].max() == pytest.approx(2.0 / 3.0)  # the old box is two thirds of the new in log
    assert Y is m.emulator.Y and SE is m.emulator.SE


def test_what_stays_pinned_is_said():
    m = _model([1.0, 0.5])
    note = pinned_note(pinned(m, ["E_b"]), m)
    assert note.startswith("E_b = 2e+08 is at the upper end of its box [2e+07, 2e+08]")
    assert pinned_note([], m) == ""
