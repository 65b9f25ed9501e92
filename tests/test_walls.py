"""Analytic walls: load balance, containment under strong compression, prescribed motion and
force/torque reporting, each against a statics or kinematics answer.

Gravity: the engine divides physical gravity by density_scale (1e4 here); these tests pass
1e4 times 9.81 m/s^2 so that the effective gravity is G = 9.81 m/s^2 and a column settles in a
few ten thousand steps. The expected loads use G, i.e. sum(m) * gravity / density_scale.
"""

import math

import numpy as np
import pytest

import pelletdem as pd

R = 2.0e-4
G = 9.81
SW = 2.0  # wall stiffness factor, set explicitly


def settled_column(mu_wall, n=150, seed=3):
    """n particles poured into a cylinder (radius 1.5 mm) on a floor, left to settle."""
    radii = pd.truncated_normal_radii(n, seed=seed)
    x, radii = pd.random_pack_cylinder(radii, radius=1.5e-3, z_lo=0.0, z_hi=4e-3, seed=seed)
    law = pd.ContactLaw(mu_wall=mu_wall, wall_stiffness_factor=SW)
    w = pd.World(dt=2e-6, box=((-2e-3, -2e-3, -1e-3), (2e-3, 2e-3, 6e-3)), contact=law,
                 gravity=(0, 0, -G * 1e4), skin=2e-5, sample_interval=1)
    w.add_particles(x, radii)
    floor = w.add_plane("floor", [0, 0, 0], [0, 0, 1])
    cyl = w.add_cylinder("mould", [0, 0, 0], 1.5e-3)
    # A quiet state: the paper's law has no normal dashpot, so the pile keeps a faint elastic
    # rattle; what is left is averaged out below.
    out = w.run_until(max_steps=150_000, kinetic_energy_below=1e-10, check_interval=100)
    assert out.reason == "kinetic_energy_below"
    w.clear_samples()
    w.run(2_000)
    weight = w.masses().sum() * G
    fz_floor = w.wall_samples(floor)["force"][:, 2].mean()
    fz_cyl = w.wall_samples(cyl)["force"][:, 2].mean()
    return w, weight, fz_floor, fz_cyl, floor, cyl


def test_settled_column_weight_on_floor_without_wall_friction():
    # mu_wall = 0: the side wall can carry no vertical load (no Janssen effect), so the floor
    # carries the whole weight sum(m) g / density_scale.
    w, weight, fz_floor, fz_cyl, floor, cyl = settled_column(mu_wall=0.0)
    assert -fz_floor == pytest.approx(weight, rel=1e-2)
    assert abs(fz_cyl) < 1e-12 * weight
    # The floor's reported compressive normal force is the same load.
    assert w.wall_state(floor)["normal_force"] == pytest.approx(weight, rel=2e-2)
    # The horizontal thrust on the cylinder balances out around it.
    f_cyl = np.array(w.wall_state(cyl)["force"])
    assert np.hypot(f_cyl[0], f_cyl[1]) < 0.05 * w.wall_state(cyl)["normal_force"]


def test_settled_column_with_wall_friction_balances_the_weight():
    # With wall friction the side wall takes part of the weight (Janssen); floor plus wall
    # still carry all of it.
    w, weight, fz_floor, fz_cyl, floor, cyl = settled_column(mu_wall=0.15)
    assert -(fz_floor + fz_cyl) == pytest.approx(weight, rel=1e-2)
    assert -fz_cyl > 0.0  # the particles hang on the wall, dragging it down


def test_single_sphere_force_and_torque_on_a_plane():
    # A sphere resting at (x0, y0) on a floor through p: the wall feels F = (0, 0, -m g) at the
    # contact point c = (x0, y0, p_z); torque about p is (c - p) x F.
    law = pd.ContactLaw(k1=1e5, k2=4e5, wall_stiffness_factor=SW)
    w = pd.World(dt=1e-6, contact=law, gravity=(0, 0, -G * 1e4), skin=2e-5)
    x0, y0 = 1.2e-3, -0.7e-3
    w.add_particles(np.array([[x0, y0, 1e-3]]), np.array([R]))
    m = w.masses()[0]
    p = np.array([0.3e-3, 0.5e-3, 1e-3 - R + m * G / (SW * 1e5)])
    floor = w.add_plane("floor", p.tolist(), [0, 0, 1])
    w.run(10)
    s = w.wall_state(floor)
    F = np.array([0, 0, -m * G])
    np.testing.assert_allclose(s["force"], F, atol=1e-9 * m * G)
    c = np.array([x0, y0, p[2]])
    np.testing.assert_allclose(s["torque"], np.cross(c - p, F), atol=1e-12 * m * G)
    assert s["normal_force"] == pytest.approx(m * G, rel=1e-9)
    assert s["contacts"] == 1


