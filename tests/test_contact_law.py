"""The normal and tangential contact law of section 3.1.1 (eq. 5, 8, 10) against analytic answers.

Every expected value here comes from the equations of the paper, written out in this file,
never from a previous run of the engine:

* eq. 8: a head-on collision without friction or adhesion has restitution e = sqrt(k1/k2);
* eq. 5: the normal force follows k1 delta on loading, k2 (delta - delta0) on unloading and
  reloading with delta0 = delta_max (1 - k1/k2), and -kc delta on the adhesive branch;
* eq. 10: the tangential dashpot sqrt(4 m* kt / (1 + (pi/ln e)^2)) damps the tangential
  oscillation of a sphere resting on a plane at the rate worked out below.
"""

import math

import numpy as np
import pytest

import pelletdem as pd

R = 2.0e-4  # particle radius, m (the paper's mean)


# Wall contacts are stiffer than pair contacts by this factor (eq. 7: r* = r against a flat
# wall, r/2 between two equal spheres); set explicitly so the tests do not lean on a default.
SW = 2.0


def frictionless(k1=1.0e5, k2=4.0e5, kc=0.0):
    return pd.ContactLaw(k1=k1, k2=k2, kc=kc, mu=0.0, mu_wall=0.0, rolling=0.0,
                         wall_stiffness_factor=SW, wall_adhesion=True)


def eq5_reference(deltas, k1, k2, kc):
    """Force of eq. 5 along a history of overlaps, written in Luding's (2008) terms.

    The history variable is delta_max, the largest overlap reached on the loading line; the
    residual overlap is delta0 = delta_max (1 - k1/k2). On the adhesive branch Luding moves
    delta_max down so that a reload from there starts a new k2 line at the current point:
    delta_max = (k2 + kc) / (k2 - k1) delta. Out of contact (delta <= 0) the history is gone.
    Returns the forces and the branch of each sample (0 loading, 1 k2 line, 2 adhesive,
    -1 no contact).
    """
    d_max = 0.0
    f_out, branch = [], []
    for d in deltas:
        if d <= 0.0:
            d_max, f, b = 0.0, 0.0, -1
        elif d >= d_max:  # loading line, eq. 5 first case
            d_max, f, b = d, k1 * d, 0
        else:
            d0 = d_max * (1.0 - k1 / k2)
            f, b = k2 * (d - d0), 1  # unloading / reloading line, eq. 5 second case
            if f <= -kc * d:  # adhesive branch, eq. 5 third case
                f, b = -kc * d, 2
                d_max = (k2 + kc) / (k2 - k1) * d
        f_out.append(f)
        branch.append(b)
    return np.array(f_out), np.array(branch)


