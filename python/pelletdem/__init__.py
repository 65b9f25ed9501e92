"""pelletdem: DEM with a bonded particle model for wood-sawdust pellets.

The C++ engine (``pelletdem._core``) steps; this package arranges stages, scans, fits and
plots. See the README for the model, its parameters and their sources.
"""
from importlib.metadata import PackageNotFoundError, version as _version

from .engine import (  # noqa: F401
    BondLaw,
    ContactLaw,
    NonFiniteError,
    OverlapError,
    ParameterError,
    ParticleEscapedError,
    RunOutcome,
    SimulationError,
    World,
    k1_from_yield_strength,
    random_pack_cylinder,
    rayleigh_time_step,
    truncated_normal_radii,
)

try:
    __version__ = _version("pelletdem")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0+source"
