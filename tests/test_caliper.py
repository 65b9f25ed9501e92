"""The pellet's size, density and bulk coordination number as a laboratory measures them
(pelletdem.caliper), on shapes whose volume is known."""

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from pelletdem import ParameterError, caliper, stages
from pelletdem.presets import get_preset

R0 = 2.0e-4
A_FCC = 2.0 * R0 * math.sqrt(2.0)  # fcc cube edge for touching spheres of radius R0


def fcc(inside) -> np.ndarray:
    """Centres of an fcc lattice of spheres of radius R0 for which inside(centre) holds."""
    base = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]]) * A_FCC
    g = np.arange(-12, 13) * A_FCC
    cells = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 1, 3)
    pts = (cells + base[None]).reshape(-1, 3)
    return pts[np.array([inside(p) for p in pts])]


def cylinder(radius, height):
    return fcc(lambda p: math.hypot(p[0], p[1]) + R0 <= radius and abs(p[2]) + R0 <= 0.5 * height)


def cube(half):
    return fcc(lambda p: (np.abs(p) + R0 <= half).all())


@pytest.mark.parametrize("shape", ["cylinder", "cube"])
def test_a_lattice_packed_body_has_its_cells_volume(shape):
    """N spheres of a lattice fill N cells of a^3/4: the enclosed solid's volume is that within
    2 %, where the cylinder through the outermost extents is several times further off."""
    x = cylinder(2.4e-3, 2.4e-3) if shape == "cylinder" else cube(1.9e-3)
    r = np.full(len(x), R0)
    true = len(x) * A_FCC**3 / 4.0
    solid = caliper.enclosed_solid(x, r)
    assert solid.volume == pytest.approx(true, rel=0.02)
    if shape == "cylinder":
        size = caliper.pellet_size(x, r, 1e-6)
        assert size.volume == solid.volume
        assert size.bulk_density == pytest.approx(len(x) * 1e-6 / true, rel=0.02)
        assert abs(size.volume_extent / true - 1.0) > 2.0 * abs(size.volume / true - 1.0)
        # a caliper's diameter and height: the cylinder of that volume, and the distance of
        # the flat faces, which bound the outer layers' cells half a layer spacing (a/4)
        # beyond their centres (the spheres' tops, the extents, stand 0.29 r further out)
        assert math.pi * 0.25 * size.diameter**2 * size.height == pytest.approx(size.volume, rel=1e-12)
        assert size.height == pytest.approx(np.ptp(x[:, 2]) + 0.5 * A_FCC, rel=0.01)


def test_a_protruding_sphere_moves_the_extents_not_the_caliper():
    x = cylinder(2.4e-3, 2.4e-3)
    r = np.full(len(x), R0)
    top = x[np.argmax(x[:, 2])]
    bump = np.vstack([x, top + [0.0, 0.0, 1.9 * R0]])
    before = caliper.pellet_size(x, r, 1e-6)
    after = caliper.pellet_size(bump, np.append(r, R0), 1e-6)
    assert after.height_extent - before.height_extent == pytest.approx(1.9 * R0, rel=1e-9)
    assert after.height == pytest.approx(before.height, rel=0.005)
    assert after.volume == pytest.approx(before.volume, rel=0.005)


def test_depth_below_the_surface_of_a_lattice_cube():
    """A particle's depth is its distance to the nearest point of the surface, which runs
    between the outer spheres' tops (r above their centres) and the hollows between them
    (0.41 r above on a face, where the probe sphere of radius r rests on four touching
    spheres; less on the cube's edges). The surface never cuts into a sphere."""
    half = 1.9e-3
    x = cube(half)
    r = np.full(len(x), R0)
    solid = caliper.enclosed_solid(x, r)
    below_outer = np.abs(x).max() - np.abs(x).max(axis=1)  # below the outer layer's centres
    got = solid.depth(x)
    deep = below_outer > R0
    assert (got[deep] <= below_outer[deep] + R0).all()
    assert (got[deep] >= below_outer[deep]).all()
    assert (got >= 0.75 * R0).all()  # r, less a voxel
    assert solid.depth(np.array([[0.0, 0.0, 10 * half]]))[0] == 0.0  # outside


