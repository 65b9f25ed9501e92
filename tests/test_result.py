"""Result: the HDF5 round trip, the XDMF file beside it, damaged and foreign files, atomic
saves, and summary(). The Result is the shared 'tiny' pellet life (conftest.py `tiny_life`)."""
from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

import pelletdem
from pelletdem import result as result_mod
from pelletdem.result import FORMAT, Result, ResultFileError
from pelletdem.stages import StageResult


@pytest.fixture(scope="module")
def res(tiny_life):
    return tiny_life.result


@pytest.fixture(scope="module")
def saved(res, tmp_path_factory):
    """The Result saved once (HDF5 + XDMF); tests copy it before changing anything."""
    path = tmp_path_factory.mktemp("saved") / "result.h5"
    assert res.save(path) == str(path)
    return path


def assert_results_equal(a: Result, b: Result):
    assert a.seed == b.seed
    assert a.version == b.version
    assert a.params == b.params
    assert list(a.stages) == list(b.stages)  # stage order kept
    for name in a.stages:
        sa, sb = a.stages[name], b.stages[name]
        assert sa.name == sb.name == name
        assert sa.steps == sb.steps
        assert sa.wall_time_s == sb.wall_time_s
        assert sa.scalars.keys() == sb.scalars.keys(), name
        for k in sa.scalars:
            assert float(sa.scalars[k]) == float(sb.scalars[k]) or (
                np.isnan(sa.scalars[k]) and np.isnan(sb.scalars[k])), f"{name}.{k}"
        assert sa.series.keys() == sb.series.keys(), name
        for k in sa.series:
            x, y = np.asarray(sa.series[k]), np.asarray(sb.series[k])
            assert x.shape == y.shape, f"{name}.{k}"
            assert x.dtype == y.dtype, f"{name}.{k}"
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f"{name}.{k}"
    assert list(a.snapshots) == list(b.snapshots)
    for name in a.snapshots:
        assert a.snapshots[name].keys() == b.snapshots[name].keys(), name
        for k, v in a.snapshots[name].items():
            w = b.snapshots[name][k]
            if np.ndim(v) == 0:
                assert float(v) == float(w), f"{name}.{k}"
            else:
                assert np.asarray(v).dtype == np.asarray(w).dtype
                assert np.array_equal(v, w), f"{name}.{k}"


# --- round trip -------------------------------------------------------------------------------

def test_round_trip_keeps_everything(res, saved):
    loaded = Result.load(saved)
    assert_results_equal(res, loaded)
    # Spot checks of what the stages need downstream.
    assert loaded.scalar("diametral", "sigma_f") == res.scalar("diametral", "sigma_f")
    assert np.array_equal(loaded.series("compact", "sigma_z"), res.series("compact", "sigma_z"))
    assert loaded.params["bond"]["youngs_modulus"] == res.params["bond"]["youngs_modulus"]
    assert loaded.params["preset"]["name"] == "tiny"
    assert loaded.snapshots["relax"]["position"].shape == (400, 3)
    assert isinstance(loaded.stages["fill"], StageResult)


def test_round_trip_of_a_hand_made_result(tmp_path):
    """Values a run does not produce: NaN scalars, integer and empty series, nested params."""
    r = Result(params={"a": 1, "b": [1.5, 2.5], "c": {"d": None, "e": "text"}, "f": np.float64(2.0)},
               seed=7, version="9.9")
    r.stages["one"] = StageResult("one", series={"t": np.linspace(0, 1, 5), "n": np.arange(5),
                                                 "empty": np.zeros(0)},
                                  scalars={"x": 1.25, "nan": float("nan")}, wall_time_s=0.5, steps=3)
    r.stages["two"] = StageResult("two")
    r.snapshots["one"] = {"position": np.ones((2, 3)), "radius": np.array([1e-4, 2e-4]), "time": 0.25}
    p = r.save(tmp_path / "hand.h5")
    back = Result.load(p)
    assert back.params == {"a": 1, "b": [1.5, 2.5], "c": {"d": None, "e": "text"}, "f": 2.0}
    r.params["f"] = 2.0
    assert_results_equal(r, back)
    assert list(back.stages) == ["one", "two"]


def test_save_without_xdmf(res, tmp_path):
    p = res.save(tmp_path / "r.h5", xdmf=False)
    assert os.path.exists(p)
    assert not os.path.exists(tmp_path / "r.xdmf")