def head_on(k1, k2, r1=R, r2=R, v0=0.05, dt=None, record=False):
    """Two spheres, no gravity, meeting head-on along x with relative speed 2 v0."""
    w = pd.World(dt=1e-7, box=((-3e-3, -1e-3, -1e-3), (3e-3, 1e-3, 1e-3)),
                 contact=frictionless(k1, k2), gravity=(0, 0, 0), skin=2e-5)
    w.add_particles(np.array([[-r1 - 1e-6, 0, 0], [r2 + 1e-6, 0, 0]]), np.array([r1, r2]))
    w.set_velocities(np.array([[v0, 0, 0], [-v0, 0, 0]]), np.zeros((2, 3)))
    m = w.masses()
    m_eff = m[0] * m[1] / (m[0] + m[1])
    # Contact duration: a quarter period on k1 (loading) plus a quarter period on k2.
    duration = 0.5 * math.pi * (math.sqrt(m_eff / k1) + math.sqrt(m_eff / k2))
    if dt is None:
        dt = duration / 1000.0  # ~1000 steps per contact, i.e. dt << sqrt(m*/k2)
    w.dt = dt
    rows = []
    # After the force drops to zero at the residual overlap the spheres still overlap
    # (plastically) until they have moved delta0 apart: run until the overlap is gone.
    n_max = int(20 * duration / dt) + int(2e-6 / v0 / dt)
    for _ in range(n_max // 50):
        if record:
            for _ in range(50):
                w.step()
                c = w.contacts()
                if len(c["overlap"]):
                    rows.append((c["overlap"][0], c["fn"][0]))
                elif rows:
                    rows.append((0.0, 0.0))
        else:
            w.run(50)
        if w.time > 1e-6 / v0 and w.contact_count == 0 and w.velocities()[0, 0] <= 0:
            break
    assert w.contact_count == 0, "the spheres must have separated"
    v = w.velocities()
    p = m[0] * v[0, 0] + m[1] * v[1, 0]
    e = (v[1, 0] - v[0, 0]) / (2.0 * v0)
    return e, p, m, np.array(rows)


@pytest.mark.parametrize("k1,k2", [(1.0e5, 4.0e5), (1.0e5, 1.0e5), (4.0e4, 4.0e5), (2.0e5, 2.5e5)])
def test_head_on_restitution_is_sqrt_k1_over_k2(k1, k2):
    # Loading on k1 stores (1/2) k1 dmax^2 = (1/2) m* v^2; unloading on k2 from dmax gives
    # back (1/2) (k1 dmax)^2 / k2, so v_out^2 / v_in^2 = k1 / k2 (eq. 8).
    e, p, _, _ = head_on(k1, k2)
    assert e == pytest.approx(math.sqrt(k1 / k2), rel=1e-2)
    assert abs(p) < 1e-12  # momentum conserved (it starts at zero)


def test_restitution_unequal_spheres_and_coarse_step():
    # e depends on neither the masses nor (with ~50 steps per contact, the paper's
    # resolution) on the time step beyond 1%.
    e, p, m, _ = head_on(1.0e5, 4.0e5, r1=1.4e-4, r2=2.6e-4)
    assert e == pytest.approx(0.5, rel=1e-2)
    e, _, _, _ = head_on(1.0e5, 4.0e5, dt=1.6e-6)
    assert e == pytest.approx(0.5, rel=1e-2)


def test_pair_force_follows_eq5_during_collision():
    k1, k2 = 1.0e5, 4.0e5
    _, _, _, rows = head_on(k1, k2, record=True)
    f_ref, branch = eq5_reference(rows[:, 0], k1, k2, 0.0)
    assert np.abs(rows[:, 1] - f_ref).max() < 1e-9 * np.abs(f_ref).max()
    assert (branch == 0).sum() > 100 and (branch == 1).sum() > 100
    # Unloading runs down the line f = k2 (delta - delta0) with delta0 = delta_max (1 - k1/k2):
    # every repulsive unloading sample points back to that residual overlap.
    d_max = rows[:, 0].max()
    unload = (branch == 1) & (rows[:, 1] > 0)
    d0 = rows[unload, 0] - rows[unload, 1] / k2
    np.testing.assert_allclose(d0, d_max * (1 - k1 / k2), rtol=1e-9)


class PlateCycle:
    """A sphere held by a fixed floor and squeezed by a moving top plate (no gravity).

    The top plate's velocity is the prescribed program; the force the sphere exerts on each
    plate is compared with eq. 5 evaluated on that plate's overlap. The sphere's own motion
    (it oscillates a little between the plates) does not matter: eq. 5 is a function of the
    overlap history, which we read every step. The walls adhere here (wall_adhesion=True) and
    are SW times as stiff as a pair: the law is eq. 5 with SW k1, SW k2, SW kc.
    """

    def __init__(self, k1, k2, kc, speed=0.02, dt=1e-7):
        self.w = pd.World(dt=dt, box=((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 2e-3)),
                          contact=frictionless(k1, k2, kc), gravity=(0, 0, 0), skin=2e-5)
        self.w.add_particles(np.array([[0.0, 0.0, R]]), np.array([R]))
        self.floor = self.w.add_plane("floor", [0, 0, 0], [0, 0, 1])
        self.top = self.w.add_plane("top", [0, 0, 2 * R], [0, 0, -1])
        self.speed = speed
        self.rows = []

    def state(self):
        z = self.w.positions()[0, 2]
        top = self.w.wall_state(self.top)
        return (R - (top["point"][2] - z), top["normal_force"], R - z,
                self.w.wall_state(self.floor)["normal_force"])

    def drive(self, direction, until, max_steps=200000):
        self.w.set_wall_velocity(self.top, [0, 0, -direction * self.speed])
        for _ in range(max_steps):
            self.w.step()
            s = self.state()
            self.rows.append(s)
            if until(s):
                return
        raise AssertionError("the plate program did not reach its target")


def test_load_unload_reload_cycle_follows_eq5():
    c = PlateCycle(1.0e5, 4.0e5, 600.0)
    k1, k2, kc = SW * 1.0e5, SW * 4.0e5, SW * 600.0  # the stiffnesses of a wall contact
    d1 = 0.02 * R
    c.drive(+1, lambda s: s[0] >= d1)            # load on k1 to d1
    n_load = len(c.rows)
    c.drive(-1, lambda s: s[0] <= 0.85 * d1)     # partial unload, still repulsive
    n_unload = len(c.rows)
    c.drive(+1, lambda s: s[0] >= 1.5 * d1)      # reload: k2 line up to d1, then k1 again
    n_reload = len(c.rows)
    c.drive(-1, lambda s: s[0] <= 0.5 * d1)      # unload through zero force into adhesion
    n_adh = len(c.rows)
    c.drive(+1, lambda s: s[0] >= 2.0 * d1)      # reload from the adhesive branch
    c.drive(-1, lambda s: s[0] <= 0.0 or c.w.wall_state(c.top)["point"][2] > 2 * R + 2e-6)
    a = np.array(c.rows)

    for col in (0, 2):  # top plate, floor
        f_ref, branch = eq5_reference(a[:, col], k1, k2, kc)
        assert np.abs(a[:, col + 1] - f_ref).max() < 1e-9 * np.abs(f_ref).max()
        assert min((branch == b).sum() for b in (0, 1, 2)) > 100  # every branch was visited

    top_d, top_f = a[:, 0], a[:, 1]
    # Loading: f = k1 delta wherever the overlap is a new maximum (the sphere jiggles a little
    # between the plates, so a few samples step back onto the k2 line).
    top_branch = eq5_reference(top_d, k1, k2, kc)[1]
    load = np.zeros(len(top_d), bool)
    load[:n_load] = top_branch[:n_load] == 0
    assert load.sum() > 0.9 * n_load
    np.testing.assert_allclose(top_f[load], k1 * top_d[load], rtol=1e-9)
    # Partial unloading: the k2 line through (d_max, k1 d_max), delta0 = d_max (1 - k1/k2).
    d_max = top_d[:n_load].max()
    d0 = d_max * (1 - k1 / k2)
    seg = slice(n_load + 5, n_unload)
    np.testing.assert_allclose(top_f[seg], k2 * (top_d[seg] - d0), rtol=1e-9)
    # Reloading: back up the same k2 line below d_max, on k1 beyond it.
    seg_d, seg_f = top_d[n_unload:n_reload], top_f[n_unload:n_reload]
    below = seg_d < d_max * (1 - 1e-6)
    above = seg_d > d_max * (1 + 1e-6)
    np.testing.assert_allclose(seg_f[below], k2 * (seg_d[below] - d0), rtol=1e-9)
    new_max = top_branch[n_unload:n_reload] == 0
    assert (new_max & above).sum() > 100
    np.testing.assert_allclose(seg_f[above & new_max], k1 * seg_d[above & new_max], rtol=1e-9)
    # Second unloading: zero force at the residual overlap delta0 = 1.5 d1 (1 - k1/k2), and
    # the adhesive branch -kc delta once k2 (delta - delta0) falls below it.
    seg_d, seg_f = top_d[n_reload:n_adh], top_f[n_reload:n_adh]
    d_max2 = top_d[:n_reload].max()
    d0_2 = d_max2 * (1 - k1 / k2)
    k = np.nonzero(seg_f <= 0)[0][0]
    crossing = seg_d[k - 1] + (seg_d[k] - seg_d[k - 1]) * seg_f[k - 1] / (seg_f[k - 1] - seg_f[k])
    assert crossing == pytest.approx(d0_2, rel=1e-6)
    adhesive = seg_d < k2 * d0_2 / (k2 + kc) * (1 - 1e-6)
    assert adhesive.sum() > 100
    np.testing.assert_allclose(seg_f[adhesive], -kc * seg_d[adhesive], rtol=1e-9)


def test_residual_overlap_scales_with_max_overlap():
    # delta0 / delta_max = 1 - k1/k2 for any k1/k2 (here e = 0.8 and e = 0.3): each repulsive
    # unloading sample (delta, f) lies on f = k2 (delta - delta0).
    for k1, k2 in ((2.56e5, 4.0e5), (3.6e4, 4.0e5)):
        c = PlateCycle(k1, k2, 0.0)
        c.drive(+1, lambda s: s[0] >= 0.01 * R)
        n_load = len(c.rows)
        c.drive(-1, lambda s: s[1] <= 0.0)
        a = np.array(c.rows)
        d_max = a[:, 0].max()
        unload = a[n_load + 5:]
        unload = unload[unload[:, 1] > 0]
        assert len(unload) > 50
        d0 = unload[:, 0] - unload[:, 1] / (SW * k2)
        np.testing.assert_allclose(d0, d_max * (1 - k1 / k2), rtol=1e-7)


@pytest.mark.parametrize("e", [0.5, 0.8, 1.0])
def test_tangential_damping_of_eq10(e):
    """Damped tangential oscillation of a sphere resting on a plane (no sliding).

    The tangential spring of stiffness kt and the dashpot gamma_t of eq. 10 act at the contact
    point, at lever arm r from the centre. With F the tangential force on the sphere,
    m dv/dt = F and I dw/dt = r F (I = 2/5 m r^2), so the slip velocity u = v - r w changes at
    du/dt = F (1/m + r^2/I) = 3.5 F/m. With F = -kt s - gamma_t u and ds/dt = u:
        s'' + (3.5 gamma_t / m) s' + (3.5 kt / m) s = 0,
    a damped oscillator with w0^2 = 3.5 kt/m and damping ratio
        zeta = 3.5 gamma_t / (2 m w0) = sqrt(3.5) gamma_t / (2 sqrt(m kt)).
    (kt is the wall contact's: SW times the pair value.) Eq. 10 with m* = m (a wall has
    infinite mass): gamma_t = 2 sqrt(m kt) / sqrt(1 + (pi/ln e)^2),
    so zeta = sqrt(3.5 / (1 + (pi/ln e)^2)), and successive force maxima shrink by
    exp(-2 pi zeta / sqrt(1 - zeta^2)) one damped period 2 pi / (w0 sqrt(1 - zeta^2)) apart.
    """
    k2 = 4.0e5
    k1 = k2 * e * e
    law = pd.ContactLaw(k1=k1, k2=k2, kc=0.0, mu=0.5, mu_wall=10.0, rolling=0.0,
                        wall_stiffness_factor=SW)
    g = 9.81  # effective gravity (physical gravity is divided by density_scale = 1e4)
    dt = 1e-7
    w = pd.World(dt=dt, box=((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 1e-3)), contact=law,
                 gravity=(0, 0, -g * 1e4), skin=2e-5, sample_interval=1)
    w.add_particles(np.zeros((1, 3)), np.array([R]))
    m = w.masses()[0]
    fn = m * g
    # The floor is placed so that the sphere starts in equilibrium on the loading line.
    floor = w.add_plane("floor", [0, 0, -R + fn / (SW * k1)], [0, 0, 1])
    u0 = 1e-3  # initial slip velocity: the spring force stays well below mu_wall fn
    w.set_velocities(np.array([[u0, 0, 0]]), np.zeros((1, 3)))
    kt = SW * k1  # kt_ratio = 1: the paper's k_t equal to the (wall's) normal stiffness
    w0 = math.sqrt(3.5 * kt / m)
    zeta = math.sqrt(3.5) / math.sqrt(1 + (math.pi / math.log(e)) ** 2) if e < 1 else 0.0
    period = 2 * math.pi / (w0 * math.sqrt(1 - zeta ** 2))
    w.run(int(4.5 * period / dt))
    s = w.wall_samples(floor)
    fx = s["force"][:, 0]
    assert np.abs(s["normal_force"] - fn).max() < 1e-9 * fn  # the normal force stays m g
    peaks = [i for i in range(1, len(fx) - 1) if fx[i] > 0 and fx[i] > fx[i - 1] and fx[i] >= fx[i + 1]]
    assert len(peaks) >= 4
    ratios = fx[peaks[1:]] / fx[peaks[:-1]]
    expected = math.exp(-2 * math.pi * zeta / math.sqrt(1 - zeta ** 2))
    np.testing.assert_allclose(ratios, expected, rtol=5e-3)
    np.testing.assert_allclose(np.diff(peaks) * dt, period, rtol=2e-3)


@pytest.mark.parametrize("vector_kernels", [True, False])
def test_a_pair_that_came_apart_starts_afresh(vector_kernels):
    # Eq. 5's residual overlap belongs to one contact: once two spheres have parted, touching
    # again starts a new contact on the k1 line. Four loaded pairs (the pair loop tests them
    # four at a time, as in a bed, with vector_kernels; one at a time without) are pulled
    # apart by less than the skin, so that they stay listed with their history, then put back
    # at a smaller overlap than their residual one: afresh, f = k1 delta; with the old delta0
    # it would be the k2 line's k2 (delta - delta0) < 0, i.e. no force (kc = 0).
    k1, k2 = 1.0e5, 4.0e5
    w = pd.World(dt=1e-9, box=((-3e-3, -1e-3, -3e-3), (3e-3, 1e-3, 3e-3)),
                 contact=frictionless(k1, k2), gravity=(0, 0, 0), skin=2e-4)
    w.vector_kernels = vector_kernels
    z = np.array([-2e-3, -1e-3, 1e-3, 2e-3])  # 1 mm apart: the pairs never meet each other

    def place(overlap):
        half = R - 0.5 * overlap
        return np.concatenate([np.stack([np.full(4, -half), np.zeros(4), z], axis=1),
                               np.stack([np.full(4, half), np.zeros(4), z], axis=1)])

    w.add_particles(place(4e-6), np.full(8, R))
    w.run(1)  # loading line: delta_max ~ 4 um, so delta0 ~ 3 um
    assert w.contacts()["fn"] == pytest.approx(np.full(4, k1 * 4e-6), rel=1e-3)
    for overlap in (-1e-6, 2e-6):  # parted by 1 um, then back at 2 um < delta0
        w.set_positions(place(overlap))
        w.set_velocities(np.zeros((8, 3)), np.zeros((8, 3)))
        w.run(1)
    c = w.contacts()
    assert len(c["fn"]) == 4
    assert c["fn"] == pytest.approx(k1 * c["overlap"], rel=1e-6)
    assert c["overlap"] == pytest.approx(np.full(4, 2e-6), rel=1e-3)
