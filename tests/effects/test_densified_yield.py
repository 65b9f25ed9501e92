"""densified_yield (cpp effects/densified_yield.hpp): from the bonding on, contacts load along
Y k1. Two spheres pressed together follow that line, unload from it along k2 to eq. 5's
residual overlap, and follow k2 where Y k1 is steeper; the stages keep it off from fill to
relaxation, so one relaxed pellet serves every Y, and put it in force for the test."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_hardening import _assert_loads_along, _assert_unloads_from_its_loading_line

from pelletdem import stages
from pelletdem.engine import BondLaw
from pelletdem.pipeline import relaxed_pellet
from pelletdem.presets import get_preset
from pelletdem.runs import make_spec
from test_contact_law import frictionless


def _densified(y):
    law = frictionless()
    law.densified_yield = y
    return law


@pytest.mark.parametrize("y", [1.5, 3.0])
def test_loading_follows_the_densified_line(y):
    law = _densified(y)
    assert y * law.k1 < law.k2
    _assert_loads_along(law, y * law.k1, steps=2000)
    assert law.to_core().plain_pairs()


def test_the_residual_overlap_is_that_of_the_densified_k1():
    """Loaded to delta_max and drawn apart, the pair unloads along k2 to zero force at
    delta_max (1 - Y k1 / k2) (eq. 5)."""
    law = _densified(3.0)
    _assert_unloads_from_its_loading_line(law, 3.0 * law.k1)


def test_a_yield_above_k2_over_k1_leaves_the_contact_elastic():
    law = _densified(10.0)  # 10 k1 > k2 = 4 k1: the pair loads and unloads along k2
    _assert_loads_along(law, law.k2, steps=1000)


def test_off_it_is_the_paper_line():
    _assert_loads_along(_densified(1.0), frictionless().k1, steps=500, rtol=1e-12)


def assert_one_relaxed_pellet_serves_every(field, value):
    """A diametral-stage contact effect leaves the relaxed pellet's cache key as it is."""
    plain = make_spec({}, preset="tiny", diametral=False)
    on = make_spec({}, preset="tiny", diametral=False, contact={field: value})
    assert on.relax_key == plain.relax_key


def assert_kept_off_until_the_bonding(field, value):
    """The relaxed pellet is the paper law's to the bit with ``field`` = ``value`` in the
    preset's law; the bond stage puts it in force."""
    base = get_preset("tiny")
    off = getattr(base.contact, field)
    law = replace(base.contact, **{field: value})
    assert stages.compaction_law(law) == base.contact
    got = {}
    for name, preset in (("plain", base), ("on", replace(base, contact=law))):
        pellet, _ = relaxed_pellet(preset, sigma_z=60e6, seed=3, n_particles=120, progress=False)
        assert getattr(pellet.world.contact_law, field) == off
        got[name] = np.array(pellet.world.x)
        if name == "on":
            stages.bond(pellet, BondLaw(), progress=False)
            assert getattr(pellet.world.contact_law, field) == value
    np.testing.assert_array_equal(got["on"], got["plain"])


def test_one_relaxed_pellet_serves_every_densified_yield():
    assert_one_relaxed_pellet_serves_every("densified_yield", 50.0)


def test_the_stages_keep_it_off_until_the_bonding():
    assert_kept_off_until_the_bonding("densified_yield", 50.0)
