"""Parallel bonds (eq. 12-15) against analytic answers.

Most checks use a pair of spheres made so heavy (density 1e8 kg/m^3 scaled by 1e12: ~3e9 kg,
moments of inertia ~50 kg m^2) that the bond's forces (< 0.1 N) change nothing of the motion
in the few thousand steps a test runs: the particles then move exactly as the velocities set
at the start say, and the bond's force and moment can be compared with closed forms of the
imposed relative motion. Gravity is off and the spheres start a small gap apart (bonded with
gap_tolerance), so the contact law never acts.

Conventions (bonds.hpp): n points from i to j; fn > 0 is compression; ft, mn, mt are the force
and moments on j. k_n^b = E_b / (r_i + r_j) (eq. 13), k_t^b = kt_ratio k_n^b, A = pi r_b^2,
J = pi r_b^4 / 2, I = J / 2; eq. 12: dF_n = k_n A du_n, dF_t = -k_t A du_t, dM_n = -k_t J dth_n,
dM_t = -k_n I dth_t; eq. 14: sigma = -F_n/A + |M_t| r_b / I, tau = |F_t|/A + |M_n| r_b / J.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import pelletdem as pd

R1, R2 = 2.0e-4, 1.6e-4          # unequal radii so that k_n = E_b / (r_i + r_j) is checked
GAP = 1.0e-6                     # surfaces apart: no contact force, ever
HEAVY = dict(density=1e8, density_scale=1e12)
BOX = ((-0.01, -0.01, -0.01), (0.01, 0.01, 0.01))


def heavy_pair(r1=R1, r2=R2, gap=GAP, law=None, dt=2e-6, contact=None):
    """Two heavy spheres on the x axis, gap `gap` apart, bonded with `law` (the world's contact
    law `contact`, default ContactLaw())."""
    w = pd.World(dt=dt, gravity=(0, 0, 0), box=BOX, skin=5e-5, contact=contact, **HEAVY)
    w.add_particles(np.array([[0.0, 0, 0], [r1 + r2 + gap, 0, 0]]), np.array([r1, r2]))
    law = law or pd.BondLaw(gap_tolerance=2 * gap)
    assert w.create_bonds(law.to_core()) == 1
    return w, law


def kn_of(law, r1=R1, r2=R2):
    return law.youngs_modulus / (r1 + r2)


def area(law):
    return math.pi * law.radius**2


def polar(law):
    return 0.5 * math.pi * law.radius**4


def bond0(w):
    b = w.bonds()
    return {k: v[0] for k, v in b.items()}


def run_until_broken(w, max_steps, every=1, record=None):
    """Step one at a time until the bond breaks; `record(w)` every `every` steps."""
    for s in range(max_steps):
        w.step()
        if w.intact_bond_count() == 0:
            return s + 1
        if record is not None and (s + 1) % every == 0:
            record(w)
    raise AssertionError("the bond did not break")


# --------------------------------------------------------------------------------------
# eq. 12-15: force-elongation slope and strengths
# --------------------------------------------------------------------------------------


def test_tension_slope_is_kn_A_and_break_at_A_sigma_c():
    law = pd.BondLaw(radius=2e-5, youngs_modulus=120e6, sigma_c=36e6, tau_c=36e6, gap_tolerance=2 * GAP)
    w, law = heavy_pair(law=law)
    d0 = R1 + R2 + GAP
    v = 0.01  # m/s each, apart: the pair's separation grows at 2 v
    w.set_velocities(np.array([[-v, 0, 0], [v, 0, 0]]), np.zeros((2, 3)))
    elong, force, fpart = [], [], []

    def rec(w):
        x = w.positions()
        elong.append(x[1, 0] - x[0, 0] - d0)
        force.append(bond0(w)["fn"])
        fpart.append(np.array(w.f[1]))

    run_until_broken(w, 5000, every=10, record=rec)
    elong, force = np.array(elong), np.array(force)
    slope, icept = np.polyfit(elong, force, 1)
    expected = -kn_of(law) * area(law)                       # tension is fn < 0
    assert slope == pytest.approx(expected, rel=1e-2)
    assert abs(icept) < 1e-3 * law.sigma_c * area(law)       # stress-free at creation
    # The force the bond puts on j is fn along n (+x), and nothing else.
    fpart = np.array(fpart)
    np.testing.assert_allclose(fpart[:, 0], force, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(fpart[:, 1:], 0.0, atol=1e-15)
    # Breakage at F = A sigma_c (eq. 15), within one step's increment (< 1%).
    f_c = area(law) * law.sigma_c
    assert -force[-1] <= f_c and -force[-1] == pytest.approx(f_c, rel=1e-2)
    br = w.broken_bonds()
    assert list(br["mode"]) == [1]
    assert br["sigma"][0] == pytest.approx(law.sigma_c, rel=1e-2) and br["sigma"][0] >= law.sigma_c
    assert br["tau"][0] == pytest.approx(0.0, abs=1e-6 * law.tau_c)
    # After breaking the bond pulls no more.
    w.step()
    np.testing.assert_allclose(np.array(w.f), 0.0, atol=1e-15)


def test_shear_force_and_break_at_tau_c():
    # j slides along +y, i along -y, no spin. The bond's frame turns with the pair (tan a = s/d0),
    # the tangential relative speed is 2 v cos a, so F_t = k_t A d0 asinh(s / d0) (= k_t A s at
    # small s) and F_n = -k_n A (sqrt(d0^2 + s^2) - d0).
    law = pd.BondLaw(radius=2e-5, youngs_modulus=120e6, kt_ratio=0.7, sigma_c=36e6, tau_c=6e6,
                     gap_tolerance=2 * GAP)
    w, law = heavy_pair(law=law)
    d0 = R1 + R2 + GAP
    v = 0.005
    w.set_velocities(np.array([[0, -v, 0], [0, v, 0]]), np.zeros((2, 3)))
    kt_a = 0.7 * kn_of(law) * area(law)
    kn_a = kn_of(law) * area(law)
    rows = []

    def rec(w):
        x = w.positions()
        b = bond0(w)
        rows.append((x[1, 1] - x[0, 1], np.linalg.norm(b["ft"]), b["fn"]))

    run_until_broken(w, 20000, every=10, record=rec)
    s, ft, fn = np.array(rows).T
    np.testing.assert_allclose(ft, kt_a * d0 * np.arcsinh(s / d0), rtol=1e-2)
    np.testing.assert_allclose(fn, -kn_a * (np.hypot(d0, s) - d0), rtol=1e-2, atol=1e-3 * ft.max())
    small = s < 0.1 * s.max()
    assert np.polyfit(s[small], ft[small], 1)[0] == pytest.approx(kt_a, rel=1e-2)
    # Breaks in shear when |F_t| / A reaches tau_c (no twist, so tau = |F_t| / A).
    assert ft[-1] / area(law) == pytest.approx(law.tau_c, rel=1e-2)
    br = w.broken_bonds()
    assert list(br["mode"]) == [2]
    assert br["tau"][0] == pytest.approx(law.tau_c, rel=1e-2) and br["tau"][0] >= law.tau_c


def test_bending_moment_is_kn_I_theta():
    # Pure bending: spins about z chosen so that the bond's two ends do not slide
    # (a_i w_i + a_j w_j = 0), relative rotation theta = (w_j - w_i) t.
    law = pd.BondLaw(radius=2e-5, youngs_modulus=120e6, sigma_c=36e6, tau_c=36e6, gap_tolerance=2 * GAP)
    w, law = heavy_pair(law=law)
    ai, aj = R1 + 0.5 * GAP, R2 + 0.5 * GAP
    om = 2.0  # rad/s on j
    wi = -om * aj / ai
    w.set_velocities(np.zeros((2, 3)), np.array([[0, 0, wi], [0, 0, om]]))
    steps = 1500
    w.run(steps)
    theta = (om - wi) * steps * w.dt
    b = bond0(w)
    m_expected = kn_of(law) * 0.5 * polar(law) * theta      # M_t = k_n (J/2) theta
    np.testing.assert_allclose(b["mt"], [0, 0, -m_expected], rtol=1e-2, atol=1e-3 * m_expected)
    assert np.linalg.norm(b["ft"]) < 1e-6 * kn_of(law) * area(law) * ai * theta
    assert b["mn"] == 0.0 and b["fn"] == pytest.approx(0.0, abs=1e-12)
    # The moment is the torque on j and minus the torque on i.
    np.testing.assert_allclose(np.array(w.t[1]), [0, 0, -m_expected], rtol=1e-2)
    np.testing.assert_allclose(np.array(w.t[0]), [0, 0, m_expected], rtol=1e-2)
    # Eq. 14: sigma = |M_t| r_b / I.
    assert b["sigma_max"] == pytest.approx(m_expected * law.radius / (0.5 * polar(law)), rel=1e-9)


def test_twisting_moment_is_kt_J_phi():
    law = pd.BondLaw(radius=2e-5, youngs_modulus=120e6, kt_ratio=0.6, sigma_c=36e6, tau_c=36e6,
                     gap_tolerance=2 * GAP)
    w, law = heavy_pair(law=law)
    om = 3.0  # j spins about the bond axis
    w.set_velocities(np.zeros((2, 3)), np.array([[0, 0, 0], [om, 0, 0]]))
    steps = 1500
    w.run(steps)
    phi = om * steps * w.dt
    b = bond0(w)
    m_expected = 0.6 * kn_of(law) * polar(law) * phi          # M_n = k_t J phi
    assert b["mn"] == pytest.approx(-m_expected, rel=1e-2)
    assert np.linalg.norm(b["mt"]) < 1e-9 * m_expected and np.linalg.norm(b["ft"]) < 1e-12
    np.testing.assert_allclose(np.array(w.t[1]), [-m_expected, 0, 0], rtol=1e-2)
    assert b["tau_max"] == pytest.approx(m_expected * law.radius / polar(law), rel=1e-9)


@pytest.mark.parametrize("kind", ["bending", "twisting"])
def test_moment_breakage(kind):
    # Bending breaks in tension when k_n theta r_b = sigma_c; twisting in shear when
    # k_t phi r_b = tau_c (eq. 14 with F = 0).
    law = pd.BondLaw(radius=2e-5, youngs_modulus=120e6, sigma_c=3e6, tau_c=3e6, gap_tolerance=2 * GAP)
    w, law = heavy_pair(r1=R1, r2=R1, law=law)
    om = 200.0
    spins = np.array([[0, 0, -om], [0, 0, om]]) if kind == "bending" else np.array([[0, 0, 0], [om, 0, 0]])
    w.set_velocities(np.zeros((2, 3)), spins)
    steps = run_until_broken(w, 10000)
    angle = (2 * om if kind == "bending" else om) * steps * w.dt
    kn = law.youngs_modulus / (2 * R1)
    expected = law.sigma_c / (kn * law.radius)
    assert angle == pytest.approx(expected, rel=1e-2)
    assert list(w.broken_bonds()["mode"]) == ([1] if kind == "bending" else [2])


# --------------------------------------------------------------------------------------
# Objectivity: a rigid rotation of a loaded pair
# --------------------------------------------------------------------------------------


def _rot(axis, th):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(th) * k + (1 - math.cos(th)) * k @ k


def _force_and_moment(w):
    b, x = bond0(w), w.positions()
    n = (x[1] - x[0]) / np.linalg.norm(x[1] - x[0])
    return b["fn"] * n + b["ft"], b["mn"] * n + b["mt"]


def _rotate_loaded_pair(axis, n_steps):
    w, law = heavy_pair()
    # Pre-load: stretch, shear, bend and twist, then stop.
    w.set_velocities(np.array([[-0.005, -0.003, 0], [0.005, 0.003, 0.002]]),
                     np.array([[0, 0, -2.0], [3.0, 0, 5.0]]))
    w.run(1000)
    w.set_velocities(np.zeros((2, 3)), np.zeros((2, 3)))
    f0, m0 = _force_and_moment(w)
    x0 = w.positions()
    c = x0.mean(axis=0)
    dt, theta = w.dt, 0.5 * math.pi
    dth = theta / n_steps
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    worst = 0.0
    for k in range(n_steps):
        xk = c + (x0 - c) @ _rot(a, k * dth).T
        xk1 = c + (x0 - c) @ _rot(a, (k + 1) * dth).T
        # Positions on the circle, velocities that carry them to the next point in one step,
        # spins equal to the pair's rotation rate: a rigid motion.
        w.set_positions(xk)
        w.set_velocities((xk1 - xk) / dt, np.tile(a * dth / dt, (2, 1)))
        w.step()
        f, _ = _force_and_moment(w)
        worst = max(worst, abs(np.linalg.norm(f) / np.linalg.norm(f0) - 1.0))
    rot = _rot(a, theta)
    f, m = _force_and_moment(w)
    d = np.linalg.norm(x0[1] - x0[0])
    # The incremental law takes the normal increment along the end-of-step normal, so each step
    # of a rotation by dth registers a spurious stretch d (1 - cos dth) ~ d dth^2 / 2: after a
    # turn theta in N steps, |dF| <= k_n A d theta^2 / (2 N).
    bound = kn_of(law) * area(law) * d * theta**2 / (2 * n_steps) / np.linalg.norm(f0)
    return (np.linalg.norm(f - rot @ f0) / np.linalg.norm(f0), worst,
            np.linalg.norm(m - rot @ m0) / np.linalg.norm(m0), bound)


@pytest.mark.parametrize("axis", [(0, 0, 1), (1, 1, 1)])
def test_rigid_rotation_turns_force_and_moment_without_changing_them(axis):
    # Tolerance: 1% of |F| for a quarter turn in 4000 steps (4e-4 rad per step, a thousand
    # times faster than any bonded pair turns in a pellet run); the residual is the scheme's
    # second-order error k_n A d theta^2 / (2N), which halves when N doubles. Moments are
    # turned exactly (relative error < 1e-6).
    err, worst, merr, bound = _rotate_loaded_pair(axis, 4000)
    assert err < 1e-2 and worst < 1e-2
    assert err < 1.2 * bound + 1e-6
    assert merr < 1e-6


def test_rigid_rotation_error_is_second_order():
    e1, _, _, _ = _rotate_loaded_pair((0, 0, 1), 1000)
    e2, _, _, _ = _rotate_loaded_pair((0, 0, 1), 2000)
    assert e1 / e2 == pytest.approx(2.0, rel=0.1)


# --------------------------------------------------------------------------------------
# A bonded chain as a cantilever
# --------------------------------------------------------------------------------------


def test_cantilever_chain_deflection_matches_beam_theory():
    """Tip-loaded cantilever: a straight chain of N+1 equal spheres, particle 0 clamped.

    The spheres (radius r) sit a gap g apart (spacing l = 2 r + g), so no contact ever acts;
    the contact law is made soft (k1 = k2 = 100 N/m) only so that the time step can follow the
    bonds. Bond k joins particles k-1 and k; its centre is at x_k = (k - 1/2) l.

    Discrete chain (small deflections, rigid spheres joined by the bonds' springs): a
    transverse tip load P at particle N gives the bond at x_k the moment P (N l - x_k) and the
    shear force P. Bond k's relative rotation is then dth_k = P (N l - x_k) / K with
    K = k_n I (k_n = E_b / (2 r), I = pi r_b^4 / 4) and its shear slip P / (k_t A). Summing the
    rigid-body rotations and the slips, the deflection of particle m is
        u_m = sum_{k <= m} [P (N l - x_k)(m l - x_k) / K + P / (k_t A)],
    so the tip (m = N): u_N = P l^2 N (4 N^2 - 1) / (12 K) + N P / (k_t A).
    Euler-Bernoulli with L = N l and EI = K l (the bond's rotational stiffness per unit
    length): u_N = P L^3 / (3 EI) = P l^2 N^3 / (3 K). The chain is stiffer by the factor
    1 / (1 - 1/(4 N^2)) (the midpoint sum of x^2), softer by the shear term 3 r_b^2/(4 N^2 l^2)
    of the bending one: for N = 8, r_b = r/2: -0.39% and +0.07%.
    Tolerances: simulation vs the discrete formula 0.1% (what is left is the relaxation and
    second-order geometry at u_N / L = 0.5%); vs Euler-Bernoulli 0.5% (the 0.32% above).

    Clamp and loading by resetting velocities every step: particle 0 gets v = -dt f/(2 m),
    w = -dt t/(2 I), which the next half kick cancels, so it never moves; the tip's z speed is
    prescribed the same way (x and rotation free: a point load); the others are damped by a
    factor (1 - c) per step to reach the static state. The tip load is then -f_z on it.
    """
    n_b, r, g = 8, 2e-4, 2e-6
    ell = 2 * r + g
    rb, eb = 1e-4, 120e6
    dt = 4e-5
    w = pd.World(dt=dt, gravity=(0, 0, 0), box=BOX, skin=2e-5,
                 contact=pd.ContactLaw(k1=100.0, k2=100.0, kc=0.0, mu=0.0, rolling=0.0))
    x0 = np.zeros((n_b + 1, 3))
    x0[:, 0] = np.arange(n_b + 1) * ell
    w.add_particles(x0, np.full(n_b + 1, r))
    assert w.create_bonds(pd.BondLaw(radius=rb, youngs_modulus=eb, gap_tolerance=5e-6).to_core()) == n_b
    m = np.array(w.m)
    inertia = 0.4 * m * r * r
    length = n_b * ell
    target = 5e-3 * length
    ramp, hold, c = 3000, 9000, 4e-3
    for s in range(ramp + hold):
        v, om = np.array(w.v) * (1 - c), np.array(w.w) * (1 - c)
        f, t = np.array(w.f), np.array(w.t)
        v[0], om[0] = -0.5 * dt * f[0] / m[0], -0.5 * dt * t[0] / inertia[0]
        v[n_b, 2] = (target / (ramp * dt) if s < ramp else 0.0) - 0.5 * dt * f[n_b, 2] / m[n_b]
        w.set_velocities(v, om)
        w.step()
    x = w.positions()
    np.testing.assert_allclose(x[0], x0[0], atol=1e-15)          # the clamp held
    u = x[:, 2]
    assert u[n_b] == pytest.approx(target, rel=1e-9)
    load = -float(np.array(w.f)[n_b, 2])
    kn = eb / (2 * r)
    k_rot = kn * math.pi * rb**4 / 4
    kt_a = kn * math.pi * rb**2
    xk = (np.arange(1, n_b + 1) - 0.5) * ell
    u_disc = np.array([sum(load * (length - xk[q]) * (mm * ell - xk[q]) / k_rot + load / kt_a
                           for q in range(mm)) for mm in range(n_b + 1)])
    np.testing.assert_allclose(u[1:], u_disc[1:], rtol=1e-3)
    u_eb = load * length**3 / (3 * k_rot * ell)
    assert u[n_b] == pytest.approx(u_eb, rel=5e-3)
    # The deflected shape too: Euler-Bernoulli u(x) = P x^2 (3 L - x) / (6 EI) at the particles.
    xs = np.arange(n_b + 1) * ell
    u_eb_shape = load * xs**2 * (3 * length - xs) / (6 * k_rot * ell)
    np.testing.assert_allclose(u[2:], u_eb_shape[2:], rtol=2e-2)


# --------------------------------------------------------------------------------------
# Fig. 12b: r_b halved with E_b r_b^2 and sigma_c r_b^2 held
# --------------------------------------------------------------------------------------


def _scaled(law, f):
    return pd.BondLaw(radius=law.radius * f, youngs_modulus=law.youngs_modulus / f**2,
                      kt_ratio=law.kt_ratio, sigma_c=law.sigma_c / f**2, tau_c=law.tau_c / f**2,
                      gap_tolerance=law.gap_tolerance)


def test_scaling_leaves_normal_and_shear_response_unchanged_pair():
    # Translation only: F_n, F_t and the breakage (stretch and shear) are exactly invariant.
    base = pd.BondLaw(radius=2e-5, youngs_modulus=120e6, sigma_c=36e6, tau_c=20e6, gap_tolerance=2 * GAP)
    out = []
    for law in (base, _scaled(base, 0.5)):
        w, _ = heavy_pair(law=law)
        w.set_velocities(np.array([[-0.004, -0.003, 0], [0.004, 0.003, 0]]), np.zeros((2, 3)))
        hist = []

        def record(w, hist=hist):
            hist.append((bond0(w)["fn"], *bond0(w)["ft"]))

        steps = run_until_broken(w, 20000, every=50, record=record)
        out.append((steps, np.array(hist), w.broken_bonds()["mode"][0]))
    assert out[0][0] == out[1][0] and out[0][2] == out[1][2]
    np.testing.assert_allclose(out[1][1], out[0][1], rtol=1e-9, atol=1e-15)


def test_scaling_changes_moments_as_r_b_squared():
    # M = k_n I theta ~ E_b r_b^4 ~ r_b^2: a quarter when r_b halves; the bending stress
    # relative to the strength, k_n theta r_b / sigma_c ~ r_b, halves.
    base = pd.BondLaw(radius=2e-5, youngs_modulus=120e6, sigma_c=36e6, tau_c=36e6, gap_tolerance=2 * GAP)
    res = []
    for law in (base, _scaled(base, 0.5)):
        w, _ = heavy_pair(r1=R1, r2=R1, law=law)
        w.set_velocities(np.zeros((2, 3)), np.array([[0, 0, -1.0], [0, 0, 1.0]]))
        w.run(1000)
        b = bond0(w)
        res.append((np.linalg.norm(b["mt"]), b["sigma_max"] / law.sigma_c))
    assert res[1][0] / res[0][0] == pytest.approx(0.25, rel=1e-9)
    assert res[1][1] / res[0][1] == pytest.approx(0.5, rel=1e-9)


def _bonded_sample(n=300, seed=1):
    """A few hundred particles compacted to 50 MPa in a 3.2 mm mould, unloaded, at rest, free."""
    rad = 1.6e-3
    radii = pd.truncated_normal_radii(n, seed=seed)
    h = float(np.sum(4 / 3 * np.pi * radii**3)) / (0.25 * np.pi * rad * rad)
    x, radii = pd.random_pack_cylinder(radii, radius=rad - 1e-9, z_lo=0.0, z_hi=h, seed=seed + 1)
    w = pd.World(dt=2e-6, box=((-4e-3, -4e-3, -1e-3), (4e-3, 4e-3, h + 2e-3)), gravity=(0, 0, -9.81e4),
                 skin=2e-5, max_overlap_ratio=1.5, contact=pd.ContactLaw(normal_damping_ratio=0.5))
    w.add_particles(x, radii)
    fl = w.add_plane("floor", (0, 0, 0), (0, 0, 1))
    mo = w.add_cylinder("mould", (0, 0, 0), rad)
    pi_ = w.add_plane("piston", (0, 0, h + 5e-4), (0, 0, -1))
    w.run_until(max_steps=40000, kinetic_energy_below=0.5 * float(np.sum(w.m)) * 1e-6, check_interval=100)
    w.set_wall_velocity(pi_, (0, 0, -0.1))
    w.run_until(max_steps=100000, wall_force_above=(pi_, 50e6 * np.pi * rad * rad))
    w.set_wall_velocity(pi_, (0, 0, 0.05))
    w.run_until(max_steps=100000, wall_force_below=(pi_, 0.0))
    w.run(200)
    w.set_wall_velocity(pi_, (0, 0, 0))
    w.set_wall_active(pi_, False)
    w.run_until(max_steps=30000, kinetic_energy_below=1e-9, check_interval=50)
    w.gravity = (0, 0, 0)
    w.set_wall_active(mo, False)
    w.set_wall_active(fl, False)
    zero = np.zeros((w.n, 3))
    for _ in range(2):
        w.run(5000)
        w.set_velocities(zero, zero)
    return w


def _diametral(w, law, speed=0.005, dld=0.15):
    if law is not None:
        w.create_bonds(law.to_core())
    x, r = w.positions(), w.radii()
    d = float((x[:, 0] + r).max() - (x[:, 0] - r).min())
    lo = w.add_plane("lo", (0, float((x[:, 1] - r).min()), 0), (0, 1, 0))
    hi = w.add_plane("hi", (0, float((x[:, 1] + r).max()), 0), (0, -1, 0))
    w.set_load_walls([lo, hi])
    w.set_wall_velocity(lo, (0, speed / 2, 0))
    w.set_wall_velocity(hi, (0, -speed / 2, 0))
    w.set_sample_interval(50)
    w.clear_samples()
    w.run_until(max_steps=10**6, load_marker_above=dld * d)
    force = 0.5 * (w.wall_samples(lo)["normal_force"] + w.wall_samples(hi)["normal_force"])
    broken = w.broken_bonds()
    return w.samples()["load_marker"] / d, force, broken["load_marker"] / d, w


def _bending_share(w):
    """Largest bending and twisting terms of eq. 14 over the intact bonds, relative to strength."""
    b = w.bonds()
    ok = b["mode"] == 0
    rb = b["radius"][ok]
    i_ = math.pi * rb**4 / 4
    bend = np.linalg.norm(b["mt"][ok], axis=1) * rb / i_ / b["sigma_c"][ok]
    twist = np.abs(b["mn"][ok]) * rb / (2 * i_) / b["tau_c"][ok]
    return float(bend.max()), float(twist.max())


@pytest.mark.slow
def test_fig12b_scaling_bonded_sample_curve():
    """Diametral compression of a bonded ~300-particle sample, r_b = 20 um vs 10 um with
    E_b r_b^2, sigma_c r_b^2 and tau_c r_b^2 held (Fig. 12b).

    What holds (measured when written: 300 particles, 876 bonds, dL/D to 0.15, 23 and 21 bonds
    broken, the first at dL/D = 0.066; the force still rising at the end): up to the first
    breakage the two curves agree within 1% of the largest force; averaged over windows of
    dL/D = 0.01 within 0.6% up to dL/D = 0.10 and 1.4% up to 0.12; beyond, where single
    breakages set the curve, windows differ by 1.9-3.1%; the largest forces within 0.5%.
    So 2% holds for the curve up to dL/D ~ 0.12, not for its breakage-dominated end.
    The normal and shear parts are exactly invariant (test above); what differs is bending and
    twisting: the moment stiffness k_n I ~ r_b^2 drops to a quarter (a drift of < 1% of the
    force before breakage), and the moment terms of eq. 14 relative to the strength, ~ r_b,
    halve (at the end they reach 29% of sigma_c and 36% of tau_c at r_b = 20 um, 16% and 19%
    at 10 um), so some bonds break at other moments (tension/shear 13/10 against 9/12).
    """
    sample = _bonded_sample()
    base = pd.BondLaw(gap_tolerance=5e-6)
    m_b, p_b, brk_b, w_b = _diametral(sample.clone(), base)
    m_h, p_h, brk_h, w_h = _diametral(sample.clone(), _scaled(base, 0.5))
    m_u, p_u, _, _ = _diametral(sample.clone(), None)
    n = min(len(p_b), len(p_h))
    m_b, p_b, p_h = m_b[:n], p_b[:n], p_h[:n]
    peak = p_b.max()
    # The bonds matter: without them the sample carries a small fraction of the load.
    assert p_u.max() < 0.5 * peak
    first = min(brk_b.min(), brk_h.min())
    pre = m_b < first
    assert pre.sum() > 20
    assert np.abs(p_h[pre] - p_b[pre]).max() < 0.02 * peak
    edges = np.arange(0.0, 0.12 + 1e-9, 0.01)
    idx = np.digitize(m_b, edges)
    for q in range(1, len(edges)):
        sel = idx == q
        assert abs(p_h[sel].mean() - p_b[sel].mean()) < 0.02 * peak, (q, edges[q])
    assert p_h.max() == pytest.approx(peak, rel=0.05)
    assert len(brk_h) == pytest.approx(len(brk_b), rel=0.5)
    # Bending and twisting relative to strength halve with r_b.
    bend_b, twist_b = _bending_share(w_b)
    bend_h, twist_h = _bending_share(w_h)
    assert bend_h < 0.8 * bend_b and twist_h < 0.8 * twist_b
