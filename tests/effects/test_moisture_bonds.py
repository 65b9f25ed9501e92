"""moisture_bonds (cpp effects/moisture_bonds.hpp): k_n and the strengths times
exp(-c (mc - mc_ref)), MC being the world's contact law's moisture content."""
from __future__ import annotations

import math

import pytest

import pelletdem as pd
from test_bonds import GAP, R1, R2, heavy_pair


@pytest.mark.parametrize("mc,ref", [(20.0, 8.0), (8.0, 8.0), (5.0, 12.0)])
def test_moisture_scales_stiffness_and_strengths(mc, ref):
    c = 0.05
    law = pd.BondLaw(youngs_modulus=100e6, sigma_c=10e6, tau_c=12e6, moisture_coefficient=c,
                     gap_tolerance=2 * GAP)
    w, _ = heavy_pair(law=law, contact=pd.ContactLaw(moisture_content=mc, moisture_reference=ref))
    b = w.bonds()
    fac = math.exp(-c * (mc - ref))
    assert b["kn"][0] == pytest.approx(fac * 100e6 / (R1 + R2), rel=1e-12)
    assert b["sigma_c"][0] == pytest.approx(fac * 10e6, rel=1e-12)
    assert b["tau_c"][0] == pytest.approx(fac * 12e6, rel=1e-12)


def test_off_the_moisture_changes_no_bond():
    law = pd.BondLaw(youngs_modulus=100e6, sigma_c=10e6, tau_c=12e6, gap_tolerance=2 * GAP)
    w, _ = heavy_pair(law=law, contact=pd.ContactLaw(moisture_content=30.0))
    b = w.bonds()
    assert b["kn"][0] == 100e6 / (R1 + R2) and b["sigma_c"][0] == 10e6 and b["tau_c"][0] == 12e6