def test_sphere_pressed_on_a_cylinder_force_and_torque():
    # No gravity; a sphere starts overlapping the cylinder wall by delta0 at angle theta and is
    # pushed back, so after a step it is on eq. 5's unloading line: the wall feels
    # SW k2 (delta - delta0 (1 - k1/k2)) radially outward at the contact point, which lies on
    # the cylinder surface; torque about the axis point p is (c - p) x F.
    k1, k2 = 1e5, 4e5
    law = pd.ContactLaw(k1=k1, k2=k2, mu_wall=0.0, wall_stiffness_factor=SW)
    w = pd.World(dt=1e-8, contact=law, gravity=(0, 0, 0), skin=2e-5)
    Rc, delta, theta, z0 = 2e-3, 2e-6, 0.6, 3e-3
    rho = Rc - R + delta
    w.add_particles(np.array([[rho * math.cos(theta), rho * math.sin(theta), z0]]), np.array([R]))
    p = np.array([0.0, 0.0, 1e-3])
    cyl = w.add_cylinder("mould", p.tolist(), Rc)
    w.run(1)
    x = w.positions()[0]
    rho = math.hypot(x[0], x[1])
    d = -(Rc - rho - R)  # overlap, now a little below the initial delta
    assert 0.99 * delta < d < delta
    fn = SW * k2 * (d - delta * (1 - k1 / k2))
    u = np.array([x[0], x[1], 0.0]) / rho
    F = fn * u
    s = w.wall_state(cyl)
    np.testing.assert_allclose(s["force"], F, rtol=1e-9)
    assert s["normal_force"] == pytest.approx(fn, rel=1e-9)
    c = np.array([Rc * u[0], Rc * u[1], x[2]])
    np.testing.assert_allclose(s["torque"], np.cross(c - p, F), rtol=1e-9, atol=1e-15)


def test_walls_hold_particles_under_strong_compression():
    # Squeeze a loose packing with a lid until some wall contact reaches delta / r > 0.5: no
    # particle centre may cross a plane or leave the cylinder (an analytic wall's signed
    # distance never flips the way a mesh's side test can).
    radii = pd.truncated_normal_radii(60, seed=8)
    x, radii = pd.random_pack_cylinder(radii, radius=1.2e-3, z_lo=0.0, z_hi=3e-3, seed=8)
    law = pd.ContactLaw(wall_stiffness_factor=SW)
    w = pd.World(dt=2e-7, box=((-2e-3, -2e-3, -1e-3), (2e-3, 2e-3, 4e-3)), contact=law,
                 gravity=(0, 0, 0), skin=2e-5, max_overlap_ratio=5.0)
    w.add_particles(x, radii)
    floor = w.add_plane("floor", [0, 0, 0], [0, 0, 1])
    cyl = w.add_cylinder("mould", [0, 0, 0], 1.2e-3)
    lid = w.add_plane("lid", [0, 0, 3e-3], [0, 0, -1])
    w.set_wall_velocity(lid, [0, 0, -0.5])
    worst = 0.0
    for _ in range(2000):
        w.run(50)
        xs = w.positions()
        z_lid = w.wall_state(lid)["point"][2]
        assert (xs[:, 2] > 0.0).all() and (xs[:, 2] < z_lid).all()
        assert (np.hypot(xs[:, 0], xs[:, 1]) < 1.2e-3).all()
        worst = max(worst, *(w.wall_state(k)["max_overlap_ratio"] for k in (floor, cyl, lid)))
        if worst > 0.55:
            break
    assert worst > 0.55
    assert w.max_overlap_ratio_seen > 0.55


def test_sphere_squeezed_between_two_planes_stays_between_them():
    # One sphere, two planes closing in until each overlap is 0.8 r: the centre stays between.
    law = pd.ContactLaw(wall_stiffness_factor=SW)
    w = pd.World(dt=2e-7, contact=law, gravity=(0, 0, 0), skin=2e-5, max_overlap_ratio=5.0)
    w.add_particles(np.array([[0, 0, 1e-3]]), np.array([R]))
    lo = w.add_plane("lo", [0, 0, 1e-3 - R], [0, 0, 1])
    hi = w.add_plane("hi", [0, 0, 1e-3 + R], [0, 0, -1])
    w.set_wall_velocity(lo, [0, 0, 0.2])
    w.set_wall_velocity(hi, [0, 0, -0.2])
    w.run_until(max_steps=10_000, wall_travel_above=(lo, 0.8 * R))
    z = w.positions()[0, 2]
    z_lo, z_hi = w.wall_state(lo)["point"][2], w.wall_state(hi)["point"][2]
    assert z_lo < z < z_hi
    assert w.wall_state(lo)["max_overlap_ratio"] > 0.7
    assert w.wall_state(hi)["max_overlap_ratio"] > 0.7


