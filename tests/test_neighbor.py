"""The cell-grid Verlet list against the O(N^2) definition, and contact history across rebuilds.

The list built from positions x holds exactly the pairs i < j with |x_j - x_i| < r_i + r_j + skin
(pelletdem._core.brute_force_pairs computes that set directly). Between rebuilds it must keep
holding every pair that is actually in contact.
"""

import numpy as np
import pytest

import pelletdem as pd
from pelletdem import _core

SKIN = 2.0e-5


def pair_set(i, j):
    return set(zip(np.asarray(i).tolist(), np.asarray(j).tolist()))


def list_after_rebuild(w):
    """Force a rebuild at the current positions; return (positions it was built at, pairs)."""
    x = w.positions()
    w.set_positions(x)  # invalidates the list: the next step rebuilds at exactly x
    before = w.rebuild_count
    w.step()
    # A rebuild during the step (after the move) would replace the list: make sure it did not.
    assert w.rebuild_count == before + 1
    return x, pair_set(*_core.neighbor_pairs(w._core))


def static_world(x, r, box, skin=SKIN):
    # dt tiny: the step that builds the list moves nothing enough to trigger a second build.
    w = pd.World(dt=1e-13, box=box, gravity=(0, 0, 0), skin=skin, max_overlap_ratio=10.0)
    w.add_particles(x, r)
    return w


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_random_polydisperse_positions_match_brute_force(seed):
    # Uniform random centres (overlaps allowed: the search does not care), radii 0.14-0.26 mm,
    # in a box whose sides are not multiples of the cell size.
    rng = np.random.default_rng(seed)
    n = 800
    lo, hi = np.array([-1.1e-3, -0.93e-3, 0.0]), np.array([1.3e-3, 0.71e-3, 2.37e-3])
    x = lo + (hi - lo) * rng.random((n, 3))
    r = rng.uniform(1.4e-4, 2.6e-4, n)
    w = static_world(x, r, (lo.tolist(), hi.tolist()))
    xb, pairs = list_after_rebuild(w)
    expected = pair_set(*_core.brute_force_pairs(xb, np.array(w.r), SKIN))
    assert len(expected) > 1000
    assert pairs == expected


@pytest.mark.parametrize("box", [
    ((0.0, 0.0, 0.0), (0.6e-3, 0.6e-3, 0.6e-3)),      # one cell only
    ((0.0, 0.0, 0.0), (20e-3, 20e-3, 0.7e-3)),        # many cells, one layer, sparse
    ((-5e-3, -0.4e-3, -0.4e-3), (5e-3, 0.4e-3, 0.4e-3)),  # a thin rod of cells
])
def test_box_shapes_match_brute_force(box):
    rng = np.random.default_rng(7)
    lo, hi = np.array(box[0]), np.array(box[1])
    n = 300
    x = lo + (hi - lo) * rng.random((n, 3))
    for k in range(10):  # centres exactly on the box's faces
        x[k, k % 3] = lo[k % 3]
        x[10 + k, k % 3] = hi[k % 3]
    x[20], x[21] = lo, hi  # and corners
    r = pd.truncated_normal_radii(n, sd=4e-5, seed=7)
    w = static_world(x, r, box)
    xb, pairs = list_after_rebuild(w)
    assert pairs == pair_set(*_core.brute_force_pairs(xb, np.array(w.r), SKIN))


@pytest.mark.parametrize("skin", [0.0, 1e-6, 1e-4])
def test_skin_values_match_brute_force(skin):
    # skin = 0 means 0.1 of the largest radius.
    rng = np.random.default_rng(11)
    x = rng.random((400, 3)) * 2e-3
    r = rng.uniform(1.4e-4, 2.6e-4, 400)
    w = static_world(x, r, ((0, 0, 0), (2e-3, 2e-3, 2e-3)), skin=skin)
    xb, pairs = list_after_rebuild(w)
    effective = skin if skin > 0 else 0.1 * r.max()
    assert pairs == pair_set(*_core.brute_force_pairs(xb, np.array(w.r), effective))


def dense_packing(seed, threads=1):
    """A polydisperse packing poured into a cylinder and left to collapse for a few steps."""
    radii = pd.truncated_normal_radii(400, seed=seed)
    x, radii = pd.random_pack_cylinder(radii, radius=1.5e-3, z_lo=0.0, z_hi=8e-3, seed=seed)
    w = pd.World(dt=2e-6, box=((-2e-3, -2e-3, -1e-3), (2e-3, 2e-3, 9e-3)),
                 gravity=(0, 0, -9.81e4), skin=SKIN, threads=threads)
    w.add_particles(x, radii)
    w.add_plane("floor", [0, 0, 0], [0, 0, 1])
    w.add_cylinder("mould", [0, 0, 0], 1.5e-3)
    return w


