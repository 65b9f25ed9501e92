"""The pellet's life (section 3.1.3) as stages over one C++ world.

fill -> compact -> unload -> demould -> relax -> bond -> diametral. Each stage takes the
`Pellet` (the world and its geometry) and its own parameters, runs in C++ until its stop
condition, and returns a `StageResult` with its time series and scalars in SI units.
Geometry: the mould axis is z, the floor is the plane z = 0, the piston a plane moving down;
in the diametral test the plates are planes normal to y, moving towards each other.
"""
from __future__ import annotations

import contextvars
import math
import time
from dataclasses import dataclass, field, replace
from typing import Dict, List, Optional, Tuple

import numpy as np

from .engine import BondLaw, ParameterError, RunOutcome, World, random_pack_cylinder, truncated_normal_radii
from .pellet_measures import (
    bulk_coordination_number,
    inertia_number,
    largest_cluster_fraction,
    main_piece,
    measure,
)
from .presets import Preset
from .stage_laws import (  # noqa: F401
    check_time_step,
    compaction_law,
    fill_law,
    preset_law,
    release_damping,
    stable_time_step,
)


@dataclass
class StageResult:
    """What one stage measured: time series (numpy arrays) and scalars, SI units."""

    name: str
    series: Dict[str, np.ndarray] = field(default_factory=dict)
    scalars: Dict[str, float] = field(default_factory=dict)
    wall_time_s: float = 0.0
    steps: int = 0


@dataclass
class Pellet:
    """The world plus the geometry the stages share (wall indices, heights, masses)."""

    world: World
    preset: Preset
    walls: Dict[str, int]
    mould_radius: float
    mass: float                 # unscaled sawdust mass, kg
    h0: float = float("nan")    # bed height after filling, m
    diameter: float = float("nan")  # relaxed pellet diameter, m
    height: float = float("nan")    # relaxed pellet height, m
    snapshots: Dict[str, dict] = field(default_factory=dict)

    def snapshot(self, stage: str) -> None:
        """Keep the particles' state at the end of `stage` (positions, velocities, forces)."""
        w = self.world
        self.snapshots[stage] = {
            "position": np.array(w.x), "velocity": np.array(w.v), "angular_velocity": np.array(w.w),
            "force": np.array(w.f), "radius": np.array(w.r), "time": w.time,
        }


class _Progress:
    """A tqdm bar fed by the engine's chunk callback; silent off a terminal or when asked."""

    def __init__(self, desc: str, total: int, enabled: Optional[bool]):
        self.bar = None
        if enabled is False:
            return
        try:
            from tqdm.auto import tqdm
        except ImportError:  # tqdm is a dependency, but a bar is never worth a crash
            return
        self.bar = tqdm(total=total, desc=desc, unit="step", disable=None if enabled is None else not enabled,
                        leave=False, dynamic_ncols=True)
        self.last = 0

    def __call__(self, done: int) -> None:
        if self.bar is not None:
            self.bar.update(done - self.last)
            self.last = done

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


# A checkpointing run (pelletdem.checkpoint) installs a runner here: every engine run of a stage
# then goes through it, so it can save between chunks and, on resume, replay a stage up to the
# run it stopped in. Stage code must therefore read world arrays afresh after a run: a resumed
# run swaps the engine object under `pellet.world`, and a view taken before it goes stale.
STAGE_RUNNER: contextvars.ContextVar = contextvars.ContextVar("pelletdem_stage_runner", default=None)


def _run(pellet: Pellet, name: str, max_steps: int, progress, **conditions):
    runner = STAGE_RUNNER.get()
    if runner is not None:
        return runner(pellet, name, max_steps, progress, conditions)
    return run_engine(pellet, name, max_steps, progress, conditions)


def run_engine(pellet: Pellet, name: str, max_steps: int, progress, conditions: dict, between=None):
    """One engine run of a stage with a progress bar named `name`: `max_steps` steps at most,
    stop `conditions` as World.run_until takes them, `between` its checkpoint hook."""
    bar = _Progress(name, max_steps, progress)
    try:
        return pellet.world.run_until(max_steps=max_steps, progress=bar, between=between, **conditions)
    finally:
        bar.close()


def _sample_every(pellet: Pellet, expected_steps: float) -> None:
    n = max(1, int(expected_steps / max(pellet.preset.sample_points, 1)))
    pellet.world.set_sample_interval(n)
    pellet.world.clear_samples()


