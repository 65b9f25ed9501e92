"""plate_crushing (cpp effects/plate_crushing.hpp): a crushable plate's contact force never
exceeds p pi r^2, and plain walls are untouched."""
from __future__ import annotations

import math

import numpy as np

import pelletdem as pd
from test_contact_law import R, frictionless


def _squeeze(crushable, p_y, travel=0.1 * R, speed=0.02):
    law = frictionless()
    law.plate_yield_stress = p_y
    w = pd.World(dt=1e-7, box=((-1e-3, -1e-3, -1e-3), (1e-3, 1e-3, 2e-3)), contact=law,
                 gravity=(0, 0, 0), skin=2e-5)
    w.add_particles(np.array([[0.0, 0.0, R]]), np.array([R]))
    floor = w.add_plane("floor", [0, 0, 0], [0, 0, 1])
    top = w.add_plane("top", [0, 0, 2 * R], [0, 0, -1])
    if crushable:
        w.set_wall_crushable(top, True)
        w.set_wall_crushable(floor, True)
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
