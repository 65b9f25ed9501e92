"""Checkpoints: a world saved to HDF5 and loaded back continues bit for bit; damaged and foreign
files raise CheckpointError naming the file."""
import h5py
import numpy as np
import pytest

import pelletdem as pd
from pelletdem import checkpoint


def _bonded_pair_bed(threads=1):
    r = pd.truncated_normal_radii(300, seed=5)
    x, r = pd.random_pack_cylinder(r, radius=1.5e-3, z_lo=0.0, z_hi=0.012, seed=6)
    w = pd.World(dt=2e-6, box=((-2e-3, -2e-3, -1e-3), (2e-3, 2e-3, 0.015)), threads=threads)
    w.add_particles(x, r)
    w.add_plane("floor", (0, 0, 0), (0, 0, 1))
    w.add_cylinder("mould", (0, 0, 0), 1.5e-3)
    w.gravity = (0, 0, -9.81e4)  # settle fast
    w.run(6000)
    w.create_bonds(pd.BondLaw(youngs_modulus=20e6, sigma_c=2e5, tau_c=2e5, gap_tolerance=1e-5))
    w.run(500)
    return w


def test_restart_from_a_checkpoint_is_bit_identical(tmp_path):
    w = _bonded_pair_bed()
    path = checkpoint.save_world(w, tmp_path / "ck.h5", extra={"stage": "test"})
    b = checkpoint.load_world(path)
    assert b.n == w.n and b.bond_count == w.bond_count
    w.run(2000)
    b.run(2000)
    assert np.array_equal(np.asarray(w.x), np.asarray(b.x))
    assert np.array_equal(np.asarray(w.w), np.asarray(b.w))
    assert w.intact_bond_count() == b.intact_bond_count()
    assert np.array_equal(w.broken_bonds()["time"], b.broken_bonds()["time"])
    assert b.time == w.time and b.step_count == w.step_count


def test_extra_metadata_round_trips(tmp_path):
    w = _bonded_pair_bed()
    path = checkpoint.save_world(w, tmp_path / "ck.h5", extra={"stage": "bond", "n": 3})
    _, extra = checkpoint.read_state(path)
    assert extra == {"stage": "bond", "n": 3}


def test_truncated_checkpoint_is_a_clear_error(tmp_path):
    w = _bonded_pair_bed()
    path = checkpoint.save_world(w, tmp_path / "ck.h5")
    data = open(path, "rb").read()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(checkpoint.CheckpointError, match="cut.h5"):
        checkpoint.load_world(cut)


def test_foreign_and_missing_files_are_clear_errors(tmp_path):
    foreign = tmp_path / "other.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = np.zeros(3)
    with pytest.raises(checkpoint.CheckpointError, match="not a pelletdem checkpoint"):
        checkpoint.load_world(foreign)
    with pytest.raises(checkpoint.CheckpointError, match="no such file"):
        checkpoint.load_world(tmp_path / "missing.h5")


def test_a_failed_save_leaves_the_previous_checkpoint_whole(tmp_path, monkeypatch):
    w = _bonded_pair_bed()
    path = checkpoint.save_world(w, tmp_path / "ck.h5")
    before = open(path, "rb").read()
    w.run(100)

    def dies(*args, **kwargs):
        raise KeyboardInterrupt("killed while writing")

    monkeypatch.setattr(h5py.Group, "create_dataset", dies)
    with pytest.raises(KeyboardInterrupt):
        checkpoint.save_world(w, path)
    monkeypatch.undo()
    assert open(path, "rb").read() == before
    assert [p.name for p in tmp_path.iterdir()] == ["ck.h5"]  # no temporary left behind


def test_random_bytes_and_damaged_files_are_clear_errors(tmp_path):
    rng = np.random.default_rng(0)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())
    with pytest.raises(checkpoint.CheckpointError, match="junk.h5.*not a readable HDF5 file"):
        checkpoint.load_world(junk)
    # A whole HDF5 file of the right format with a part missing inside.
    path = checkpoint.save_world(_bonded_pair_bed(), tmp_path / "ck.h5")
    with h5py.File(path, "a") as f:
        del f["x"]
    with pytest.raises(checkpoint.CheckpointError, match="ck.h5.*(damaged|does not load)"):
        checkpoint.load_world(path)
    # A pelletdem file of another kind: a run checkpoint is not a world checkpoint.
    run_ck = tmp_path / "run.h5"
    with h5py.File(run_ck, "w") as f:
        f.attrs["format"] = checkpoint.RUN_FORMAT
    with pytest.raises(checkpoint.CheckpointError, match="not a pelletdem checkpoint"):
        checkpoint.load_world(run_ck)


