"""Parallel bonds as the engine keeps them: weak bonds, bad parameters, the broken-bond
record, bonds in and out of the neighbour list, saved states, and the slot blocks that hold
the listed bonds' state between list builds (World::map_bonds). The closed forms of eq. 12-15
are in test_bonds.py, whose heavy pair this reuses.
"""
from __future__ import annotations

import numpy as np
import pytest

import pelletdem as pd
from pelletdem import _core
from test_bonds import BOX, GAP, HEAVY, R1, R2, area, bond0, heavy_pair, kn_of, run_until_broken

# --------------------------------------------------------------------------------------
# Weak bonds, bad parameters, the broken-bond record
# --------------------------------------------------------------------------------------


def _settling_world(seed=3):
    """27 spheres on a slightly jittered cubic lattice (surfaces ~1 um apart) dropped on a floor."""
    rng = np.random.default_rng(seed)
    r = 2e-4
    g = np.arange(3) * (2 * r + 1e-6)
    x = np.array([(a, b, c) for a in g for b in g for c in g]) + rng.uniform(-2e-7, 2e-7, (27, 3))
    x[:, 2] += r + 2e-5
    w = pd.World(dt=2e-6, box=((-2e-3, -2e-3, -1e-3), (3e-3, 3e-3, 4e-3)), gravity=(0, 0, -9.81e4),
                 skin=4e-5)
    w.add_particles(x, np.full(27, r))
    w.add_plane("floor", (0, 0, 0), (0, 0, 1))
    return w


@pytest.mark.parametrize("law", [
    pd.BondLaw(youngs_modulus=1e-2, sigma_c=1e4, tau_c=1e4, gap_tolerance=4e-5),     # stays intact
    pd.BondLaw(youngs_modulus=1e-2, sigma_c=1e-9, tau_c=1e-9, gap_tolerance=4e-5),   # breaks at once
])
def test_weak_bonds_behave_like_no_bonds(law):
    # E_b = 0.01 Pa: k_n A ~ 3e-11 N/m, bond forces < 1e-15 N against weights of ~2e-5 N
    # (scaled gravity). 27 particles dropped on a floor, 3000 steps (they fall, hit it and
    # spread): positions agree within 1e-6 r.
    ref = _settling_world()
    bonded = _settling_world()
    nb = bonded.create_bonds(law.to_core())
    assert nb > 10
    ref.run(3000)
    bonded.run(3000)
    r = ref.radii().min()
    assert np.abs(ref.positions() - bonded.positions()).max() < 1e-6 * r
    if law.sigma_c < 1:
        assert bonded.intact_bond_count() == 0
    # The comparison can tell: the paper's bonds change the motion by far more than that.
    strong = _settling_world()
    strong.create_bonds(pd.BondLaw(gap_tolerance=4e-5).to_core())
    strong.run(3000)
    assert np.abs(ref.positions() - strong.positions()).max() > 1e-3 * r


BAD = [
    dict(radius=0.0), dict(radius=-1e-5), dict(radius=float("nan")), dict(radius=float("inf")),
    dict(youngs_modulus=0.0), dict(youngs_modulus=-1.0), dict(youngs_modulus=float("nan")),
    dict(sigma_c=-1.0), dict(sigma_c=0.0), dict(sigma_c=float("nan")),
    dict(tau_c=-1.0), dict(tau_c=float("nan")),
    dict(kt_ratio=-0.1), dict(kt_ratio=float("nan")),
    dict(gap_tolerance=-1e-6), dict(gap_tolerance=float("nan")),
]


