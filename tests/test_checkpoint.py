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
