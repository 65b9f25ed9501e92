"""Crack maps (Fig. 16) and the share of broken bonds near the loaded diameter."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

import pelletdem as pd
from pelletdem import cracks

D, H = 10e-3, 6.4e-3   # pellet diameter and height, m


def _pellet_particles(seed=0, n=600):
    rng = np.random.default_rng(seed)
    r = np.full(n, 2e-4)
    rho = 0.5 * D * np.sqrt(rng.uniform(0, 1, n)) - 2e-4
    a = rng.uniform(0, 2 * np.pi, n)
    x = np.c_[rho * np.cos(a), rho * np.sin(a), rng.uniform(2e-4, H - 2e-4, n)]
    x[0] = (0.5 * D - 2e-4, 0, 2e-4)       # pin the extent: diameter D, height H
    x[1] = (0, 0, H - 2e-4)
    return x, r


def _disk_points(rng, n, half_width=None, along="x"):
    """Uniform points in the pellet's section (and height); optionally only within a band."""
    out = []
    while len(out) < n:
        p = rng.uniform(-0.5 * D, 0.5 * D, 2)
        if np.hypot(*p) > 0.5 * D:
            continue
        if half_width is not None and abs(p[0 if along == "x" else 1]) > half_width:
            continue
        out.append((p[0], p[1], rng.uniform(0, H)))
    return np.array(out)


def test_band_area_fraction():
    assert cracks.band_area_fraction(1.0) == pytest.approx(1.0)
    assert cracks.band_area_fraction(0.0) == 0.0
    # 0.3 D band: (2/pi)(asin 0.3 + 0.3 sqrt(0.91))
    assert cracks.band_area_fraction(0.3) == pytest.approx(
        2 / math.pi * (math.asin(0.3) + 0.3 * math.sqrt(0.91)), rel=1e-12)
    # Monte Carlo check of the formula.
    rng = np.random.default_rng(1)
    p = _disk_points(rng, 20000)
    assert np.mean(np.abs(p[:, 0]) <= 0.15 * D) == pytest.approx(cracks.band_area_fraction(0.3), abs=0.01)


def test_band_fraction_on_a_synthetic_set():
    rng = np.random.default_rng(2)
    x, r = _pellet_particles()
    near = _disk_points(rng, 300, half_width=0.1 * D)            # all inside the 0.3 D band
    far = _disk_points(rng, 2000)
    far = far[np.abs(far[:, 0]) > 0.2 * D][:100]                  # all outside it
    pos = np.vstack([near, far])
    broken = {"position": pos, "mode": np.r_[np.ones(300, int), 2 * np.ones(100, int)]}
    rep = cracks.broken_fraction_by_region(broken, x, r, axis_center=(0.0, 0.0), loaded_axis="y")
    assert rep["n_total"] == 400 and rep["n_band"] == 300
    assert rep["fraction"] == pytest.approx(0.75)
    assert rep["diameter"] == pytest.approx(D, rel=1e-9)
    assert rep["band_width"] == pytest.approx(0.3 * D, rel=1e-9)
    assert rep["concentration"] == pytest.approx(0.75 / cracks.band_area_fraction(0.3))
    # Loaded along x: the band is around y = 0 instead, which these points do not favour.
    rep_x = cracks.broken_fraction_by_region(broken, axis_center=(0, 0), diameter=D, loaded_axis="x")
    expected = np.mean(np.abs(pos[:, 1]) <= 0.15 * D)
    assert rep_x["fraction"] == pytest.approx(expected)
    # The diametral stage's series names work too, and an off-centre pellet is handled.
    shifted = {"broken_position": pos + [1e-3, -2e-3, 0], "broken_mode": broken["mode"]}
    rep_s = cracks.broken_fraction_by_region(shifted, x + [1e-3, -2e-3, 0], r, axis_center=(1e-3, -2e-3))
    assert rep_s["fraction"] == pytest.approx(0.75)


def test_uniform_cracks_give_the_area_fraction():
    rng = np.random.default_rng(3)
    pos = _disk_points(rng, 4000)
    rep = cracks.broken_fraction_by_region({"position": pos}, axis_center=(0, 0), diameter=D)
    assert rep["fraction"] == pytest.approx(cracks.band_area_fraction(0.3), abs=0.025)
    assert rep["concentration"] == pytest.approx(1.0, abs=0.07)


