"""pelletdem's C++ engine: DEM with the linear hysteretic adhesive contact law and parallel bonds.

Use the Python layer (``pelletdem``: ``World``, ``ContactLaw``, ``BondLaw``) rather than this
module directly. SI units throughout (m, s, kg with the density scaling applied, N, Pa, J).

Generated with ``pybind11-stubgen pelletdem._core`` and reviewed by hand: parameter names of
positional-only arguments are ours (the bindings do not name them), numpy arrays are typed by
dtype, dicts list their keys in the docstrings. ``tests/test_stubs.py`` checks that this file
names every public attribute of the compiled module.
"""
from __future__ import annotations

from typing import Any, Callable, ClassVar, Sequence, overload

import numpy
from numpy.typing import ArrayLike, NDArray

_Vec3 = Sequence[float]
_Float64Array = NDArray[numpy.float64]
_IndexArray = NDArray[numpy.uint32]

# --- errors -------------------------------------------------------------------------------

TIME_STEP_SAFETY: float
"""The fraction of the stiffest spring's stability limit that a World accepts as dt (-)."""

class ParameterError(ValueError):
    """A bad input; the message names the parameter and its allowed range."""

class SimulationError(RuntimeError):
    """A run that went wrong (base of the three below)."""

class ParticleEscapedError(SimulationError):
    """A particle left the world's box."""

class OverlapError(SimulationError):
    """An overlap beyond ``max_overlap_ratio`` of a radius."""

class NonFiniteError(SimulationError):
    """A position, velocity or force became NaN or infinite."""

# --- parameters ---------------------------------------------------------------------------

class ParamRow:
    """One row of a law's parameter table (cpp/include/pelletdem/params.hpp); made by the
    engine only (``ContactLawParams.rows()``, ``BondParams.rows()``)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None: ...

    @property
    def name(self) -> str: ...
    @property
    def type(self) -> str:
        """'double' or 'bool'."""
    @property
    def default(self) -> float: ...
    @property
    def lo(self) -> float: ...
    @property
    def hi(self) -> float: ...
    @property
    def check(self) -> str:
        """How a value is checked: none, range, positive, nonnegative, zero_or_range, whole_range."""
    @property
    def unit(self) -> str:
        """SI unit ('-' dimensionless)."""
    @property
    def label(self) -> str:
        """The name in error messages."""
    @property
    def lanes(self) -> bool:
        """False when the four-lane pair kernel lacks it (a value off its default runs the
        scalar kernel); the contact effects' hooks run in the four lanes."""
    @property
    def doc(self) -> str: ...

class ContactLawParams:
    """The contact law of eq. 5-11 and its candidate effects: one attribute per row of
    ``rows()`` (float, or bool where the row's type is 'bool'), made from the law's table;
    ``pelletdem.laws.ContactLaw`` documents them. ``tests/test_stubs.py`` checks the
    attributes against the rows."""

    def __init__(self) -> None: ...
    def __getattr__(self, name: str) -> Any: ...
    def __setattr__(self, name: str, value: Any) -> None: ...
    def restitution(self) -> float:
        """e = sqrt(k1 / k2) (eq. 8), dimensionless."""
    def validate(self) -> None:
        """Raise ParameterError naming the first field out of its range."""
    def plain_pairs(self) -> bool:
        """True while every row the four-lane pair kernel lacks keeps its default."""
    def moisture_acts(self) -> bool:
        """True when an effect on makes compaction depend on moisture_content (%)."""
    def wood_density_acts(self) -> bool:
        """True when an effect on makes compaction depend on wood_density (kg/m^3)."""
    @staticmethod
    def rows() -> list[ParamRow]:
        """The law's parameter table."""

class BondParams:
    """The parallel bond of eq. 12-15 and the bonds' candidate effects: one float attribute
    per row of ``rows()``, made from the law's table; ``pelletdem.laws.BondLaw`` documents
    them. ``tests/test_stubs.py`` checks the attributes against the rows."""

    def __init__(self) -> None: ...
    def __getattr__(self, name: str) -> Any: ...
    def __setattr__(self, name: str, value: Any) -> None: ...
    def validate(self) -> None:
        """Raise ParameterError naming the first field out of its range."""
    @staticmethod
    def rows() -> list[ParamRow]:
        """The law's parameter table."""

class WorldParams:
    """Construction parameters of a World.

    dt: time step, s. gravity: physical gravity, m/s^2 (divided by density_scale in the
    engine). density: particle solid density, kg/m^3. density_scale: mass factor.
    skin: Verlet skin, m (0: a tenth of the largest radius). box_lo, box_hi: the domain
    corners, m (leaving it is an error). threads: OpenMP threads. max_overlap_ratio: guard on
    overlap / radius. sample_interval: steps between time-series samples. contact: the law.
    """

    dt: float
    gravity: list[float]
    density: float
    density_scale: float
    skin: float
    box_lo: list[float]
    box_hi: list[float]
    threads: int
    max_overlap_ratio: float
    sample_interval: int
    contact: ContactLawParams
    def __init__(self) -> None: ...

