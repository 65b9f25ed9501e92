"""hardening (cpp effects/hardening.hpp): the loading line k1 delta (1 + h (delta/r*)^n). Two
spheres pressed together at a constant speed follow it while they load; off (h = 0) they
follow the paper's k1 delta; the four-lane pair kernel takes the effect's pairs."""
from __future__ import annotations

import numpy as np
import pytest

import pelletdem as pd
from test_contact_law import R, frictionless


def _press(law, speed=0.01, steps=5000):
    """Two equal spheres driven together at `speed` each (m/s): (overlap m, f_n N) rows."""
    return _drive(law, [(speed, steps)])


def _drive(law, phases):
    """Two equal spheres driven at +-speed each (m/s; > 0 together) for each (speed, steps) of
    ``phases`` in turn: (overlap m, f_n N) rows while they touch."""
    w = pd.World(dt=1e-7, box=((-3e-3, -1e-3, -1e-3), (3e-3, 1e-3, 1e-3)), contact=law,
                 gravity=(0, 0, 0), skin=2e-5)
    w.add_particles(np.array([[-R, 0, 0], [R, 0, 0]]), np.array([R, R]))
    rows = []
    for speed, steps in phases:
        for _ in range(steps):
            # the spheres are held to the speed, whatever the contact pushes
            w.set_velocities(np.array([[speed, 0, 0], [-speed, 0, 0]]), np.zeros((2, 3)))
            w.step()
            c = w.contacts()
            if len(c["overlap"]):
                rows.append((c["overlap"][0], c["fn"][0]))
    return np.array(rows)


def _assert_loads_along(law, slope, steps, rtol=1e-9):
    """Pressed together for ``steps`` steps, the pair's force is ``slope`` (N/m) times the overlap."""
    rows = _press(law, steps=steps)
    np.testing.assert_allclose(rows[:, 1], slope * rows[:, 0], rtol=rtol)


def _assert_unloads_from_its_loading_line(law, k1_line):
    """Loaded to delta_max and drawn apart, the pair unloads along k2 to zero force at the
    residual overlap delta_max (1 - k1_line / k2) (eq. 5), k1_line the slope it loaded along."""
    d_max = _press(law, steps=2000)[-1, 0]
    d, f = _drive(law, [(0.01, 2000), (-0.01, 4000)]).T
    top = int(np.argmax(d))
    assert d[top] == pytest.approx(d_max, rel=1e-9)
    unloading = slice(top + 1, None)
    delta0 = d[top] * (1 - k1_line / law.k2)
    on_line = f[unloading] > 0
    assert on_line.sum() > 100 and d[unloading][on_line].min() < 1.05 * delta0
    np.testing.assert_allclose(f[unloading][on_line], law.k2 * (d[unloading][on_line] - delta0), rtol=1e-7,
                               atol=1e-12)


@pytest.mark.parametrize("h,n", [(5.0, 2.0), (10.0, 1.0)])
def test_loading_follows_the_hardened_line(h, n):
    """Up to delta = 0.1 r*, where the hardened line is still less steep than k2 (a steeper
    one would be followed at the unloading slope k2, eq. 5's first case)."""
    law = frictionless()
    law.hardening, law.hardening_exponent = h, n
    rows = _press(law)
    d, f = rows[:, 0], rows[:, 1]
    r_star = R / 2
    np.testing.assert_allclose(f, law.k1 * d * (1 + h * (d / r_star) ** n), rtol=1e-9)
    assert (d / r_star).max() > 0.095  # the effect is there at all: >= 5 % above k1 delta
    assert law.to_core().plain_pairs()


def test_off_it_is_the_paper_line():
    law = frictionless()
    rows = _press(law, steps=500)
    np.testing.assert_allclose(rows[:, 1], law.k1 * rows[:, 0], rtol=1e-12)
    assert law.to_core().plain_pairs()