def test_save_creates_the_directory(res, tmp_path):
    p = res.save(tmp_path / "a" / "b" / "r.h5")
    assert os.path.exists(p)
    assert os.path.exists(tmp_path / "a" / "b" / "r.xdmf")


def test_file_is_tagged(saved):
    with h5py.File(saved, "r") as f:
        assert f.attrs["format"] == FORMAT
        assert f.attrs["version"] == pelletdem.__version__
        assert json.loads(f.attrs["params"])["preset"]["name"] == "tiny"


# --- XDMF -------------------------------------------------------------------------------------

def test_xdmf_is_well_formed_and_points_at_the_datasets(res, saved):
    xdmf = saved.with_suffix(".xdmf")
    root = ET.parse(xdmf).getroot()  # raises on malformed XML
    assert root.tag == "Xdmf"
    collection = root.find("Domain/Grid")
    assert collection.get("GridType") == "Collection"
    assert collection.get("CollectionType") == "Temporal"
    grids = collection.findall("Grid")
    assert [g.get("Name") for g in grids] == list(res.snapshots)
    times = [float(g.find("Time").get("Value")) for g in grids]
    assert times == sorted(times) and len(set(times)) == len(times)
    with h5py.File(saved, "r") as f:
        n_items = 0
        for g in grids:
            snap = res.snapshots[g.get("Name")]
            n = len(snap["radius"])
            topo = g.find("Topology")
            assert topo.get("TopologyType") == "Polyvertex"
            assert int(topo.get("NumberOfElements")) == n
            assert g.find("Geometry").get("GeometryType") == "XYZ"
            names = {a.get("Name") for a in g.findall("Attribute")}
            assert {"radius", "velocity", "force"} <= names
            for item in g.iter("DataItem"):
                n_items += 1
                assert item.get("Format") == "HDF"
                file_part, _, dataset = item.text.strip().partition(":")
                # The HDF5 file is named relative to the XDMF file, and exists.
                assert os.path.exists(os.path.join(os.path.dirname(xdmf), file_part))
                assert os.path.samefile(os.path.join(os.path.dirname(xdmf), file_part), saved)
                assert dataset in f, dataset
                dims = tuple(int(d) for d in item.get("Dimensions").split())
                assert f[dataset].shape == dims, dataset
                assert dims[0] == n
                assert item.get("NumberType") == "Float"
                assert f[dataset].dtype == np.float64 and item.get("Precision") == "8"
        assert n_items == sum(2 + sum(k in s for k in ("velocity", "force", "angular_velocity"))
                              for s in res.snapshots.values())


# --- damaged, foreign and missing files --------------------------------------------------------

@pytest.mark.parametrize("keep", [0.0, 0.001, 0.1, 0.5, 0.9, 0.999])
def test_truncated_file_raises(saved, tmp_path, keep):
    data = saved.read_bytes()
    p = tmp_path / "cut.h5"
    p.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(ResultFileError, match="cut.h5"):
        Result.load(p)


@pytest.mark.parametrize("where", [0.05, 0.2, 0.5, 0.8])
def test_damaged_file_raises_result_file_error(saved, tmp_path, where):
    """Bytes zeroed inside the file: either HDF5 or the reader notices, and the error is a
    ResultFileError (or the damage hit unused space and the file still loads)."""
    data = bytearray(saved.read_bytes())
    i = int(len(data) * where)
    data[i:i + 4096] = bytes(min(4096, len(data) - i))
    p = tmp_path / "damaged.h5"
    p.write_bytes(bytes(data))
    try:
        Result.load(p)
    except ResultFileError as e:
        assert "damaged.h5" in str(e)


def test_foreign_hdf5_files_raise(tmp_path):
    empty = tmp_path / "empty.h5"
    with h5py.File(empty, "w"):
        pass
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.create_dataset("stages/fill/series/time", data=np.arange(3.0))
        f.attrs["seed"] = 1
    wrong = tmp_path / "wrong_format.h5"
    with h5py.File(wrong, "w") as f:
        f.attrs["format"] = "pelletdem-result-999"
    for p in (empty, other, wrong):
        with pytest.raises(ResultFileError, match="not a pelletdem result"):
            Result.load(p)


def test_pelletdem_file_with_missing_parts_raises(saved, tmp_path):
    p = tmp_path / "parts.h5"
    p.write_bytes(saved.read_bytes())
    with h5py.File(p, "a") as f:
        del f.attrs["params"]
    with pytest.raises(ResultFileError, match="damaged"):
        Result.load(p)


