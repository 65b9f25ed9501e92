"""Bad input fails early with a named error whose message names the parameter and its range;
a run that goes wrong raises a SimulationError subclass instead of crashing."""

import math

import numpy as np
import pytest

import pelletdem as pd
from pelletdem import ParameterError, ParticleEscapedError, SimulationError

R = 2.0e-4


def world(**kw):
    kw.setdefault("gravity", (0.0, 0.0, 0.0))
    return pd.World(**kw)


def one_particle(**kw):
    w = world(**kw)
    w.add_particles(np.zeros((1, 3)), np.array([R]))
    return w


def raises(match, exc=ParameterError):
    return pytest.raises(exc, match=match)


def test_error_hierarchy():
    assert issubclass(ParameterError, ValueError)
    assert issubclass(SimulationError, RuntimeError)
    assert issubclass(ParticleEscapedError, SimulationError)
    assert issubclass(pd.OverlapError, SimulationError)
    assert issubclass(pd.NonFiniteError, SimulationError)


# --- particles ---------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [-1e-4, 0.0, float("nan"), float("inf")])
def test_bad_radius(bad):
    with raises(r"radius\[1\] = .* radii must be finite and > 0"):
        world().add_particles(np.array([[0, 0, 0], [1e-3, 0, 0]]), np.array([R, bad]))


def test_non_finite_position():
    with raises(r"position\[0\] is not finite"):
        world().add_particles(np.array([[np.nan, 0, 0]]), np.array([R]))


def test_particle_outside_the_box():
    box = ((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 1e-3))
    with raises(r"position\[1\] = \(0, 0, 0\.002\) m lies outside the domain box: "
                r"allowed \[-0\.001, 0\.001\] x \[-0\.001, 0\.001\] x \[-0\.001, 0\.001\] m"):
        world(box=box).add_particles(np.array([[0, 0, 0], [0, 0, 2e-3]]), np.array([R, R]))


@pytest.mark.parametrize("x,r,match", [
    (np.zeros((2, 2)), np.full(2, R), r"positions must have shape \(N, 3\), got shape \(2, 2\)"),
    (np.zeros(3), np.full(1, R), r"positions must have shape \(N, 3\), got shape \(3,\)"),
    (np.zeros((1, 3)), np.full((1, 1), R), r"radii must be one-dimensional, shape \(N,\), got shape \(1, 1\)"),
    (np.zeros((2, 3)), np.full(1, R), r"positions \(2\) and radii \(1\) must have the same length"),
    (np.array([["a", "b", "c"]]), np.full(1, R), r"positions must be a real numeric array .* got dtype <U1"),
    (np.zeros((1, 3), complex), np.full(1, R), r"positions must be a real numeric array .* got dtype complex128"),
    ([[None, 0, 0]], np.full(1, R), r"positions must be a real numeric array .* got dtype object"),
    (np.zeros((1, 3)), np.array([True]), r"radii must be a real numeric array .* got dtype bool"),
])
def test_wrong_array_shapes_and_dtypes(x, r, match):
    with raises(match):
        world().add_particles(x, r)


def test_integer_and_list_inputs_are_fine():
    w = world(box=((-10, -10, -10), (10, 10, 10)))
    w.add_particles([[0, 0, 0], [1, 1, 1]], np.array([R, R], dtype=np.float32))
    assert w.n == 2


def test_set_velocities_and_positions_shapes():
    w = one_particle()
    with raises(r"velocities must have shape \(1, 3\)"):
        w.set_velocities(np.zeros((2, 3)), np.zeros((2, 3)))
    with raises(r"velocities must be finite"):
        w.set_velocities(np.full((1, 3), np.inf), np.zeros((1, 3)))
    with raises(r"positions must have shape \(1, 3\)"):
        w.set_positions(np.zeros((3, 3)))


def test_a_live_view_blocks_add_particles():
    w = one_particle()
    view = w.x
    with raises(r"cannot add particles while numpy views of the particle arrays are alive"):
        w.add_particles(np.array([[1e-3, 0, 0]]), np.array([R]))
    assert view.shape == (1, 3) and not view.flags.writeable
    del view
    copy = w.positions()  # a copy does not block
    w.add_particles(np.array([[1e-3, 0, 0]]), np.array([R]))
    assert w.n == 2 and copy.shape == (1, 3)


# --- contact law and world parameters --------------------------------------------------------


def test_k2_below_k1():
    msg = r"k2 = 100000 N/m is below k1 = 400000 N/m: .* k2 >= k1"
    with raises(msg):
        world(contact=pd.ContactLaw(k1=4e5, k2=1e5))
    w = world()
    with raises(msg):
        w.set_contact_params(pd.ContactLaw(k1=4e5, k2=1e5).to_core())


@pytest.mark.parametrize("field,value,match", [
    ("k1", -1.0, r"k1 = -1 N/m must be a finite number > 0"),
    ("kc", -1.0, r"kc = -1 N/m must be a finite number >= 0"),
    ("mu", float("nan"), r"mu = nan .* out of range: allowed 0 <= mu <= 10"),
    ("mu_wall", -0.1, r"mu_wall = -0.1 .* out of range: allowed 0 <= mu_wall <= 10"),
    ("rolling", 2.0, r"rolling = 2 .* out of range: allowed 0 <= rolling <= 1"),
])
def test_contact_law_ranges(field, value, match):
    with raises(match):
        pd.ContactLaw(**{field: value}).to_core()