def _close_series(w) -> None:
    """Record one more sample where a stage stops, unless the last periodic one fell there:
    a stage's series end at its end (bonds broken, or a wall moved, after the last periodic
    sample would otherwise be missing)."""
    t = w.samples()["time"]
    if not len(t) or t[-1] < w.time:
        w.record_sample()


def _check_positive(name: str, value: float, unit: str) -> float:
    if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and value > 0):
        raise ParameterError(f"{name} = {value!r} {unit} must be a finite number > 0")
    return float(value)


def check_sigma_z(sigma_z) -> float:
    """The compaction pressure (Pa) if it is a finite number in (0, 1e9]; ParameterError if not."""
    v = _check_positive("sigma_z", sigma_z, "Pa")
    if v > 1e9:
        raise ParameterError(f"sigma_z = {v} Pa is out of range: allowed 0 < sigma_z <= 1e9 Pa")
    return v


def check_sigma_zs(sigma_zs) -> List[float]:
    """Compaction pressures (Pa) as a list if there is at least one, each allowed by
    :func:`check_sigma_z`, in ascending order; ParameterError if not."""
    try:
        given = list(sigma_zs)
    except TypeError:
        raise ParameterError(f"sigma_zs = {sigma_zs!r}: give a list of pressures (Pa)") from None
    targets = [check_sigma_z(sz) for sz in given]
    if not targets or any(b <= a for a, b in zip(targets, targets[1:])):
        raise ParameterError(f"sigma_zs = {given!r}: give one or more pressures in (0, 1e9] Pa, "
                             "each above the one before (ascending)")
    return targets


def calm(world) -> float:
    """Set every particle's velocity and spin to zero (PFC's `calm`: kinetic damping at one
    moment). Returns the kinetic energy removed, J (scaled mass).

    The release stages call it when a wall has let go of the pellet. A piston or mould that
    withdraws at our accelerated speed drags the springing-back pellet with it, and with the
    scaled mass the pellet keeps up to M v^2 / 6 of kinetic energy when the wall lets go
    (1.4e-2 J on a 40,000-particle pellet unloaded at 0.1 m/s, six orders above the
    relaxation threshold); in the laboratory, at 3.3e-5 m/s and the true mass, it is nil.
    Positions, and with them the stored elastic energy, are untouched.
    """
    e = float(world.kinetic_energy())
    zero = np.zeros((world.n, 3))
    world.set_velocities(zero, zero.copy())
    return e


# --- fill ------------------------------------------------------------------------------------

