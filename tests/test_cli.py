"""The command line (`pelletdem run`) and the pipeline entry points it calls.

One CLI run of the 'tiny' preset (the paper's Table 5 oak bonds) in a subprocess, shared by
the tests of its outputs; bad arguments are checked in-process (they exit before any work).
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from dataclasses import asdict

import h5py
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
    (["run", "--out", "x", "--checkpoint-interval", "-1"], "--checkpoint-interval"),
    (["run", "--out", "x", "--checkpoint-interval", "nan"], "--checkpoint-interval"),
    (["run", "--out", "x", "--checkpoint-interval", "soon"], "--checkpoint-interval"),
    (["run", "--out", "x", "--sigma-z", "nan"], "--sigma-z"),
    (["run", "--out", "x", "--sigma-z", "2000", "--E-b", "30", "--sigma-c", "9"], "--sigma-z"),
    (["run", "--out", "x", "--E-b", "30"], "--sigma-c"),
    (["run", "--out", "x", "--tau-c", "9"], "--tau-c"),
    (["run", "--out", "x", "--E-b", "-3", "--sigma-c", "9"], "--E-b"),
    (["run", "--out", "x", "--E-b", "30", "--sigma-c", "inf"], "--sigma-c"),
    (["run", "--out", "x", "--r-b", "0"], "--r-b"),
    (["run", "--out", "x", "--max-dld", "0.7"], "--max-dld"),
    (["run", "--out", "x", "--max-dld", "0"], "--max-dld"),
    (["run", "--out", "x", "--break-drop", "1"], "--break-drop"),
    (["run", "--out", "x", "--break-drop", "nan"], "--break-drop"),
    (["run", "--out", "", "--preset", "tiny"], "--out"),
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


# --- checkpoints: resume, refuse another run, restart, survive kills ----------------------------

def _cli(out, *extra, timeout=900):
    return subprocess.run([sys.executable, "-m", "pelletdem.cli", "run", "--preset", "tiny", "--out", str(out),
                           "--quiet", "--threads", "1", *extra], capture_output=True, text=True,
                          timeout=timeout, env=_env())


def _start(out, *extra):
    return subprocess.Popen([sys.executable, "-m", "pelletdem.cli", "run", "--preset", "tiny", "--out", str(out),
                             "--quiet", "--threads", "1", *extra], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env=_env())


def _kill_after(out, delay, sig=signal.SIGKILL, extra=("--checkpoint-interval", "0.3")):
    """Start the tiny run and send `sig` after `delay` s; returns its exit status (negative:
    killed by that signal; 0: it finished first)."""
    proc = _start(out, *extra)
    try:
        proc.wait(timeout=delay)
    except subprocess.TimeoutExpired:
        proc.send_signal(sig)
        proc.wait(timeout=120)
    proc.stderr.close()
    return proc.returncode


def _final(out):
    """summary.json and every snapshot array of result.h5 in `out`."""
    summary = json.loads((out / "summary.json").read_text())
    with h5py.File(out / "result.h5", "r") as f:
        arrays = {f"{name}/{key}": f[f"snapshots/{name}/{key}"][()] for name in f["snapshots"]
                  for key in f[f"snapshots/{name}"]}
        arrays["diametral/sigma_1"] = f["stages/diametral/series/sigma_1"][()]
    return summary, arrays


def assert_same_run(out, ref):
    """sigma_f and dL_f/D in summary.json equal, and every snapshot (positions, velocities,
    forces, ...) and the sigma_1 curve in result.h5 equal bit for bit."""
    (s, a), (s_ref, a_ref) = _final(out), _final(ref)
    assert (s["sigma_f_mpa"], s["dLf_D"]) == (s_ref["sigma_f_mpa"], s_ref["dLf_D"])
    assert s["steps"] == s_ref["steps"]
    assert sorted(a) == sorted(a_ref)
    for key, value in a_ref.items():
        assert np.array_equal(a[key], value), key
    assert not [p.name for p in out.iterdir() if p.name.startswith(".tmp-")]


def test_rerunning_a_finished_run_resumes_from_its_last_checkpoint(cli_run, tmp_path):
    ref, _ = cli_run
    out = tmp_path / "again"
    shutil.copytree(ref, out)
    proc = _cli(out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert_same_run(out, ref)


def test_another_run_in_the_same_directory_is_refused_and_restart_discards(cli_run, tmp_path):
    ref, _ = cli_run
    out = tmp_path / "other"
    shutil.copytree(ref, out)
    before = (out / "result.h5").read_bytes()
    proc = _cli(out, "--seed", "1")
    assert proc.returncode == 2
    assert "another run (seed: 0 in the checkpoint, 1 now" in proc.stderr and "--restart" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert (out / "result.h5").read_bytes() == before
    proc = _cli(out, "--seed", "1", "--particles", "60", "--restart")
    assert proc.returncode == 0, proc.stderr[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert (s["seed"], s["n_particles"]) == (1, 60)


def test_explicit_bonds_at_a_pressure_table_5_lacks(tmp_path):
    """--E-b/--sigma-c (MPa) and --r-b (um) set the bonds, so any pressure runs; the summary says
    where the bonds came from and has no measured values to compare; another bond law in the
    same directory is refused, like any other change of the run."""
    out = tmp_path / "p90"
    args = ["--sigma-z", "90", "--E-b", "30", "--sigma-c", "9", "--tau-c", "12", "--r-b", "25",
            "--max-dld", "0.04", "--particles", "150"]
    proc = _cli(out, *args)
    assert proc.returncode == 0, proc.stderr[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["sigma_z_mpa"] == 90.0 and s["bond"]["source"] == "command line"
    assert s["measured_sigma_f_mpa"] is None and s["measured_dLf_D"] is None
    res = Result.load(out / "result.h5")
    law = res.params["bond"]
    assert (law["youngs_modulus"], law["sigma_c"], law["tau_c"]) == (30e6, 9e6, 12e6)
    assert law["radius"] == pytest.approx(25e-6, rel=1e-12)
    assert res.params["sigma_z"] == 90e6 and res.params["preset"]["max_dLD"] == 0.04
    assert res.scalar("compact", "sigma_z_reached") >= 90e6
    assert res.series("diametral", "dL_D")[-1] == pytest.approx(0.04, abs=2e-3)
    proc = _cli(out, *args[:-4], "--E-b", "31", *args[-4:])
    assert proc.returncode == 2 and "E_b" in proc.stderr and "Traceback" not in proc.stderr


def test_a_run_killed_with_sigkill_resumes_to_the_same_bits(cli_run, tmp_path):
    ref, _ = cli_run
    out = tmp_path / "killed"
    assert _kill_after(out, 4.0) == -signal.SIGKILL
    assert (out / "checkpoint.h5").is_file() and not (out / "result.h5").exists()
    proc = _cli(out, "--checkpoint-interval", "0.3")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert_same_run(out, ref)


# When the run is killed, as fractions of an uninterrupted run's duration (the reference run's
# time plus ~1.5 s to start the interpreter): they land in every stage, some during a write.
KILL_FRACTIONS = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.97]


@pytest.mark.slow
def test_sigkill_at_many_moments_and_repeated_kills(cli_run, tmp_path):
    ref, _ = cli_run
    duration = json.loads((ref / "summary.json").read_text())["total_wall_time_s"] + 1.5
    outcomes = []
    for k, fraction in enumerate(KILL_FRACTIONS):
        delay = round(fraction * duration, 2)
        out = tmp_path / f"k{k}"
        rc = _kill_after(out, delay)
        stage = "-"
        if (out / "checkpoint.h5").exists():
            with h5py.File(out / "checkpoint.h5", "r") as f:
                done = json.loads(f.attrs["stages_done"])
                stage = f"after {done[-1] if done else 'start'}" + (
                    f", inside {f['progress'].attrs['stage']}" if "progress" in f else "")
        # every other one is killed again in its resumed run before it may finish
        rc2 = _kill_after(out, round(0.3 * duration, 2)) if k % 2 and rc == -signal.SIGKILL else None
        proc = _cli(out, "--checkpoint-interval", "0.3")
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert_same_run(out, ref)
        outcomes.append((delay, rc, stage) + (() if rc2 is None else (f"killed again: {rc2}",)))
    print("kill outcomes (delay s, exit status, checkpoint at the kill):", outcomes)
    # The machine's load moves the kills about; most must land before the run ends.
    assert sum(o[1] == -signal.SIGKILL for o in outcomes) >= 6


@pytest.mark.slow
def test_ctrl_c_leaves_a_resumable_run(cli_run, tmp_path):
    ref, _ = cli_run
    out = tmp_path / "sigint"
    rc = _kill_after(out, 5.0, sig=signal.SIGINT)
    assert rc != 0  # KeyboardInterrupt: exit status 1 (or -SIGINT)
    proc = _cli(out, "--checkpoint-interval", "0.3")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert_same_run(out, ref)


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