def test_dt_above_the_stable_time_step():
    w = one_particle(dt=1e-6)
    dt_max = w.max_time_step()
    assert dt_max == pytest.approx(pd.World.TIME_STEP_SAFETY * w.critical_time_step(), rel=1e-15)
    with raises(r"dt = .* s is above the stable time step: allowed 0 < dt <= .* s, 0\.5 of the stability limit"):
        w.dt = 1.01 * dt_max
    assert w.dt == 1e-6  # unchanged after the refusal
    w.dt = 0.99 * dt_max
    with raises(r"dt = 0\.001 s is above the stable time step"):
        one_particle(dt=1e-3)
    with raises(r"dt = -1 s must be a finite number > 0"):
        w.dt = -1.0
    with raises(r"dt = nan must be finite"):
        world(dt=float("nan"))


def test_stiffer_contact_params_refused_when_dt_too_large():
    w = one_particle(dt=1e-5)
    with raises(r"dt = 1e-05 s is above the stable time step"):
        w.set_contact_params(pd.ContactLaw(k1=1e7, k2=4e7).to_core())
    assert w.contact_params.k2 == 4e5  # the old law is kept


def test_stable_time_step_holds_for_a_free_pair():
    """critical_time_step() must be a real bound for a single contact between two free spheres:
    their relative motion has the reduced mass m/2, so omega^2 = 2 k2 / m, twice that of a
    sphere on a wall of the same stiffness. A pair glued by strong adhesion oscillates on the
    k2 line; at the largest dt the world accepts it must stay bound and bounded (velocity
    Verlet is stable for omega dt < 2). Walls here are no stiffer than pairs
    (wall_stiffness_factor = 1), the case where a wall-only bound is sqrt(2) too large."""
    k2 = 4e5
    law = pd.ContactLaw(k1=1e5, k2=k2, kc=4e5, mu=0.0, mu_wall=0.0, rolling=0.0,
                        wall_stiffness_factor=1.0)
    w = world(dt=1e-7, contact=law, max_overlap_ratio=5.0)
    d = 4e-6
    w.add_particles(np.array([[-R + d / 2, 0, 0], [R - d / 2, 0, 0]]), np.array([R, R]))
    m = w.masses()[0]
    assert w.critical_time_step() <= 2 * math.sqrt((m / 2) / k2) * (1 + 1e-12)
    w.run(2000)
    ke_ref = 0.0
    for _ in range(100):
        w.run(20)
        ke_ref = max(ke_ref, w.kinetic_energy())
    w.dt = w.max_time_step()
    for _ in range(100):
        w.run(10)
        assert w.contact_count == 1
        assert w.kinetic_energy() < 2 * ke_ref


@pytest.mark.parametrize("g", [(0, 0, float("nan")), (float("inf"), 0, 0)])
def test_non_finite_gravity(g):
    with raises(r"gravity = .* must be finite"):
        world(gravity=g)
    w = world()
    with raises(r"gravity must be finite"):
        w.gravity = list(g)


def test_gravity_needs_three_components():
    with raises(r"gravity must have 3 components, got 2"):
        world().gravity = [0.0, -9.81]


@pytest.mark.parametrize("threads,match", [
    (0, r"threads = 0 is out of range: allowed 1 <= threads <= 1024"),
    (-2, r"threads = -2 is out of range: allowed 1 <= threads <= 1024"),
    (5000, r"threads = 5000 is out of range: allowed 1 <= threads <= 1024"),
    (2.5, r"threads must be an integer in \[1, 1024\], got 2\.5"),
    ("2", r"threads must be an integer in \[1, 1024\], got '2'"),
    (True, r"threads must be an integer in \[1, 1024\], got True"),
    (None, r"threads must be an integer in \[1, 1024\], got None"),
])
def test_bad_thread_counts(threads, match):
    with raises(match):
        world(threads=threads)


def test_bad_thread_count_set_later():
    w = world()
    with raises(r"threads = 0 +is out of range: allowed 1 <= threads <= 1024"):
        w.threads = 0
    assert w.threads == 1


def test_bad_box_and_density():
    with raises(r"box: every extent must be > 0 m"):
        world(box=((0, 0, 0), (0, 1, 1)))
    with raises(r"density = -1 kg/m\^3 is out of range: allowed 0\.001 <= density"):
        world(density=-1.0)


# --- stop conditions ---------------------------------------------------------------------------


def test_unknown_stop_condition():
    w = one_particle()
    with raises(r"unknown stop condition 'bogus': allowed \[.*'kinetic_energy_below'.*\]"):
        w.run_until(max_steps=10, bogus=1.0)


