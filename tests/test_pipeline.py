"""pelletdem.pipeline: one piston stroke through several pressures relaxes each pressure's pellet
bit for bit as its own compaction does (the engine steps the same whether a run stops and goes on
or not), and bad pressures are refused before the fill."""
import numpy as np
import pytest

from pelletdem import ParameterError, pipeline, stages
from pelletdem.presets import get_preset

PRESSURES = (60e6, 120e6)  # Pa: the paper's two


def _state(pellet):
    w = pellet.world
    return {name: np.asarray(getattr(w, name)).copy() for name in ("x", "v", "w", "f", "r")}


@pytest.fixture(scope="module")
def stroke():
    """The tiny pellets of both pressures from one stroke, and each from its own (seed 2)."""
    one = pipeline.relaxed_pellets("tiny", PRESSURES, seed=2, progress=False)
    own = [pipeline.relaxed_pellet("tiny", sigma_z=sz, seed=2, progress=False) for sz in PRESSURES]
    return one, own


@pytest.mark.parametrize("k", range(len(PRESSURES)))
def test_each_pressures_pellet_is_its_own_compactions_bit_for_bit(stroke, k):
    (pellet, res), (own_pellet, own_res) = stroke[0][k], stroke[1][k]
    a, b = _state(pellet), _state(own_pellet)
    for name in a:
        assert np.array_equal(a[name], b[name]), name
    assert pellet.world.time == own_pellet.world.time
    assert list(res.stages) == list(own_res.stages) == ["fill", "compact", "unload", "demould", "relax"]
    for name, st in res.stages.items():
        mine = own_res.stages[name]
        assert st.scalars == mine.scalars and st.steps == mine.steps, name
        assert set(st.series) == set(mine.series), name
        for key in st.series:
            assert np.array_equal(st.series[key], mine.series[key]), (name, key)
    assert res.params["sigma_z"] == PRESSURES[k]


def test_the_pressures_are_the_strokes_own(stroke):
    """Each pellet reached its own pressure (Pa) and the higher one is the denser."""
    one, _ = stroke
    reached = [res.stages["compact"].scalars["sigma_z_reached"] for _, res in one]
    assert all(r >= sz for r, sz in zip(reached, PRESSURES))
    dens = [res.stages["relax"].scalars["bulk_density"] for _, res in one]
    assert dens[1] > dens[0]


@pytest.mark.parametrize("sigma_zs", [[], [120e6, 60e6], [60e6, 60e6], [60e6, -1.0], [60e6, 2e9], [60e6, "120"]])
def test_bad_pressures_are_refused_before_any_work(sigma_zs):
    with pytest.raises(ParameterError, match="sigma_z"):
        pipeline.relaxed_pellets("tiny", sigma_zs, progress=False)


def test_compact_through_refuses_pressures_out_of_order_before_moving_the_piston():
    pellet, _ = stages.fill(get_preset("tiny"), seed=1, n_particles=30, progress=False)
    steps = pellet.world.step_count
    with pytest.raises(ParameterError, match="ascending"):
        stages.compact_through(pellet, [120e6, 60e6])
    assert pellet.world.step_count == steps
