"""saturating_unloading (cpp effects/saturating_unloading.hpp): k2(delta0) = k2 + (k_p - k2)
min(delta0 / (phi r*), 1). After a head-on collision the pair unloads along the line through
the residual overlap delta0 that solves k2(delta0) (delta_max - delta0) = k1 delta_max, with
that slope, and leaves with e = sqrt(k1 / k2(delta0)); once saturated the slope is k_p."""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_unloading_growth import _collide

import pelletdem as pd
from test_contact_law import R, frictionless


def _residual(k1, k2, ratio, phi, d_max):
    """delta0 (m) and k2(delta0) (N/m) of a contact unloaded from d_max, by bisection."""
    r_star = R / 2

    def k2e(d0):
        return k2 + (ratio - 1) * k2 * min(d0 / (phi * r_star), 1.0)

    lo, hi = 0.0, d_max
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if k2e(mid) * (d_max - mid) > k1 * d_max:
            lo = mid
        else:
            hi = mid
    return lo, k2e(lo)


@pytest.mark.parametrize("ratio,phi", [(3.0, 0.5), (3.0, 0.02)])  # rising, and saturated
def test_unloading_line_and_restitution(ratio, phi):
    k1, k2 = 1.0e5, 4.0e5
    law = frictionless(k1, k2)
    law.plastic_stiffness_ratio, law.plastic_overlap = ratio, phi
    e, rows = _collide(law)
    d_max = rows[:, 0].max()
    d0, k2e = _residual(k1, k2, ratio, phi, d_max)
    saturated = d0 >= phi * R / 2
    assert saturated == (phi < 0.1)
    if saturated:
        assert k2e == pytest.approx(ratio * k2)
    after = int(np.argmax(rows[:, 0])) + 3
    unload = rows[after:]
    unload = unload[unload[:, 1] > 0]
    np.testing.assert_allclose(unload[:, 1], k2e * (unload[:, 0] - d0), rtol=1e-7)
    assert e == pytest.approx(math.sqrt(k1 / k2e), rel=1e-2)
    assert k2e > 1.05 * k2


def test_off_it_is_the_paper_law_and_one_unloading_effect_at_a_time():
    law = pd.ContactLaw()
    assert law.plastic_stiffness_ratio == 1.0 and law.to_core().plain_pairs()
    assert pd.ContactLaw(plastic_stiffness_ratio=2.0).to_core().plain_pairs()  # four lanes take it
    with pytest.raises(pd.ParameterError, match="unloading stiffness"):
        pd.ContactLaw(plastic_stiffness_ratio=2.0, unloading_growth=5.0).to_core()
    with pytest.raises(pd.ParameterError, match="plastic_stiffness_ratio"):
        pd.ContactLaw(plastic_stiffness_ratio=0.5).to_core()