def test_bad_stop_condition_arguments():
    w = one_particle()
    with raises(r"wall_force_above must be \(wall index, value\)"):
        w.run_until(max_steps=10, wall_force_above=1.0)
    with raises(r"stop condition wall = 3 +is out of range"):
        w.run_until(max_steps=10, wall_force_above=(3, 1.0))
    with raises(r"time = nan must be finite"):
        w.run_until(max_steps=10, time=float("nan"))
    with raises(r"max_steps = -1 is out of range"):
        w.run_until(max_steps=-1, time=1.0)
    with raises(r"steps = -1 is out of range"):
        w.run(-1)
    assert w.step_count == 0


# --- generation --------------------------------------------------------------------------------


def test_particles_that_do_not_fit_their_container():
    radii = pd.truncated_normal_radii(500, seed=0)
    with raises(r"particles do not fit their container: solid fraction .* exceeds 0\.30 .* "
                r"allowed fill height >= .* m"):
        pd.random_pack_cylinder(radii, radius=1e-3, z_lo=0.0, z_hi=1e-3)
    with raises(r"largest radius 0\.0005 m does not fit the cylinder of radius 0\.0004 m"):
        pd.random_pack_cylinder([5e-4], radius=4e-4, z_lo=0.0, z_hi=1e-2)
    with raises(r"fill region: z_hi = 0 m must be > z_lo = 0\.001 m"):
        pd.random_pack_cylinder(radii, radius=1e-3, z_lo=1e-3, z_hi=0.0)


def test_radius_distribution_ranges():
    with raises(r"radius mean = 0\.0003 m must lie in \[r_min, r_max\]"):
        pd.truncated_normal_radii(10, mean=3e-4)
    with raises(r"radius sd = -1e-05 m must be a finite number >= 0"):
        pd.truncated_normal_radii(10, sd=-1e-5)


# --- bonds -------------------------------------------------------------------------------------


@pytest.mark.parametrize("field,value,match", [
    ("radius", 0.0, r"bond radius r_b = 0 m must be a finite number > 0"),
    ("radius", -2e-5, r"bond radius r_b = -2e-05 m must be a finite number > 0"),
    ("radius", float("nan"), r"bond radius r_b = nan m must be a finite number > 0"),
    ("youngs_modulus", -1.0, r"bond Young's modulus E_b = -1 Pa must be a finite number > 0"),
    ("sigma_c", -1.0, r"bond tension strength sigma_c = -1 Pa must be a finite number > 0"),
    ("tau_c", -1.0, r"bond shear strength tau_c = -1 Pa must be a finite number > 0"),
    ("sigma_c", float("nan"), r"bond tension strength sigma_c = nan Pa must be a finite number > 0"),
    ("tau_c", float("inf"), r"bond shear strength tau_c = inf Pa must be a finite number > 0"),
    ("kt_ratio", -1.0, r"bond kt_ratio = -1 +is out of range: allowed 0 <= bond kt_ratio <= 100"),
    ("gap_tolerance", -1e-6, r"bond gap_tolerance = -1e-06 m must be a finite number >= 0"),
])
def test_bad_bond_parameters(field, value, match):
    with raises(match):
        pd.BondLaw(**{field: value}).to_core()
    # The C++ struct refuses them too when handed straight to a world.
    w = world()
    w.add_particles(np.array([[0, 0, 0], [2 * R - 1e-6, 0, 0]]), np.array([R, R]))
    b = pd._core.BondParams()
    setattr(b, field, value)
    with raises(match):
        w.create_bonds(b)
    assert w.bond_count == 0


# --- runs that go wrong --------------------------------------------------------------------------


def test_particle_leaving_the_domain_raises_particle_escaped():
    w = one_particle(box=((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 1e-3)), dt=1e-6)
    w.set_velocities(np.array([[1.0, 0, 0]]), np.zeros((1, 3)))
    with pytest.raises(ParticleEscapedError, match=r"particle 0 at \(.*\) m left the domain box"):
        w.run(10_000)
    # Caught as the base classes too.
    w2 = one_particle(box=((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 1e-3)), dt=1e-6)
    w2.set_velocities(np.array([[0, 0, -1.0]]), np.zeros((1, 3)))
    with pytest.raises(RuntimeError):
        w2.run(10_000)


def test_particle_shot_through_a_wall_raises_particle_escaped():
    # Fast enough to cross the plane within one step: the wall cannot stop it, the box catches it.
    w = one_particle(box=((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 1e-3)), dt=1e-6)
    w.add_plane("floor", [0, 0, -3e-4], [0, 0, 1])
    w.set_velocities(np.array([[0, 0, -700.0]]), np.zeros((1, 3)))
    with pytest.raises(SimulationError):
        w.run(100)


def test_overlap_guard_raises_overlap_error():
    w = one_particle(dt=1e-6, max_overlap_ratio=0.2)
    lid = w.add_plane("lid", [0, 0, R], [0, 0, -1])
    w.add_plane("floor", [0, 0, -R], [0, 0, 1])
    w.set_wall_velocity(lid, [0, 0, -1.0])
    with pytest.raises(pd.OverlapError, match=r"overlap / radius = .* exceeds max_overlap_ratio = 0\.2"):
        w.run(1000)
