"""Coulomb friction (eq. 9) and rolling friction (eq. 11) against textbook mechanics.

Gravity: the engine divides physical gravity by density_scale (1e4 here). These tests pass
1e4 times 9.81 m/s^2 so that the effective gravity g is 9.81 m/s^2 and a sphere slides or
rolls a measurable amount in a few thousand steps; the results depend only on g.
"""

import math

import numpy as np
import pytest

import pelletdem as pd

R = 2.0e-4   # sphere radius, m
G = 9.81     # effective gravity, m/s^2
SW = 2.0     # wall stiffness factor, set explicitly (the results do not depend on it)


def sphere_on_floor(law, dt, sample_interval=1):
    """One sphere resting on a floor at z = 0, placed at the equilibrium overlap m g / (SW k1)."""
    w = pd.World(dt=dt, box=((-1e-3, -1e-3, -1e-3), (5e-2, 1e-3, 1e-3)), contact=law,
                 gravity=(0, 0, -G * 1e4), skin=2e-5, sample_interval=sample_interval)
    w.add_particles(np.zeros((1, 3)), np.array([R]))
    m = w.masses()[0]
    floor = w.add_plane("floor", [0, 0, -R + m * G / (SW * law.k1)], [0, 0, 1])
    return w, floor, m


def assert_wall_slides_at(law, mu_wall):
    """A sphere launched without spin slides on a floor, then rolls.

    While it slides the friction force is mu_wall m g: v = v0 - mu_wall g t and the spin grows
    as r dw/dt = r^2 mu_wall m g / I = (5/2) mu_wall g. Slip ends when v = r w, at
    t* = 2 v0 / (7 mu_wall g), with v = (5/7) v0; with no rolling friction it then rolls on.
    """
    dt = 1e-6
    w, floor, m = sphere_on_floor(law, dt)
    v0 = 0.05
    w.set_velocities(np.array([[v0, 0, 0]]), np.zeros((1, 3)))
    t_star = 2 * v0 / (7 * mu_wall * G)
    w.run(int(1.5 * t_star / dt))
    s = w.wall_samples(floor)
    f, t = s["force"], s["time"]
    tangential = np.hypot(f[:, 0], f[:, 1])
    normal = -f[:, 2]
    sliding = t < 0.95 * t_star
    np.testing.assert_allclose(normal, m * G, rtol=1e-6)
    np.testing.assert_allclose(tangential[sliding] / normal[sliding], mu_wall, rtol=1e-9)
    # Friction on the sphere opposes the slip (-x); the reaction on the wall is +x.
    assert (f[sliding, 0] > 0).all()
    # Once rolling the friction force drops below its limit and (the tangential spring's
    # oscillation being damped by eq. 10) dies away.
    rolling = t > 1.05 * t_star
    assert (tangential[rolling] < 0.1 * mu_wall * normal[rolling]).all()


@pytest.mark.parametrize("mu_wall", [0.15, 0.4])
def test_sliding_sphere_friction_saturates_at_mu_wall_fn(mu_wall):
    law = pd.ContactLaw(k1=1e5, k2=4e5, kc=0.0, mu=0.5, mu_wall=mu_wall, rolling=0.0,
                        wall_stiffness_factor=SW)
    assert_wall_slides_at(law, mu_wall)


