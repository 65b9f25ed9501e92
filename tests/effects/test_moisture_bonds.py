"""moisture_bonds (cpp effects/moisture_bonds.hpp): k_n and the strengths times
exp(-c (mc - mc_ref))."""
from __future__ import annotations

import math

import pytest

import pelletdem as pd
from test_bonds import GAP, R1, R2, heavy_pair


def test_moisture_scales_stiffness_and_strengths():
    c = 0.05
    law = pd.BondLaw(youngs_modulus=100e6, sigma_c=10e6, tau_c=12e6, moisture_content=20.0,
                     moisture_coefficient=c, gap_tolerance=2 * GAP)
    w, _ = heavy_pair(law=law)
    b = w.bonds()
    fac = math.exp(-c * (20.0 - 8.0))
    assert b["kn"][0] == pytest.approx(fac * 100e6 / (R1 + R2), rel=1e-12)
    assert b["sigma_c"][0] == pytest.approx(fac * 10e6, rel=1e-12)
    assert b["tau_c"][0] == pytest.approx(fac * 12e6, rel=1e-12)
