"""interlocking_friction (cpp effects/interlocking_friction.hpp): from the bonding on, two
particles slide past each other at F mu f_n (eq. 9 with mu times F), while a particle on a
wall still slides at mu_wall f_n; the stages keep it off from fill to relaxation, so one
relaxed pellet serves every F, and put it in force for the test."""
from __future__ import annotations

import pytest
from test_densified_yield import assert_kept_off_until_the_bonding, assert_one_relaxed_pellet_serves_every

import pelletdem as pd
from test_friction import assert_pair_slides_at, assert_wall_slides_at


def _interlocked(f, mu_wall=0.0, wall_stiffness_factor=1.0):
    return pd.ContactLaw(k1=1e5, k2=4e5, kc=0.0, mu=0.3, mu_wall=mu_wall, rolling=0.0,
                         wall_stiffness_factor=wall_stiffness_factor, interlocking_friction=f)


@pytest.mark.parametrize("f", [1.0, 2.5])
def test_a_pair_slides_at_f_mu_fn(f):
    law = _interlocked(f)
    assert law.to_core().plain_pairs()  # the four-lane kernel takes it
    assert_pair_slides_at(law, f * 0.3)


def test_a_wall_keeps_mu_wall():
    assert_wall_slides_at(_interlocked(4.0, mu_wall=0.15, wall_stiffness_factor=2.0), 0.15)


def test_one_relaxed_pellet_serves_every_interlocking_friction():
    assert_one_relaxed_pellet_serves_every("interlocking_friction", 3.0)


def test_the_stages_keep_it_off_until_the_bonding():
    assert_kept_off_until_the_bonding("interlocking_friction", 3.0)