@pytest.mark.parametrize("seed", [4, 5])
def test_dense_packing_lists_stay_complete(seed):
    """During a run every touching pair is in the list, and each rebuild is exact."""
    w = dense_packing(seed)
    r = np.array(w.r)
    for _ in range(30):
        w.run(500)
        x = w.positions()
        touching = pair_set(*_core.brute_force_pairs(x, r, 0.0))
        assert touching <= pair_set(*_core.neighbor_pairs(w._core))
    assert w.contact_count > len(r)  # dense by now: more contacts than particles
    assert w.rebuild_count > 20
    # An exact rebuild on the dense state.
    w.dt = 1e-13
    xb, pairs = list_after_rebuild(w)
    assert pairs == pair_set(*_core.brute_force_pairs(xb, r, SKIN))


def test_contact_history_survives_many_rebuilds():
    """Two spheres stacked on a floor, pressed by a lid, then partly unloaded, so each contact
    sits on its k2 line with a residual overlap delta0 = delta_max (1 - k1/k2) > 0. A fast
    particle flying far from them forces hundreds of list rebuilds. Had any rebuild dropped the
    history, that contact would restart on the loading line (f = k1 delta, a quarter of the
    force at the same overlap), the stack would sink, and delta0 = delta - f/k2 would change."""
    k1, k2 = 1e5, 4e5
    sw = 2.0  # wall contacts: k1, k2 times sw
    law = pd.ContactLaw(k1=k1, k2=k2, kc=0.0, mu_wall=0.0, wall_stiffness_factor=sw)
    r = 2e-4
    w = pd.World(dt=1e-6, box=((-3e-3, -1e-3, -1e-3), (3e-3, 1e-3, 3e-3)), contact=law,
                 gravity=(0, 0, 0), skin=SKIN)
    # The third particle flies along x at y = 0.6 mm, clear of the stack.
    x = np.array([[0, 0, r], [0, 0, 3 * r], [-2e-3, 0.6e-3, 2 * r]])
    w.add_particles(x, np.full(3, r))
    floor = w.add_plane("floor", [0, 0, 0], [0, 0, 1])
    lid = w.add_plane("lid", [0, 0, 4 * r], [0, 0, -1])
    w.add_plane("left", [-2.5e-3, 0, 0], [1, 0, 0])
    w.add_plane("right", [2.5e-3, 0, 0], [-1, 0, 0])
    w.set_wall_velocity(lid, [0, 0, -0.01])
    w.run_until(max_steps=100_000, wall_force_above=(lid, 1.0))
    w.set_wall_velocity(lid, [0, 0, 0.01])
    w.run_until(max_steps=100_000, wall_force_below=(lid, 0.5))
    w.set_wall_velocity(lid, [0, 0, 0])
    w.run(20_000)  # the stack rings down to its (undamped, small) elastic vibration

    def state():
        c = w.contacts()
        assert len(c["i"]) == 1
        z = w.positions()[:2, 2].copy()
        floor_d0 = (r - z[0]) - w.wall_state(floor)["normal_force"] / (sw * k2)
        return c["overlap"][0], c["fn"][0], z, floor_d0

    d_a, f_a, z_a, floor_d0_a = state()
    assert f_a < 0.9 * k1 * d_a  # on the k2 line: history is present
    d0_a = d_a - f_a / k2
    assert d0_a > 0.5 * d_a
    assert floor_d0_a > 0.5 * (r - z_a[0])

    rebuilds = w.rebuild_count
    w.set_velocities(np.array([[0, 0, 0], [0, 0, 0], [2.0, 0.0, 0.0]]), np.zeros((3, 3)))
    samples = []
    for _ in range(40):
        w.run(500)
        samples.append(state())
    assert w.rebuild_count - rebuilds > 200
    for d, f, z, floor_d0 in samples:
        assert d - f / k2 == pytest.approx(d0_a, rel=1e-9)
        assert f < 0.9 * k1 * d
        # No sinking beyond the stack's own elastic ringing (a few % of the overlap).
        np.testing.assert_allclose(z, z_a, atol=0.05 * d_a)
        # The floor contact's history (kept in the wall's own list) survives too.
        assert floor_d0 == pytest.approx(floor_d0_a, rel=1e-9)