def assert_pair_slides_at(law, mu):
    """Two spheres pressed together by two frictionless walls slide past each other.

    Slip u = v_B - v_A - (r w_A + r w_B) x n. While they slip the friction force F = mu f_n acts
    on both; each sphere's velocity and spin change so that du/dt = -F (2/m)(1 + m r^2/I)
    = -7 F/m, so slip ends at t* = u0 m / (7 mu f_n). Until then |f_t| = mu f_n exactly, and
    never more afterwards. ``law``: k1 = 1e5 N/m, no wall friction, wall stiffness factor 1.
    """
    dt = 1e-7
    w = pd.World(dt=dt, box=((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 1e-3)), contact=law,
                 gravity=(0, 0, 0), skin=2e-5)
    d = 2e-6  # overlap of each of the three contacts: the column starts in equilibrium
    w.add_particles(np.array([[-R + d / 2, 0, 0], [R - d / 2, 0, 0]]), np.array([R, R]))
    w.add_plane("left", [-2 * R + 1.5 * d, 0, 0], [1, 0, 0])
    right = w.add_plane("right", [2 * R - 1.5 * d, 0, 0], [-1, 0, 0])
    u0 = 0.1
    w.set_velocities(np.array([[0, u0 / 2, 0], [0, -u0 / 2, 0]]), np.zeros((2, 3)))
    m = w.masses()[0]
    fn0 = 1e5 * d
    t_star = u0 * m / (7 * mu * fn0)
    rows = []
    for _ in range(int(2 * t_star / dt)):
        w.step()
        x = w.positions()
        # Pair force on B: its total force less the (purely normal) force of the right wall.
        pair = np.array(w.f)[1] + np.array(w.wall_state(right)["force"])
        n = (x[1] - x[0]) / np.linalg.norm(x[1] - x[0])
        fn = pair @ n
        ft = np.linalg.norm(pair - fn * n)
        c = w.contacts()
        rows.append((w.time, fn, ft, c["fn"][0]))
    a = np.array(rows)
    np.testing.assert_allclose(a[:, 1], a[:, 3], rtol=1e-9)  # same f_n as contacts() reports
    # The tangential spring first stretches to the limit (k_t u0 t = mu f_n), then slides.
    t_limit = a[np.argmax(a[:, 2] >= mu * a[:, 1] * (1 - 1e-9)), 0]
    assert t_limit < 0.1 * t_star
    sliding = (a[:, 0] >= t_limit) & (a[:, 0] < 0.9 * t_star)
    assert sliding.sum() > 100
    np.testing.assert_allclose(a[sliding, 2] / a[sliding, 1], mu, rtol=1e-9)
    assert (a[:, 2] <= mu * a[:, 1] * (1 + 1e-12)).all()
    stuck = a[:, 0] > 1.1 * t_star
    assert (a[stuck, 2] < 0.95 * mu * a[stuck, 1]).any()  # slip ended near t*


def test_pair_friction_saturates_at_mu_fn():
    law = pd.ContactLaw(k1=1e5, k2=4e5, kc=0.0, mu=0.5, mu_wall=0.0, rolling=0.0,
                        wall_stiffness_factor=1.0)
    assert_pair_slides_at(law, 0.5)


@pytest.mark.parametrize("m_r", [0.01, 0.05])
def test_rolling_sphere_decelerates_as_eq11_predicts(m_r):
    """A sphere rolling without slipping on a plane, torque of eq. 11 M = -m_r f_n r w/|w|.

    Rolling along +x: v = r w_y. With F the friction force on the sphere along x, applied at
    the contact point -r z (torque -r F about y) and f_n = m g:
        m dv/dt = F,   I dw_y/dt = -r F - m_r m g r.
    Rolling without slipping, dv/dt = r dw_y/dt, so (I/r) dv/dt = -r m dv/dt - m_r m g r and
        dv/dt = -m_r m g r^2 / (I + m r^2) = -(5/7) m_r g       (I = 2/5 m r^2).
    The static friction needed, |F| = (5/7) m_r m g, is below mu_wall m g, so it does not slip.
    """
    law = pd.ContactLaw(k1=1e5, k2=4e5, kc=0.0, mu=0.5, mu_wall=0.15, rolling=m_r,
                        wall_stiffness_factor=SW)
    w, floor, m = sphere_on_floor(law, dt=2e-6, sample_interval=100)
    v0 = 0.01
    w.set_velocities(np.array([[v0, 0, 0]]), np.array([[0, v0 / R, 0]]))
    ts, vs = [], []
    for _ in range(20):
        w.run(500)
        ts.append(w.time)
        vs.append(w.velocities()[0, 0])
    a = np.polyfit(ts, vs, 1)[0]
    assert a == pytest.approx(-5 / 7 * m_r * G, rel=2e-3)
    # Still rolling without slipping at the end.
    assert np.array(w.w)[0, 1] * R == pytest.approx(vs[-1], rel=1e-3)
    # Friction on the sphere is m dv/dt = -(5/7) m_r m g; its reaction drags the wall along +x.
    fx = w.wall_samples(floor)["force"][5:, 0]
    np.testing.assert_allclose(fx, 5 / 7 * m_r * m * G, rtol=1e-3)


