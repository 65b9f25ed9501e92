"""overlap_bond_radius (cpp effects/overlap_bond_radius.hpp): r_b = radius (1 + g delta0 / r*)
from the contact's residual overlap at bonding."""
from __future__ import annotations

import numpy as np
import pytest

import pelletdem as pd
from test_contact_law import R, frictionless


def test_overlap_radius_gain_uses_the_residual_overlap_at_bonding():
    # Two spheres collide; once past the largest overlap (unloading, delta0 > 0) they are
    # bonded: r_b follows the contact's residual overlap delta0.
    law = frictionless(kc=0.0)
    w = pd.World(dt=1e-7, box=((-3e-3, -1e-3, -1e-3), (3e-3, 1e-3, 1e-3)), contact=law,
                 gravity=(0, 0, 0), skin=2e-5)
    w.add_particles(np.array([[-R - 1e-6, 0, 0], [R + 1e-6, 0, 0]]), np.array([R, R]))
    w.set_velocities(np.array([[0.05, 0, 0], [-0.05, 0, 0]]), np.zeros((2, 3)))
    last = 0.0
    for _ in range(100000):
        w.step()
        c = w.contacts()
        if len(c["overlap"]) and c["overlap"][0] < last:
            break
        last = c["overlap"][0] if len(c["overlap"]) else 0.0
    st = w.get_state()
    assert len(st["contact_delta0"]) == 1 and st["contact_delta0"][0] > 0
    d0 = float(st["contact_delta0"][0])
    g = 50.0
    assert w.create_bonds(pd.BondLaw(radius=2e-5, overlap_radius_gain=g).to_core()) == 1
    assert w.bonds()["radius"][0] == pytest.approx(2e-5 * (1 + g * d0 / (R / 2)), rel=1e-12)
    assert g * d0 / (R / 2) > 0.1  # the effect is there at all
