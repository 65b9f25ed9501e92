"""Design points that share relaxed pellets: along a compaction parameter every new value
compacts new pellets, so the designs pair their points on such axes."""
from __future__ import annotations

import numpy as np
import pytest
from toy_pellet import FIT, PACKING, toy

from pelletdem.loop import FunctionSimulator
from pelletdem.loop_emulator import Axis, Space, design
from pelletdem.loop_models import local_design, relaxing_axes, share_relaxations


def test_the_second_half_of_a_design_takes_the_first_half_s_relaxing_coordinates():
    U = design(3, 8)
    P = share_relaxations(U, (2,))
    assert np.array_equal(P[4:, 2], U[:4, 2]) and np.array_equal(P[:4], U[:4])
    assert np.array_equal(P[:, :2], U[:, :2])  # the other axes keep the whole Sobol design
    assert len({round(v, 12) for v in P[:, 2]}) == 4  # four relaxations serve eight points
    assert len({tuple(np.round(r, 12)) for r in P}) == 8  # and no two points coincide
    # an odd number: the middle point keeps its own
    P5 = share_relaxations(design(2, 5), (1,))
    assert len({round(v, 12) for v in P5[:, 1]}) == 3


def test_nothing_is_paired_where_every_axis_or_none_relaxes():
    U = design(2, 8)
    assert np.array_equal(share_relaxations(U, ()), U)
    assert np.array_equal(share_relaxations(U, (0, 1)), U)  # pairs would be the same point


def test_a_local_design_keeps_its_centre_and_pairs_the_rest():
    space = Space((Axis("E_b", 1e7, 1e9), Axis("contact.unloading_growth", 0.1, 50.0)))
    u = np.array([0.4, 0.6])
    L = local_design(space, u, 0.15, 6, seed=1, relaxing=(1,))
    assert np.array_equal(L[0], u)
    assert np.array_equal(L[4:, 1], L[1:4, 1])
    assert np.all(np.abs(L - u) <= 0.15 + 1e-12)


def test_the_relaxing_axes_are_those_the_simulator_says_change_the_packing():
    space = Space((Axis("E_b", 1e7, 1e9), Axis("sigma_c", 1e6, 1e8), Axis("contact.unloading_growth", 0.1, 50.0)))
    assert relaxing_axes(FunctionSimulator(toy, packing_params=PACKING), space, FIT) == (2,)
    # a simulator that cannot tell: every axis, and the design is left as it was
    assert relaxing_axes(FunctionSimulator(toy), space, FIT) == (0, 1, 2)


def test_the_engine_says_which_parameters_compact_new_pellets():
    from pelletdem.loop import Condition, EngineSimulator

    base = {"E_b": 6e7, "sigma_c": 9e6}
    conds = [Condition(60e6), Condition(120e6)]
    with EngineSimulator("tiny") as sim:
        assert sim.same_relaxation(base, dict(base, E_b=1e8), conds)  # bonds form after relaxation
        assert sim.same_relaxation(base, dict(base, **{"bond.softening": 2.0}), conds)
        assert not sim.same_relaxation(base, dict(base, **{"contact.hardening": 3.0}), conds)
        assert not sim.same_relaxation(base, dict(base, k1=3e4), conds)


def test_wet_and_dry_pellets_share_a_relaxation_unless_the_yield_reads_the_moisture():
    from pelletdem.loop import Condition, EngineSimulator

    base = {"E_b": 6e7, "sigma_c": 9e6}
    dry, wet = Condition(60e6, mc=8.0), Condition(60e6, mc=20.0)
    with EngineSimulator("tiny") as sim:
        a, b = sim._spec(base, dry, 0), sim._spec(base, wet, 0)
        assert a.preset.contact.moisture_content == 8.0 and b.preset.contact.moisture_content == 20.0
        assert a.relax_key == b.relax_key and a.key != b.key  # the bonds take the moisture
        yielding = dict(base, **{"contact.moisture_yield": 0.03})
        assert sim._spec(yielding, dry, 0).relax_key != sim._spec(yielding, wet, 0).relax_key
        assert sim.same_relaxation(base, dict(base, **{"bond.moisture_coefficient": 0.03}), [dry, wet])
        assert not sim.same_relaxation(base, yielding, [wet])


