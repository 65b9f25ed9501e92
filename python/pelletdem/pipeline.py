"""A whole pellet's life in one call: fill -> compact -> unload -> demould -> relax -> bond ->
diametral, returning one Result. `relaxed_pellet` and `break_pellet` split it where the
calibration branches: everything before bonding does not depend on the bond parameters, and
`relaxed_pellets` relaxes the pellets of several pressures from one piston stroke."""
from __future__ import annotations

import time
from dataclasses import asdict
from typing import Optional

from . import stages
from ._version import __version__
from .engine import BondLaw, ParameterError
from .presets import Preset, get_preset
from .result import Result


def bond_law_for(material: str, mc: float, sigma_z_mpa: float, radius: float = 2e-5) -> BondLaw:
    """The paper's Table 5 bond parameters for one variant (E_b, sigma_c = tau_c in Pa, r_b in m)."""
    from .measured import variant

    v = variant(material, mc, sigma_z_mpa)
    return BondLaw(radius=radius, youngs_modulus=v.e_b, sigma_c=v.sigma_c, tau_c=v.sigma_c)


def _preset(preset) -> Preset:
    if isinstance(preset, Preset):
        return preset
    return get_preset(preset)


def relaxed_pellet(preset="quick", sigma_z: float = 120e6, seed: int = 0, threads: int = 1,
                   n_particles: Optional[int] = None, progress: Optional[bool] = None):
    """Fill, compact to `sigma_z` (Pa), unload, demould and relax. Returns (Pellet, Result)
    with the stages so far; the Pellet's world can be cloned to branch bond-parameter runs."""
    return relaxed_pellets(preset, [sigma_z], seed, threads, n_particles, progress)[0]


def relaxed_pellets(preset="quick", sigma_zs=(60e6, 120e6), seed: int = 0, threads: int = 1,
                    n_particles: Optional[int] = None, progress: Optional[bool] = None):
    """:func:`relaxed_pellet` at each of the pressures `sigma_zs` (Pa, ascending) from one bed
    and one piston stroke (:func:`pelletdem.stages.compact_through`): each pellet is bit for
    bit the one relaxed_pellet gives, and the strokes to the lower pressures are not run.
    Returns [(Pellet, Result)] in the order of `sigma_zs`."""
    p = _preset(preset)
    if not isinstance(threads, int) or not 1 <= threads <= 1024:
        raise ParameterError(f"threads = {threads!r} is out of range: allowed 1 <= threads <= 1024")
    sigma_zs = stages.check_sigma_zs(sigma_zs)  # before the fill, not after it
    pellet, filled = stages.fill(p, seed=seed, threads=threads, n_particles=n_particles, progress=progress)
    out = []
    for (pe, compacted), sigma_z in zip(stages.compact_through(pellet, sigma_zs, progress=progress), sigma_zs):
        res = Result(params={"preset": asdict(p), "sigma_z": sigma_z, "threads": threads,
                             "n_particles": n_particles}, seed=seed, version=__version__)
        res.stages["fill"], res.stages["compact"] = filled, compacted
        for st in (stages.unload(pe, progress=progress), stages.demould(pe, progress=progress),
                   stages.relax(pe, progress=progress)):
            res.stages[st.name] = st
        res.snapshots.update(pe.snapshots)
        out.append((pe, res))
    return out


def break_pellet(pellet, bond_law: BondLaw, result: Optional[Result] = None,
                 plate_speed: Optional[float] = None, max_dLD: Optional[float] = None,
                 progress: Optional[bool] = None) -> Result:
    """Bond a relaxed pellet and run the diametral test on it. The Pellet is used up (clone its
    world first to branch). `plate_speed` (m/s) and `max_dLD` (-) default to the preset's.
    Returns `result` (or a new one) with the bond and diametral stages."""
    res = result if result is not None else Result(params={}, seed=-1, version=__version__)
    res.params["bond"] = asdict(bond_law)
    res.stages["bond"] = stages.bond(pellet, bond_law, progress=progress)
    res.stages["diametral"] = stages.diametral(pellet, speed=plate_speed, max_dLD=max_dLD, progress=progress)
    res.snapshots.update(pellet.snapshots)
    return res


def run_pellet(preset="quick", material: str = "oak", mc: float = 8, sigma_z_mpa: float = 120,
               seed: int = 0, threads: int = 1, bond_law: Optional[BondLaw] = None,
               n_particles: Optional[int] = None, progress: Optional[bool] = None,
               checkpoint=None) -> Result:
    """Fill to broken pellet for one variant (material, mc in %, sigma_z in MPa). The bond
    parameters default to the paper's Table 5 values for that variant. Returns the Result.

    `checkpoint`: a checkpoint.RunCheckpoint to save the run to at every stage end and every
    `interval` s of wall time inside a stage, and to resume it from when its file exists; the
    result is the same, bit for bit at the same thread count, as a run never stopped.
    """
    law = bond_law if bond_law is not None else bond_law_for(material, mc, sigma_z_mpa)
    law.to_core()  # a bad bond law fails here, not after the relaxation
    t0 = time.perf_counter()
    p = _preset(preset)
    if not isinstance(threads, int) or isinstance(threads, bool) or not 1 <= threads <= 1024:
        raise ParameterError(f"threads = {threads!r} is out of range: allowed 1 <= threads <= 1024")
    sigma_z = sigma_z_mpa * 1e6
    stages.check_sigma_z(sigma_z)  # before the fill, not after it
    # The same stages, arguments and params as relaxed_pellet + break_pellet.
    life = [
        ("fill", lambda _: stages.fill(p, seed=seed, threads=threads, n_particles=n_particles, progress=progress)),
        ("compact", lambda pe: (pe, stages.compact(pe, sigma_z, progress=progress))),
        ("unload", lambda pe: (pe, stages.unload(pe, progress=progress))),
        ("demould", lambda pe: (pe, stages.demould(pe, progress=progress))),
        ("relax", lambda pe: (pe, stages.relax(pe, progress=progress))),
        ("bond", lambda pe: (pe, stages.bond(pe, law, progress=progress))),
        ("diametral", lambda pe: (pe, stages.diametral(pe, speed=None, max_dLD=None, progress=progress))),
    ]
    res = Result(params={"preset": asdict(p), "sigma_z": sigma_z, "threads": threads,
                         "n_particles": n_particles, "material": material, "mc_percent": mc,
                         "sigma_z_mpa": sigma_z_mpa, "bond": asdict(law)},
                 seed=seed, version=__version__)
    pellet, done, prior = None, 0, 0.0
    saved = checkpoint.resume() if checkpoint is not None else None
    if saved is not None:
        res, pellet, done, prior = saved.result, saved.make_pellet(p), len(saved.stages_done), saved.wall_time_s
        if [name for name, _ in life[:done]] != saved.stages_done:
            raise ParameterError(f"checkpoint {checkpoint.path}: finished stages {saved.stages_done} "
                                 f"are not the first of {[n for n, _ in life]}")
    for name, run in life[done:]:
        if checkpoint is None:
            pellet, st = run(pellet)
        else:
            with checkpoint.stage(name, pellet, res) as journal:
                pellet, st = run(pellet)
            st.wall_time_s += journal.prior_elapsed_s
        res.stages[name] = st
        if checkpoint is not None:
            checkpoint.stage_done(pellet, res)
    res.snapshots.update(pellet.snapshots)
    res.params["total_wall_time_s"] = prior + time.perf_counter() - t0
    return res