def test_a_saved_world_keeps_its_time_series_and_sample_interval(tmp_path):
    w = _bonded_pair_bed()
    w.set_sample_interval(7)
    w.clear_samples()
    w.run(70)
    b = checkpoint.load_world(checkpoint.save_world(w, tmp_path / "ck.h5"))
    assert b.sample_interval == 7
    for x in (w, b):
        x.run(70)
    for key, series in w.samples().items():
        assert np.array_equal(series, b.samples()[key]), key
    for k in range(w.wall_count):
        for key, series in w.wall_samples(k).items():
            assert np.array_equal(series, b.wall_samples(k)[key]), (k, key)
    assert len(b.samples()["time"]) == 20
    b.clear_samples()
    assert len(b.samples()["time"]) == 0


# --- checkpointed pellet runs (pipeline.run_pellet with a RunCheckpoint) ---------------------------

STAGES = ["fill", "compact", "unload", "demould", "relax", "bond", "diametral"]


class Killed(BaseException):
    """Stands for SIGKILL: raised right after a chosen checkpoint write, caught by nobody."""


def _tiny_run(tiny_life, ck):
    """run_pellet with the arguments that reproduce the shared tiny pellet (see test_cli)."""
    from dataclasses import asdict

    from pelletdem import pipeline
    from pelletdem.presets import get_preset

    return pipeline.run_pellet(get_preset("tiny").with_(max_dLD=tiny_life.max_dLD), material="oak", mc=8,
                               sigma_z_mpa=tiny_life.sigma_z / 1e6, seed=0, threads=1,
                               bond_law=pd.BondLaw(**asdict(tiny_life.bond_law)), progress=False, checkpoint=ck)


def assert_same_result(res, ref):
    """Bit for bit: every stage's scalars, steps and series, every snapshot, the params."""
    assert list(res.stages) == list(ref.stages) == STAGES
    for name in STAGES:
        a, b = res.stages[name], ref.stages[name]
        assert a.scalars == b.scalars, name
        assert a.steps == b.steps, name
        assert sorted(a.series) == sorted(b.series), name
        for key in a.series:
            assert np.array_equal(a.series[key], b.series[key]), (name, key)
    assert list(res.snapshots) == list(ref.snapshots)
    for name, snap in ref.snapshots.items():
        for key, value in snap.items():
            assert np.array_equal(res.snapshots[name][key], value), (name, key)


def _kill_when(monkeypatch, predicate):
    """Make RunCheckpoint raise Killed right after the first write for which
    predicate(result, progress) holds (the file on disk is then that checkpoint)."""
    original = checkpoint.RunCheckpoint._write

    def write(self, result, pellet, world_state, progress):
        original(self, result, pellet, world_state, progress)
        if predicate(result, progress):
            raise Killed

    monkeypatch.setattr(checkpoint.RunCheckpoint, "_write", write)


def test_checkpoints_inside_stages_do_not_change_the_result(tiny_life, tmp_path):
    """A checkpoint after every chunk (~10 per second, interval 0) gives the same bits as the
    shared pellet, which ran without any."""
    ck = checkpoint.RunCheckpoint(tmp_path / "ck.h5", {"run": "tiny"}, interval=0.0)
    res = _tiny_run(tiny_life, ck)
    assert ck.n_saved > 30  # stage ends plus many inside stages
    assert_same_result(res, tiny_life.result)
    saved = checkpoint.RunCheckpoint(tmp_path / "ck.h5", {"run": "tiny"}).resume()
    assert saved.stages_done == STAGES and saved.progress is None


# Where a kill lands: inside the demould stage after its first run has finished (the resumed
# stage replays that run from the file, then the one under way), or right at a stage end.
KILL_POINTS = {
    "demould, second run": lambda res, pr: pr is not None and pr["stage"] == "demould" and len(pr["runs"]) == 1,
    "fill, first run": lambda res, pr: pr is not None and pr["stage"] == "fill",
    "compact": lambda res, pr: pr is not None and pr["stage"] == "compact" and pr["mid"]["done"] > 5000,
    "unload, first run": lambda res, pr: pr is not None and pr["stage"] == "unload" and not pr["runs"],
    "end of relax": lambda res, pr: pr is None and list(res.stages)[-1:] == ["relax"],
    "bond": lambda res, pr: pr is not None and pr["stage"] == "bond",
    "diametral": lambda res, pr: pr is not None and pr["stage"] == "diametral" and pr["mid"]["done"] > 3000,
}


@pytest.mark.parametrize("where", [pytest.param(k, marks=[] if k == "demould, second run" else pytest.mark.slow)
                                   for k in KILL_POINTS])
def test_a_killed_run_resumes_to_the_same_bits(where, tiny_life, tmp_path, monkeypatch):
    path = tmp_path / "ck.h5"
    _kill_when(monkeypatch, KILL_POINTS[where])
    with pytest.raises(Killed):
        _tiny_run(tiny_life, checkpoint.RunCheckpoint(path, {"run": "tiny"}, interval=0.0))
    monkeypatch.undo()
    saved = checkpoint.RunCheckpoint(path, {"run": "tiny"}).resume()
    assert saved is not None
    # Resumed with another interval: checkpointing never enters the physics.
    ck = checkpoint.RunCheckpoint(path, {"run": "tiny"}, interval=0.05)
    res = _tiny_run(tiny_life, ck)
    assert_same_result(res, tiny_life.result)
    assert res.params["total_wall_time_s"] >= saved.wall_time_s