def test_rolling_friction_stops_a_sphere_and_holds_it_still():
    # Without the cap on the rolling torque a resting sphere would chatter about w = 0; with it
    # the sphere comes to rest at t = v0 / ((5/7) m_r g) and stays there.
    m_r = 0.2
    law = pd.ContactLaw(k1=1e5, k2=4e5, kc=0.0, mu=0.5, mu_wall=0.5, rolling=m_r,
                        wall_stiffness_factor=SW)
    dt = 2e-6
    w, floor, m = sphere_on_floor(law, dt=dt)
    v0 = 0.002
    w.set_velocities(np.array([[v0, 0, 0]]), np.array([[0, v0 / R, 0]]))
    t_stop = v0 / (5 / 7 * m_r * G)
    w.run(int(0.5 * t_stop / dt))
    assert w.velocities()[0, 0] == pytest.approx(0.5 * v0, rel=0.02)
    w.run(int(1.0 * t_stop / dt))
    assert abs(w.velocities()[0, 0]) < 1e-3 * v0
    assert abs(np.array(w.w)[0, 1]) * R < 1e-3 * v0


# --- a body held by several contacts: eq. 11's moments summed per body ----------------------

W0 = 100.0     # initial spin, rad/s: rolling friction stops it within a few hundred steps
DELTA = 1e-6   # overlap of every contact, m: all of them sit on the loading branch, f_n = k1 DELTA


def held_sphere(walls: int, particles: int, m_r: float = 0.01, mu: float = 0.0):
    """A sphere at the origin held by `walls` planes and `particles` neighbours (each pressed
    on by a plane behind it), every contact at overlap DELTA with f_n = k1 DELTA, so the
    whole cluster is in equilibrium. Returns the world. The sphere spins at W0 about an axis
    that is no contact normal."""
    law = pd.ContactLaw(k1=1e5, k2=4e5, kc=0.0, mu=mu, mu_wall=mu, rolling=m_r,
                        wall_stiffness_factor=1.0)
    w = pd.World(dt=2e-6, box=((-2e-3,) * 3, (2e-3,) * 3), contact=law, gravity=(0, 0, 0), skin=2e-5)
    axes = [np.array(a, float) for a in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (-1, 0, 0), (0, -1, 0), (0, 0, -1))]
    if walls + particles == 3:      # three normals 120 degrees apart in the xy plane
        axes = [np.array([math.cos(a), math.sin(a), 0.0]) for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)]
    elif walls + particles == 4:    # the four corners of a tetrahedron
        axes = [np.array(a, float) / math.sqrt(3) for a in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1))]
    assert walls + particles == len(axes)
    centres = [np.zeros(3)]
    for k, a in enumerate(axes):
        if k < particles:
            c = a * (2 * R - DELTA)
            centres.append(c)
            w.add_plane(f"behind{k}", tuple(c + a * (R - DELTA)), tuple(-a))
        else:
            w.add_plane(f"wall{k}", tuple(a * (R - DELTA)), tuple(-a))
    w.add_particles(np.array(centres), np.full(len(centres), R))
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    spins = np.zeros((len(centres), 3))
    spins[0] = W0 * axis
    w.set_velocities(np.zeros((len(centres), 3)), spins)
    return w, axis