def test_the_engine_ends_its_tests_at_the_break_when_asked_and_shares_the_relaxed_pellets():
    from pelletdem.loop import Condition, EngineSimulator

    base, cond = {"E_b": 6e7, "sigma_c": 9e6}, Condition(60e6)
    with EngineSimulator("tiny") as sim:
        before = sim._spec(base, cond, 0)
        sim.end_at_break(0.5)
        after = sim._spec(base, cond, 0)
        assert after.preset.break_drop == 0.5 and after.relax_key == before.relax_key and after.key != before.key
        for bad in (0.0, 1.0, float("nan")):
            with pytest.raises(ValueError, match="break_drop"):
                sim.end_at_break(bad)


def test_a_material_s_particle_density_scales_its_bulk_density_and_shares_the_relaxed_pellet():
    from pelletdem.loop import Condition, EngineSimulator
    from pelletdem.loop_simulators import _prediction

    base = {"E_b": 6e7, "sigma_c": 9e6}
    oak, birch = Condition(120e6, 8.0, "oak"), Condition(120e6, 8.0, "birch")
    with EngineSimulator("tiny", particle_density={"birch": 550.0}) as sim:
        assert sim._spec(base, oak, 0).relax_key == sim._spec(base, birch, 0).relax_key
        rho = sim.setup.preset.density
        assert sim._density_factor == {"birch": pytest.approx(550.0 / rho)}
    rec = {"ok": True, "outputs": {"bulk_density_relaxed": 500.0, "sigma_f": 1e6}}
    assert _prediction(rec, 550.0 / 680.0).scalars["bulk_density"] == pytest.approx(500.0 * 550.0 / 680.0)
    assert _prediction(rec).scalars["bulk_density"] == 500.0
    for bad in (0.0, -5.0, float("nan"), "heavy"):
        with pytest.raises(ValueError, match=r"particle_density\[pine\]"):
            EngineSimulator("tiny", particle_density={"pine": bad})


def test_where_the_wood_density_acts_each_material_relaxes_its_own_pellet():
    from pelletdem.loop import Condition, EngineSimulator

    base = {"E_b": 6e7, "sigma_c": 9e6, "contact.wood_density_yield": 1.5}
    oak, birch = Condition(120e6, 8.0, "oak"), Condition(120e6, 8.0, "birch")
    with EngineSimulator("tiny", particle_density={"birch": 550.0, "oak": 675.0}) as sim:
        b = sim._spec(base, birch, 0)
        assert b.preset.contact.wood_density == 550.0
        assert b.relax_key != sim._spec(base, oak, 0).relax_key
        with pytest.raises(ValueError, match="wood_density"):
            sim._spec(base, Condition(120e6, 8.0, "pine"), 0)  # no density given for pine
        with pytest.raises(ValueError, match="contact.wood_density is set by each condition"):
            sim._spec({**base, "contact.wood_density": 500.0}, oak, 0)


def test_the_engine_s_predictions_carry_each_material_s_density():
    from pelletdem.loop import Condition, EngineSimulator

    oak, birch = Condition(120e6, 8.0, "oak"), Condition(120e6, 8.0, "birch")
    with EngineSimulator("tiny", particle_density={"birch": 550.0}) as sim:
        # the engine's records, stood in for: every pellet relaxes to 500 kg/m^3 at the preset's density
        sim.evaluator.run_all = lambda specs: [{"ok": True, "outputs": {"bulk_density_relaxed": 500.0}}
                                               for _ in specs]
        ens = sim.predict({"E_b": 6e7, "sigma_c": 9e6}, [oak, birch], seeds=(0, 1))
        rho = sim.setup.preset.density
    assert ens[oak].scalar("bulk_density") == 500.0
    assert ens[birch].scalar("bulk_density") == pytest.approx(500.0 * 550.0 / rho)