def _squeezed_sphere():
    """One sphere between two load-wall planes closing in at 0.2 m/s each."""
    law = pd.ContactLaw(wall_stiffness_factor=SW, kc=0.0)
    w = pd.World(dt=2e-7, contact=law, gravity=(0, 0, 0), skin=2e-5, max_overlap_ratio=5.0)
    w.add_particles(np.array([[0, 0, 1e-3]]), np.array([R]))
    lo = w.add_plane("lo", [0, 0, 1e-3 - R], [0, 0, 1])
    hi = w.add_plane("hi", [0, 0, 1e-3 + R], [0, 0, -1])
    w.set_load_walls([lo, hi])
    for k, vz in ((lo, 0.2), (hi, -0.2)):
        w.set_wall_velocity(k, [0, 0, vz])
    return w, lo, hi


def test_load_drop_stop_fires_at_the_fraction_of_the_kept_peak():
    # Load, then open the plates again: the force falls along the unloading line, and the
    # break detection (load_drop_below) stops the run where it reaches half the peak.
    w, lo, hi = _squeezed_sphere()
    w.track_load_peak(0.0)
    out = w.run_until(max_steps=10_000, wall_travel_above=(lo, 0.3 * R))
    assert out.reason == "wall_travel_above"
    peak = w.load_force
    assert peak > 0 and w.load_peak == pytest.approx(peak, rel=1e-12)
    assert w.load_force == pytest.approx(0.5 * (w.wall_state(lo)["normal_force"] + w.wall_state(hi)["normal_force"]))
    for k, vz in ((lo, -0.2), (hi, 0.2)):
        w.set_wall_velocity(k, [0, 0, vz])
    saved = w.get_state()
    out = w.run_until(max_steps=10_000, load_drop_below=0.5)
    assert out.reason == "load_drop_below"
    f_end = w.load_force
    # One step before it the force was above half the peak: the steps' decrement bounds it.
    per_step = peak / (0.3 * R / (0.2 * 2e-7))
    assert 0.5 * peak - 4 * per_step < f_end <= 0.5 * peak
    assert w.load_peak == pytest.approx(peak, rel=1e-12)  # unloading adds nothing to the peak
    # The peak is state: a world restored to the saved state stops at the same step.
    w2, _, _ = _squeezed_sphere()
    w2.restore_state(saved)
    assert w2.load_peak == pytest.approx(peak, rel=1e-12)
    out2 = w2.run_until(max_steps=10_000, load_drop_below=0.5)
    assert (out2.reason, out2.steps, w2.load_force) == (out.reason, out.steps, f_end)


def test_load_smoothing_is_an_exponential_mean_that_lags_a_ramp_by_n_minus_one_steps():
    # Under a force growing by df per step, s += (f - s) / n settles at f - (n - 1) df.
    w, lo, hi = _squeezed_sphere()
    w.run_until(max_steps=10_000, wall_travel_above=(lo, 0.05 * R))  # in contact, loading
    n = 20.0
    w.track_load_peak(0.0, n)
    f0 = w.load_force
    w.run(400)
    f1 = w.load_force
    w.run(1)
    df = w.load_force - f1
    assert df > 0 and f1 > f0
    assert w.load_smoothed == pytest.approx(w.load_force - (n - 1) * df, rel=2e-3)
    assert w.load_peak == pytest.approx(w.load_smoothed, rel=1e-12)
    with pytest.raises(pd.ParameterError, match="smoothing_steps"):
        w.track_load_peak(0.0, 0.5)


def test_load_peak_is_kept_only_from_its_marker_on():
    w, lo, hi = _squeezed_sphere()
    w.track_load_peak(1.0)  # 1 m of plate travel: never reached
    w.run_until(max_steps=10_000, wall_travel_above=(lo, 0.3 * R))
    assert w.load_force > 0 and w.load_peak == 0.0
    for k, vz in ((lo, -0.2), (hi, 0.2)):
        w.set_wall_velocity(k, [0, 0, vz])
    out = w.run_until(max_steps=3_000, load_drop_below=0.5)
    assert out.reason == "max_steps"  # no peak kept, nothing to fall from
    with pytest.raises(pd.ParameterError, match="load_drop_below"):
        w.run_until(max_steps=10, load_drop_below=1.5)
    w.set_load_walls([])
    with pytest.raises(pd.ParameterError, match="load walls"):
        w.run_until(max_steps=10, load_drop_below=0.5)