@pytest.mark.parametrize("bad", BAD, ids=[f"{k}={v}" for d in BAD for k, v in d.items()])
def test_bad_bond_parameters_raise_before_stepping(bad):
    with pytest.raises(pd.ParameterError) as e:
        pd.BondLaw(**bad).to_core()
    assert isinstance(e.value, ValueError)
    # The engine checks too, when handed the raw struct; nothing is bonded or stepped.
    w = pd.World(dt=2e-6, gravity=(0, 0, 0), box=BOX, skin=5e-5, **HEAVY)
    w.add_particles(np.array([[0.0, 0, 0], [R1 + R2 + GAP, 0, 0]]), np.array([R1, R2]))
    p = _core.BondParams()
    for k, v in bad.items():
        setattr(p, k, v)
    with pytest.raises(pd.ParameterError):
        w.create_bonds(p)
    assert w.bond_count == 0 and w.step_count == 0


def test_bond_gap_beyond_skin_and_bad_per_bond_values_raise():
    w = pd.World(dt=2e-6, gravity=(0, 0, 0), box=BOX, skin=5e-5, **HEAVY)
    w.add_particles(np.array([[0.0, 0, 0], [R1 + R2 + GAP, 0, 0]]), np.array([R1, R2]))
    with pytest.raises(pd.ParameterError, match="skin"):
        w.create_bonds(pd.BondLaw(gap_tolerance=1e-4).to_core())
    assert w.create_bonds(pd.BondLaw(gap_tolerance=2 * GAP).to_core()) == 1
    for name in ("radius", "kn", "kt", "sigma_c", "tau_c"):
        for v in (-1.0, 0.0, float("nan")):
            with pytest.raises(pd.ParameterError, match=name):
                w.set_bond_property(name, np.array([v]))
    with pytest.raises(pd.ParameterError, match="one value per bond"):
        w.set_bond_property("sigma_c", np.array([1.0, 2.0]))
    with pytest.raises(pd.ParameterError, match="unknown bond property"):
        w.set_bond_property("colour", np.array([1.0]))
    with pytest.raises(pd.ParameterError, match="already"):
        w.create_bonds(pd.BondLaw(gap_tolerance=2 * GAP).to_core())
    assert w.step_count == 0


def test_set_bond_property_changes_strength():
    law = pd.BondLaw(sigma_c=36e6, gap_tolerance=2 * GAP)
    w, _ = heavy_pair(law=law)
    w.set_bond_property("sigma_c", np.array([18e6]))
    w.set_velocities(np.array([[-0.01, 0, 0], [0.01, 0, 0]]), np.zeros((2, 3)))
    run_until_broken(w, 5000)
    assert w.broken_bonds()["sigma"][0] == pytest.approx(18e6, rel=1e-2)


@pytest.mark.parametrize("mode", ["tension", "shear"])
def test_broken_bond_record(mode):
    law = pd.BondLaw(sigma_c=36e6, tau_c=6e6, gap_tolerance=2 * GAP)
    w, _ = heavy_pair(law=law)
    # A load wall below the pair moving away from it at 1 m/s: the load marker is its travel
    # along its normal, -1 m/s times the time.
    k = w.add_plane("plate", (0.0, 0.0, -5e-3), (0.0, 0.0, 1.0))
    w.set_wall_velocity(k, (0.0, 0.0, -1.0))
    w.set_load_walls([k])
    v = np.array([[-0.01, 0, 0], [0.01, 0, 0]]) if mode == "tension" else np.array([[0, -0.005, 0], [0, 0.005, 0]])
    w.set_velocities(v, np.zeros((2, 3)))
    steps = run_until_broken(w, 20000)
    br = w.broken_bonds()
    assert len(br["i"]) == 1
    assert br["time"][0] == pytest.approx(w.time, rel=1e-12)
    assert br["step"][0] == w.step_count == steps
    assert (br["i"][0], br["j"][0]) == (0, 1)
    assert br["mode"][0] == (1 if mode == "tension" else 2)
    x = w.positions()
    d = x[1] - x[0]
    dist = np.linalg.norm(d)
    centre = x[0] + (R1 + 0.5 * (dist - R1 - R2)) * d / dist
    np.testing.assert_allclose(br["position"][0], centre, rtol=0, atol=1e-12)
    assert br["load_marker"][0] == pytest.approx(w.load_marker, rel=1e-12)
    assert br["load_marker"][0] == pytest.approx(-w.time, rel=1e-9)
    # The bond's record in bonds() says broken, with its mode; nothing breaks twice.
    b = w.bonds()
    assert b["mode"][0] == br["mode"][0]
    w.run(100)
    assert len(w.broken_bonds()["i"]) == 1


