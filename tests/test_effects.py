"""The optional effects of the contact and bond laws (the discrepancy loop's candidate library,
issue 6) against analytic answers. Each is off by default, and off it is the paper's law
(checked bit for bit in test_contact_law / test_bonds, which run with the defaults).

* unloading_growth: k2(delta0) = k2 (1 + g delta0 / r*); after a head-on collision the
  restitution is sqrt(k1 / k2(delta0)) with delta0 from k2(delta0) (delta_max - delta0) =
  k1 delta_max.
* plate_yield_stress: a crushable plate's contact force never exceeds p pi r^2.
* weibull_modulus: per-bond strengths with mean sigma_c and the Weibull coefficient of
  variation sqrt(G(1 + 2/m) / G(1 + 1/m)^2 - 1), fixed by (strength_seed, i, j).
* softening: a pulled bond carries A sigma_c at its peak strain u_c, then its force falls
  linearly (slope -k_n A / s) and it breaks near (1 + s) u_c.
* overlap_radius_gain: r_b = radius (1 + g delta0 / r*) from the contact's residual overlap.
* moisture: k_n and the strengths times exp(-c (mc - mc_ref)).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import pelletdem as pd
from test_bonds import GAP, R1, R2, area, heavy_pair, kn_of
from test_contact_law import R, frictionless


def test_effects_are_off_by_default():
    c, b = pd.ContactLaw(), pd.BondLaw()
    assert c.unloading_growth == 0 and c.plate_yield_stress == 0 and c.hardening == 0
    assert b.weibull_modulus == 0 and b.softening == 0 and b.overlap_radius_gain == 0
    assert b.moisture_coefficient == 0


# --------------------------------------------------------------------------------------
# contact law
# --------------------------------------------------------------------------------------

def _collide(law, v0=0.05):
    w = pd.World(dt=1e-7, box=((-3e-3, -1e-3, -1e-3), (3e-3, 1e-3, 1e-3)), contact=law,
                 gravity=(0, 0, 0), skin=2e-5)
    w.add_particles(np.array([[-R - 1e-6, 0, 0], [R + 1e-6, 0, 0]]), np.array([R, R]))
    w.set_velocities(np.array([[v0, 0, 0], [-v0, 0, 0]]), np.zeros((2, 3)))
    rows = []
    for _ in range(400000):
        w.step()
        c = w.contacts()
        if len(c["overlap"]):
            rows.append((c["overlap"][0], c["fn"][0]))
        elif rows:
            break
    v = w.velocities()
    return (v[1, 0] - v[0, 0]) / (2 * v0), np.array(rows)


@pytest.mark.parametrize("g", [5.0, 40.0])
def test_unloading_growth_follows_its_k2_line_and_sets_restitution(g):
    k1, k2 = 1.0e5, 4.0e5
    law = frictionless(k1, k2)
    law.unloading_growth = g
    e, rows = _collide(law)
    r_star = R / 2
    d_max = rows[:, 0].max()
    # delta0 from k2 (1 + a d0) (d_max - d0) = k1 d_max, a = g / r*: the positive root
    a = g / r_star
    b, c = 1 - a * d_max, d_max - k1 * d_max / k2
    d0 = (-b + math.sqrt(b * b + 4 * a * c)) / (2 * a)
    k2e = k2 * (1 + a * d0)
    after = int(np.argmax(rows[:, 0])) + 3
    unload = rows[after:]
    unload = unload[unload[:, 1] > 0]
    np.testing.assert_allclose(unload[:, 1], k2e * (unload[:, 0] - d0), rtol=1e-9)
    # energy k1 d_max^2 / 2 in, (k1 d_max)^2 / (2 k2e) back: e^2 = k1 / k2e
    assert e == pytest.approx(math.sqrt(k1 / k2e), rel=1e-2)
    assert k2e > 1.05 * k2  # the effect is there at all


def _squeeze(crushable, p_y, travel=0.1 * R, speed=0.02):
    law = frictionless()
    law.plate_yield_stress = p_y
    w = pd.World(dt=1e-7, box=((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 2e-3)), contact=law,
                 gravity=(0, 0, 0), skin=2e-5)
    w.add_particles(np.array([[0.0, 0.0, R]]), np.array([R]))
    floor = w.add_plane("floor", [0, 0, 0], [0, 0, 1])
    top = w.add_plane("top", [0, 0, 2 * R], [0, 0, -1])
    if crushable:
        w.set_wall_crushable(top, True)
        w.set_wall_crushable(floor, True)
    w.set_wall_velocity(top, [0, 0, -speed])
    forces = []
    for _ in range(int(travel / speed / w.dt)):
        w.step()
        forces.append(w.wall_state(top)["normal_force"])
    return np.array(forces)


def test_plate_yield_caps_the_force_on_crushable_walls_only():
    p_y = 5e6
    cap = p_y * math.pi * R * R  # 0.63 N; the linear law reaches ~2 N at the end
    f_hard = _squeeze(False, p_y)
    f_crush = _squeeze(True, p_y)
    assert f_hard.max() > 2.0 * cap  # the plain walls go on stiffening
    assert f_crush.max() <= cap * (1 + 1e-9)
    assert f_crush[-100:].min() > 0.99 * cap  # flattening at constant force at the end


# --------------------------------------------------------------------------------------
# bond law
# --------------------------------------------------------------------------------------

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


@pytest.mark.parametrize("field,value", [
    ("weibull_modulus", 0.1), ("weibull_modulus", float("nan")), ("strength_seed", -1.0),
    ("strength_seed", 0.5), ("softening", -1.0), ("overlap_radius_gain", -0.1),
    ("moisture_coefficient", 2.0), ("moisture_content", 150.0)])
def test_bad_bond_effect_parameters_name_themselves(field, value):
    with pytest.raises(ValueError, match=field):
        pd.BondLaw(**{field: value}).to_core()


@pytest.mark.parametrize("field,value", [("unloading_growth", -1.0), ("plate_yield_stress", -1.0),
                                         ("unloading_growth", float("inf"))])
def test_bad_contact_effect_parameters_name_themselves(field, value):
    with pytest.raises(ValueError, match=field):
        pd.ContactLaw(**{field: value}).to_core()


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
