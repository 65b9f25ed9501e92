"""Every stage of the pellet's life on a small pellet, with physical assertions.

One life of the 'tiny' preset (400 particles, 3 mm mould, one thread) runs once per session
(the `tiny_life` fixture in conftest.py) and every test reads it: fill -> compact (120 MPa)
-> unload -> demould -> relax -> bond -> diametral. The bond law is softer than the paper's
Table 5 so that the tiny pellet breaks within the test (see TINY_BOND in conftest.py).

Geometry (stages.py): the mould axis is z, the floor is z = 0, the piston a plane moving
down; the plates of the diametral test are planes normal to y, so the loaded diameter is the
line x = x_c of the pellet's section.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.stats import spearmanr

import pelletdem
from pelletdem import ParameterError, caliper, cracks, pellet_measures, pipeline, stages
from pelletdem.engine import BondLaw
from pelletdem.presets import get_preset


@pytest.fixture(scope="module")
def life(tiny_life):
    return tiny_life


def _stage(life, name):
    return life.result.stages[name]


def _pair_overlaps(x, r):
    """(i, j, overlap in m) of every touching pair of spheres."""
    pairs = np.array(sorted(cKDTree(x).query_pairs(2.0 * r.max())), dtype=int).reshape(-1, 2)
    i, j = pairs[:, 0], pairs[:, 1]
    ov = r[i] + r[j] - np.linalg.norm(x[i] - x[j], axis=1)
    keep = ov > 0
    return i[keep], j[keep], ov[keep]


def _extent(x, r):
    """(diameter, height, centre x, centre y) as pellet_measures.pellet_extent computes them, m."""
    cx, cy = x[:, 0].mean(), x[:, 1].mean()
    d = 2.0 * (np.hypot(x[:, 0] - cx, x[:, 1] - cy) + r).max()
    h = (x[:, 2] + r).max() - (x[:, 2] - r).min()
    return d, h, cx, cy


# --- the life as a whole ----------------------------------------------------------------------

def test_every_stage_ran_in_order(life):
    assert list(life.result.stages) == ["fill", "compact", "unload", "demould", "relax", "bond", "diametral"]
    for name, st in life.result.stages.items():
        assert st.name == name
        assert st.steps > 0 or name == "relax"  # relax with min_time = 0 may end at once
        assert st.wall_time_s >= 0.0
        assert name in life.result.snapshots
        for key, arr in st.series.items():
            if key == "inertia_number":  # inf by definition where the stress is 0 (pellet_measures.inertia_number)
                p = st.series["sigma_z" if name == "compact" else "sigma_1"]
                assert np.all(np.isfinite(arr[p > 0])) and np.all(np.isinf(arr[p <= 0])), name
                continue
            assert np.all(np.isfinite(arr)), f"{name}.{key} has non-finite values"


# --- fill ------------------------------------------------------------------------------------

def test_fill_settles_in_the_mould(life):
    st, pellet = _stage(life, "fill"), life.pellet
    sc = st.scalars
    assert sc["n_particles"] == 400
    assert sc["settled"] == 1.0
    snap = pellet.snapshots["fill"]
    x, r = snap["position"], snap["radius"]
    # h0 is the top of the settled bed, and BD_s = m / (pi R^2 h0) with the unscaled mass.
    assert sc["h0"] == pytest.approx((x[:, 2] + r).max(), rel=1e-12)
    R = pellet.mould_radius
    assert sc["bulk_density"] == pytest.approx(sc["mass"] / (math.pi * R * R * sc["h0"]), rel=1e-12)
    # A random loose packing of spheres: solid fraction between ~0.4 and random close packing.
    assert 0.40 < sc["solid_fraction"] < 0.66
    assert np.all(x[:, 2] > 0.0)
    assert np.all(np.hypot(x[:, 0], x[:, 1]) < R)
    # At rest under (boosted) gravity: the kinetic energy fell by orders of magnitude.
    ke = st.series["kinetic_energy"]
    assert ke[-1] < 1e-2 * ke.max()


def test_every_compaction_effects_strength_settles_the_same_bed():
    """The bed settles with the compaction effects off, then the law in force is the preset's:
    a packing seed gives one bed whatever the effects' strengths (a settling is chaotic, and
    strengths differing in the fourth digit settled beds whose tops differed by 3 %), and a
    preset without effects is untouched."""
    base = get_preset("tiny")
    laws = {"plain": base.contact,
            "growth": replace(base.contact, unloading_growth=6.16925),  # g <= 6.8 holds 2e-6 s on tiny
            "saturating": replace(base.contact, plastic_stiffness_ratio=4.0, plastic_overlap=0.2),
            "hardening": replace(base.contact, hardening=5.0)}
    beds = {}
    for name, law in laws.items():
        pellet, st = stages.fill(replace(base, contact=law), seed=100, n_particles=120)
        beds[name] = (st.scalars["h0"], pellet.snapshots["fill"]["position"])
        assert pellet.world.contact_law == law
        assert stages.fill_law(law) == replace(law, unloading_growth=0.0, plastic_stiffness_ratio=1.0, hardening=0.0,
                                               moisture_yield=0.0)
    for name in laws:
        assert beds[name][0] == beds["plain"][0]
        assert np.array_equal(beds[name][1], beds["plain"][1])
    assert stages.fill_law(base.contact) == base.contact


# --- compact ---------------------------------------------------------------------------------

def test_compaction_reaches_the_target_pressure(life):
    sc = _stage(life, "compact").scalars
    assert sc["reached"] == 1.0
    assert sc["sigma_z_target"] == life.sigma_z
    assert sc["sigma_z_reached"] >= life.sigma_z
    assert sc["sigma_z_reached"] <= 1.03 * life.sigma_z  # stopped within a few % of the target
    s = _stage(life, "compact").series
    assert s["sigma_z"][-1] == pytest.approx(sc["sigma_z_reached"], rel=1e-9)


def test_compaction_geometry_is_consistent(life):
    st, pellet = _stage(life, "compact"), life.pellet
    s, sc = st.series, st.scalars
    h0 = _stage(life, "fill").scalars["h0"]
    area = math.pi * pellet.mould_radius**2
    assert np.all(np.diff(s["time"]) > 0)
    assert np.all(np.diff(s["h"]) <= 0)  # the piston only goes down
    assert np.allclose(s["dh_h0"], (h0 - s["h"]) / h0)
    assert np.allclose(s["bulk_density"], pellet.mass / (area * s["h"]))
    assert sc["h_min"] == s["h"][-1]
    assert sc["bulk_density_max"] == pytest.approx(pellet.mass / (area * sc["h_min"]))
    # 120 MPa roughly doubles the density of the loose bed (the paper: dh/h0 ~ 0.75 measured).
    assert 0.3 < sc["dh_h0_max"] < 0.9
    assert sc["coordination_number_max"] > _stage(life, "fill").scalars["coordination_number"]


def test_density_rises_monotonically_with_pressure(life):
    s = _stage(life, "compact").series
    sz, bd = s["sigma_z"], s["bulk_density"]
    assert spearmanr(sz, bd).correlation > 0.99
    # Sorted by pressure and smoothed over a few samples, the density never falls once the
    # piston carries the bed. Below ~1 % of the final pressure the piston only touches a
    # rattling bed: its reading jumps between 0 and ~0.4 MPa while the density wanders by a
    # few kg/m^3, and the order of those samples is a matter of rounding.
    loaded = sz >= 0.01 * sz.max()
    order = np.argsort(sz[loaded], kind="stable")
    k = 9
    smooth = np.convolve(bd[loaded][order], np.ones(k) / k, mode="valid")
    assert np.all(np.diff(smooth) >= 0.0)
    # Coordination number rises with density too (Fig. 10).
    n = min(len(bd), len(s["coordination_number"]))
    assert spearmanr(bd[:n], s["coordination_number"][:n]).correlation > 0.9


def test_largest_overlap_is_reported_and_nothing_passed_through_a_wall(life):
    st, pellet = _stage(life, "compact"), life.pellet
    sc, s = st.scalars, st.series
    preset = pellet.preset
    snap = pellet.snapshots["compact"]
    x, r = snap["position"], snap["radius"]
    z_floor, z_piston, R = 0.0, s["h"][-1], pellet.mould_radius
    rho = np.hypot(x[:, 0], x[:, 1])
    # The largest overlap ratio seen is reported, positive and below the guard of the preset.
    assert 0.0 < sc["max_overlap_ratio"] < preset.max_overlap_ratio
    assert sc["max_overlap_ratio"] >= s["max_overlap_ratio"].max()
    # ... and it bounds the overlaps in the final state (pairs: delta / min(ri, rj); walls:
    # delta / r).
    i, j, ov = _pair_overlaps(x, r)
    pair_ratio = (ov / np.minimum(r[i], r[j])).max()
    wall_ratio = np.concatenate([(r - (x[:, 2] - z_floor)) / r, (r - (z_piston - x[:, 2])) / r,
                                 (rho + r - R) / r]).max()
    assert max(pair_ratio, wall_ratio) <= sc["max_overlap_ratio"] * (1 + 1e-9)
    # No particle passed through the floor, the piston or the mould: every centre is inside.
    assert np.all(x[:, 2] > z_floor)
    assert np.all(x[:, 2] < z_piston)
    assert np.all(rho < R)
    # ... at every later stage too (the floor stays until the diametral test).
    for name in ("unload", "demould", "relax", "bond"):
        assert np.all(pellet.snapshots[name]["position"][:, 2] > z_floor), name


def test_compaction_inertia_number_is_reported(life):
    st = _stage(life, "compact")
    inertia = st.series["inertia_number"]
    assert inertia.shape == st.series["sigma_z"].shape
    assert np.isfinite(st.scalars["inertia_number_at_target"])
    assert 0.0 < st.scalars["inertia_number_at_target"] < 1e-1


# --- unload ----------------------------------------------------------------------------------

def test_unload_releases_the_piston(life):
    st, pellet = _stage(life, "unload"), life.pellet
    sc, s = st.scalars, st.series
    assert sc["released"] == 1.0
    assert s["sigma_z"][-1] == pytest.approx(0.0, abs=1e-4 * life.sigma_z)
    assert s["sigma_z"].max() < 1.01 * _stage(life, "compact").scalars["sigma_z_reached"]
    # The pellet springs back: the piston leaves it higher than at the end of compaction.
    assert sc["h_at_release"] > _stage(life, "compact").scalars["h_min"]
    assert np.all(np.diff(s["h"]) >= 0)  # the piston only goes up
    # h_at_release is the piston's height when it let go: the piston moves at constant speed
    # through the stage, so its sampled path interpolates to it exactly; the series go on
    # past it (the piston is lifted clear) and end where the stage ended.
    t_rel = sc["time_at_release"]
    assert s["time"][0] <= t_rel < s["time"][-1]
    assert np.interp(t_rel, s["time"], s["h"]) == pytest.approx(sc["h_at_release"], rel=1e-9)
    assert s["h"][-1] > sc["h_at_release"]
    assert s["time"][-1] == pellet.snapshots["unload"]["time"]
    # The piston is switched off, and it is above every particle.
    state = pellet.world.wall_state(pellet.walls["piston"])
    assert state["active"] is False
    x, r = pellet.snapshots["unload"]["position"], pellet.snapshots["unload"]["radius"]
    assert (x[:, 2] + r).max() < s["h"][-1]


def test_unload_takes_away_the_kinetic_energy_of_following_the_piston(life):
    # Until it lets go, the springing-back pellet follows the piston: its bottom rests on the
    # floor and its top moves at the piston speed v, so its velocity grows linearly with
    # height and it carries M v^2 / 6 (M the scaled mass). Near release the top lags the
    # piston a little (the last contacts open one by one), or runs ahead of it as it springs
    # back: measured 0.84 (tiny), 0.99 (quick), 0.89 (paper) of M v^2 / 6, and on the tiny
    # pellet (400 spheres) 0.50-1.08 over seeds 0-2 and two builds' rounding (2026-12-04).
    # calm() takes it away.
    pellet = life.pellet
    sc = _stage(life, "unload").scalars
    v = pellet.preset.unload_speed
    M = float(np.asarray(pellet.world.m).sum())
    assert 0.35 * M * v * v / 6.0 < sc["kinetic_energy_removed"] < 1.3 * M * v * v / 6.0


def test_calm_zeroes_every_velocity_and_returns_the_energy():
    w = pelletdem.World(dt=1e-6, box=((-0.01, -0.01, -0.01), (0.01, 0.01, 0.01)), gravity=(0, 0, 0))
    w.add_particles(np.array([[0.0, 0.0, 0.0], [0.005, 0.0, 0.0]]), np.full(2, 2e-4))
    v = np.array([[1.0, 0.0, 0.0], [0.0, -2.0, 0.0]])
    spin = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 0.0]])
    w.set_velocities(v, spin)
    m, r = np.asarray(w.m), np.asarray(w.r)
    expected = 0.5 * m[0] * 1.0 + 0.5 * m[1] * 4.0 + 0.5 * 0.4 * m[0] * r[0] ** 2 * 100.0
    assert stages.calm(w) == pytest.approx(expected, rel=1e-12)
    assert np.all(np.asarray(w.v) == 0.0) and np.all(np.asarray(w.w) == 0.0)
    assert w.kinetic_energy() == 0.0


# --- demould ---------------------------------------------------------------------------------

def test_demould_removes_the_mould(life):
    st, pellet = _stage(life, "demould"), life.pellet
    R, rmax = pellet.mould_radius, pellet.preset.radius_max
    step = pellet.preset.demould_rate * pellet.preset.dt  # the growth runs whole steps
    # Released on force (no load on the mould), then grown two particle diameters clear.
    assert st.scalars["released"] == 1.0
    r0 = st.scalars["release_radius"]
    assert R <= r0 < R + 4.0 * rmax
    assert r0 + 4.0 * rmax <= st.scalars["final_radius"] <= r0 + 4.0 * rmax + step * (1 + 1e-6)
    rad = st.series["radius"]
    assert np.all(np.diff(rad) >= 0)
    # The series end where the stage ended, with the mould at its final radius.
    assert st.series["time"][-1] == pellet.snapshots["demould"]["time"]
    assert rad[-1] == st.scalars["final_radius"]
    # The unloaded pellet still pressed on the mould (residual radial stress); the grown mould
    # no longer touches it.
    assert _stage(life, "unload").series["mould_radial_force"][-1] > 0.0
    assert st.series["radial_force"][-1] == 0.0
    assert pellet.world.wall_state(pellet.walls["mould"])["active"] is False


# --- relax -----------------------------------------------------------------------------------

def test_relax_reports_what_the_snapshot_shows(life):
    st, pellet = _stage(life, "relax"), life.pellet
    sc = st.scalars
    snap = pellet.snapshots["relax"]
    x, r = snap["position"], snap["radius"]
    assert sc["shed_particles"] == 0  # so the main piece is every particle
    d, h, _, _ = _extent(x, r)
    assert sc["diameter_extent"] == pytest.approx(d, rel=1e-12)
    assert sc["height_extent"] == pytest.approx(h, rel=1e-12)
    assert sc["bulk_density_extent"] == pytest.approx(pellet.mass / (math.pi * 0.25 * d * d * h), rel=1e-12)
    # The caliper's figures (pelletdem.caliper): the enclosed solid of the same particles.
    size = caliper.pellet_size(x, r, np.asarray(pellet.world.m) / pellet.preset.density_scale)
    assert sc["diameter"] == size.diameter and sc["height"] == size.height
    assert sc["bulk_density"] == pytest.approx(pellet.mass / size.volume, rel=1e-12)
    assert sc["bulk_density_core"] == size.core_density
    # One protruding particle sets the extents: the caliper reads a denser pellet.
    assert sc["bulk_density_extent"] < sc["bulk_density"]
    i, j, _ = _pair_overlaps(x, r)
    assert sc["coordination_number"] == pytest.approx(2.0 * len(i) / len(x), abs=0.05)
    z = np.bincount(i, minlength=len(x)) + np.bincount(j, minlength=len(x))
    assert sc["bulk_particles"] == size.bulk.sum() > 0
    assert sc["coordination_number_bulk"] == pytest.approx(z[size.bulk].mean(), abs=0.1)
    assert sc["coordination_number_bulk"] > sc["coordination_number"]
    # At rest: the kinetic energy is below the threshold, or what is left of it is the
    # pellet's rigid drift (a pellet that springs off the floor floats up slowly under the
    # scaled gravity); relative to its centre of mass the pellet is at rest either way.
    v, m = snap["velocity"], np.asarray(pellet.world.m)
    v_com = (m[:, None] * v).sum(0) / m.sum()
    internal = 0.5 * float((m * ((v - v_com) ** 2).sum(1)).sum())
    assert internal < pellet.preset.ke_threshold
    assert sc["converged"] == float(sc["kinetic_energy"] < pellet.preset.ke_threshold)
    # The relaxed pellet is wider than the mould and denser than the loose bed, but less
    # dense than at peak pressure (springback).
    assert d > 2.0 * pellet.mould_radius
    assert _stage(life, "fill").scalars["bulk_density"] < sc["bulk_density"] \
        < _stage(life, "compact").scalars["bulk_density_max"]


def test_relaxation_runs_its_minimum_time_before_testing(life):
    pellet = life.pellet
    min_steps = int(pellet.preset.relax_min_time / pellet.preset.dt)
    assert min_steps > 0
    assert _stage(life, "relax").steps >= min_steps


def test_relaxation_is_damped_and_the_law_is_restored_for_bonding(life):
    # Demould and relax release the pellet's stored energy; the release damping lets the
    # relaxation end on its kinetic-energy test, and the bonds and plates see the law itself.
    assert life.pellet.preset.release_damping_ratio > 0.0
    assert _stage(life, "relax").scalars["converged"] == 1.0
    assert life.pellet.world.contact_law.normal_damping_ratio == life.pellet.preset.contact.normal_damping_ratio


def test_main_piece_leaves_out_shed_particles():
    # Three touching spheres in a row and one far off: the pellet is the three.
    w = pelletdem.World(dt=1e-6, box=((-0.01, -0.01, -0.01), (0.01, 0.01, 0.01)), gravity=(0, 0, 0))
    r = 2e-4
    x = np.array([[0.0, 0.0, 0.0], [1.9 * r, 0.0, 0.0], [3.8 * r, 0.0, 0.0], [0.008, 0.0, 0.0]])
    w.add_particles(x, np.full(4, r))
    w.run(1)  # contacts are found by a force evaluation
    mask = pellet_measures.main_piece(w)
    assert mask.tolist() == [True, True, True, False]
    d, h, cx, cy = pellet_measures.pellet_extent(w, mask)
    assert cx == pytest.approx(1.9 * r, rel=1e-4) and cy == pytest.approx(0.0, abs=1e-12)
    assert d == pytest.approx(2.0 * (1.9 * r + r), rel=1e-4)
    assert h == pytest.approx(2.0 * r, rel=1e-4)
    assert pellet_measures.pellet_extent(w)[0] > 0.01  # every particle: the shed one sets the width


@pytest.mark.parametrize("value", [-0.1, 1.5, float("nan"), "0.3"])
def test_release_damping_ratio_is_checked(value):
    with pytest.raises(ParameterError, match="release_damping_ratio"):
        get_preset("tiny").with_(release_damping_ratio=value)


# --- bond ------------------------------------------------------------------------------------

def test_bonded_pellet_is_one_piece(life):
    sc = _stage(life, "bond").scalars
    n = _stage(life, "fill").scalars["n_particles"]
    assert sc["largest_cluster_fraction"] > 0.95
    assert sc["n_bonds"] > 0
    # Bonds go on the relaxed pellet's contacts (gap tolerance 0): one per touching pair.
    cn = _stage(life, "relax").scalars["coordination_number"]
    assert sc["n_bonds"] == pytest.approx(0.5 * cn * n, abs=3)
    assert sc["bonds_per_particle"] == pytest.approx(2.0 * sc["n_bonds"] / n)
    # Taking the adhesion away breaks (almost) nothing and keeps the shape.
    assert sc["broken_during_ramp"] <= 0.02 * sc["n_bonds"]
    series = _stage(life, "bond").series
    assert np.all(np.diff(series["n_bonds_intact"]) <= 0)
    # The series end where the stage ended, with the bonds left intact then.
    assert series["time"][-1] == life.pellet.snapshots["bond"]["time"]
    assert series["n_bonds_intact"][-1] == sc["n_bonds"] - sc["broken_during_ramp"]
    for key in ("diameter", "height", "diameter_extent", "height_extent"):
        assert sc[key] == pytest.approx(_stage(life, "relax").scalars[key], rel=0.02), key
    assert life.result.params["bond"]["youngs_modulus"] == life.bond_law.youngs_modulus


def test_largest_cluster_fraction():
    i, j = np.array([0, 1, 3]), np.array([1, 2, 4])
    assert pellet_measures.largest_cluster_fraction(6, i, j) == pytest.approx(0.5)
    assert pellet_measures.largest_cluster_fraction(3, np.array([], int), np.array([], int)) == pytest.approx(1 / 3)
    assert pellet_measures.largest_cluster_fraction(0, i[:0], j[:0]) == 0.0


# --- diametral -------------------------------------------------------------------------------

def test_diametral_stress_rises_to_a_peak_and_falls(life):
    st = _stage(life, "diametral")
    s, sc = st.series, st.scalars
    x, y = s["dL_D"], s["sigma_1"]
    assert np.all(np.diff(x) >= 0)
    assert x[-1] == pytest.approx(life.max_dLD, abs=0.01)
    k = int(np.argmax(y))
    assert sc["sigma_f"] == y[k]
    assert sc["dLf_D"] == x[k]
    # sigma_1 = P / (pi R h) (eq. 4) with the bonded pellet's diameter and height.
    assert np.allclose(y, s["plate_force"] / (math.pi * 0.5 * sc["diameter"] * sc["height"]))
    # It rises: from a small start, increasing on the whole up to the peak ...
    assert y[0] < 0.25 * y[k]
    assert spearmanr(x[: k + 1], y[: k + 1]).correlation > 0.9
    # ... the peak is inside the test, not at its end ...
    assert 0.02 < sc["dLf_D"] < 0.8 * life.max_dLD
    # ... and after it the pellet has failed: sigma_1 falls by more than 20 %.
    assert y[k:].min() < 0.8 * y[k]
    assert sc["sigma_f"] > 0.0


def test_diametral_test_stops_at_the_break_with_the_same_failure_point(life):
    # The same pellet and bonds with the preset's break detection on: the run is the same
    # step for step until the plate force has fallen to break_drop of its peak, then stops.
    from pelletdem.calibrate import clone_pellet

    full = _stage(life, "diametral")
    x = full.series["dL_D"]
    # the detector averages the force over BREAK_SMOOTHING_DLD of plate approach: so does this
    width = max(1, int(round(stages.BREAK_SMOOTHING_DLD / float(np.median(np.diff(x))))))
    y = np.convolve(full.series["sigma_1"], np.ones(width) / width)[:len(x)]
    k = int(np.argmax(y))
    # The threshold halfway between the deepest dip before the peak (from break_from_dLD on,
    # against the running maximum) and the level the force keeps after it (its lower
    # quartile): the tiny pellet's curve after the break wanders between ~0.7 and ~0.9 of the
    # peak from one build's rounding to the next, and a fixed 0.75 was missed by the smoothed
    # force on one of them. The break must be the deepest fall of the curve.
    on = x >= 0.02
    run_max = np.maximum.accumulate(np.where(on, y, 0.0))
    before = max([1.0 - y[i] / run_max[i] for i in range(k) if on[i] and run_max[i] > 0], default=0.0)
    after = 1.0 - np.quantile(y[k:] / y[k], 0.25)
    assert after > before + 0.05, (before, after)
    drop = 1.0 - 0.5 * (before + after)
    pellet = clone_pellet(life.relaxed)
    pellet.preset = pellet.preset.with_(break_drop=drop, break_from_dLD=0.02)
    res = pipeline.break_pellet(pellet, life.bond_law, max_dLD=life.max_dLD, progress=False)
    st = res.stages["diametral"]
    assert st.scalars["stopped_on_break"] == 1.0 and full.scalars["stopped_on_break"] == 0.0
    n = len(st.series["sigma_1"]) - 1  # the last sample is the stop's own
    assert st.series["dL_D"][-1] < full.series["dL_D"][-1] - 0.005
    assert st.steps < full.steps
    np.testing.assert_array_equal(st.series["sigma_1"][:n], full.series["sigma_1"][:n])
    assert (st.scalars["sigma_f"], st.scalars["dLf_D"]) == (full.scalars["sigma_f"], full.scalars["dLf_D"])
    # It stopped past the peak, with the averaged force below break_drop of its peak.
    assert st.series["dL_D"][-1] > full.scalars["dLf_D"]
    assert y[n - 1] <= drop * y[k] * 1.05


def test_a_shorter_test_samples_the_same_curve(life):
    # The samples' dL/D spacing does not depend on where the test stops: a test stopped
    # sooner records the same points of the same curve, so its sampled peak is no higher.
    from pelletdem.calibrate import clone_pellet

    full = _stage(life, "diametral")
    short = pipeline.break_pellet(clone_pellet(life.relaxed), life.bond_law, max_dLD=0.6 * life.max_dLD,
                                  progress=False).stages["diametral"]
    n = len(short.series["dL_D"]) - 1  # the last sample is the stop's own
    assert n > 50
    np.testing.assert_array_equal(short.series["dL_D"][:n], full.series["dL_D"][:n])
    np.testing.assert_array_equal(short.series["sigma_1"][:n], full.series["sigma_1"][:n])


def test_a_broken_pellet_runs_to_three_tenths_without_losing_particles(life):
    # Past the break the halves of a tiny pellet slide out under the plates: with a domain
    # floor only a few particle radii below the pellet they left it (ParticleEscapedError) before
    # dL/D 0.3. The floor now lies a whole pellet radius lower.
    from pelletdem.calibrate import clone_pellet

    pellet = clone_pellet(life.relaxed)
    law = BondLaw(youngs_modulus=60e6, sigma_c=9e6, tau_c=9e6)
    res = pipeline.break_pellet(pellet, law, max_dLD=0.3, progress=False)
    st = res.stages["diametral"]
    assert st.series["dL_D"][-1] >= 0.3 - 1e-3
    assert st.scalars["dLf_D"] < 0.25 and st.scalars["sigma_f"] > 0.0


def test_bonds_break_during_the_diametral_test(life):
    st, bond = _stage(life, "diametral"), _stage(life, "bond")
    s, sc = st.series, st.scalars
    nb = len(s["broken_mode"])
    assert nb == sc["bonds_broken"] > 0
    assert s["broken_position"].shape == (nb, 3)
    assert set(np.unique(s["broken_mode"])) <= {1, 2}  # tension, shear
    assert np.all(np.diff(s["n_bonds_broken"]) >= 0)
    assert s["n_bonds_broken"][-1] == nb
    # The series end where the test stopped: at max_dLD, after every breakage.
    assert s["dL_D"][-1] >= life.max_dLD - 1e-9
    assert s["time"][-1] >= s["broken_time"].max()
    assert np.all(np.diff(s["broken_time"]) >= 0)
    assert np.all((s["broken_dL_D"] >= 0) & (s["broken_dL_D"] <= life.max_dLD + 1e-3))
    assert sc["bonds_intact"] + sc["bonds_broken"] + bond.scalars["broken_during_ramp"] == bond.scalars["n_bonds"]
    # Most bonds break around the peak and after it, not early in the loading.
    assert np.median(s["broken_dL_D"]) > 0.5 * sc["dLf_D"]


def test_broken_bonds_lie_near_the_loaded_diameter(life):
    st, pellet = _stage(life, "diametral"), life.pellet
    snap = pellet.snapshots["bond"]  # the pellet as it was loaded
    frac = cracks.broken_fraction_by_region(st.series, snap["position"], snap["radius"],
                                            loaded_axis="y", band=0.3)
    assert frac["n_total"] == st.scalars["bonds_broken"]
    # A uniform spread would put 38 % in the band of width 0.3 D along the loaded diameter.
    assert frac["fraction"] > 0.5
    assert frac["concentration"] > 1.5
    # The cracks run along the loaded diameter (x = x_c, from plate to plate): the broken bonds
    # lie closer to that line than to the other diameter. (Counting them in a band along each
    # diameter cannot tell the two apart when the cracks gather at the centre, where the bands
    # cross, as they do in a 400-particle pellet.)
    other = cracks.broken_fraction_by_region(st.series, snap["position"], snap["radius"],
                                             loaded_axis="x", band=0.3)
    assert other["fraction"] <= frac["fraction"]
    pos = np.asarray(st.series["broken_position"])
    x, r = snap["position"], snap["radius"]
    _, _, cx, cy = _extent(x, r)
    assert np.abs(pos[:, 0] - cx).mean() < np.abs(pos[:, 1] - cy).mean()


# --- bad parameters: named errors before any work ----------------------------------------------

@pytest.fixture(scope="module")
def small():
    """A 30-particle pellet just after filling, for the parameter checks (cheap)."""
    pellet, _ = stages.fill(get_preset("tiny"), seed=1, threads=1, n_particles=30, progress=False)
    return pellet


def _untouched(pellet):
    w = pellet.world
    return (w.step_count, w.time, len(w.bonds()["i"]), tuple(w.gravity),
            tuple(w.wall_state(pellet.walls["floor"])["velocity"]),
            w.wall_state(pellet.walls["floor"])["active"], tuple(sorted(pellet.walls)))


NAN, INF = float("nan"), float("inf")


@pytest.mark.parametrize("call, match", [
    (lambda p: stages.compact(p, -120e6), "sigma_z"),
    (lambda p: stages.compact(p, NAN), "sigma_z"),
    (lambda p: stages.compact(p, 0.0), "sigma_z"),
    (lambda p: stages.compact(p, INF), "sigma_z"),
    (lambda p: stages.compact(p, 2e9), "sigma_z"),
    (lambda p: stages.compact(p, "120"), "sigma_z"),
    (lambda p: stages.compact(p, 1e6, speed=0.0), "speed"),
    (lambda p: stages.compact(p, 1e6, speed=-0.1), "speed"),
    (lambda p: stages.compact(p, 1e6, speed=NAN), "speed"),
    (lambda p: stages.unload(p, speed=0.0), "speed"),
    (lambda p: stages.unload(p, speed=-1.0), "speed"),
    (lambda p: stages.demould(p, rate=0.0), "rate"),
    (lambda p: stages.relax(p, ke_threshold=-1.0), "ke_threshold"),
    (lambda p: stages.relax(p, max_time=0.0), "max_time"),
    (lambda p: stages.relax(p, min_time=-1e-3), "min_time"),
    (lambda p: stages.relax(p, min_time=0.01, max_time=0.01), "min_time"),
    (lambda p: stages.relax(p, min_time=NAN), "min_time"),
    (lambda p: stages.bond(p, BondLaw(youngs_modulus=-1.0)), "E_b"),
    (lambda p: stages.bond(p, BondLaw(youngs_modulus=NAN)), "E_b"),
    (lambda p: stages.bond(p, BondLaw(sigma_c=0.0)), "sigma_c"),
    (lambda p: stages.bond(p, BondLaw(tau_c=-1.0)), "tau_c"),
    (lambda p: stages.bond(p, BondLaw(radius=0.0)), "r_b"),
    (lambda p: stages.bond(p, BondLaw(gap_tolerance=-1e-6)), "gap_tolerance"),
    (lambda p: stages.bond(p, BondLaw(), ramp_time=0.0), "ramp_time"),
    (lambda p: stages.diametral(p, speed=0.0), "speed"),
    (lambda p: stages.diametral(p, speed=-0.01), "speed"),
    (lambda p: stages.diametral(p, max_dLD=0.0), "max_dLD"),
    (lambda p: stages.diametral(p, max_dLD=-0.1), "max_dLD"),
    (lambda p: stages.diametral(p, max_dLD=0.6), "max_dLD"),
    (lambda p: stages.diametral(p, max_dLD=NAN), "max_dLD"),
])
def test_bad_stage_parameters_raise_before_any_work(small, call, match):
    before = _untouched(small)
    with pytest.raises(ParameterError, match=match):
        call(small)
    assert _untouched(small) == before


def test_parameter_error_is_a_value_error():
    assert issubclass(ParameterError, ValueError)
    assert pelletdem.ParameterError is ParameterError


@pytest.mark.parametrize("name", ["huge", "Tiny", "", None])
def test_unknown_preset(name):
    with pytest.raises(ParameterError, match="preset"):
        get_preset(name)


@pytest.mark.parametrize("kwargs, match", [
    ({"preset": "huge"}, "preset"),
    ({"sigma_z": -1.0}, "sigma_z"),
    ({"sigma_z": NAN}, "sigma_z"),
    ({"threads": 0}, "threads"),
])
def test_relaxed_pellet_checks_before_filling(monkeypatch, kwargs, match):
    def no_fill(*a, **k):
        raise AssertionError("fill ran before the parameters were checked")

    monkeypatch.setattr(stages, "fill", no_fill)
    args = {"preset": "tiny", "progress": False, **kwargs}
    with pytest.raises(ParameterError, match=match):
        pipeline.relaxed_pellet(**args)


@pytest.mark.parametrize("kwargs, match", [
    ({"preset": "huge"}, "preset"),
    ({"bond_law": BondLaw(youngs_modulus=-1.0)}, "E_b"),
    ({"bond_law": BondLaw(sigma_c=NAN)}, "sigma_c"),
    ({"sigma_z_mpa": -120, "bond_law": BondLaw()}, "sigma_z"),
    ({"threads": 0}, "threads"),
])
def test_run_pellet_checks_before_filling(monkeypatch, kwargs, match):
    def no_fill(*a, **k):
        raise AssertionError("fill ran before the parameters were checked")

    monkeypatch.setattr(stages, "fill", no_fill)
    with pytest.raises(ParameterError, match=match):
        pipeline.run_pellet(**{"preset": "tiny", "progress": False, **kwargs})


def test_fill_rejects_bad_sizes():
    p = get_preset("tiny")
    with pytest.raises(ParameterError, match="n_particles"):
        stages.fill(p, n_particles=0)
    with pytest.raises(ParameterError, match="mass"):
        stages.fill(p, mass=-1e-3)
    with pytest.raises(ParameterError, match="not both"):
        stages.fill(p, n_particles=10, mass=1e-5)