def test_resetting_velocities_adds_no_bond_increment():
    # Forces are recomputed after set_velocities (the state changed from outside) but no time
    # has passed: the bond must not take a second increment (it did before: each reset added
    # v dt of stretch, and a clamp reset every step doubled the bonds' apparent stiffness).
    w, law = heavy_pair()
    v = np.array([[-0.01, 0, 0], [0.01, 0, 0]])
    for _ in range(200):
        w.set_velocities(v, np.zeros((2, 3)))
        w.step()
    x = w.positions()
    stretch = x[1, 0] - x[0, 0] - (R1 + R2 + GAP)
    assert bond0(w)["fn"] == pytest.approx(-kn_of(law) * area(law) * stretch, rel=1e-9)


def test_bonded_pair_continues_bit_for_bit_from_a_saved_state():
    # The saved state does not carry the bonds' last-update step; restoring sets it to the
    # saved step, so a restored world takes no spurious increment when its forces are
    # recomputed (e.g. after set_velocities) and goes on exactly as the original.
    w, law = heavy_pair()
    v = np.array([[-0.01, 0.002, 0], [0.01, -0.002, 0]])
    w.set_velocities(v, np.array([[0, 0, 1.0], [2.0, 0, 0]]))
    w.run(300)
    state = w.get_state()
    copy = pd.World.from_state(state)
    for world in (w, copy):
        world.set_velocities(np.array(world.v), np.array(world.w))  # forces recomputed
        world.run(300)
    a, b = bond0(w), bond0(copy)
    for k in ("fn", "ft", "mn", "mt"):
        np.testing.assert_array_equal(a[k], b[k])
    np.testing.assert_array_equal(w.positions(), copy.positions())


def _stretched_chain(skin):
    """Six heavy spheres in a row, bonded to their neighbours across 1 um gaps and pulled apart
    with shear and spin: every bond stretches by ~1.2e-5 m in 300 steps."""
    n = 6
    r = np.where(np.arange(n) % 2 == 0, R1, R2)
    x = np.zeros((n, 3))
    for k in range(1, n):
        x[k, 0] = x[k - 1, 0] + r[k - 1] + r[k] + GAP
    w = pd.World(dt=2e-6, gravity=(0, 0, 0), box=BOX, skin=skin, **HEAVY)
    w.add_particles(x, r)
    assert w.create_bonds(pd.BondLaw(gap_tolerance=2 * GAP).to_core()) == n - 1
    k = np.arange(n)[:, None]
    v = (k - 2.5) * np.array([[0.01, 0.003, -0.002]])
    spin = np.cos(k + np.array([[0.0, 1.0, 2.0]])) * 30.0
    w.set_velocities(v, spin)
    return w


def test_a_bond_is_the_same_in_and_out_of_the_neighbour_list():
    """The pair loop updates a bond whose pair is listed, the bond loop one whose pair has left
    the list (stretched past r_i + r_j + skin). A 50 um skin keeps the chain's pairs listed for
    the whole run, a 2 um one drops them within ~100 steps: the bonds, forces and torques must
    agree bit for bit (the pairs are apart, so no contact acts, and each particle's two bonds
    add in bond order either way)."""
    listed, dropped = _stretched_chain(skin=5e-5), _stretched_chain(skin=2e-6)
    listed.run(300)
    dropped.run(300)
    i, _ = _core.neighbor_pairs(listed._core)
    assert len(i) == 5
    i, _ = _core.neighbor_pairs(dropped._core)
    assert len(i) == 0
    a, b = listed.bonds(), dropped.bonds()
    for key in ("fn", "ft", "mn", "mt"):
        np.testing.assert_array_equal(a[key], b[key])
        assert np.all(np.abs(a[key]) > 0) if key in ("fn", "mn") else np.abs(a[key]).max() > 0
    np.testing.assert_array_equal(np.array(listed.f), np.array(dropped.f))
    np.testing.assert_array_equal(np.array(listed.t), np.array(dropped.t))


