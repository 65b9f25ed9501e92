"""The contact law in force in each stage of the pellet's life (:mod:`pelletdem.stages`).

The bed settles under :func:`fill_law`, compaction to relaxation runs :func:`compaction_law`
(with the preset's release damping from the demoulding on), and the bond and diametral stages
the preset's whole law; :func:`check_time_step` holds the preset's dt against all of them
before the bed settles.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np


def _released(preset, law):
    """``law`` with the preset's release damping (never below the law's own normal damping)."""
    return replace(law, normal_damping_ratio=max(preset.release_damping_ratio, preset.contact.normal_damping_ratio))


def release_damping(pellet, on: bool) -> None:
    """Switch the preset's release damping on (demould, relax) or back to the law's own."""
    w = pellet.world
    law = w.contact_law
    new = _released(pellet.preset, law) if on else replace(
        law, normal_damping_ratio=pellet.preset.contact.normal_damping_ratio)
    if law != new:
        w.set_contact_law(new)


def preset_law(pellet) -> None:
    """Put the preset's contact law in force. A pellet relaxed once serves runs whose laws
    differ in what acts after relaxation (the calibration and the loop branch bond-parameter
    runs off one relaxed pellet): the moisture content its bonds take, the plates' crushing."""
    if pellet.world.contact_law != pellet.preset.contact:
        pellet.world.set_contact_law(pellet.preset.contact)


def _effects_off(law, stage: str):
    """``law`` with every contact effect of the library that acts in ``stage`` switched off."""
    from .effects import EFFECTS

    off = {e.param[len("contact."):]: e.off for e in EFFECTS.values()
           if e.stage == stage and e.param.startswith("contact.")}
    return replace(law, **off)


def compaction_law(law):
    """The contact law from fill to relaxation: ``law`` with the library's 'diametral' contact
    effects switched off. They describe the made pellet (its particles densified by the
    compaction, the plates' crushing), so they act from the bonding on (:func:`bond` and
    :func:`diametral` put the preset's whole law in force), and the relaxed pellet, one per
    packing whatever their strengths, is that of the paper's law."""
    return _effects_off(law, "diametral")


def fill_law(law):
    """The contact law a bed settles under: :func:`compaction_law` of ``law`` with every
    compaction effect of the library (:mod:`pelletdem.effects`, stage 'compaction') switched
    off too. Those effects act on plastic flattening, which a bed settling under gravity
    (overlaps ~1e-4 of a radius) does not reach; but the settling is chaotic, so a law
    differing in the fourth digit of an effect's strength settles another bed (the highest
    particle, h0, moved 3 % with it). With one bed per packing seed, whatever the effects'
    strengths, a model and its candidates compact the same beds and their differences are
    paired."""
    return _effects_off(compaction_law(law), "compaction")


def _stage_laws(preset) -> list:
    """Every contact law the stages put in force, in order: the fill's, the compaction's, the
    compaction's with the release damping (demould, relax), the preset's whole law."""
    compaction = compaction_law(preset.contact)
    return [fill_law(preset.contact), compaction, _released(preset, compaction), preset.contact]


def _lightest_particle(preset, dt: float):
    """A world holding one particle of the preset's smallest radius (radius_min): the
    lightest the preset's radii allow, on which the time step guard is strictest."""
    from .engine import World

    r = preset.radius_min
    world = World(dt=dt, box=((-2 * r, -2 * r, -2 * r), (2 * r, 2 * r, 2 * r)), contact=fill_law(preset.contact),
                  density=preset.density, density_scale=preset.density_scale, gravity=(0.0, 0.0, 0.0),
                  max_overlap_ratio=preset.max_overlap_ratio)
    world.add_particles(np.zeros((1, 3)), np.array([r]))
    return world


def stable_time_step(preset) -> float:
    """The largest dt (s) that the law of every stage accepts (World.max_time_step on the
    lightest particle the preset's radii allow)."""
    world = _lightest_particle(preset, 1e-15)
    out = []
    for law in _stage_laws(preset):
        world.set_contact_law(law)
        out.append(world.max_time_step())
    return min(out)


def check_time_step(preset) -> None:
    """Refuse the preset's dt (ParameterError naming the stiffest spring) if the law of any
    stage would make it unstable, before any work: World's time step guard on the lightest
    particle the preset's radii allow (radius_min), with each stage's law in turn. The fill's
    law leaves the compaction and diametral effects off and the release stages add their
    damping, so a world checked with the fill's law alone would pass a step that the
    compaction then refuses, after the fill's work."""
    world = _lightest_particle(preset, preset.dt)
    for law in _stage_laws(preset)[1:]:
        world.set_contact_law(law)
    if preset.fill_dt > 0.0:  # the bed settles at its own step, under its own law
        world.set_contact_law(fill_law(preset.contact))
        world.dt = preset.fill_dt


def with_stable_time_step(preset):
    """``preset``, or where a stage's law cannot hold its dt, a copy whose dt is the stable
    step rounded down to two digits and whose bed settles at the old dt (``fill_dt``, which
    the fill's law holds): the same bed, the stages after it at a step their springs allow.
    The calibration and the loop make their runs with it, so that a fit whose box reaches
    stiff springs (saturating_unloading's k_p, unloading_growth at its top) runs them stably
    instead of failing or running unstably."""
    allowed = stable_time_step(preset)
    if preset.dt <= allowed:
        return preset
    digits = 10.0 ** (np.floor(np.log10(allowed)) - 1)
    return preset.with_(dt=float(np.floor(allowed / digits) * digits), fill_dt=preset.fill_dt or preset.dt)
