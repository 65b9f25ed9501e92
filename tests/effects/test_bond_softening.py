"""bond_softening (cpp effects/bond_softening.hpp): a pulled bond carries A sigma_c at its peak
strain u_c, then its force falls linearly (slope -k_n A / s) and it breaks near (1 + s) u_c;
off, the bond is the paper's brittle one; its damage survives a checkpoint."""
from __future__ import annotations

import numpy as np
import pytest

import pelletdem as pd
from test_bonds import GAP, R1, R2, area, heavy_pair, kn_of


def test_softening_bond_force_falls_linearly_to_zero_at_1_plus_s_peak_strain():
    s = 2.0
    law = pd.BondLaw(radius=2e-5, youngs_modulus=120e6, sigma_c=36e6, tau_c=36e6, gap_tolerance=2 * GAP,
                     softening=s)
    w, law = heavy_pair(law=law)
    d0 = R1 + R2 + GAP
    v = 0.01
    w.set_velocities(np.array([[-v, 0, 0], [v, 0, 0]]), np.zeros((2, 3)))
    kA = kn_of(law) * area(law)
    f_peak = area(law) * law.sigma_c
    u_c = f_peak / kA
    rows = []
    for _ in range(200000):
        w.step()
        if w.intact_bond_count() == 0:
            break
        x = w.positions()
        rows.append((x[1, 0] - x[0, 0] - d0, -w.bonds()["fn"][0]))
    else:
        raise AssertionError("the bond did not break")
    u, f = np.array(rows).T
    up = u < 0.98 * u_c
    np.testing.assert_allclose(f[up], kA * u[up], rtol=2e-3, atol=1e-4 * f_peak)
    assert f.max() == pytest.approx(f_peak, rel=1e-2)
    down = (u > 1.05 * u_c) & (f > 0.05 * f_peak)
    expect = f_peak - (kA / s) * (u[down] - u_c)
    np.testing.assert_allclose(f[down], expect, rtol=1e-2, atol=5e-3 * f_peak)
    assert u[-1] == pytest.approx((1 + s) * u_c, rel=2e-2)  # gone at 1% of its capacity
    assert w.broken_bonds()["mode"][0] == 1


def test_brittle_bond_is_unchanged_by_the_softening_code():
    law = pd.BondLaw(gap_tolerance=2 * GAP)
    w, _ = heavy_pair(law=law)
    w.set_velocities(np.array([[-0.01, 0, 0], [0.01, 0, 0]]), np.zeros((2, 3)))
    peak = 0.0
    for _ in range(100000):
        w.step()
        if w.intact_bond_count() == 0:
            break
        peak = max(peak, -w.bonds()["fn"][0])
    assert w.bonds()["damage"][0] == 0.0
    assert peak <= area(law) * law.sigma_c


def test_softening_state_survives_a_checkpoint_round_trip():
    law = pd.BondLaw(gap_tolerance=2 * GAP, softening=1.0)
    w, _ = heavy_pair(law=law)
    w.set_velocities(np.array([[-0.01, 0, 0], [0.01, 0, 0]]), np.zeros((2, 3)))
    while w.bonds()["damage"][0] == 0.0:
        w.step()
    w2 = pd.World.from_state(w.get_state())
    for _ in range(200):
        w.step()
        w2.step()
    np.testing.assert_array_equal(w.bonds()["damage"], w2.bonds()["damage"])
    np.testing.assert_array_equal(w.positions(), w2.positions())