# --------------------------------------------------------------------------------------
# The slots: listed bonds' state kept in blocks between list builds (World::map_bonds)
# --------------------------------------------------------------------------------------


def _bonded_cube(n_side=4, seed=5):
    """n_side^3 spheres on a squeezed cubic lattice in a box of six planes, every contact and
    every pair within 5 um bonded (so some bonded pairs start apart), shaken by random
    velocities and spins: the pair loop takes groups of four bonds from the slot blocks, pairs
    come into and out of contact, and the list is rebuilt now and then."""
    rng = np.random.default_rng(seed)
    a = 3.9e-4
    g = np.arange(n_side) * a
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    r = 2.0e-4 * (1.0 + 0.02 * rng.uniform(-1, 1, len(x)))
    L = (n_side - 1) * a
    w = pd.World(dt=2e-6, gravity=(0, 0, 0), box=((-1e-3,) * 3, (L + 1e-3,) * 3), skin=2e-5)
    w.add_particles(x, r)
    for k in range(3):
        e = np.eye(3)[k]
        w.add_plane(f"lo{k}", (-1.9e-4 * e).tolist(), e.tolist())
        w.add_plane(f"hi{k}", ((L + 1.9e-4) * e).tolist(), (-e).tolist())
    w.create_bonds(pd.BondLaw(gap_tolerance=5e-6).to_core())
    w.set_velocities(rng.normal(0.0, 0.02, (len(x), 3)), rng.normal(0.0, 50.0, (len(x), 3)))
    return w


def test_reading_or_saving_bonds_mid_run_changes_nothing():
    """The records are written back from the slots whenever something outside the force pass
    reads them; reading, saving and restoring mid-run must leave the run bit for bit as it
    was, and the values read must be the bonds' current state (a restored copy continues from
    them)."""
    quiet, busy = _bonded_cube(), _bonded_cube()
    assert quiet.bond_count > 100
    quiet.run(400)
    for _ in range(40):
        busy.run(10)
        busy.bonds()
        busy.potential_energy()  # reads the bonds' records too
    np.testing.assert_array_equal(quiet.positions(), busy.positions())
    a, b = quiet.bonds(), busy.bonds()
    for key in ("fn", "ft", "mn", "mt", "mode"):
        np.testing.assert_array_equal(a[key], b[key])
    assert np.abs(a["fn"]).max() > 0 and np.abs(a["mt"]).max() > 0
    # A copy restored from the state read now goes on exactly as the original.
    copy = pd.World.from_state(busy.get_state())
    busy.run(200)
    copy.run(200)
    np.testing.assert_array_equal(busy.positions(), copy.positions())
    for key in ("fn", "ft", "mn", "mt"):
        np.testing.assert_array_equal(busy.bonds()[key], copy.bonds()[key])


def test_changing_a_bond_property_mid_run_reaches_the_slots():
    """set_bond_property between runs must act on the next step, listed bonds included: halving
    every bond's k_n halves the normal force increment of the next step."""
    w = _bonded_cube()
    w.run(100)
    kn = w.bonds()["kn"]
    ref = w.clone()
    fn0 = w.bonds()["fn"].copy()
    w.set_bond_property("kn", 0.5 * kn)
    ref.set_bond_property("kn", kn)  # the same values: nothing changes
    w.step()
    ref.step()
    d_half = w.bonds()["fn"] - fn0
    d_full = ref.bonds()["fn"] - fn0
    moving = np.abs(d_full) > 1e-12 * np.abs(fn0).max()
    assert moving.sum() > 50
    np.testing.assert_allclose(d_half[moving], 0.5 * d_full[moving], rtol=1e-6)
