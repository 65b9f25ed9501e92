"""moisture_yield (cpp effects/moisture_yield.hpp): the loading line k1 exp(-c (MC - MC_ref))
delta. Two spheres pressed together follow it; unloaded they keep the residual overlap of eq. 5
with that k1; a line steeper than k2 is followed at k2; off, or at MC_ref, it is the paper's."""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_hardening import _assert_loads_along, _assert_unloads_from_its_loading_line, _press

from test_contact_law import frictionless


def _wet(c, mc, ref=8.0):
    law = frictionless()
    law.moisture_yield, law.moisture_content, law.moisture_reference = c, mc, ref
    return law


@pytest.mark.parametrize("c,mc,ref", [(0.05, 20.0, 8.0), (-0.03, 20.0, 8.0), (0.05, 4.0, 12.0)])
def test_loading_follows_the_moist_line(c, mc, ref):
    law = _wet(c, mc, ref)
    rows = _press(law, steps=2000)
    fac = math.exp(-c * (mc - ref))
    assert fac * law.k1 < law.k2
    np.testing.assert_allclose(rows[:, 1], fac * law.k1 * rows[:, 0], rtol=1e-9)
    assert law.to_core().plain_pairs() and law.to_core().moisture_acts()


def test_the_residual_overlap_is_that_of_the_moist_k1():
    """Loaded to delta_max and drawn apart, the pair unloads along k2 to zero force at the
    residual overlap delta_max (1 - k1' / k2), k1' the moist k1 (eq. 5)."""
    law = _wet(0.05, 20.0)
    _assert_unloads_from_its_loading_line(law, math.exp(-0.05 * 12.0) * law.k1)


def test_a_line_steeper_than_k2_is_followed_at_k2():
    law = _wet(-0.2, 20.0)  # k1 e^2.4 = 11 k1 > k2 = 4 k1
    _assert_loads_along(law, law.k2, steps=1000)


@pytest.mark.parametrize("law", [_wet(0.0, 20.0), _wet(0.05, 8.0)])
def test_off_or_at_the_reference_moisture_it_is_the_paper_line(law):
    _assert_loads_along(law, law.k1, steps=500, rtol=1e-12)
    assert law.to_core().moisture_acts() == (law.moisture_yield != 0.0)