def fill(preset: Preset, seed: int = 0, threads: int = 1, n_particles: Optional[int] = None,
         mass: Optional[float] = None, progress: Optional[bool] = None):
    """Random non-overlapping generation in the mould and settling.

    Give either `n_particles` or the sawdust `mass` (kg, unscaled; 0.5 g in the paper); the
    preset's count otherwise. Settling runs with gravity raised by preset.fill_gravity_factor
    (only the resting structure matters and scaled gravity would need ~10^6 steps to drop the
    bed), then gravity returns to 9.81/density_scale. Measures h0 (m) and the initial bulk
    density BD_s (kg/m^3). Returns (Pellet, StageResult).
    """
    t0 = time.perf_counter()
    if n_particles is not None and mass is not None:
        raise ParameterError("give n_particles or mass, not both")
    r_mean = preset.radius_mean
    mean_volume = 4.0 / 3.0 * math.pi * (r_mean**3 + 3.0 * r_mean * preset.radius_sd**2)
    if mass is not None:
        _check_positive("mass", mass, "kg")
        n_particles = int(round(mass / (preset.density * mean_volume)))
    n = preset.n_particles if n_particles is None else n_particles
    if not (isinstance(n, (int, np.integer)) and 1 <= n <= 10_000_000):
        raise ParameterError(f"n_particles = {n!r} is out of range: allowed 1 <= n_particles <= 1e7")
    check_time_step(preset)  # before the packing is made
    R = 0.5 * preset.mould_diameter
    radii = truncated_normal_radii(n, preset.radius_mean, preset.radius_sd, preset.radius_min,
                                   preset.radius_max, seed=seed)
    solid = float(np.sum(4.0 / 3.0 * math.pi * radii**3))
    fill_height = solid / (preset.fill_solid_fraction * math.pi * R * R)
    x, radii = random_pack_cylinder(radii, radius=R - 1e-9, z_lo=0.0, z_hi=fill_height, seed=seed + 1)
    # Room around the mould for the pellet's radial spring-back after demoulding (up to ~30 %
    # on a tall 10 mm pellet at 120 MPa), its bulge between the plates, and particles it sheds;
    # below the floor too: in the diametral test (floor off) a broken pellet spreads along its
    # axis both ways, and a short pellet crushed to dL/D = 0.3 sheds particles a millimetre down.
    margin = 1.0 * R + 4.0 * preset.radius_max
    box = ((-R - margin, -R - margin, -margin),
           (R + margin, R + margin, fill_height + 10.0 * preset.radius_max))
    world = World(dt=preset.dt, box=box, contact=fill_law(preset.contact), density=preset.density,
                  density_scale=preset.density_scale, gravity=(0.0, 0.0, -9.81), threads=threads,
                  skin=0.1 * preset.radius_mean, max_overlap_ratio=preset.max_overlap_ratio)
    world.add_particles(x, radii)
    walls = {
        "floor": world.add_plane("floor", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
        "mould": world.add_cylinder("mould", (0.0, 0.0, 0.0), R),
        "piston": world.add_plane("piston", (0.0, 0.0, fill_height + 2.0 * preset.radius_max), (0.0, 0.0, -1.0)),
    }
    masses = np.array(world.m)  # a copy: sort_particles below refuses while views are alive
    pellet = Pellet(world, preset, walls, R, float(masses.sum() / preset.density_scale))
    # Free fall of the bed under g takes sqrt(2 h / g); allow four times that.
    world.gravity = (0.0, 0.0, -9.81 * preset.fill_gravity_factor / 1.0)
    g_eff = 9.81 * preset.fill_gravity_factor / preset.density_scale
    t_fall = math.sqrt(2.0 * fill_height / g_eff)
    dt = preset.fill_dt if preset.fill_dt > 0.0 else preset.dt
    world.dt = dt  # refused here, before a step, if the fill's law cannot hold it
    max_steps = int(6.0 * t_fall / dt)
    _sample_every(pellet, max_steps)
    # At rest enough: rms speed below 3 mm/s. The bed's structure is fixed by then (the
    # coordination number has stopped rising). The compaction erases most of the rest, not
    # all: settled at 4 dt, `quick`'s pellets broke 9 % stronger (docs/performance.md).
    ke_rest = 0.5 * masses.sum() * 3e-3**2
    # The bed starts at rest and needs ~1.5 ms to pass 3 mm/s: let it fall first, or the test
    # passes at its first check and the bed is never settled.
    fall = _run(pellet, "fill", int(t_fall / dt), progress)
    out = _run(pellet, "fill", max_steps - fall.steps, progress, kinetic_energy_below=ke_rest,
               check_interval=100)
    world.dt = preset.dt
    world.gravity = (0.0, 0.0, -9.81)
    law = compaction_law(preset.contact)
    if world.contact_law != law:
        world.set_contact_law(law)  # the compaction effects act from here on
    # The bed has settled: renumber its particles so that neighbours in space are neighbours in
    # memory for the stages that follow (on a 40,000 bed ~15 % faster on one thread, ~2x on two).
    world.sort_particles()
    s = world.samples()
    xs, rs = np.asarray(world.x), np.asarray(world.r)
    pellet.h0 = float((xs[:, 2] + rs).max())
    bd_s = pellet.mass / (math.pi * R * R * pellet.h0)
    world.set_wall_point(walls["piston"], (0.0, 0.0, pellet.h0 + 1e-6))
    pellet.snapshot("fill")
    res = StageResult("fill", series={"time": s["time"], "kinetic_energy": s["kinetic_energy"],
                                      "coordination_number": s["coordination_number"]},
                      scalars={"n_particles": float(world.n), "h0": pellet.h0,
                               "bulk_density": bd_s, "mass": pellet.mass,
                               "solid_fraction": solid / (math.pi * R * R * pellet.h0),
                               "settled": float(out.reason == "kinetic_energy_below"),
                               "coordination_number": world.coordination_number()},
                      wall_time_s=time.perf_counter() - t0, steps=fall.steps + out.steps)
    return pellet, res


# --- compact / unload -----------------------------------------------------------------------

def _piston_series(pellet: Pellet) -> dict:
    w = pellet.world
    piston = w.wall_samples(pellet.walls["piston"])
    mould = w.wall_samples(pellet.walls["mould"])
    glob = w.samples()
    area = math.pi * pellet.mould_radius**2
    h = piston["point"][:, 2]
    sigma_z = piston["normal_force"] / area
    bd = pellet.mass / (area * h)
    return {"time": piston["time"], "sigma_z": sigma_z, "h": h, "dh_h0": (pellet.h0 - h) / pellet.h0,
            "bulk_density": bd, "coordination_number": glob["coordination_number"],
            "mould_radial_force": mould["normal_force"], "max_overlap_ratio": glob["max_overlap_ratio"],
            "kinetic_energy": glob["kinetic_energy"]}


def compact(pellet: Pellet, sigma_z: float, speed: Optional[float] = None,
            progress: Optional[bool] = None) -> StageResult:
    """Piston down at `speed` (m/s) until the piston stress F / (pi R_c^2) reaches sigma_z (Pa).

    Records sigma_z against dh/h0, bulk density against sigma_z, coordination number against
    density, the inertia number, and the largest overlap ratio seen (particles and walls).
    """
    return compact_through(pellet, [sigma_z], speed, progress)[0][1]


def compact_through(pellet: Pellet, sigma_zs, speed: Optional[float] = None,
                    progress: Optional[bool] = None) -> List[Tuple[Pellet, StageResult]]:
    """One piston stroke through the pressures `sigma_zs` (Pa, ascending): at each but the
    last the pellet is cloned and the clone's compaction ends there; `pellet` goes on to the
    last. Returns [(pellet at sigma_z, its :func:`compact` StageResult)] in the order given.

    A compaction to a higher pressure passes through every lower one, and the engine steps
    the same whether a run stops and goes on or not, so each clone is bit for bit the pellet
    that :func:`compact` to its pressure gives, for the cost of one stroke.
    """
    t0 = time.perf_counter()
    targets = check_sigma_zs(sigma_zs)
    v = _check_positive("speed", pellet.preset.piston_speed if speed is None else speed, "m/s")
    w, pid = pellet.world, pellet.walls["piston"]
    area = math.pi * pellet.mould_radius**2
    max_steps = int(pellet.h0 / (v * w.dt)) + 1
    _sample_every(pellet, 0.6 * max_steps)
    w.reset_max_overlap_seen()
    w.set_wall_velocity(pid, (0.0, 0.0, -v))
    out, steps = [], 0
    for i, sigma_z in enumerate(targets):
        run = _run(pellet, "compact", max_steps - steps, progress, wall_force_above=(pid, sigma_z * area))
        steps += run.steps
        last = i == len(targets) - 1
        here = pellet if last else replace(pellet, world=w.clone(), walls=dict(pellet.walls),
                                           snapshots=dict(pellet.snapshots))
        out.append((here, _compaction_done(here, sigma_z, v, run.reason == "wall_force_above", steps, t0)))
    return out


def _compaction_done(pellet: Pellet, sigma_z: float, v: float, reached: bool, steps: int, t0: float) -> StageResult:
    """Stop the piston of `pellet` at `sigma_z` (Pa) and measure its compaction stage."""
    w, pid = pellet.world, pellet.walls["piston"]
    area = math.pi * pellet.mould_radius**2
    w.set_wall_velocity(pid, (0.0, 0.0, 0.0))
    w.record_sample()
    s = _piston_series(pellet)
    scaled_density = pellet.preset.density * pellet.preset.density_scale
    s["inertia_number"] = inertia_number(v / s["h"], 2 * pellet.preset.radius_mean, scaled_density, s["sigma_z"])
    pellet.snapshot("compact")
    return StageResult("compact", series=s, scalars={
        "sigma_z_target": sigma_z, "sigma_z_reached": float(w.wall_state(pid)["normal_force"] / area),
        "reached": float(reached), "h_min": float(s["h"][-1]), "dh_h0_max": float(s["dh_h0"][-1]),
        "bulk_density_max": float(s["bulk_density"][-1]),
        "coordination_number_max": float(w.coordination_number()),
        "max_overlap_ratio": float(w.max_overlap_ratio_seen), "piston_speed": v,
        "inertia_number_at_target": float(s["inertia_number"][-1])},
        wall_time_s=time.perf_counter() - t0, steps=steps)


def _clear(pellet: Pellet, wall: int, name: str, distance: float, speed: float, released: bool, progress):
    """Move `wall` (the piston or the mould) `distance` (m) further out: stepped at `speed`
    (m/s) as it moves, or, with the preset's clear_at_once and the wall `released` (it carries
    no load), at once. Returns the run."""
    w = pellet.world
    if not (pellet.preset.clear_at_once and released):  # a loaded wall let go at once bursts the pellet
        return _run(pellet, name, int(distance / (speed * w.dt)) + 1, progress)
    state = w.wall_state(wall)
    if w.wall_kind(wall) == "cylinder":
        w.set_wall_radius(wall, state["radius"] + distance)
    else:  # a plane's normal points into the pellet: clear is against it
        w.set_wall_point(wall, np.asarray(state["point"]) - distance * np.asarray(state["normal"]))
    return RunOutcome("cleared at once", 0, float(w.time))


def unload(pellet: Pellet, speed: Optional[float] = None, progress: Optional[bool] = None) -> StageResult:
    """Piston back up at `speed` (m/s) until it carries no load, then clear of the pellet.

    When the piston lets go, the pellet's velocities are set to zero (:func:`calm`): the
    kinetic energy it carried from following the fast piston is an artefact of the
    accelerated, mass-scaled unloading. Reports the piston's height above the floor when it
    let go (m) and that time (s), and the kinetic energy removed (J, scaled mass)."""
    t0 = time.perf_counter()
    v = _check_positive("speed", pellet.preset.unload_speed if speed is None else speed, "m/s")
    w, pid = pellet.world, pellet.walls["piston"]
    h_start = w.wall_state(pid)["point"][2]
    max_steps = int(h_start / (v * w.dt)) + 1
    _sample_every(pellet, 0.05 * max_steps)
    w.set_wall_velocity(pid, (0.0, 0.0, v))
    # Released when the piston carries less than 1e-4 of its peak load (a particle grazing
    # the piston keeps an exact zero from ever being reached).
    f_peak = max(w.wall_state(pid)["normal_force"], 0.0)
    out = _run(pellet, "unload", max_steps, progress, wall_force_below=(pid, 1e-4 * f_peak))
    # The piston's height (above the floor at z = 0) and the time when it let go.
    h_release, t_release = float(w.wall_state(pid)["point"][2]), float(w.time)
    calmed = calm(w)
    # Adhesion can hold the piston a little longer; lift it clear by two radii.
    out2 = _clear(pellet, pid, "unload (clear)", 2.0 * pellet.preset.radius_max, v,
                  out.reason == "wall_force_below", progress)
    _close_series(w)
    w.set_wall_velocity(pid, (0.0, 0.0, 0.0))
    w.set_wall_active(pid, False)
    s = _piston_series(pellet)
    pellet.snapshot("unload")
    return StageResult("unload", series=s, scalars={"h_at_release": h_release, "time_at_release": t_release,
                                                    "released": float(out.reason == "wall_force_below"),
                                                    "kinetic_energy_removed": calmed},
                       wall_time_s=time.perf_counter() - t0, steps=out.steps + out2.steps)


def demould(pellet: Pellet, rate: Optional[float] = None, progress: Optional[bool] = None) -> StageResult:
    """Mould radius grows at `rate` (m/s) until the mould carries no load, then two particle
    diameters more, and the mould is removed.

    The release is on force, like the piston's: the pellet's radial spring-back grows with its
    size (over 1 mm on a 10 mm pellet at 120 MPa), and a mould removed while still loaded lets
    the stored elastic energy out at once, which bursts the pellet. Reports the radius at
    release and whether the release happened within the stage's budget (twice the mould radius).
    When the mould lets go, and again once it is gone, the velocities are set to zero
    (:func:`calm`, as after unloading); the kinetic energy removed (J) is reported.
    """
    t0 = time.perf_counter()
    rate = _check_positive("rate", pellet.preset.demould_rate if rate is None else rate, "m/s")
    w, mid = pellet.world, pellet.walls["mould"]
    budget = int(pellet.mould_radius / (rate * w.dt)) + 1
    _sample_every(pellet, budget / 4)
    f_start = max(w.wall_state(mid)["normal_force"], 0.0)
    w.set_wall_radius_rate(mid, rate)
    out = _run(pellet, "demould", budget, progress, wall_force_below=(mid, 1e-4 * f_start))
    r_release = float(w.wall_state(mid)["radius"])
    calmed = calm(w)
    out2 = _clear(pellet, mid, "demould (clear)", 4.0 * pellet.preset.radius_max, rate,
                  out.reason == "wall_force_below", progress)
    _close_series(w)
    w.set_wall_radius_rate(mid, 0.0)
    w.set_wall_active(mid, False)
    ms = w.wall_samples(mid)
    calmed += calm(w)
    pellet.snapshot("demould")
    return StageResult("demould", series={"time": ms["time"], "radial_force": ms["normal_force"],
                                          "radius": ms["radius"]},
                       scalars={"release_radius": r_release, "released": float(out.reason == "wall_force_below"),
                                "radial_force_at_start": f_start, "kinetic_energy_removed": calmed,
                                "final_radius": float(w.wall_state(mid)["radius"])},
                       wall_time_s=time.perf_counter() - t0, steps=out.steps + out2.steps)


def relax(pellet: Pellet, ke_threshold: Optional[float] = None, max_time: Optional[float] = None,
          progress: Optional[bool] = None, min_time: Optional[float] = None) -> StageResult:
    """Run until the kinetic energy (with the scaled mass, J) about the pellet's centre of mass
    is below `ke_threshold`, then stop the pellet's drift as a whole.

    The elastic energy released at unloading can lift the pellet off the floor, and under the
    scaled gravity it then floats at a few mm/s; that motion is not the pellet relaxing, so
    the test uses the internal kinetic energy, and the drift is removed at the end (the pellet
    is picked up and laid between the plates). The preset's release_damping_ratio damps the
    pair and floor contacts meanwhile (the bond stage switches it off). Reports the relaxed
    pellet's height and diameter (m) and bulk density (kg/m^3, unscaled mass) as a caliper
    and a balance read them, the same from the outermost particle extents (``*_extent``) and
    the density of its interior (``bulk_density_core``) (:mod:`pelletdem.caliper`), and its
    coordination number over every particle and over the bulk, away from the free surfaces
    (``coordination_number_bulk``, the one to compare with the paper's Fig. 10 and Table 5).
    The test starts after `min_time` (s): the release stages leave
    the pellet at rest (:func:`calm`) but not yet in balance, and its stress waves need a few
    passes to settle. `max_time` (s) bounds the stage; `converged` says which ended it.
    """
    t0 = time.perf_counter()
    ke = _check_positive("ke_threshold", pellet.preset.ke_threshold if ke_threshold is None else ke_threshold, "J")
    tmax = _check_positive("max_time", pellet.preset.relax_max_time if max_time is None else max_time, "s")
    tmin = pellet.preset.relax_min_time if min_time is None else min_time
    if not (isinstance(tmin, (int, float, np.floating)) and 0.0 <= tmin < tmax):
        raise ParameterError(f"min_time = {tmin!r} s is out of range: allowed 0 <= min_time < max_time = {tmax} s")
    w = pellet.world
    release_damping(pellet, True)
    max_steps = int(tmax / w.dt) + 1
    min_steps = int(tmin / w.dt)
    _sample_every(pellet, max_steps / 4)
    settle = _run(pellet, "relax (settle)", min_steps, progress).steps if min_steps > 0 else 0
    out = _run(pellet, "relax", max_steps - min_steps, progress, internal_kinetic_energy_below=ke,
               check_interval=50)
    drift = np.linalg.norm(w.mean_velocity())
    ke_internal = w.internal_kinetic_energy()
    w.remove_mean_velocity()
    w.record_sample()
    s = w.samples()
    # Particles the pellet shed are not part of it: a caliper would not measure them.
    piece = main_piece(w)
    size = measure(pellet.world, piece)
    pellet.diameter, pellet.height = size.diameter, size.height
    pellet.snapshot("relax")
    return StageResult("relax", series={"time": s["time"], "kinetic_energy": s["kinetic_energy"],
                                        "coordination_number": s["coordination_number"]},
                       scalars={"height": size.height, "diameter": size.diameter,
                                "bulk_density": size.bulk_density,
                                "height_extent": size.height_extent, "diameter_extent": size.diameter_extent,
                                "bulk_density_extent": size.bulk_density_extent,
                                "bulk_density_core": size.core_density,
                                "shed_particles": float(w.n - piece.sum()),
                                "coordination_number": w.coordination_number(),
                                "coordination_number_bulk": bulk_coordination_number(w, piece, size),
                                "bulk_particles": float(size.bulk.sum()), "bulk_depth": size.bulk_depth,
                                "kinetic_energy": ke_internal, "drift_speed": float(drift),
                                "converged": float(out.reason == "internal_kinetic_energy_below")},
                       wall_time_s=time.perf_counter() - t0, steps=settle + out.steps)


# --- bond / diametral -------------------------------------------------------------------------

def bond(pellet: Pellet, law: BondLaw, ramp_time: Optional[float] = None,
         progress: Optional[bool] = None) -> StageResult:
    """Parallel bonds on the relaxed pellet's contacts; adhesion then ramps to zero over
    `ramp_time` (s) and the pellet settles on its bonds for as long again."""
    t0 = time.perf_counter()
    tr = _check_positive("ramp_time", pellet.preset.bond_ramp_time if ramp_time is None else ramp_time, "s")
    w = pellet.world
    core_law = law.to_core()  # validates before any work
    preset_law(pellet)  # the relaxation's damping off; the bonds take its moisture content
    n_bonds = w.create_bonds(core_law)
    w.set_adhesion_ramp(w.time, tr)
    steps = int(2.0 * tr / w.dt) + 1
    _sample_every(pellet, steps)
    out = _run(pellet, "bond", steps, progress)
    _close_series(w)
    b = w.bonds()
    intact = b["mode"] == 0
    frac = largest_cluster_fraction(w.n, b["i"][intact], b["j"][intact])
    size = measure(pellet.world, main_piece(w))
    pellet.diameter, pellet.height = size.diameter, size.height
    pellet.snapshot("bond")
    s = w.samples()
    return StageResult("bond", series={"time": s["time"], "kinetic_energy": s["kinetic_energy"],
                                       "n_bonds_intact": s["n_bonds_intact"]},
                       scalars={"n_bonds": float(n_bonds), "bonds_per_particle": 2.0 * n_bonds / w.n,
                                "largest_cluster_fraction": frac,
                                "broken_during_ramp": float(len(w.broken_bonds()["i"])),
                                "height": size.height, "diameter": size.diameter,
                                "height_extent": size.height_extent, "diameter_extent": size.diameter_extent},
                       wall_time_s=time.perf_counter() - t0, steps=out.steps)


# Plate approach (fraction of D) over which the break detection averages the plate force.
BREAK_SMOOTHING_DLD = 0.0025
# Plate approach (fraction of D) over which the diametral test records the preset's
# sample_points samples; longer tests record more at the same spacing.
DIAMETRAL_SAMPLE_SPAN = 0.1


def diametral(pellet: Pellet, speed: Optional[float] = None, max_dLD: Optional[float] = None,
              progress: Optional[bool] = None) -> StageResult:
    """Diametral compression between two plates parallel to the pellet's axis.

    Both plates move towards each other at speed/2 (m/s) so the pellet stays centred; dL is
    their approach. R_p, h_p and D are the bonded pellet's size as a caliper reads it
    (:func:`measure`). Records sigma_1 = P / (pi R_p h_p) (eq. 4, Pa) against dL/D, the tensile
    strength sigma_f (the peak, Pa), dL_f/D, and broken bonds against dL/D; the series end
    at the step where the test stops: dL/D = max_dLD, or earlier where the preset's
    break_drop > 0 and the plate force, averaged over dL/D = BREAK_SMOOTHING_DLD, has fallen
    to break_drop times its peak (scalar ``stopped_on_break`` 1).
    """
    t0 = time.perf_counter()
    v = _check_positive("speed", pellet.preset.plate_speed if speed is None else speed, "m/s")
    dld = _check_positive("max_dLD", pellet.preset.max_dLD if max_dLD is None else max_dLD, "")
    if dld > 0.5:
        raise ParameterError(f"max_dLD = {dld} is out of range: allowed 0 < max_dLD <= 0.5")
    w = pellet.world
    w.set_wall_active(pellet.walls["floor"], False)
    w.gravity = (0.0, 0.0, 0.0)  # the pellet lies between the plates; its weight is negligible
    piece = main_piece(w)
    if not piece.all():
        # The pellet is picked up and laid between the plates; its crumbs stay behind at rest
        # instead of drifting out of the domain during the test.
        vel, spin = np.array(w.v), np.array(w.w)
        vel[~piece] = 0.0
        spin[~piece] = 0.0
        w.set_velocities(vel, spin)
    # Eq. 4's R_p and h_p and the D of dL/D: the pellet's size as a caliper reads it before
    # the test.
    size = measure(pellet.world, piece)
    d, h = size.diameter, size.height
    cx, _ = size.centre
    x, r = np.asarray(w.x), np.asarray(w.r)
    # The plates start clear of every particle (a plane must not start with a particle behind
    # it); dL counts from the moment they reach the pellet itself, past any shed particles.
    y_lo, y_hi = float((x[:, 1] - r).min()), float((x[:, 1] + r).max())
    gap = (float((x[piece, 1] - r[piece]).min()) - y_lo) + (y_hi - float((x[piece, 1] + r[piece]).max()))
    if "plate_low" not in pellet.walls:
        pellet.walls["plate_low"] = w.add_plane("plate_low", (cx, y_lo, 0.0), (0.0, 1.0, 0.0))
        pellet.walls["plate_high"] = w.add_plane("plate_high", (cx, y_hi, 0.0), (0.0, -1.0, 0.0))
    lo, hi = pellet.walls["plate_low"], pellet.walls["plate_high"]
    w.set_wall_crushable(lo, True)  # effects acting under the plates act here only
    w.set_wall_crushable(hi, True)
    preset_law(pellet)
    w.set_load_walls([lo, hi])
    w.set_wall_velocity(lo, (0.0, 0.5 * v, 0.0))
    w.set_wall_velocity(hi, (0.0, -0.5 * v, 0.0))
    marker0 = w.load_marker + gap
    target = dld * d
    max_steps = int((target + gap) / (v * w.dt)) + 1
    # samples at a spacing in dL/D that does not depend on where the test stops, as a test
    # machine's: a shorter test must not see a finer curve and a higher sampled peak
    _sample_every(pellet, DIAMETRAL_SAMPLE_SPAN * d / (v * w.dt))
    n_broken0 = len(w.broken_bonds()["i"])
    stop = {"load_marker_above": marker0 + target}
    if pellet.preset.break_drop > 0.0:
        # The force is averaged over 0.25 % of D of plate approach, the width the calibration's
        # failure point smooths over, so one bond breaking is not taken for the break.
        smoothing = max(1.0, BREAK_SMOOTHING_DLD * d / (v * w.dt))
        w.track_load_peak(marker0 + pellet.preset.break_from_dLD * d, smoothing)
        stop["load_drop_below"] = pellet.preset.break_drop
    out = _run(pellet, "diametral", max_steps + 10, progress, **stop)
    w.track_load_peak(math.inf)
    _close_series(w)
    w.set_wall_velocity(lo, (0.0, 0.0, 0.0))
    w.set_wall_velocity(hi, (0.0, 0.0, 0.0))
    sl, sh, g = w.wall_samples(lo), w.wall_samples(hi), w.samples()
    P = 0.5 * (sl["normal_force"] + sh["normal_force"])
    sigma_1 = P / (math.pi * 0.5 * d * h)
    dL_D = (g["load_marker"] - marker0) / d
    k = int(np.argmax(sigma_1)) if len(sigma_1) else 0
    broken = w.broken_bonds()
    sel = slice(n_broken0, None)
    strain_rate = v / d
    scaled_density = pellet.preset.density * pellet.preset.density_scale
    pellet.snapshot("diametral")
    return StageResult("diametral", series={
        "time": g["time"], "dL_D": dL_D, "sigma_1": sigma_1, "plate_force": P,
        "n_bonds_broken": g["n_bonds_broken"] - n_broken0, "kinetic_energy": g["kinetic_energy"],
        "inertia_number": inertia_number(strain_rate, 2 * pellet.preset.radius_mean, scaled_density, sigma_1),
        "broken_time": broken["time"][sel], "broken_position": broken["position"][sel],
        "broken_mode": broken["mode"][sel], "broken_dL_D": (broken["load_marker"][sel] - marker0) / d},
        scalars={"sigma_f": float(sigma_1[k]) if len(sigma_1) else float("nan"),
                 "dLf_D": float(dL_D[k]) if len(sigma_1) else float("nan"),
                 "diameter": d, "height": h, "plate_speed": v,
                 "diameter_extent": size.diameter_extent, "height_extent": size.height_extent,
                 "bonds_broken": float(len(broken["i"]) - n_broken0),
                 "bonds_intact": float(w.intact_bond_count()),
                 "stopped_on_break": float(out.reason == "load_drop_below")},
        wall_time_s=time.perf_counter() - t0, steps=out.steps)
