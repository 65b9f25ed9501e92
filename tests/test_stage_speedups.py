"""The stages' speed-ups, each off in the presets until it is shown converged
(docs/performance.md, "Quasi-static speed-ups"): the fill at its own time step (`fill_dt`)
and unloaded walls moved clear at once (`clear_at_once`). Off, the stages are the tiny_life
fixture's to the step; on, they save exactly the steps they claim."""
from __future__ import annotations

import numpy as np
import pytest

from pelletdem import ParameterError, stages
from pelletdem.presets import get_preset


def _to_demould(preset):
    pellet, filled = stages.fill(preset, seed=0, progress=False)
    compacted = stages.compact(pellet, 120e6, progress=False)
    return pellet, filled, compacted, stages.unload(pellet, progress=False), stages.demould(pellet, progress=False)


def test_clear_at_once_skips_the_clearing_steps_and_nothing_before_them(tiny_life):
    p = get_preset("tiny").with_(clear_at_once=True)
    pellet, _, compacted, unloaded, demoulded = _to_demould(p)
    life = tiny_life.result.stages
    assert compacted.steps == life["compact"].steps
    # The piston lets go at the same step, then moves two radii clear without a step.
    stepped_clear = int(2.0 * p.radius_max / (p.unload_speed * p.dt)) + 1
    assert unloaded.steps == life["unload"].steps - stepped_clear
    assert unloaded.scalars["h_at_release"] == life["unload"].scalars["h_at_release"]
    piston = pellet.world.wall_state(pellet.walls["piston"])
    assert piston["active"] is False
    assert piston["point"][2] == pytest.approx(unloaded.scalars["h_at_release"] + 2.0 * p.radius_max, rel=1e-12)
    # The mould: released on force, then four radii clear at once, and removed.
    r0 = demoulded.scalars["release_radius"]
    assert demoulded.scalars["final_radius"] == pytest.approx(r0 + 4.0 * p.radius_max, rel=1e-12)
    assert pellet.world.wall_state(pellet.walls["mould"])["active"] is False
    x, r = np.asarray(pellet.world.x), np.asarray(pellet.world.r)
    assert (np.hypot(x[:, 0], x[:, 1]) + r).max() < demoulded.scalars["final_radius"]


def test_fill_dt_settles_at_its_own_step_and_hands_the_presets_back(tiny_life):
    base = get_preset("tiny")
    p = base.with_(fill_dt=3 * base.dt)  # the paper law's fill allows 7.2e-6 s
    pellet, filled = stages.fill(p, seed=0, progress=False)
    life = tiny_life.result.stages["fill"]
    assert pellet.world.dt == base.dt
    assert filled.scalars["settled"] == 1.0
    assert filled.steps < 0.4 * life.steps
    assert filled.scalars["h0"] == pytest.approx(life.scalars["h0"], rel=0.05)


@pytest.mark.parametrize("changes,match", [
    ({"fill_dt": -1e-6}, r"fill_dt = -1e-06 s is out of range: allowed 0 <= fill_dt <= 1e-3 s"),
    ({"fill_dt": True}, r"fill_dt = True s is out of range"),
    ({"clear_at_once": 1}, r"clear_at_once = 1 must be True or False"),
])
def test_bad_speedup_settings_are_named(changes, match):
    with pytest.raises(ParameterError, match=match):
        get_preset("tiny").with_(**changes)


def test_a_fill_dt_beyond_the_fill_laws_stable_step_is_refused_before_it_steps(monkeypatch):
    def no_run(*args, **kwargs):
        raise AssertionError("the fill stepped")

    monkeypatch.setattr(stages, "_run", no_run)
    with pytest.raises(ParameterError, match=r"dt = 0\.001 s is above the stable time step"):
        stages.fill(get_preset("tiny").with_(fill_dt=1e-3), progress=False)
