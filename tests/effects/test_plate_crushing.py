"""plate_crushing (cpp effects/plate_crushing.hpp): a crushable plate's contact force stays at
p pi r^2 until the particle is crushed to half its radius, then stiffens again with the
loading stiffness; plain walls are untouched."""
from __future__ import annotations

import math

import numpy as np
import pytest

import pelletdem as pd
from test_contact_law import R, frictionless


def _squeeze(crushable, p_y, travel=0.1 * R, speed=0.02, floor_crushable=True):
    law = frictionless()
    law.plate_yield_stress = p_y
    w = pd.World(dt=1e-7, box=((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 2e-3)), contact=law,
                 gravity=(0, 0, 0), skin=2e-5)
    w.add_particles(np.array([[0.0, 0.0, R]]), np.array([R]))
    floor = w.add_plane("floor", [0, 0, 0], [0, 0, 1])
    top = w.add_plane("top", [0, 0, 2 * R], [0, 0, -1])
    if crushable:
        w.set_wall_crushable(top, True)
        w.set_wall_crushable(floor, floor_crushable)
    w.set_wall_velocity(top, [0, 0, -speed])
    forces = []
    for _ in range(int(travel / speed / w.dt)):
        w.step()
        forces.append(w.wall_state(top)["normal_force"])
    return np.array(forces)


def test_plate_yield_caps_the_force_on_crushable_walls_only():
    p_y = 5e6
    cap = p_y * math.pi * R * R  # 0.63 N; the linear law reaches ~2 N at the end
    f_hard = _squeeze(False, p_y)
    f_crush = _squeeze(True, p_y)
    assert f_hard.max() > 2.0 * cap  # the plain walls go on stiffening
    assert f_crush.max() <= cap * (1 + 1e-9)
    assert f_crush[-100:].min() > 0.99 * cap  # flattening at constant force at the end


def test_a_crushed_particle_stiffens_again_past_half_its_radius():
    # a crushable plate above, a plain floor below: the plate takes the travel at the capped
    # force until its overlap reaches 0.5 R, then the particle stiffens again
    p_y = 5e6
    cap = p_y * math.pi * R * R
    law = frictionless()
    k1w = law.k1 * law.wall_stiffness_factor * (R / law.r_ref if law.scale_with_radius else 1.0)
    speed = 0.02
    f = _squeeze(True, p_y, travel=1.0 * R, speed=speed, floor_crushable=False)
    travel = speed * 1e-7 * np.arange(1, len(f) + 1)
    # the floor holds the particle at overlap cap / k1w; the plate's overlap is the rest
    plate = travel - cap / k1w
    flat = (plate > 0.1 * R) & (plate < 0.45 * R)
    assert np.allclose(f[flat], cap, rtol=1e-3)
    late = plate > 0.6 * R
    assert f[late].min() > cap * 1.05
    # past the crushed depth both contacts load with k1w, in series: slope k1w / 2 per travel
    slope = np.polyfit(travel[late], f[late], 1)[0]
    assert slope == pytest.approx(k1w / 2, rel=0.05)
