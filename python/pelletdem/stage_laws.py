"""The contact law in force in each stage of the pellet's life (:mod:`pelletdem.stages`).

The bed settles under :func:`fill_law`, compaction to relaxation runs :func:`compaction_law`
(with the preset's release damping from the demoulding on), and the bond and diametral stages
the preset's whole law; :func:`check_time_step` holds the preset's dt against all of them
before the bed settles.
"""
from __future__ import annotations

from dataclasses import replace


def release_damping(pellet, on: bool) -> None:
    """Switch the preset's release damping on (demould, relax) or back to the law's own."""
    w = pellet.world
    law = w.contact_law
    ratio = pellet.preset.release_damping_ratio if on else pellet.preset.contact.normal_damping_ratio
    ratio = max(ratio, pellet.preset.contact.normal_damping_ratio)
    if law.normal_damping_ratio != ratio:
        w.set_contact_law(replace(law, normal_damping_ratio=ratio))


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


def check_time_step(world, preset) -> None:
    """Refuse the preset's dt before the bed settles if the law of a later stage would make it
    unstable (World's time step guard): the fill's law leaves the compaction and diametral
    effects off, and the release stages add their damping, so the fill alone would pass a
    step that the compaction then refuses, after the fill's work."""
    own = world.contact_law
    compaction = compaction_law(preset.contact)
    damping = max(preset.release_damping_ratio, preset.contact.normal_damping_ratio)
    for later in (compaction, replace(compaction, normal_damping_ratio=damping), preset.contact):
        world.set_contact_law(later)
    world.set_contact_law(own)
