"""weibull_strength (cpp effects/weibull_strength.hpp): per-bond strengths with mean sigma_c
and the Weibull coefficient of variation sqrt(G(1 + 2/m) / G(1 + 1/m)^2 - 1), fixed by
(strength_seed, i, j)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import pelletdem as pd


def _bonded_grid(law, n=6):
    """A simple cubic block of n^3 touching spheres, all neighbours bonded."""
    w = pd.World(gravity=(0, 0, 0), box=((-0.01,) * 3, (0.01,) * 3), skin=2e-5)
    r = 2e-4
    g = np.arange(n) * 2 * r * 0.999
    x = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    w.add_particles(x, np.full(len(x), r))
    w.create_bonds(law.to_core())
    return w


@pytest.mark.parametrize("m", [2.0, 5.0])
def test_weibull_strengths_have_the_stated_mean_and_spread(m):
    law = pd.BondLaw(sigma_c=10e6, tau_c=20e6, weibull_modulus=m, strength_seed=3)
    b = _bonded_grid(law, n=10).bonds()
    sc, tc = b["sigma_c"], b["tau_c"]
    n = len(sc)
    assert n == 3 * 10 * 10 * 9
    cv = math.sqrt(math.gamma(1 + 2 / m) / math.gamma(1 + 1 / m) ** 2 - 1)
    assert sc.mean() == pytest.approx(10e6, abs=4 * cv * 10e6 / math.sqrt(n))
    assert sc.std() / sc.mean() == pytest.approx(cv, rel=0.1)
    np.testing.assert_allclose(tc / sc, 2.0, rtol=1e-12)  # one flaw per bond weakens both
    again = _bonded_grid(law, n=10).bonds()["sigma_c"]
    np.testing.assert_array_equal(again, sc)  # fixed by (seed, i, j)
    other = _bonded_grid(pd.BondLaw(sigma_c=10e6, weibull_modulus=m, strength_seed=4), n=10).bonds()["sigma_c"]
    assert np.mean(other != sc) > 0.99
