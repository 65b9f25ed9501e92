"""The command line (`pelletdem run`) and the pipeline entry points it calls.

One CLI run of the 'tiny' preset (the paper's Table 5 oak bonds) in a subprocess, shared by
the tests of its outputs; bad arguments are checked in-process (they exit before any work).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import asdict

import numpy as np
import pytest

from pelletdem import cli, pipeline
from pelletdem.engine import BondLaw
from pelletdem.measured import best_fit_dem
from pelletdem.presets import get_preset
from pelletdem.result import Result

STAGES = ["fill", "compact", "unload", "demould", "relax", "bond", "diametral"]
PLOTS = ["fig5_stress_deformation.png", "fig9_compaction.png", "fig10_coordination.png",
         "fig15_fit.png", "fig16_crack_map.png"]


def _env():
    env = dict(os.environ)
    env.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    env["MPLBACKEND"] = "Agg"
    env.pop("DISPLAY", None)
    return env


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "pelletdem.cli", "run", "--preset", "tiny", "--out", str(out),
         "--quiet", "--threads", "1"],
        capture_output=True, text=True, timeout=900, env=_env())
    assert proc.returncode == 0, proc.stderr[-4000:]
    return out, proc


def test_cli_writes_result_files(cli_run):
    out, _ = cli_run
    for name in ["result.h5", "result.xdmf", "summary.json"] + PLOTS:
        assert (out / name).is_file(), name
        assert (out / name).stat().st_size > 0, name
    for name in PLOTS:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    # Nothing half-written is left behind.
    assert not [p.name for p in out.iterdir() if p.name.startswith(".tmp-") or p.suffix == ".tmp"]


def test_cli_summary(cli_run):
    out, proc = cli_run
    s = json.loads((out / "summary.json").read_text())
    for key in ("sigma_f_mpa", "dLf_D", "relaxed_bulk_density", "relaxed_coordination_number",
                "n_particles", "seed", "wall_time_s"):
        assert key in s, key
    assert s["n_particles"] == 400
    assert s["seed"] == 0
    assert s["preset"] == "tiny"
    assert (s["material"], s["mc_percent"], s["sigma_z_mpa"]) == ("oak", 8, 120)
    assert list(s["wall_time_s"]) == STAGES
    assert all(t >= 0 for t in s["wall_time_s"].values())
    assert s["total_wall_time_s"] >= sum(s["wall_time_s"].values()) - 0.1
    assert sorted(s["plots"]) == sorted(PLOTS)
    # Table 3, oak MC 8 % 120 MPa, for comparison.
    assert s["measured_sigma_f_mpa"] == pytest.approx(1.346)
    assert 0 < s["sigma_f_mpa"] < 10
    assert 0 < s["dLf_D"] <= 0.1 + 1e-3
    assert 200 < s["relaxed_bulk_density"] < 1200
    assert 3 < s["relaxed_coordination_number"] < 12
    # What was printed is what was written, and the HDF5 file agrees with both.
    assert json.loads(proc.stdout) == s
    res = Result.load(out / "result.h5")
    for key, value in res.summary().items():
        if key != "wall_time_s":
            assert s[key] == value, key
    assert res.params["bond"]["youngs_modulus"] == 120e6
    assert res.params["bond"]["sigma_c"] == 36e6


def test_cli_quiet_prints_no_progress(cli_run):
    _, proc = cli_run
    assert "step/s" not in proc.stderr and "it/s" not in proc.stderr


def test_cli_run_matches_the_pipeline(cli_run, tiny_life):
    """The CLI's relaxed pellet is the pipeline's (same preset, seed 0, one thread): the
    stages before bonding do not depend on the bond law, so they agree bit for bit."""
    out, _ = cli_run
    res = Result.load(out / "result.h5")
    ref = tiny_life.result
    for name in ("fill", "compact", "unload", "demould", "relax"):
        assert res.stages[name].scalars == ref.stages[name].scalars, name
        assert res.stages[name].steps == ref.stages[name].steps, name
    assert np.array_equal(res.snapshots["relax"]["position"], ref.snapshots["relax"]["position"])


# --- bad arguments ------------------------------------------------------------------------------

@pytest.mark.parametrize("argv, name", [
    (["run", "--preset", "huge", "--out", "x"], "--preset"),
    (["run", "--out", "x", "--sigma-z", "90"], "--sigma-z"),
    (["run", "--out", "x", "--mc", "10"], "--mc"),
    (["run", "--out", "x", "--material", "teak"], "--material"),
    (["run", "--out", "x", "--threads", "0"], "--threads"),
    (["run", "--out", "x", "--threads", "two"], "--threads"),
    (["run", "--out", "x", "--particles", "0"], "--particles"),
    (["run", "--out", "x", "--seed", "-1"], "--seed"),
    (["run", "--out", "x", "--seed", "1.5"], "--seed"),
    (["run", "--preset", "tiny"], "--out"),
    (["fly"], "command"),
    ([], "command"),
])
def test_bad_arguments_exit_nonzero_naming_the_argument(argv, name, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)

    def no_run(*a, **k):
        raise AssertionError("a simulation started despite a bad argument")

    monkeypatch.setattr(pipeline, "run_pellet", no_run)
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code != 0
    err = capsys.readouterr().err
    assert name in err, err
    assert not (tmp_path / "x").exists()


def test_bad_argument_in_a_subprocess(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pelletdem.cli", "run", "--out", str(tmp_path / "o"),
                           "--sigma-z", "100"], capture_output=True, text=True, timeout=120, env=_env())
    assert proc.returncode != 0
    assert "--sigma-z" in proc.stderr
    assert "100" in proc.stderr
    assert not (tmp_path / "o").exists()


# --- pipeline ------------------------------------------------------------------------------------

def test_bond_law_for_is_table_5():
    law = pipeline.bond_law_for("oak", 8, 120)
    assert law.youngs_modulus == 120e6
    assert law.sigma_c == 36e6
    assert law.tau_c == 36e6  # the paper: tensile strength = shear strength
    assert law.radius == 20e-6
    for row in best_fit_dem().to_dict("records"):
        law = pipeline.bond_law_for(row["material"], row["mc_percent"], row["sigma_z_mpa"])
        assert law.youngs_modulus == pytest.approx(row["e_b_mpa"] * 1e6, rel=1e-12)
        assert law.sigma_c == pytest.approx(row["sigma_c_mpa"] * 1e6, rel=1e-12)
    assert pipeline.bond_law_for("oak", 8, 120, radius=1e-5).radius == 1e-5
    with pytest.raises(ValueError, match="material"):
        pipeline.bond_law_for("teak", 8, 120)
    with pytest.raises(ValueError, match="sigma_z"):
        pipeline.bond_law_for("oak", 8, 100)


def test_run_pellet_with_an_explicit_bond_law(tiny_life):
    """run_pellet with the shared pellet's bond law and test length reproduces that pellet's
    life exactly (the law is used, not Table 5's), and records the law in the params."""
    law = BondLaw(**asdict(tiny_life.bond_law))
    preset = get_preset("tiny").with_(max_dLD=tiny_life.max_dLD)
    res = pipeline.run_pellet(preset, material="oak", mc=8, sigma_z_mpa=tiny_life.sigma_z / 1e6,
                              seed=0, threads=1, bond_law=law, progress=False)
    ref = tiny_life.result
    assert res.params["bond"] == asdict(law)
    assert (res.params["material"], res.params["mc_percent"], res.params["sigma_z_mpa"]) == ("oak", 8, 120)
    assert res.params["total_wall_time_s"] > 0
    assert list(res.stages) == STAGES
    for name in STAGES:
        assert res.stages[name].scalars == ref.stages[name].scalars, name
    assert np.array_equal(res.series("diametral", "sigma_1"), ref.series("diametral", "sigma_1"))
    assert res.scalar("bond", "n_bonds") > 0
