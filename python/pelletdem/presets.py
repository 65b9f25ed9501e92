"""Named run sizes. `paper` follows Table 4; `quick` keeps the paper's particles and contact
law but shrinks the mould so a whole pellet's life takes about a minute on 2 cores."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

from .engine import ContactLaw, ParameterError


@dataclass(frozen=True)
class Preset:
    """Geometry, particles, loading speeds and numerics of one run (SI units).

    n_particles: particle count. mould_diameter: D_c, m. radius_mean/sd/min/max: truncated
    normal radii, m. density: particle density, kg/m^3; density_scale: mass factor (gravity
    divided by it). dt: time step, s. piston_speed, unload_speed, plate_speed, demould_rate: m/s
    (the laboratory's 3.3e-5 m/s is out of reach, see docs/model.md, "Quasi-static control").
    fill_solid_fraction: solid fraction of the random-placement region (-). fill_gravity_factor:
    gravity is raised by this factor while the bed settles (-). fill_dt: the time step while
    the bed settles, s (0: dt); the fill's law has no compaction effects, so its stable step
    is larger. clear_at_once: the piston and the mould, once they carry no load, are moved
    clear and removed at once instead of stepped clear at the release speed (bool). ke_threshold: relaxation ends
    when the kinetic energy (scaled mass) falls below it, J. release_damping_ratio: viscous
    normal damping (fraction of critical) on the pairs and the floor during relax only, so the
    energy released at unloading and demoulding leaves the pellet as heat instead of as
    vibrations (-). relax_min_time: the relaxation runs at least this long before its
    kinetic-energy test, s. relax_max_time: the relaxation's time limit, s. bond_ramp_time:
    adhesion goes from full to zero over it, s. max_dLD: the diametral test ends at this
    dL/D (-). break_drop: the diametral test ends earlier, once the plate force has fallen to
    this fraction of its peak (a test machine's break detection; 0: off), the peak being
    kept from dL/D = break_from_dLD on (skips the plates' first contacts) (-).
    sample_points: samples recorded per stage.
    max_overlap_ratio: the engine's guard on overlap / radius (-). contact: the ContactLaw.
    Every field with its default and source: docs/parameters.md.
    """

    name: str
    n_particles: int
    mould_diameter: float = 0.010
    radius_mean: float = 2.0e-4
    radius_sd: float = 2.0e-5
    radius_min: float = 1.4e-4
    radius_max: float = 2.6e-4
    density: float = 680.0
    density_scale: float = 1.0e4
    dt: float = 2.0e-6
    piston_speed: float = 0.1
    unload_speed: float = 0.1
    demould_rate: float = 0.1
    plate_speed: float = 0.02
    fill_solid_fraction: float = 0.25
    fill_gravity_factor: float = 1.0e4
    fill_dt: float = 0.0
    clear_at_once: bool = False
    ke_threshold: float = 1.0e-8
    release_damping_ratio: float = 0.3
    relax_min_time: float = 0.005
    relax_max_time: float = 0.05
    bond_ramp_time: float = 0.004
    max_dLD: float = 0.1
    break_drop: float = 0.0
    break_from_dLD: float = 0.02
    sample_points: int = 400
    # Guard on overlap / radius. Wall contacts at 120 MPa exceed 0.75 r with the paper's linear
    # stiffness (15 N per particle on k1 = 1e5 N/m); analytic walls hold at any overlap, so the
    # guard only catches a run that has gone wrong.
    max_overlap_ratio: float = 1.5
    contact: ContactLaw = field(default_factory=ContactLaw)

    def __post_init__(self):
        r = self.release_damping_ratio
        if not (isinstance(r, (int, float)) and 0.0 <= r <= 1.0):
            raise ParameterError(f"release_damping_ratio = {r!r} is out of range: allowed 0 <= "
                                 "release_damping_ratio <= 1 (fraction of critical damping)")
        b = self.break_drop
        if not (isinstance(b, (int, float)) and 0.0 <= b < 1.0):
            raise ParameterError(f"break_drop = {b!r} is out of range: allowed 0 <= break_drop < 1 "
                                 "(fraction of the peak plate force; 0 is off)")
        f = self.break_from_dLD
        if not (isinstance(f, (int, float)) and 0.0 <= f <= 0.5):
            raise ParameterError(f"break_from_dLD = {f!r} is out of range: allowed 0 <= break_from_dLD <= 0.5")
        fd = self.fill_dt
        if not (isinstance(fd, (int, float)) and not isinstance(fd, bool) and 0.0 <= fd <= 1e-3):
            raise ParameterError(f"fill_dt = {fd!r} s is out of range: allowed 0 <= fill_dt <= 1e-3 s "
                                 "(0: the preset's dt)")
        if not isinstance(self.clear_at_once, bool):
            raise ParameterError(f"clear_at_once = {self.clear_at_once!r} must be True or False")

    def with_(self, **changes) -> "Preset":
        """A copy with some fields changed (e.g. halved speeds for a quasi-static check)."""
        return replace(self, **changes)

    def as_dict(self) -> dict:
        """All fields as plain values (for HDF5 attributes and summary.json)."""
        d = asdict(self)
        return d


PRESETS = {
    "paper": Preset(name="paper", n_particles=40000),
    "quick": Preset(name="quick", n_particles=2500, mould_diameter=0.005, piston_speed=0.05,
                    unload_speed=0.05, demould_rate=0.05, plate_speed=0.01),
    "tiny": Preset(name="tiny", n_particles=400, mould_diameter=0.003, piston_speed=0.05,
                   unload_speed=0.05, demould_rate=0.05, plate_speed=0.01, sample_points=200),
}


def get_preset(name: str) -> Preset:
    """The preset called `name` ('paper', 'quick' or 'tiny'); ParameterError (a ValueError)
    lists the allowed ones."""
    try:
        return PRESETS[name]
    except (KeyError, TypeError):
        raise ParameterError(f"preset = {name!r} is unknown: allowed {sorted(PRESETS)}") from None
