"""The Python face of the C++ world: keyword construction, stop conditions by name, progress.

Everything here runs outside the time-step loop: one ``run_until`` call runs thousands of
steps in C++ and returns when a condition evaluated there fires.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Callable, Optional, Sequence

import numpy as np

from . import _core
from ._core import (  # noqa: F401  (re-exported)
    NonFiniteError,
    OverlapError,
    ParameterError,
    ParticleEscapedError,
    SimulationError,
    StopKind,
)

__all__ = [
    "ContactLaw", "BondLaw", "World", "RunOutcome", "ParameterError", "SimulationError",
    "OverlapError", "ParticleEscapedError", "NonFiniteError", "truncated_normal_radii",
    "random_pack_cylinder", "k1_from_yield_strength", "rayleigh_time_step",
]


@dataclass
class ContactLaw:
    """Parameters of the paper's contact law (eq. 5-11), SI units.

    k1, k2, kc: loading, unloading and adhesion stiffness, N/m (Table 4: 1e5, 4e5, 600).
    kt_ratio: tangential stiffness over k1 (the paper: k_t equal to the normal stiffness).
    mu, mu_wall: friction with particles (0.5) and walls (0.15). rolling: m_r of eq. 11 (0.01).
    wall_adhesion: walls adhere too (off: a withdrawing steel mould must not drag particles).
    wall_stiffness_factor: wall contact stiffness over a pair's (2: eq. 7 with r* = r at a wall).
    normal_damping_ratio: optional viscous normal damping, fraction of critical (paper: 0).
    scale_with_radius: k scaled by 2 r*/r_ref per pair (eq. 7's proportionality to radius).
    hardening, hardening_exponent: optional stiffening of the loading branch,
    k1 (1 + hardening (delta/r*)^exponent); 0 is the paper's linear law.
    unloading_growth: optional unloading stiffness growing with the residual overlap,
    k2 (1 + unloading_growth delta0/r*) (after Luding); 0 is the paper's constant k2.
    plate_yield_stress: optional crushing under the diametral plates, Pa: their contacts'
    loading force is capped at plate_yield_stress pi r^2; 0 switches it off.
    """

    k1: float = 1.0e5
    k2: float = 4.0e5
    kc: float = 600.0
    kt_ratio: float = 1.0
    mu: float = 0.5
    mu_wall: float = 0.15
    rolling: float = 0.01
    wall_adhesion: bool = False
    wall_stiffness_factor: float = 2.0
    normal_damping_ratio: float = 0.0
    scale_with_radius: bool = False
    r_ref: float = 2.0e-4
    hardening: float = 0.0
    hardening_exponent: float = 1.0
    unloading_growth: float = 0.0
    plate_yield_stress: float = 0.0

    @property
    def restitution(self) -> float:
        """Coefficient of restitution e = sqrt(k1/k2) (eq. 8), dimensionless."""
        return math.sqrt(self.k1 / self.k2)

    def to_core(self) -> _core.ContactLawParams:
        """The C++ parameter struct, validated (raises ParameterError naming the field)."""
        c = _core.ContactLawParams()
        for f in fields(self):
            setattr(c, f.name, getattr(self, f.name))
        c.validate()
        return c


@dataclass
class BondLaw:
    """Parallel-bond parameters (eq. 12-15), SI units.

    radius: r_b, m (20e-6 in the paper). youngs_modulus: E_b, Pa (k_n^b = E_b/(r_i + r_j)).
    kt_ratio: k_t^b / k_n^b (left open by the paper; 1). sigma_c, tau_c: strengths, Pa.
    gap_tolerance: pairs whose surfaces are closer than this get a bond too, m (0: touching).

    Optional effects the paper's bonds lack (all off by default; see the discrepancy loop,
    :mod:`pelletdem.loop`): weibull_modulus (-, 0 off) and strength_seed: a Weibull spread of
    the bonds' strengths with mean sigma_c, tau_c; softening (-, 0 brittle): past its strength
    a bond's capacity falls linearly to zero at (1 + softening) times its peak strain;
    overlap_radius_gain (-): r_b,ij = radius (1 + gain delta0_ij / r*_ij) with delta0 the
    contact's residual overlap at bonding; moisture_content, moisture_reference (%) and
    moisture_coefficient (1/%): E_b and the strengths times
    exp(-coefficient (content - reference)).
    """

    radius: float = 2.0e-5
    youngs_modulus: float = 120e6
    kt_ratio: float = 1.0
    sigma_c: float = 36e6
    tau_c: float = 36e6
    gap_tolerance: float = 0.0
    weibull_modulus: float = 0.0
    strength_seed: float = 0.0
    softening: float = 0.0
    overlap_radius_gain: float = 0.0
    moisture_content: float = 8.0
    moisture_reference: float = 8.0
    moisture_coefficient: float = 0.0

    def to_core(self) -> _core.BondParams:
        """The C++ parameter struct, validated."""
        b = _core.BondParams()
        for f in fields(self):
            setattr(b, f.name, float(getattr(self, f.name)))
        b.validate()
        return b


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

    def __init__(self, *, dt: float = 2e-6, box=((-0.01, -0.01, -0.01), (0.01, 0.01, 0.05)),
                 contact: Optional[ContactLaw] = None, density: float = 680.0,
                 density_scale: float = 1e4, gravity=(0.0, 0.0, -9.81), skin: float = 0.0,
                 threads: int = 1, max_overlap_ratio: float = 0.9, sample_interval: int = 100):
        contact = ContactLaw() if contact is None else contact
        if not isinstance(contact, ContactLaw):
            raise ParameterError(f"contact must be a ContactLaw, got {type(contact).__name__}")
        try:
            lo, hi = (_vec3("box", corner) for corner in box)
        except (TypeError, ValueError):
            raise ParameterError(f"box must be ((xlo, ylo, zlo), (xhi, yhi, zhi)) in m, got {box!r}") from None
        gravity = _vec3("gravity", gravity)
        # Kept so that a saved state can rebuild an identical world (see get_state/from_state).
        object.__setattr__(self, "_init_kwargs", dict(
            dt=dt, box=(lo, hi), contact=asdict(contact),
            density=density, density_scale=density_scale, gravity=gravity, skin=skin,
            threads=threads, max_overlap_ratio=max_overlap_ratio, sample_interval=sample_interval))
        p = _core.WorldParams()
        p.dt = _finite("dt", dt)
        p.box_lo = list(lo)
        p.box_hi = list(hi)
        p.contact = contact.to_core()
        p.density = _finite("density", density)
        p.density_scale = _finite("density_scale", density_scale)
        p.gravity = [_finite("gravity", g) for g in gravity]
        p.skin = _finite("skin", skin)
        p.threads = _int("threads", threads, 1, 1024)
        p.max_overlap_ratio = _finite("max_overlap_ratio", max_overlap_ratio)
        p.sample_interval = _int("sample_interval", sample_interval, 1, 10**12)
        object.__setattr__(self, "_core", _core.World(p))
        # Samples restored from a saved state, ahead of the engine's own (see samples()).
        object.__setattr__(self, "_sample_prefix", None)
        self.box = (tuple(lo), tuple(hi))

    def __getattr__(self, name):
        # Everything not defined here is the C++ world's (views, walls, bonds, samples).
        if name == "_core":
            raise AttributeError(name)
        return getattr(self._core, name)

    def run(self, steps: int, progress: Optional[Callable[[int], None]] = None) -> RunOutcome:
        """Run exactly `steps` time steps in C++ (GIL released; Ctrl-C stops within ~0.1 s)."""
        return self.run_until(steps=_int("steps", steps, 0, 10**13), max_steps=int(steps),
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
        max_steps = _int("max_steps", max_steps, 0, 10**13)
        conds, names = [], []
        for name, value in conditions.items():
            if name not in _CONDITIONS:
                raise ParameterError(f"unknown stop condition '{name}': allowed {sorted(_CONDITIONS)}")
            wall = -1
            if name.startswith("wall_"):
                if not (isinstance(value, (tuple, list)) and len(value) == 2):
                    raise ParameterError(f"{name} must be (wall index, value)")
                wall, value = _int(f"{name} wall index", value[0], 0, 2**31 - 1), value[1]
            interval = check_interval if name.endswith("kinetic_energy_below") else 1
            conds.append(_core.StopCondition(_CONDITIONS[name], _finite(name, value), wall,
                                             _int("check_interval", interval, 1, 10**9)))
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
        40,000, ~15 % faster on one thread and ~2x on two. Velocities, forces, contact and wall histories move with the particles and
        the time series are kept. Allowed only before bonds are created and while no numpy view
        of the particle arrays (``np.asarray(world.x)``) is alive. Returns ``order`` (N,): new
        particle k was particle ``order[k]``."""
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
        return ContactLaw(**_contact_dict(self._core.contact_params))

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
        kw["contact"] = _contact_dict(self._core.contact_params)
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

    def __setattr__(self, name, value):
        # Settable engine properties (dt, threads, gravity) go to C++; the rest stays here.
        if name in ("dt", "threads", "gravity"):
            setattr(self._core, name, value)
        else:
            object.__setattr__(self, name, value)