# --- stop conditions ----------------------------------------------------------------------

class StopKind:
    """What a StopCondition tests (its value's unit in brackets).

    Time [s], Steps [steps in this call], KineticEnergyBelow [J, scaled mass],
    InternalKineticEnergyBelow [J, about the centre of mass], WallForceAbove and
    WallForceBelow [N, compressive normal force on the wall], WallTravelAbove [m, along the
    wall's normal], LoadMarkerAbove [m, summed travel of the load walls], LoadDropBelow
    [fraction 0..1 of the load peak kept since World.track_load_peak].
    """

    Time: ClassVar[StopKind]
    Steps: ClassVar[StopKind]
    KineticEnergyBelow: ClassVar[StopKind]
    InternalKineticEnergyBelow: ClassVar[StopKind]
    WallForceAbove: ClassVar[StopKind]
    WallForceBelow: ClassVar[StopKind]
    WallTravelAbove: ClassVar[StopKind]
    LoadMarkerAbove: ClassVar[StopKind]
    LoadDropBelow: ClassVar[StopKind]
    __members__: ClassVar[dict[str, StopKind]]
    def __init__(self, value: int) -> None: ...
    @overload
    def __eq__(self, other: StopKind) -> bool: ...
    @overload
    def __eq__(self, other: object) -> bool: ...
    @overload
    def __ne__(self, other: StopKind) -> bool: ...
    @overload
    def __ne__(self, other: object) -> bool: ...
    def __hash__(self) -> int: ...
    def __index__(self) -> int: ...
    def __int__(self) -> int: ...
    def __getstate__(self) -> int: ...
    def __setstate__(self, state: int) -> None: ...
    @property
    def name(self) -> str: ...
    @property
    def value(self) -> int: ...

class StopCondition:
    """One stop condition of ``World.run_until``: ``kind`` against ``value`` (unit by kind),
    on wall index ``wall`` for the wall conditions (-1 otherwise), tested every
    ``check_interval`` steps."""

    def __init__(self, kind: StopKind, value: float, wall: int = -1, check_interval: int = 1) -> None: ...
    @property
    def kind(self) -> StopKind: ...
    @property
    def value(self) -> float: ...
    @property
    def wall(self) -> int: ...
    @property
    def check_interval(self) -> int: ...

# --- the world ----------------------------------------------------------------------------

