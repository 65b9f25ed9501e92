"""unloading_growth (cpp effects/unloading_growth.hpp): k2(delta0) = k2 (1 + g delta0 / r*).
After a head-on collision the restitution is sqrt(k1 / k2(delta0)) with delta0 from
k2(delta0) (delta_max - delta0) = k1 delta_max, and the unloading line has slope k2(delta0)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import pelletdem as pd
from test_contact_law import R, frictionless


def _collide(law, v0=0.05):
    w = pd.World(dt=1e-7, box=((-3e-3, -1e-3, -1e-3), (3e-3, 1e-3, 1e-3)), contact=law,
                 gravity=(0, 0, 0), skin=2e-5)
    w.add_particles(np.array([[-R - 1e-6, 0, 0], [R + 1e-6, 0, 0]]), np.array([R, R]))
    w.set_velocities(np.array([[v0, 0, 0], [-v0, 0, 0]]), np.zeros((2, 3)))
    rows = []
    for _ in range(400000):
        w.step()
        c = w.contacts()
        if len(c["overlap"]):
            rows.append((c["overlap"][0], c["fn"][0]))
        elif rows:
            break
    v = w.velocities()
    return (v[1, 0] - v[0, 0]) / (2 * v0), np.array(rows)


@pytest.mark.parametrize("g", [5.0, 40.0])
def test_unloading_growth_follows_its_k2_line_and_sets_restitution(g):
    k1, k2 = 1.0e5, 4.0e5
    law = frictionless(k1, k2)
    law.unloading_growth = g
    e, rows = _collide(law)
    r_star = R / 2
    d_max = rows[:, 0].max()
    # delta0 from k2 (1 + a d0) (d_max - d0) = k1 d_max, a = g / r*: the positive root
    a = g / r_star
    b, c = 1 - a * d_max, d_max - k1 * d_max / k2
    d0 = (-b + math.sqrt(b * b + 4 * a * c)) / (2 * a)
    k2e = k2 * (1 + a * d0)
    after = int(np.argmax(rows[:, 0])) + 3
    unload = rows[after:]
    unload = unload[unload[:, 1] > 0]
    np.testing.assert_allclose(unload[:, 1], k2e * (unload[:, 0] - d0), rtol=1e-9)
    # energy k1 d_max^2 / 2 in, (k1 d_max)^2 / (2 k2e) back: e^2 = k1 / k2e
    assert e == pytest.approx(math.sqrt(k1 / k2e), rel=1e-2)
    assert k2e > 1.05 * k2  # the effect is there at all
