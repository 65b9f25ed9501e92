"""The engine's Python entry points: the laws (pelletdem.laws), the world (pelletdem.world),
the engine's errors, and the helpers that make particles and stiffnesses.

Errors: every bad input raises ParameterError (a ValueError) naming the parameter and its
allowed range before any work; a run that goes wrong raises a SimulationError subclass
(OverlapError, ParticleEscapedError, NonFiniteError) naming the particle, step and likely cause.
"""
from __future__ import annotations

import math

import numpy as np

from . import _core
from ._core import (  # noqa: F401  (re-exported)
    NonFiniteError,
    OverlapError,
    ParameterError,
    ParticleEscapedError,
    SimulationError,
)
from .checks import finite, integer
from .laws import BondLaw, ContactLaw  # noqa: F401  (re-exported)
from .world import RunOutcome, World  # noqa: F401  (re-exported)

__all__ = [
    "ContactLaw", "BondLaw", "World", "RunOutcome", "ParameterError", "SimulationError",
    "OverlapError", "ParticleEscapedError", "NonFiniteError", "truncated_normal_radii",
    "random_pack_cylinder", "k1_from_yield_strength", "rayleigh_time_step",
]


def truncated_normal_radii(n: int, mean: float = 2e-4, sd: float = 2e-5, r_min: float = 1.4e-4,
                           r_max: float = 2.6e-4, seed: int = 0) -> np.ndarray:
    """Radii (m) from a normal distribution truncated to [r_min, r_max] (the paper's 0.2 mm
    mean, 0.02 mm SD, 0.14-0.26 mm range by default), reproducible for a seed."""
    return np.asarray(_core.truncated_normal_radii(integer("n", n, 0, 10**7), mean, sd, r_min, r_max,
                                                   integer("seed", seed, 0, 2**63 - 1)))


def random_pack_cylinder(radii, radius: float, z_lo: float, z_hi: float, seed: int = 0,
                         center=(0.0, 0.0), max_attempts: int = 100000):
    """Random non-overlapping spheres in a z-aligned cylinder of `radius` (m) between z_lo and
    z_hi (m). Returns (positions (N, 3) m, radii (N,) m), sorted along z."""
    return _core.random_pack_cylinder(np.asarray(radii, dtype=float), center[0], center[1],
                                      radius, z_lo, z_hi, integer("seed", seed, 0, 2**63 - 1),
                                      integer("max_attempts", max_attempts, 1, 10**9))


def k1_from_yield_strength(p_y: float, r: float = 2e-4) -> float:
    """Loading stiffness k1 = 5 r p_y (N/m) from the yield strength p_y (Pa), eq. 7.

    Convention: r is the particle radius, which reproduces Table 4 (p_y = 100 MPa,
    r = 0.2 mm -> 1e5 N/m). Eq. 7 literally uses r* = r_i r_j/(r_i + r_j), half of that for
    equal spheres (5e4 N/m); see docs/inconsistencies.md.
    """
    return 5.0 * finite("r", r) * finite("p_y", p_y)


def rayleigh_time_step(r: float, density: float, youngs_modulus: float, poisson: float) -> float:
    """Rayleigh time step pi r sqrt(rho/G) / (0.1631 nu + 0.8766), s (G = E / (2 (1 + nu)))."""
    g = youngs_modulus / (2.0 * (1.0 + poisson))
    return math.pi * r * math.sqrt(density / g) / (0.1631 * poisson + 0.8766)