def test_a_checkpoint_of_another_run_is_refused(tmp_path):
    path = tmp_path / "ck.h5"
    ck = checkpoint.RunCheckpoint(path, {"seed": 0, "preset": "tiny"})
    from pelletdem.result import Result

    ck._write(Result(params={}, seed=0, version="x"), checkpoint._pellet_fields(None), None, None)
    msg = r"another run \(seed: 0 in the checkpoint, 1 now\).*--restart"
    with pytest.raises(checkpoint.CheckpointError, match=msg):
        checkpoint.RunCheckpoint(path, {"seed": 1, "preset": "tiny"}).resume()
    assert checkpoint.RunCheckpoint(path, {"seed": 0, "preset": "tiny"}).resume().stages_done == []
    assert checkpoint.RunCheckpoint(tmp_path / "none.h5", {}).resume() is None


@pytest.mark.parametrize("damage", ["truncated", "random bytes", "world checkpoint", "result file", "part missing"])
def test_a_damaged_or_foreign_run_checkpoint_is_a_clear_error(damage, tmp_path):
    from pelletdem.result import Result

    path = tmp_path / "ck.h5"
    ck = checkpoint.RunCheckpoint(path, {"a": 1})
    w = _bonded_pair_bed()
    pellet_fields = {"walls": {"floor": 0}, "snapshots": {}, "mould_radius": 1.5e-3, "mass": 1e-4,
                     "h0": 1e-2, "diameter": 3e-3, "height": 1e-2}
    ck._write(Result(params={}, seed=0, version="x"), pellet_fields, w.get_state(), None)
    data = path.read_bytes()
    if damage == "truncated":
        path.write_bytes(data[: len(data) // 3])
    elif damage == "random bytes":
        path.write_bytes(np.random.default_rng(1).integers(0, 256, len(data), dtype=np.uint8).tobytes())
    elif damage == "world checkpoint":
        checkpoint.save_world(w, path)
    elif damage == "result file":
        Result(params={}, seed=0, version="x").save(path, xdmf=False)
    else:
        with h5py.File(path, "a") as f:
            del f["pellet"]
    with pytest.raises(checkpoint.CheckpointError, match="ck.h5"):
        checkpoint.RunCheckpoint(path, {"a": 1}).resume()


@pytest.mark.parametrize("interval", [-1.0, float("nan"), "soon", None])
def test_checkpoint_interval_is_checked(interval, tmp_path):
    with pytest.raises(pd.ParameterError, match="checkpoint interval"):
        checkpoint.RunCheckpoint(tmp_path / "ck.h5", {}, interval=interval)


def test_a_small_pellet_killed_in_every_stage_resumes_to_the_same_bits(tmp_path, monkeypatch):
    """The tiny preset with 60 particles (a few seconds a run; also run under the sanitizers):
    killed inside each stage in turn, each time resumed from the file, ending where a run never
    stopped ends."""
    from pelletdem import pipeline

    def run(ck=None):
        return pipeline.run_pellet("tiny", n_particles=60, seed=3, threads=1, progress=False, checkpoint=ck)

    ref = run()
    path = tmp_path / "ck.h5"
    for stage in STAGES:
        # Kill at the first save inside `stage` (or at its end when it is too short to have one).
        _kill_when(monkeypatch, lambda res, pr, stage=stage: (pr is not None and pr["stage"] == stage)
                   or list(res.stages)[-1:] == [stage])
        with pytest.raises(Killed):
            run(checkpoint.RunCheckpoint(path, {"n": 60}, interval=0.0))
        monkeypatch.undo()
    res = run(checkpoint.RunCheckpoint(path, {"n": 60}, interval=0.0))
    assert_same_result(res, ref)


@pytest.mark.parametrize("seed", [0, 3, 6])
def test_a_restored_bonded_pellet_takes_the_next_step_with_the_same_bits(seed):
    """Bonds made between two list builds, then the state saved and restored: the restored
    world groups its bonded pairs as the saved one did (by the pairs' contact at the list
    build, whose positions the state carries) and its next force pass adds the pairs' loads in
    the same order. Grouped by the positions at the moment of mapping, 3 of these 8 bonded
    60-particle pellets differed in the last bits of their forces right after the restore."""
    from pelletdem import pipeline

    pellet, _ = pipeline.relaxed_pellet("tiny", n_particles=60, seed=seed, threads=1, progress=False)
    w = pellet.world
    w.create_bonds(pipeline.bond_law_for("oak", 8, 120).to_core())
    w.set_adhesion_ramp(w.time, 0.004)
    w.run(500)
    b = pd.World.from_state(w.get_state(), threads=1)
    for _ in range(50):
        w.step()
        b.step()
        assert np.array_equal(np.array(w.f), np.array(b.f)) and np.array_equal(np.array(w.t), np.array(b.t))