def test_moving_plane_and_growing_cylinder_follow_their_program():
    w = pd.World(dt=1e-6, contact=pd.ContactLaw(), gravity=(0, 0, 0), skin=2e-5, sample_interval=10)
    w.add_particles(np.array([[0, 0, 1e-3]]), np.array([R]))
    plane = w.add_plane("lid", [0, 0, 4e-3], [0, 0, -1])
    cyl = w.add_cylinder("mould", [0, 0, 0], 2e-3)
    v = np.array([1e-3, -2e-3, -0.05])
    rate = 0.01
    w.set_wall_velocity(plane, v.tolist())
    w.set_wall_radius_rate(cyl, rate)
    n = 5_000
    w.run(n)
    t = n * 1e-6
    sp, sc = w.wall_state(plane), w.wall_state(cyl)
    np.testing.assert_allclose(sp["point"], np.array([0, 0, 4e-3]) + v * t, rtol=1e-12, atol=1e-15)
    assert sp["travel"] == pytest.approx(0.05 * t, rel=1e-12)  # along the normal, into the box
    assert sc["radius"] == pytest.approx(2e-3 + rate * t, rel=1e-12)
    assert sc["travel"] == pytest.approx(-rate * t, rel=1e-12)  # growing = moving away
    # The recorded time series are straight lines in time.
    ts = w.wall_samples(plane)
    np.testing.assert_allclose(ts["point"], np.array([0, 0, 4e-3]) + np.outer(ts["time"], v),
                               rtol=1e-12, atol=1e-15)
    tc = w.wall_samples(cyl)
    np.testing.assert_allclose(tc["radius"], 2e-3 + rate * tc["time"], rtol=1e-12)
    assert len(ts["time"]) == n // 10


def test_moving_plane_kicks_a_sphere_to_one_plus_e_times_its_speed():
    # A plane of infinite mass moving at V hits a sphere at rest: in the plane's frame the
    # sphere arrives at -V and leaves at +e V, so it ends at (1 + e) V, e = sqrt(k1/k2) (eq. 8).
    k1, k2 = 1e5, 4e5
    law = pd.ContactLaw(k1=k1, k2=k2, kc=0.0, mu_wall=0.0, rolling=0.0, wall_stiffness_factor=SW)
    w = pd.World(dt=2e-8, contact=law, gravity=(0, 0, 0), skin=2e-5)
    w.add_particles(np.array([[0, 0, 1e-3]]), np.array([R]))
    piston = w.add_plane("piston", [0, 0, 1e-3 - R - 1e-7], [0, 0, 1])
    V = 0.05
    w.set_wall_velocity(piston, [0, 0, V])
    w.run(30_000)
    assert w.wall_state(piston)["contacts"] <= 1 and w.wall_state(piston)["normal_force"] == 0.0
    assert w.velocities()[0, 2] == pytest.approx((1 + math.sqrt(k1 / k2)) * V, rel=5e-3)


def test_walls_do_not_adhere_unless_asked():
    # kc > 0 glues particles together, but by default not to walls: pulling a plane off a
    # pressed sphere gives no tensile force; with wall_adhesion=True the k2 line runs on into
    # -SW kc delta.
    for adhesion in (False, True):
        law = pd.ContactLaw(k1=1e5, k2=4e5, kc=2e4, mu_wall=0.0, wall_adhesion=adhesion,
                            wall_stiffness_factor=SW)
        w = pd.World(dt=1e-7, contact=law, gravity=(0, 0, 0), skin=2e-5)
        w.add_particles(np.array([[0, 0, 1e-3]]), np.array([R]))
        w.add_plane("lo", [0, 0, 1e-3 - R], [0, 0, 1])
        hi = w.add_plane("hi", [0, 0, 1e-3 + R], [0, 0, -1])
        w.set_wall_velocity(hi, [0, 0, -0.02])
        w.run_until(max_steps=100_000, wall_travel_above=(hi, 0.02 * R))
        w.set_wall_velocity(hi, [0, 0, 0.02])
        forces = []
        for _ in range(60):
            w.run(50)
            forces.append(w.wall_state(hi)["normal_force"])
        if adhesion:
            assert min(forces) < 0.0
        else:
            assert min(forces) == 0.0