def test_non_hdf5_and_missing_files_raise(tmp_path):
    text = tmp_path / "notes.h5"
    text.write_text("not an HDF5 file\n")
    with pytest.raises(ResultFileError, match="not a readable HDF5"):
        Result.load(text)
    with pytest.raises(ResultFileError, match="no such file"):
        Result.load(tmp_path / "missing.h5")
    assert issubclass(ResultFileError, ValueError)


# --- atomic save ------------------------------------------------------------------------------

def _leftovers(directory):
    return sorted(p.name for p in directory.iterdir() if p.name.startswith(".tmp-") or p.suffix == ".tmp")


@pytest.mark.parametrize("failure", [KeyboardInterrupt, OSError])
def test_interrupted_save_leaves_the_previous_file_whole(res, saved, tmp_path, monkeypatch, failure):
    path = tmp_path / "result.h5"
    path.write_bytes(saved.read_bytes())
    before = path.read_bytes()
    calls = {"n": 0}
    real = h5py.Group.create_dataset

    def dies_midway(self, *a, **k):
        calls["n"] += 1
        if calls["n"] > 5:  # a few datasets written, then the process is interrupted
            raise failure("interrupted")
        return real(self, *a, **k)

    monkeypatch.setattr(h5py.Group, "create_dataset", dies_midway)
    with pytest.raises(failure):
        res.save(path)
    monkeypatch.undo()
    assert calls["n"] > 5
    assert path.read_bytes() == before
    assert_results_equal(res, Result.load(path))
    assert _leftovers(tmp_path) == []


def test_failed_rename_leaves_the_previous_file_whole(res, saved, tmp_path, monkeypatch):
    path = tmp_path / "result.h5"
    path.write_bytes(saved.read_bytes())
    before = path.read_bytes()

    def no_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(result_mod.os, "replace", no_replace)
    with pytest.raises(OSError, match="disk full"):
        res.save(path)
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert _leftovers(tmp_path) == []


def test_failed_first_save_leaves_nothing(tmp_path):
    class Unwritable:
        def __array__(self, *a, **k):
            raise RuntimeError("cannot convert")

    r = Result(params={}, seed=0, version="x")
    r.stages["s"] = StageResult("s", series={"bad": Unwritable()})
    with pytest.raises(RuntimeError, match="cannot convert"):
        r.save(tmp_path / "new.h5")
    assert list(tmp_path.iterdir()) == []


# --- summary ----------------------------------------------------------------------------------

def test_summary(res):
    s = res.summary()
    json.dumps(s)  # plain values only
    assert s["seed"] == 0
    assert s["version"] == pelletdem.__version__
    assert s["n_particles"] == 400 and isinstance(s["n_particles"], int)
    assert s["sigma_f_mpa"] == pytest.approx(res.scalar("diametral", "sigma_f") / 1e6, rel=1e-12)
    assert s["dLf_D"] == res.scalar("diametral", "dLf_D")
    assert s["relaxed_bulk_density"] == res.scalar("relax", "bulk_density")
    assert s["relaxed_coordination_number"] == res.scalar("relax", "coordination_number")
    assert s["max_overlap_ratio"] == res.scalar("compact", "max_overlap_ratio")
    assert list(s["wall_time_s"]) == list(res.stages)
    for name, t in s["wall_time_s"].items():
        assert t == pytest.approx(res.stages[name].wall_time_s, abs=1e-3)
    assert s["steps"] == {k: v.steps for k, v in res.stages.items()}
    # Physically sensible headline numbers for the tiny pellet.
    assert 0 < s["sigma_f_mpa"] < 10
    assert 0 < s["dLf_D"] < 0.15
    assert 200 < s["relaxed_bulk_density"] < 1200
    assert 3 < s["relaxed_coordination_number"] < 12


def test_summary_of_a_partial_result(res):
    part = Result(params={}, seed=5, version="v", stages={k: res.stages[k] for k in ("fill", "compact")})
    s = part.summary()
    assert s["n_particles"] == 400
    assert "sigma_f_mpa" not in s and "relaxed_bulk_density" not in s
    assert list(s["wall_time_s"]) == ["fill", "compact"]
    assert Result(params={}, seed=1, version="v").summary() == {
        "seed": 1, "version": "v", "wall_time_s": {}, "steps": {}}