def _contact_dict(c) -> dict:
    return {f.name: getattr(c, f.name) for f in fields(ContactLaw)}


def _vec3(name: str, value) -> tuple:
    """Three finite floats, or ParameterError naming `name`."""
    try:
        items = list(value)
    except TypeError:
        raise ParameterError(f"{name} must have 3 components, got {value!r}") from None
    if len(items) != 3 or isinstance(value, (str, bytes)):
        raise ParameterError(f"{name} must have 3 components, got {value!r}")
    return tuple(_finite(name, v) for v in items)


def _finite(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(v):
        raise ParameterError(f"{name} = {v} must be finite")
    return v


def _int(name: str, value, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise ParameterError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    if not lo <= int(value) <= hi:
        raise ParameterError(f"{name} = {value} is out of range: allowed {lo} <= {name} <= {hi}")
    return int(value)


def truncated_normal_radii(n: int, mean: float = 2e-4, sd: float = 2e-5, r_min: float = 1.4e-4,
                           r_max: float = 2.6e-4, seed: int = 0) -> np.ndarray:
    """Radii (m) from a normal distribution truncated to [r_min, r_max] (the paper's 0.2 mm
    mean, 0.02 mm SD, 0.14-0.26 mm range by default), reproducible for a seed."""
    return np.asarray(_core.truncated_normal_radii(_int("n", n, 0, 10**7), mean, sd, r_min, r_max,
                                                   _int("seed", seed, 0, 2**63 - 1)))


def random_pack_cylinder(radii, radius: float, z_lo: float, z_hi: float, seed: int = 0,
                         center=(0.0, 0.0), max_attempts: int = 100000):
    """Random non-overlapping spheres in a z-aligned cylinder of `radius` (m) between z_lo and
    z_hi (m). Returns (positions (N, 3) m, radii (N,) m), sorted along z."""
    return _core.random_pack_cylinder(np.asarray(radii, dtype=float), center[0], center[1],
                                      radius, z_lo, z_hi, _int("seed", seed, 0, 2**63 - 1),
                                      _int("max_attempts", max_attempts, 1, 10**9))


def k1_from_yield_strength(p_y: float, r: float = 2e-4) -> float:
    """Loading stiffness k1 = 5 r p_y (N/m) from the yield strength p_y (Pa), eq. 7.

    Convention: r is the particle radius, which reproduces Table 4 (p_y = 100 MPa,
    r = 0.2 mm -> 1e5 N/m). Eq. 7 literally uses r* = r_i r_j/(r_i + r_j), half of that for
    equal spheres (5e4 N/m); see NOTES in the README.
    """
    return 5.0 * _finite("r", r) * _finite("p_y", p_y)


def rayleigh_time_step(r: float, density: float, youngs_modulus: float, poisson: float) -> float:
    """Rayleigh time step pi r sqrt(rho/G) / (0.1631 nu + 0.8766), s (G = E / (2 (1 + nu)))."""
    g = youngs_modulus / (2.0 * (1.0 + poisson))
    return math.pi * r * math.sqrt(density / g) / (0.1631 * poisson + 0.8766)