def test_band_fraction_bad_input():
    with pytest.raises(ValueError, match="loaded_axis"):
        cracks.broken_fraction_by_region({"position": np.zeros((1, 3))}, axis_center=(0, 0), diameter=D,
                                         loaded_axis="z")
    with pytest.raises(ValueError, match="band"):
        cracks.broken_fraction_by_region({"position": np.zeros((1, 3))}, axis_center=(0, 0), diameter=D,
                                         band=0.0)
    with pytest.raises(ValueError, match="position"):
        cracks.broken_fraction_by_region({"i": [0]}, axis_center=(0, 0), diameter=D)
    with pytest.raises(ValueError, match="positions"):
        cracks.broken_fraction_by_region({"position": np.zeros((1, 3))})
    rep = cracks.broken_fraction_by_region({"position": np.zeros((0, 3))}, axis_center=(0, 0), diameter=D)
    assert rep["n_total"] == 0 and math.isnan(rep["fraction"])


def _is_png(path):
    with open(path, "rb") as f:
        return f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_plot_crack_maps_writes_png_from_a_dict(tmp_path):
    rng = np.random.default_rng(4)
    x, r = _pellet_particles()
    pos = _disk_points(rng, 200, half_width=0.1 * D)
    broken = {"position": pos, "mode": rng.integers(1, 3, len(pos))}
    out = cracks.plot_crack_maps({"broken": broken, "positions": x, "radii": r}, tmp_path / "maps" / "c.png",
                                 title="synthetic")
    assert out.exists() and _is_png(out) and out.stat().st_size > 10_000


def test_crack_map_panels_and_section_slab():
    rng = np.random.default_rng(5)
    x, r = _pellet_particles()
    pos = _disk_points(rng, 300)
    broken = {"position": pos, "mode": np.ones(len(pos), int)}
    fig, (a2, a3) = cracks.crack_map(broken, x, r, height=H, slab=0.5e-3)
    assert a2 is not None and a3 is not None and hasattr(a3, "zaxis")
    # The section shows only the bonds within the slab around mid-height.
    shown = sum(len(c.get_offsets()) for c in a2.collections if c.get_label().startswith("tension"))
    assert shown == int(np.sum(np.abs(pos[:, 2] - 0.5 * H) <= 0.5e-3))
    # One 2D axes: the section only.
    fig2, (b2, b3) = cracks.crack_map(broken, x, r, ax=fig.axes[0])
    assert b2 is fig.axes[0] and b3 is None
    with pytest.raises(ValueError, match="slab"):
        cracks.crack_map(broken, x, r, slab=0.0)


def test_plot_crack_maps_from_a_world_and_a_stage_result(tmp_path):
    # A real broken bond: a heavy pair pulled apart.
    w = pd.World(dt=2e-6, gravity=(0, 0, 0), box=((-0.01,) * 3, (0.01,) * 3), skin=5e-5,
                 density=1e8, density_scale=1e12)
    w.add_particles(np.array([[0.0, 0, 0], [4.01e-4, 0, 0]]), np.array([2e-4, 2e-4]))
    w.create_bonds(pd.BondLaw(gap_tolerance=2e-6).to_core())
    w.set_velocities(np.array([[-0.02, 0, 0], [0.02, 0, 0]]), np.zeros((2, 3)))
    w.run(2000)
    assert len(w.broken_bonds()["i"]) == 1
    p1 = cracks.plot_crack_maps(w, tmp_path / "world.png")
    assert _is_png(p1)
    # The diametral stage's result with the pellet's snapshot.
    b = w.broken_bonds()
    res = SimpleNamespace(series={"broken_position": b["position"], "broken_mode": b["mode"]},
                          scalars={"height": 4e-4})
    snap = {"position": w.positions(), "radius": w.radii()}
    p2 = cracks.plot_crack_maps((res, snap), tmp_path / "stage.png")
    assert _is_png(p2)
    with pytest.raises(TypeError):
        cracks.plot_crack_maps(42, tmp_path / "x.png")
