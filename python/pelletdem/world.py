"""The simulated world as Python sees it: the C++ world's particles, walls, bonds, settings and
measures, each a method or property here with its units, plus keyword construction, stop
conditions by name, progress, cloning and saved states.

Everything here runs outside the time-step loop: one ``run_until`` call runs thousands of
steps in C++ and returns when a condition evaluated there fires.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Callable, Optional, Sequence

import numpy as np

from . import _core
from ._core import ParameterError, StopKind
from .checks import finite, integer, vec3
from .laws import BondLaw, ContactLaw

__all__ = ["World", "RunOutcome", "contact_dict"]


def contact_dict(params) -> dict:
    """The fields of a C++ contact-law struct as a dict of ContactLaw's fields."""
    return {f.name: getattr(params, f.name) for f in fields(ContactLaw)}


@dataclass
class RunOutcome:
    """Why a run stopped: `reason` is the name of the condition that fired, or 'max_steps';
    `steps` the steps run in this call; `time` the world's clock when it stopped, s."""

    reason: str
    steps: int
    time: float


_CONDITIONS = {
    "time": StopKind.Time,
    "steps": StopKind.Steps,
    "kinetic_energy_below": StopKind.KineticEnergyBelow,
    "internal_kinetic_energy_below": StopKind.InternalKineticEnergyBelow,
    "wall_force_above": StopKind.WallForceAbove,
    "wall_force_below": StopKind.WallForceBelow,
    "wall_travel_above": StopKind.WallTravelAbove,
    "load_marker_above": StopKind.LoadMarkerAbove,
    "load_drop_below": StopKind.LoadDropBelow,
}