@pytest.mark.parametrize("walls,particles", [(3, 0), (4, 0), (6, 0), (0, 3), (0, 4), (0, 6), (1, 2), (2, 2)])
def test_a_held_sphere_spins_down_at_eq11s_rate_and_stops(walls, particles):
    """n contacts, each with the moment m_r f_n r against the spin (eq. 11): without sliding
    friction the spin falls linearly, dw/dt = -n m_r f_n r / I, keeps its direction, and
    stops at t* = W0 I / (n m_r f_n r). Capping each contact's moment at |w| I / dt instead of
    the body's sum made n >= 3 contacts reverse and grow the spin ((1 - n) w per step).
    (Walls are infinite planes: the arrangements are chosen so that none touches a neighbour.)"""
    m_r = 0.01
    w, axis = held_sphere(walls, particles, m_r=m_r)
    n = walls + particles
    m = w.masses()[0]
    inertia = 0.4 * m * R * R
    rate = n * m_r * (1e5 * DELTA) * R / inertia
    t_stop = W0 / rate
    steps = int(1.5 * t_stop / w.dt)
    spin = np.empty(steps)
    along = np.empty(steps)
    t = np.empty(steps)
    for k in range(steps):
        w.step()
        om = np.array(w.w)[0]
        spin[k], along[k], t[k] = np.linalg.norm(om), om @ axis, w.time
    assert (np.diff(spin) <= 0.0).all()                  # never speeds up
    assert (along >= -1e-12 * W0).all()                   # never reverses (to rounding)
    early = t < 0.8 * t_stop
    np.testing.assert_allclose(spin[early], W0 - rate * t[early], rtol=1e-9, atol=1e-9 * W0)
    assert spin[-1] < 1e-12 * W0                          # at rest, and it stays there
    np.testing.assert_allclose(np.array(w.w)[1:], 0.0, atol=0.0)  # the neighbours never turn


@pytest.mark.parametrize("walls,particles", [(3, 0), (4, 0), (6, 0)])
def test_a_held_sphere_with_sliding_friction_comes_to_rest(walls, particles):
    """With friction the tangential springs make the spin a damped torsional oscillation (eq.
    9-10) on top of eq. 11's braking: the spin never exceeds its start and dies away. (Walls
    only: with friction, neighbours held by planes roll off sideways, a sphere between a
    sphere and a plane being unstable, and the cluster never comes to rest.)"""
    w, _ = held_sphere(walls, particles, m_r=0.01, mu=0.5)
    peak = 0.0
    for _ in range(25):
        w.run(100)
        peak = max(peak, float(np.linalg.norm(np.array(w.w), axis=1).max()))
    assert peak <= W0
    assert np.linalg.norm(np.array(w.w), axis=1).max() < 1e-6 * W0


def test_a_pellet_held_under_load_loses_its_spin():
    """A tiny pellet compacted to 120 MPa and held there: its rotational energy falls and
    never grows. With the cap on each contact's moment instead of the body's sum the
    particles' spins were pumped, not braked: median |w| 7.7 rad/s and 5e-8 J of rotational
    energy that never died away (2.6e-8 J after 20,000 more steps)."""
    from pelletdem import stages
    from pelletdem.presets import get_preset

    pellet, _ = stages.fill(get_preset("tiny"), seed=0, threads=1, progress=False)
    stages.compact(pellet, 120e6, progress=False)
    w = pellet.world
    m, r = np.array(w.m), np.array(w.r)

    def rotational_energy():
        return float(np.sum(0.2 * m * r * r * (np.array(w.w) ** 2).sum(axis=1)))

    energy = [rotational_energy()]
    for _ in range(40):
        w.run(250)
        energy.append(rotational_energy())
    energy = np.array(energy)
    assert (np.diff(energy) <= 0.0).all()
    assert energy[-1] < 1e-9 * energy[0]  # 4e-7 J at the end of compaction, 2e-19 J after
    assert np.median(np.linalg.norm(np.array(w.w), axis=1)) < 1e-4  # rad/s (2e-6 measured)