class World:
    """Particles, analytic walls (planes, the inside of z-cylinders) and bonds, stepped in C++.

    Particle arrays (x, v, w, f, t, r, m) are read-only zero-copy views; while one is alive the
    world refuses to add particles.
    """

    def __init__(self, params: WorldParams) -> None: ...
    def clone(self) -> World:
        """Deep copy of the whole state (particles, contact history, walls, bonds)."""
    def sort_particles(self) -> _IndexArray:
        """Renumber the particles in Morton order of their neighbour cells; returns the old index
        of each new particle."""

    # state
    def get_state(self) -> dict[str, Any]:
        """The whole state as a dict of numpy arrays (see pelletdem.checkpoint)."""
    def set_state(self, state: dict[str, Any], /) -> None:
        """Restore a state from get_state() into a world built with the same parameters."""

    # set-up
    def add_particles(self, positions: ArrayLike, radii: ArrayLike) -> None:
        """Add particles at ``positions`` ((N, 3), m) with ``radii`` ((N,), m)."""
    def add_plane(self, name: str, point: _Vec3, normal: _Vec3) -> int:
        """A plane wall through ``point`` (m) facing the particles along ``normal``; returns its index."""
    def add_cylinder(self, name: str, axis_point: _Vec3, radius: float) -> int:
        """The inside of a z-aligned cylinder through ``axis_point`` (m) of ``radius`` (m); returns its index."""
    def set_positions(self, positions: ArrayLike, /) -> None:
        """Replace all positions, (N, 3) m."""
    def set_velocities(self, velocities: ArrayLike, angular_velocities: ArrayLike, /) -> None:
        """Replace all velocities (N, 3) m/s and angular velocities (N, 3) rad/s."""
    def set_contact_params(self, params: ContactLawParams, /) -> None: ...
    def set_max_overlap_ratio(self, ratio: float, /) -> None:
        """Guard on overlap / radius beyond which a run raises OverlapError."""
    def set_sample_interval(self, steps: int, /) -> None:
        """Steps between samples of the time series."""
    def set_load_walls(self, walls: Sequence[int], /) -> None:
        """Walls whose travel sums into ``load_marker`` (the diametral test's plates)."""
    def set_adhesion_ramp(self, t_start: float, duration: float) -> None:
        """Scale the adhesion stiffness kc linearly from 1 to 0 between t_start and t_start + duration, s."""

    # walls
    @property
    def wall_count(self) -> int: ...
    def wall_name(self, wall: int, /) -> str: ...
    def wall_kind(self, wall: int, /) -> str:
        """'plane' or 'cylinder'."""
    def set_wall_velocity(self, wall: int, velocity: _Vec3, /) -> None:
        """Prescribed wall velocity, m/s (switches a servo off)."""
    def set_wall_radius_rate(self, wall: int, rate: float, /) -> None:
        """Growth rate of a cylinder's radius, m/s."""
    def set_wall_servo(self, wall: int, force: float, gain: float, max_speed: float, /) -> None:
        """Drive a plane to the compressive force ``force`` (N): speed = gain (force - F_n),
        gain in m/(s N), clipped to ``max_speed`` (m/s)."""
    def set_wall_active(self, wall: int, active: bool, /) -> None: ...
    def set_wall_crushable(self, wall: int, crushable: bool, /) -> None:
        """Contacts with this wall obey the contact law's plate_yield_stress (crushing under
        the diametral test's plates)."""
    def set_wall_point(self, wall: int, point: _Vec3, /) -> None:
        """Move a wall's reference point to ``point``, m."""
    def set_wall_radius(self, wall: int, radius: float, /) -> None:
        """A cylinder's radius, m."""
    def wall_state(self, wall: int, /) -> dict[str, Any]:
        """name, kind, point (m), normal, radius (m), velocity (m/s), radius_rate (m/s),
        force (N), torque (N m), normal_force (N, compressive > 0), travel (m), active,
        max_overlap_ratio, contacts (count)."""

    # running
    def run_until(self, conditions: Sequence[StopCondition], max_steps: int,
                  progress: Callable[[int], object] | None = None,
                  between: Callable[[int], object] | None = None) -> tuple[int, int]:
        """Run until a condition holds or ``max_steps`` steps have run, in chunks of ~0.1 s
        with the GIL released; ``progress(steps_done)`` is called after every chunk,
        ``between(steps_done)`` only when the run goes on after it (a safe point for a
        checkpoint). Returns (index of the condition that fired or -1, steps run)."""
    def step(self) -> None: ...
    @property
    def time(self) -> float:
        """Simulated time, s."""
    @property
    def step_count(self) -> int: ...
    @property
    def vector_kernels(self) -> bool:
        """Four-lane pair and bond kernels (default on); off runs the scalar ones, which give
        the same bits (the tests check it)."""
    @vector_kernels.setter
    def vector_kernels(self, value: bool) -> None: ...
    @property
    def dt(self) -> float:
        """Time step, s."""
    @dt.setter
    def dt(self, value: float) -> None: ...
    @property
    def threads(self) -> int: ...
    @threads.setter
    def threads(self, value: int) -> None: ...
    @property
    def gravity(self) -> list[float]:
        """Physical gravity, m/s^2 (the engine divides it by density_scale)."""
    @gravity.setter
    def gravity(self, value: _Vec3) -> None: ...
    @property
    def density(self) -> float:
        """Particle solid density, kg/m^3."""
    @property
    def density_scale(self) -> float: ...
    @property
    def contact_params(self) -> ContactLawParams: ...
    @property
    def sample_interval(self) -> int:
        """Steps between time-series samples."""
    @property
    def max_overlap_ratio(self) -> float:
        """The overlap guard: delta / r beyond it stops a run."""
    @property
    def adhesion_scale(self) -> float:
        """Current factor on kc (1 before an adhesion ramp, 0 after it)."""

    # measurements
    @property
    def n(self) -> int:
        """Number of particles."""
    def kinetic_energy(self) -> float:
        """Translational and rotational kinetic energy, J (scaled mass)."""
    def internal_kinetic_energy(self) -> float:
        """Kinetic energy in the centre-of-mass frame, J (scaled mass)."""
    def potential_energy(self) -> float:
        """Elastic energy in contacts and bonds plus (scaled) gravity, J."""
    def mean_velocity(self) -> list[float]:
        """Mass-weighted mean velocity, m/s."""
    def remove_mean_velocity(self) -> None: ...
    def coordination_number(self) -> float:
        """Mean number of particle-particle contacts per particle, 2 contacts / N."""
    @property
    def contact_count(self) -> int: ...
    @property
    def max_overlap_ratio_seen(self) -> float:
        """Largest overlap / radius since the last reset (particles and walls)."""
    def reset_max_overlap_seen(self) -> None: ...
    @property
    def load_marker(self) -> float:
        """Summed travel of the load walls, m."""
    @property
    def load_force(self) -> float:
        """Mean compressive normal force of the load walls, N."""
    @property
    def load_peak(self) -> float:
        """Largest load_smoothed since track_load_peak's marker was reached, N."""
    @property
    def load_smoothed(self) -> float:
        """load_force averaged over track_load_peak's smoothing_steps, N."""
    def track_load_peak(self, from_marker: float, smoothing_steps: float = 1.0) -> None:
        """Average the load force over ~smoothing_steps steps and keep its peak from the load
        marker from_marker (m) on, for the load_drop_below stop (inf: stop keeping them)."""
    def critical_time_step(self) -> float:
        """Stability limit of the stiffest spring the laws can reach on the lightest particle, s."""
    def max_time_step(self) -> float:
        """The largest dt the world accepts: TIME_STEP_SAFETY of critical_time_step(), s."""
    def time_step_springs(self) -> list[dict[str, Any]]:
        """Each spring the laws can reach: what (str), k and k_eff (N/m), zeta (-), dt_limit (s)."""
    @property
    def rebuild_count(self) -> int:
        """Neighbour-list rebuilds so far."""
    @property
    def pair_list_size(self) -> int: ...
    def contacts(self) -> dict[str, NDArray[Any]]:
        """Pairs in contact now: i, j (uint32), overlap (m), fn (normal force, N)."""

    # particle views (read-only, no copy)
    @property
    def x(self) -> _Float64Array:
        """Positions, (N, 3) m."""
    @property
    def v(self) -> _Float64Array:
        """Velocities, (N, 3) m/s."""
    @property
    def w(self) -> _Float64Array:
        """Angular velocities, (N, 3) rad/s."""
    @property
    def f(self) -> _Float64Array:
        """Forces of the last step, (N, 3) N."""
    @property
    def t(self) -> _Float64Array:
        """Torques of the last step, (N, 3) N m."""
    @property
    def r(self) -> _Float64Array:
        """Radii, (N,) m."""
    @property
    def m(self) -> _Float64Array:
        """Masses (density-scaled), (N,) kg."""

    # time series
    def samples(self) -> dict[str, _Float64Array]:
        """time (s), kinetic_energy (J), coordination_number, max_overlap_ratio,
        load_marker (m), n_contacts, n_bonds_intact, n_bonds_broken."""
    def wall_samples(self, wall: int, /) -> dict[str, _Float64Array]:
        """time (s), force ((n, 3) N), normal_force (N), point ((n, 3) m), radius (m), travel (m)."""
    def clear_samples(self) -> None: ...
    def record_sample(self) -> None:
        """Record one sample now (outside the sampling interval)."""

    # bonds
    def create_bonds(self, params: BondParams, /) -> int:
        """Bond every pair whose surfaces are closer than params.gap_tolerance, stress-free
        now; returns the number of bonds created."""
    @property
    def bond_count(self) -> int:
        """Bonds created so far, intact or broken."""
    def intact_bond_count(self) -> int: ...
    def bonds(self) -> dict[str, NDArray[Any]]:
        """Every bond: i, j (uint32), mode (uint8: 0 intact, 1 broken in tension, 2 in shear),
        fn (N), ft ((n, 3) N), mn (N m), mt ((n, 3) N m), radius (m), kn, kt (N/m^3),
        sigma_c, tau_c, sigma_max, tau_max (Pa, eq. 14), damage (0 intact .. 1 gone, softening)."""
    def set_bond_property(self, name: str, values: ArrayLike, /) -> None:
        """Set one of radius (m), kn, kt (N/m^3), sigma_c, tau_c (Pa) per bond (one value per bond)."""
    def broken_bonds(self) -> dict[str, NDArray[Any]]:
        """Bonds broken so far, in order: time (s), step, i, j, position ((n, 3) m, bond
        centre), mode (1 tension, 2 shear), sigma, tau (Pa at breakage), load_marker (m)."""

# --- free functions -----------------------------------------------------------------------

def truncated_normal_radii(n: int, mean: float, sd: float, r_min: float, r_max: float, seed: int) -> list[float]:
    """Radii (m) from a normal distribution truncated to [r_min, r_max], seeded."""

def random_pack_cylinder(radii: ArrayLike, cx: float, cy: float, radius: float, z_lo: float, z_hi: float,
                         seed: int, max_attempts: int = 100000) -> tuple[_Float64Array, _Float64Array]:
    """Random non-overlapping placement in a z-aligned cylinder (axis at cx, cy; radius, z_lo,
    z_hi in m); returns (positions (N, 3) m, radii (N,) m) sorted along z."""

def brute_force_pairs(positions: ArrayLike, radii: ArrayLike, skin: float, /) -> tuple[_IndexArray, _IndexArray]:
    """Reference O(N^2) pair search (for tests): pairs closer than r_i + r_j + skin (m)."""

def neighbor_pairs(world: World, /) -> tuple[_IndexArray, _IndexArray]:
    """The world's current neighbour pairs (i < j) as two arrays."""