class World:
    """A DEM world: particles, analytic walls, bonds; stepped in C++.

    Parameters (SI): dt (s); box ((xlo, ylo, zlo), (xhi, yhi, zhi)) in m, leaving it is an
    error; contact: ContactLaw; density (kg/m^3, 680 in Table 4); density_scale (mass factor,
    gravity divided by it, 1e4 in the paper); gravity (physical, m/s^2); skin (Verlet skin, m;
    0 = 0.1 of the largest radius); threads (OpenMP); max_overlap_ratio (guard on delta/r);
    sample_interval (steps between time-series samples).
    """

    #: The fraction of the stiffest spring's stability limit that dt may reach (-).
    TIME_STEP_SAFETY: float = _core.TIME_STEP_SAFETY

    def __init__(self, *, dt: float = 2e-6, box=((-0.01, -0.01, -0.01), (0.01, 0.01, 0.05)),
                 contact: Optional[ContactLaw] = None, density: float = 680.0,
                 density_scale: float = 1e4, gravity=(0.0, 0.0, -9.81), skin: float = 0.0,
                 threads: int = 1, max_overlap_ratio: float = 0.9, sample_interval: int = 100):
        contact = ContactLaw() if contact is None else contact
        if not isinstance(contact, ContactLaw):
            raise ParameterError(f"contact must be a ContactLaw, got {type(contact).__name__}")
        try:
            lo, hi = (vec3("box", corner) for corner in box)
        except (TypeError, ValueError):
            raise ParameterError(f"box must be ((xlo, ylo, zlo), (xhi, yhi, zhi)) in m, got {box!r}") from None
        gravity = vec3("gravity", gravity)
        # Kept so that a saved state can rebuild an identical world (see get_state/from_state).
        object.__setattr__(self, "_init_kwargs", dict(
            dt=dt, box=(lo, hi), contact=asdict(contact),
            density=density, density_scale=density_scale, gravity=gravity, skin=skin,
            threads=threads, max_overlap_ratio=max_overlap_ratio, sample_interval=sample_interval))
        p = _core.WorldParams()
        p.dt = finite("dt", dt)
        p.box_lo = list(lo)
        p.box_hi = list(hi)
        p.contact = contact.to_core()
        p.density = finite("density", density)
        p.density_scale = finite("density_scale", density_scale)
        p.gravity = [finite("gravity", g) for g in gravity]
        p.skin = finite("skin", skin)
        p.threads = integer("threads", threads, 1, 1024)
        p.max_overlap_ratio = finite("max_overlap_ratio", max_overlap_ratio)
        p.sample_interval = integer("sample_interval", sample_interval, 1, 10**12)
        object.__setattr__(self, "_core", _core.World(p))
        # Samples restored from a saved state, ahead of the engine's own (see samples()).
        object.__setattr__(self, "_sample_prefix", None)
        self.box = (tuple(lo), tuple(hi))

    def run(self, steps: int, progress: Optional[Callable[[int], None]] = None) -> RunOutcome:
        """Run exactly `steps` time steps in C++ (GIL released; Ctrl-C stops within ~0.1 s)."""
        return self.run_until(steps=integer("steps", steps, 0, 10**13), max_steps=int(steps),
                              progress=progress)

    def run_until(self, max_steps: int, progress: Optional[Callable[[int], None]] = None,
                  check_interval: int = 1, between: Optional[Callable[[int], None]] = None,
                  **conditions) -> RunOutcome:
        """Run until the first condition holds or `max_steps` steps have run.

        Conditions (keyword=value): time (s), steps, kinetic_energy_below (J, scaled mass),
        internal_kinetic_energy_below (J, about the centre of mass),
        wall_force_above=(wall, N), wall_force_below=(wall, N) (compressive normal force),
        wall_travel_above=(wall, m), load_marker_above (m), load_drop_below (fraction in (0, 1):
        the load walls' mean force has fallen to it times the peak kept since
        track_load_peak; a test machine's break detection). kinetic_energy_below is tested
        every `check_interval` steps (it costs one pass over the particles).

        The run goes in chunks of about 0.1 s of wall time with the GIL released; between
        chunks Ctrl-C is served and `progress(steps_done)` called. `between(steps_done)` is
        called only when the run continues after a chunk: the world is then between two steps
        and no condition has fired, the safe point for a checkpoint (see pelletdem.checkpoint).
        """
        max_steps = integer("max_steps", max_steps, 0, 10**13)
        conds, names = [], []
        for name, value in conditions.items():
            if name not in _CONDITIONS:
                raise ParameterError(f"unknown stop condition '{name}': allowed {sorted(_CONDITIONS)}")
            wall = -1
            if name.startswith("wall_"):
                if not (isinstance(value, (tuple, list)) and len(value) == 2):
                    raise ParameterError(f"{name} must be (wall index, value)")
                wall, value = integer(f"{name} wall index", value[0], 0, 2**31 - 1), value[1]
            interval = check_interval if name.endswith("kinetic_energy_below") else 1
            conds.append(_core.StopCondition(_CONDITIONS[name], finite(name, value), wall,
                                             integer("check_interval", interval, 1, 10**9)))
            names.append(name)
        index, steps = self._core.run_until(conds, max_steps, progress, between)
        reason = names[index] if index >= 0 else "max_steps"
        return RunOutcome(reason, int(steps), self.time)

    def positions(self) -> np.ndarray:
        """Copy of particle positions, (N, 3) m."""
        return np.array(self.x)

    def velocities(self) -> np.ndarray:
        """Copy of particle velocities, (N, 3) m/s."""
        return np.array(self.v)

    def radii(self) -> np.ndarray:
        """Copy of particle radii, (N,) m."""
        return np.array(self.r)

    def masses(self) -> np.ndarray:
        """Copy of particle masses (density-scaled), (N,) kg."""
        return np.array(self.m)

    def clone(self) -> "World":
        """Deep copy of the whole state (particles, walls, contact history, bonds)."""
        new = World.__new__(World)
        object.__setattr__(new, "_core", self._core.clone())
        object.__setattr__(new, "_init_kwargs", dict(self._init_kwargs))
        object.__setattr__(new, "_sample_prefix", self._sample_prefix)  # never mutated in place
        new.box = self.box
        return new

    def sort_particles(self) -> np.ndarray:
        """Renumber the particles so that neighbours in space are neighbours in memory (Morton
        order of the neighbour cells); the pair loop then runs from cache: on a settled bed of
        40,000, ~15 % faster on one thread and ~2x on two. Velocities, forces, contact and wall
        histories move with the particles and the time series are kept. Allowed only before
        bonds are created and while no numpy view of the particle arrays
        (``np.asarray(world.x)``) is alive. Returns ``order`` (N,): new particle k was particle
        ``order[k]``."""
        return self._core.sort_particles()

    # --- time series: the engine's samples, after any restored from a saved state -------------
    def samples(self) -> dict:
        """The global time series since the last clear_samples(), as arrays: time (s),
        kinetic_energy (J), coordination_number, max_overlap_ratio, load_marker (m), n_contacts,
        n_bonds_intact, n_bonds_broken. Includes the samples of a restored state."""
        now = self._core.samples()
        pre = self._sample_prefix
        if pre is None:
            return now
        return {k: np.concatenate([pre["samples"][k], v]) for k, v in now.items()}

    def wall_samples(self, wall: int) -> dict:
        """Wall `wall`'s time series since the last clear_samples(): time (s), force (N, 3),
        normal_force (N), point (m, 3), radius (m), travel (m)."""
        now = self._core.wall_samples(wall)
        pre = self._sample_prefix
        if pre is None or wall >= len(pre["wall_samples"]):
            return now
        old = pre["wall_samples"][wall]
        return {k: np.concatenate([np.asarray(old[k]).reshape((-1,) + v.shape[1:]), v]) for k, v in now.items()}

    def clear_samples(self) -> None:
        """Forget every time series recorded so far (global and per wall)."""
        object.__setattr__(self, "_sample_prefix", None)
        self._core.clear_samples()

    def _restore_samples(self, samples: Optional[dict], wall_samples) -> None:
        # The engine keeps no way to load samples; they are served ahead of its own instead.
        self._core.clear_samples()
        if samples is None:
            object.__setattr__(self, "_sample_prefix", None)
            return
        want = set(self._core.samples())
        if set(samples) != want:
            raise ParameterError(f"state['samples'] must have the keys {sorted(want)}, got {sorted(samples)}")
        ws = [{k: np.asarray(v) for k, v in d.items()} for d in (wall_samples or [])]
        if len(ws) > self._core.wall_count:
            raise ParameterError(f"state['wall_samples'] has {len(ws)} entries for {self._core.wall_count} walls")
        for k, d in enumerate(ws):
            wanted = set(self._core.wall_samples(k))
            if set(d) != wanted:
                raise ParameterError(f"state['wall_samples'][{k}] must have the keys {sorted(wanted)}")
        object.__setattr__(self, "_sample_prefix", {
            "samples": {k: np.asarray(v) for k, v in samples.items()}, "wall_samples": ws})

    def create_bonds(self, law) -> int:
        """Bond every touching pair (and pairs within law.gap_tolerance), stress-free now.
        `law` is a BondLaw (or the engine's BondParams). Returns the number of bonds."""
        core = law.to_core() if isinstance(law, BondLaw) else law
        return self._core.create_bonds(core)

    @property
    def contact_law(self) -> ContactLaw:
        """The contact law in force now (a copy; change it with :meth:`set_contact_law`)."""
        return ContactLaw(**contact_dict(self._core.contact_params))

    def set_contact_law(self, law: ContactLaw) -> None:
        """Replace the contact law from the next step on (validated first; contact histories
        are kept). Saved states record the law in force."""
        if not isinstance(law, ContactLaw):
            raise ParameterError(f"law must be a ContactLaw, got {type(law).__name__}")
        self._core.set_contact_params(law.to_core())

    def get_state(self) -> dict:
        """The whole state (particles with their last forces, every contact's history, walls
        with their last forces, bonds, broken bonds, the clock, the time series recorded since
        the last clear_samples()) plus the construction parameters and the current sample
        interval and overlap guard, as a dict of numpy arrays and plain values.
        `World.from_state` rebuilds a world that continues bit for bit (at the same thread
        count) and returns the same samples() and wall_samples()."""
        state = self._core.get_state()
        kw = dict(self._init_kwargs)
        kw["threads"] = self._core.threads
        kw["dt"] = self._core.dt
        kw["gravity"] = tuple(self._core.gravity)
        kw["contact"] = contact_dict(self._core.contact_params)
        kw["sample_interval"] = self._core.sample_interval
        kw["max_overlap_ratio"] = self._core.max_overlap_ratio
        state["params"] = kw
        # The time series so far, so that a stage resumed from a checkpoint returns all of it.
        state["samples"] = self.samples()
        state["wall_samples"] = [self.wall_samples(k) for k in range(self._core.wall_count)]
        return state

    @classmethod
    def from_state(cls, state: dict, threads: Optional[int] = None) -> "World":
        """A world rebuilt from `get_state()`; `threads` overrides the saved thread count."""
        if not isinstance(state, dict) or not isinstance(state.get("params"), dict):
            raise ParameterError("state must be a dict from World.get_state() (missing 'params')")
        kw = dict(state["params"])
        try:
            kw["contact"] = ContactLaw(**kw["contact"])
            if threads is not None:
                kw["threads"] = threads
            w = cls(**kw)
        except (KeyError, TypeError) as e:
            raise ParameterError(f"state['params'] is not from World.get_state(): {type(e).__name__}: {e}") from None
        w._core.set_state(state)
        samples = state.get("samples")
        if samples is not None:
            if not isinstance(samples, dict) or not isinstance(state.get("wall_samples", []), (list, tuple)):
                raise ParameterError("state['samples'] must be a dict and state['wall_samples'] a list of dicts")
            w._restore_samples(samples, state.get("wall_samples"))
        return w

    def restore_state(self, state: dict) -> None:
        """Make this world, in place, the one saved in `state` (from get_state(), with its
        construction parameters and thread count). The engine object underneath is replaced,
        so numpy views (x, v, ...) taken before the call keep showing the old one."""
        fresh = World.from_state(state)
        for name in ("_core", "_init_kwargs", "_sample_prefix", "box"):
            object.__setattr__(self, name, getattr(fresh, name))

    # --- particles -------------------------------------------------------------------------
    def add_particles(self, positions, radii) -> None:
        """Add spheres at `positions` (N, 3), m, with `radii` (N,), m; masses from the world's
        density (times density_scale). Refused while a numpy view of the arrays is alive."""
        self._core.add_particles(positions, radii)

    @property
    def n(self) -> int:
        """Number of particles."""
        return self._core.n

    @property
    def x(self) -> np.ndarray:
        """Positions (N, 3), m: a read-only view without a copy (see add_particles)."""
        return self._core.x

    @property
    def v(self) -> np.ndarray:
        """Velocities (N, 3), m/s: a read-only view."""
        return self._core.v

    @property
    def w(self) -> np.ndarray:
        """Angular velocities (N, 3), rad/s: a read-only view."""
        return self._core.w

    @property
    def f(self) -> np.ndarray:
        """Forces of the last step (N, 3), N: a read-only view."""
        return self._core.f

    @property
    def t(self) -> np.ndarray:
        """Torques of the last step (N, 3), N m: a read-only view."""
        return self._core.t

    @property
    def r(self) -> np.ndarray:
        """Radii (N,), m: a read-only view."""
        return self._core.r

    @property
    def m(self) -> np.ndarray:
        """Masses (N,), kg (density-scaled): a read-only view."""
        return self._core.m

    def set_velocities(self, velocities, angular_velocities) -> None:
        """Set every particle's velocity (N, 3), m/s, and angular velocity (N, 3), rad/s."""
        self._core.set_velocities(velocities, angular_velocities)

    def set_positions(self, positions) -> None:
        """Set every particle's position (N, 3), m; the contact list is rebuilt."""
        self._core.set_positions(positions)

    # --- walls -----------------------------------------------------------------------------
    def add_plane(self, name: str, point, normal) -> int:
        """An infinite plane wall through `point` (m) with unit `normal` pointing to the
        particles' side. Returns its index."""
        return self._core.add_plane(name, point, normal)

    def add_cylinder(self, name: str, axis_point, radius: float) -> int:
        """The inside of a cylinder along z through `axis_point` (m), of `radius` (m).
        Returns its index."""
        return self._core.add_cylinder(name, axis_point, radius)

    @property
    def wall_count(self) -> int:
        """Number of walls."""
        return self._core.wall_count

    def wall_name(self, wall: int) -> str:
        """The name wall `wall` was given."""
        return self._core.wall_name(wall)

    def wall_kind(self, wall: int) -> str:
        """'plane' or 'cylinder'."""
        return self._core.wall_kind(wall)

    def wall_state(self, wall: int) -> dict:
        """Wall `wall` now: name, kind, point (m), normal, radius (m), velocity (m/s),
        radius_rate (m/s), force (N) and torque (N m) of the last step, normal_force (N,
        compressive > 0), travel (m), active, max_overlap_ratio, contacts."""
        return self._core.wall_state(wall)

    def set_wall_velocity(self, wall: int, velocity) -> None:
        """Translate wall `wall` at `velocity` (m/s, 3 components); ends a servo."""
        self._core.set_wall_velocity(wall, velocity)

    def set_wall_radius_rate(self, wall: int, rate: float) -> None:
        """Grow cylinder `wall`'s radius at `rate`, m/s."""
        self._core.set_wall_radius_rate(wall, rate)

    def set_wall_servo(self, wall: int, force: float, gain: float, max_speed: float) -> None:
        """Drive plane `wall` along its normal towards the compressive `force` (N): speed
        gain (force - F_n), gain in m/(s N), clipped to max_speed (m/s)."""
        self._core.set_wall_servo(wall, force, gain, max_speed)

    def set_wall_active(self, wall: int, active: bool) -> None:
        """Switch wall `wall` on or off (an inactive wall touches nothing)."""
        self._core.set_wall_active(wall, active)

    def set_wall_crushable(self, wall: int, crushable: bool) -> None:
        """Mark wall `wall` as a diametral plate: the contact law's effects that act under the
        plates (effects/plate_crushing.hpp) apply to its contacts."""
        self._core.set_wall_crushable(wall, crushable)

    def set_wall_point(self, wall: int, point) -> None:
        """Move wall `wall`'s reference point to `point` (m)."""
        self._core.set_wall_point(wall, point)

    def set_wall_radius(self, wall: int, radius: float) -> None:
        """Set cylinder `wall`'s radius, m."""
        self._core.set_wall_radius(wall, radius)

    def set_load_walls(self, walls: Sequence[int]) -> None:
        """The walls whose travel makes the load marker and whose force the load force."""
        self._core.set_load_walls(list(walls))

    @property
    def load_marker(self) -> float:
        """Sum of the load walls' travel along their normals, m."""
        return self._core.load_marker

    @property
    def load_force(self) -> float:
        """Mean compressive normal force of the load walls, N."""
        return self._core.load_force

    @property
    def load_peak(self) -> float:
        """Largest load_smoothed since track_load_peak's marker was reached, N."""
        return self._core.load_peak

    @property
    def load_smoothed(self) -> float:
        """load_force averaged over track_load_peak's smoothing_steps, N."""
        return self._core.load_smoothed

    def track_load_peak(self, from_marker: float, smoothing_steps: float = 1.0) -> None:
        """Average the load force over ~smoothing_steps steps and keep its peak from the load
        marker `from_marker` (m) on, for the load_drop_below stop (inf: stop keeping them)."""
        self._core.track_load_peak(from_marker, smoothing_steps)

    # --- the world's settings ----------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Time step, s (settable; refused above the stability limit)."""
        return self._core.dt

    @property
    def threads(self) -> int:
        """OpenMP threads (settable)."""
        return self._core.threads

    @property
    def gravity(self) -> tuple:
        """Physical gravity, m/s^2 (settable; the engine divides it by density_scale)."""
        return tuple(self._core.gravity)

    @property
    def density(self) -> float:
        """Particle density, kg/m^3."""
        return self._core.density

    @property
    def density_scale(self) -> float:
        """Mass scaling factor (gravity is divided by it)."""
        return self._core.density_scale

    @property
    def sample_interval(self) -> int:
        """Steps between time-series samples."""
        return self._core.sample_interval

    def set_sample_interval(self, steps: int) -> None:
        """Record a time-series sample every `steps` steps."""
        self._core.set_sample_interval(steps)

    @property
    def max_overlap_ratio(self) -> float:
        """The overlap guard: delta / r beyond it stops a run with OverlapError."""
        return self._core.max_overlap_ratio

    def set_max_overlap_ratio(self, ratio: float) -> None:
        """Set the overlap guard (delta / r)."""
        self._core.set_max_overlap_ratio(ratio)

    @property
    def contact_params(self):
        """The C++ contact-law struct in force (see contact_law for the dataclass)."""
        return self._core.contact_params

    def set_contact_params(self, params) -> None:
        """Replace the contact law from the C++ struct (see set_contact_law)."""
        self._core.set_contact_params(params)

    def set_adhesion_ramp(self, t_start: float, duration: float) -> None:
        """Scale the adhesion stiffness kc from 1 to 0 between t_start and t_start + duration, s."""
        self._core.set_adhesion_ramp(t_start, duration)

    @property
    def adhesion_scale(self) -> float:
        """The factor on kc now (1 before the ramp, 0 after it)."""
        return self._core.adhesion_scale

    @property
    def vector_kernels(self) -> bool:
        """Four-lane pair and bond kernels (default on); off runs the scalar ones, which give
        the same bits (the tests check it). Settable."""
        return self._core.vector_kernels

    def critical_time_step(self) -> float:
        """The stability limit of the stiffest spring the laws can reach, on the lightest
        particle, s: velocity Verlet's 2 / omega (sqrt(1 + zeta^2) - zeta). The world accepts
        dt up to :meth:`max_time_step`."""
        return self._core.critical_time_step()

    def max_time_step(self) -> float:
        """The largest dt the world accepts, s: ``TIME_STEP_SAFETY`` (0.5) of
        :meth:`critical_time_step`, as a particle pressed by many contacts at once has modes
        above a single contact's (docs/model.md, "The time step")."""
        return self._core.max_time_step()

    def time_step_springs(self) -> list:
        """Every spring the contact law, its effects and the bonds can reach over the range
        they allow, as dicts: ``what`` (where it acts and the parameters that set it), ``k``
        (its stiffness, N/m), ``k_eff`` (what it puts on the lightest particle: x2 between two
        particles, x3.5 tangential, N/m), ``zeta`` (its damping, fraction of critical) and
        ``dt_limit`` (the stability limit it sets, s). The guard's is the smallest."""
        return self._core.time_step_springs()

    # --- running ---------------------------------------------------------------------------
    def step(self) -> None:
        """One time step."""
        self._core.step()

    @property
    def time(self) -> float:
        """The world's clock, s."""
        return self._core.time

    @property
    def step_count(self) -> int:
        """Steps taken since the world was made."""
        return self._core.step_count

    # --- measures --------------------------------------------------------------------------
    def kinetic_energy(self) -> float:
        """Translational and rotational kinetic energy, J (scaled mass)."""
        return self._core.kinetic_energy()

    def internal_kinetic_energy(self) -> float:
        """Kinetic energy in the centre-of-mass frame, J (scaled mass)."""
        return self._core.internal_kinetic_energy()

    def potential_energy(self) -> float:
        """Elastic energy of contacts and bonds plus (scaled) gravity's, J."""
        return self._core.potential_energy()

    def mean_velocity(self) -> np.ndarray:
        """Mass-weighted mean velocity, m/s (3,)."""
        return np.asarray(self._core.mean_velocity())

    def remove_mean_velocity(self) -> None:
        """Take the mean velocity out of every particle's."""
        self._core.remove_mean_velocity()

    def coordination_number(self) -> float:
        """Contacts per particle, 2 N_contacts / N (every particle)."""
        return self._core.coordination_number()

    @property
    def contact_count(self) -> int:
        """Particle pairs in contact at the last step."""
        return self._core.contact_count

    @property
    def max_overlap_ratio_seen(self) -> float:
        """Largest delta / r since the last reset_max_overlap_seen()."""
        return self._core.max_overlap_ratio_seen

    def reset_max_overlap_seen(self) -> None:
        """Start max_overlap_ratio_seen afresh."""
        self._core.reset_max_overlap_seen()

    def contacts(self) -> dict:
        """Pairs in contact now: i, j (indices), overlap (m), fn (N, eq. 5)."""
        return self._core.contacts()

    @property
    def rebuild_count(self) -> int:
        """Neighbour-list builds so far."""
        return self._core.rebuild_count

    @property
    def pair_list_size(self) -> int:
        """Pairs in the neighbour list."""
        return self._core.pair_list_size

    def record_sample(self) -> None:
        """Record one time-series sample now."""
        self._core.record_sample()

    # --- bonds -------------------------------------------------------------------------------
    @property
    def bond_count(self) -> int:
        """Bonds made (intact and broken)."""
        return self._core.bond_count

    def intact_bond_count(self) -> int:
        """Bonds not broken."""
        return self._core.intact_bond_count()

    def bonds(self) -> dict:
        """Every bond: i, j, mode (0 intact, 1 tension, 2 shear), fn (N), ft (N, 3), mn (N m),
        mt (N m, 3), radius (m), kn, kt (N/m^3), sigma_c, tau_c (Pa), damage, sigma_max,
        tau_max (Pa, eq. 14)."""
        return self._core.bonds()

    def broken_bonds(self) -> dict:
        """The broken-bond record: time (s), step, i, j, position (m, the bond's centre),
        mode (1 tension, 2 shear), sigma, tau (Pa), load_marker (m)."""
        return self._core.broken_bonds()

    def set_bond_property(self, name: str, values) -> None:
        """Set one constant of every bond: radius (m), kn, kt (N/m^3), sigma_c or tau_c (Pa),
        one value per bond."""
        self._core.set_bond_property(name, values)

    def __setattr__(self, name, value):
        # The settable engine properties go to C++; anything else a user sets stays here.
        if name in ("dt", "threads", "gravity", "vector_kernels"):
            setattr(self._core, name, value)
        else:
            object.__setattr__(self, name, value)


