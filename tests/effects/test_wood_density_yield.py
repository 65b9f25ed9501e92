"""wood_density_yield (cpp effects/wood_density_yield.hpp): the loading line
k1 (rho_w / rho_ref)^n delta. Two spheres pressed together follow it; unloaded they keep the
residual overlap of eq. 5 with that k1; it multiplies with moisture_yield's factor; a line
steeper than k2 is followed at k2; off, or at the reference density, it is the paper's."""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_hardening import _assert_loads_along, _assert_unloads_from_its_loading_line, _press

from test_contact_law import frictionless


def _wood(n, rho, ref=680.0):
    law = frictionless()
    law.wood_density_yield, law.wood_density, law.wood_density_reference = n, rho, ref
    return law


@pytest.mark.parametrize("n,rho,ref", [(1.5, 510.0, 680.0), (2.0, 550.0, 680.0), (-1.0, 600.0, 680.0),
                                       (1.5, 675.0, 500.0)])
def test_loading_follows_the_wood_density_line(n, rho, ref):
    law = _wood(n, rho, ref)
    rows = _press(law, steps=2000)
    fac = (rho / ref) ** n
    assert fac * law.k1 < law.k2
    np.testing.assert_allclose(rows[:, 1], fac * law.k1 * rows[:, 0], rtol=1e-9)
    core = law.to_core()
    assert core.plain_pairs() and not core.moisture_acts() and core.wood_density_acts()


def test_the_residual_overlap_is_that_of_the_wood_k1():
    """Loaded to delta_max and drawn apart, the pair unloads along k2 to zero force at the
    residual overlap delta_max (1 - k1' / k2), k1' = k1 (510 / 680)^1.5 (eq. 5)."""
    law = _wood(1.5, 510.0)
    _assert_unloads_from_its_loading_line(law, (510.0 / 680.0) ** 1.5 * law.k1)


def test_it_multiplies_with_the_moisture_factor():
    law = _wood(2.0, 550.0)
    law.moisture_yield, law.moisture_content = -0.04, 20.0
    rows = _press(law, steps=1000)
    fac = (550.0 / 680.0) ** 2.0 * math.exp(0.04 * 12.0)
    np.testing.assert_allclose(rows[:, 1], fac * law.k1 * rows[:, 0], rtol=1e-9)


def test_a_line_steeper_than_k2_is_followed_at_k2():
    law = _wood(-6.0, 500.0)  # (500/680)^-6 = 6.3 > k2 / k1 = 4
    _assert_loads_along(law, law.k2, steps=1000)


@pytest.mark.parametrize("law", [_wood(0.0, 510.0), _wood(1.5, 680.0)])
def test_off_or_at_the_reference_density_it_is_the_paper_line(law):
    _assert_loads_along(law, law.k1, steps=500, rtol=1e-12)
    # off, the wood's density is not read: the woods share their relaxed pellets
    assert law.to_core().wood_density_acts() == (law.wood_density_yield != 0.0)
