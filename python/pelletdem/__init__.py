"""pelletdem: DEM with a bonded particle model for wood-sawdust pellets.

The C++ engine (``pelletdem._core``) steps; this package arranges stages, scans, fits and
plots. docs/model.md describes the model, docs/parameters.md its parameters and their sources.
"""
import os as _os

# Threads that spin while they wait starve each other when the machine is shared (a 2-core
# box running anything else: a 2-thread step ran ~50x slower); threads that sleep at once pay a
# wake-up per parallel region (-25 % on a 10,000-particle bed). A short spin, then sleep,
# keeps both: measured 13.5 M particle-steps/s on 2 threads vs 9.2 passive, 11.8 spinning.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
_os.environ.setdefault("GOMP_SPINCOUNT", "20000")

from ._version import __version__  # noqa: E402,F401
from .engine import (  # noqa: F401,E402
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