def test_bulk_coordination_number_leaves_the_surface_layer_out():
    """Touching fcc spheres have 12 neighbours inside and fewer at the faces: the bulk CN is
    12 exactly, the whole body's less."""
    x = cube(2.2e-3)
    r = np.full(len(x), R0)
    pairs = np.array(sorted(cKDTree(x).query_pairs(2 * R0 * (1 + 1e-9))))
    size = caliper.pellet_size(x, r, 1e-6)
    assert size.bulk.sum() > 20
    assert caliper.coordination_number(len(x), pairs[:, 0], pairs[:, 1], size.bulk) == pytest.approx(12.0)
    assert caliper.coordination_number(len(x), pairs[:, 0], pairs[:, 1]) < 11.0
    # every bulk particle lies two diameters below the surface
    assert size.bulk_depth == pytest.approx(caliper.BULK_DEPTH_DIAMETERS * 2 * R0)
    assert (size.depth[size.bulk] >= size.bulk_depth).all()
    # the core density of a uniform lattice is the lattice's
    assert size.core_density == pytest.approx(1e-6 / (A_FCC**3 / 4.0), rel=0.05)


def test_a_body_too_small_for_a_bulk_keeps_its_deeper_half():
    x = cube(0.9e-3)  # four layers: no particle two diameters deep
    size = caliper.pellet_size(x, np.full(len(x), R0), 1e-6)
    assert size.bulk_depth == pytest.approx(0.5 * size.depth.max())
    assert 0 < size.bulk.sum() < len(x)
    assert math.isfinite(size.core_density)


def test_a_pellet_held_in_its_mould_has_the_moulds_volume():
    """Compacted to 120 MPa and still in the mould, the pellet fills the mould up to the
    piston: the one pellet whose volume is known. The extents overshoot it by the wall
    overlaps (up to 0.7 r at 120 MPa)."""
    p = get_preset("tiny")
    pellet, _ = stages.fill(p, seed=5, threads=1, progress=False)
    stages.compact(pellet, 120e6, progress=False)
    w = pellet.world
    x, r = np.array(w.x), np.array(w.r)
    h_piston = w.wall_state(pellet.walls["piston"])["point"][2]
    mould = math.pi * pellet.mould_radius**2 * h_piston
    size = caliper.pellet_size(x, r, np.array(w.m) / p.density_scale)
    assert size.volume == pytest.approx(mould, rel=0.02)
    assert size.volume_extent > 1.08 * mould


@pytest.mark.parametrize("x,r,match", [
    (np.zeros((3, 2)), np.full(3, R0), "positions"),
    (np.zeros((3, 3)), np.full(2, R0), "positions"),
    (np.full((1, 3), np.nan), np.full(1, R0), "finite"),
    (np.zeros((1, 3)), np.array([-R0]), "radii"),
])
def test_bad_particles_are_refused(x, r, match):
    with pytest.raises(ParameterError, match=match):
        caliper.enclosed_solid(x, r)


@pytest.mark.parametrize("kw,match", [({"probe": -1e-4}, "probe"), ({"probe": math.nan}, "probe"),
                                      ({"voxel": 0.0}, "voxel"), ({"voxel": 1.0}, "voxel")])
def test_bad_probe_or_voxel_is_refused(kw, match):
    with pytest.raises(ParameterError, match=match):
        caliper.enclosed_solid(np.zeros((1, 3)), np.full(1, R0), **kw)


def test_bad_mass_is_refused():
    with pytest.raises(ParameterError, match="mass"):
        caliper.pellet_size(np.zeros((1, 3)), np.full(1, R0), -1.0)
