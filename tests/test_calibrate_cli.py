"""`pelletdem calibrate OUT_DIR` (calibrate_cli.py) and the library call it makes
(calibration_dir.calibrate_into).

Bad arguments are checked in-process with the calibration replaced by a trap (they exit with
status 2 before any work); the files and the resume are checked with the fast stand-in for the
engine of test_calibrate.py; one real `tiny` calibration of one variant runs in a subprocess
(~10 s) and then again, from its cache, without a simulation.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import types

import numpy as np
import pytest

from pelletdem import calibration_dir, cli
from pelletdem.presets import get_preset
from pelletdem.variants import calibrate_variants
from test_calibrate import CALLS, power_law_runner

FILES = ["calibration.csv", "calibration.json", "fig15_measured_vs_simulated.png", "fig15_curves.png",
         "fig10_relaxed.png",
         "segments.jsonl"]


def _env():
    env = dict(os.environ, OMP_WAIT_POLICY="PASSIVE", MPLBACKEND="Agg")
    env.pop("DISPLAY", None)
    return env


@pytest.fixture
def no_calibration(monkeypatch):
    """calibrate_into replaced: a call records its arguments instead of simulating."""
    calls = []

    def trap(out, **kw):
        calls.append((out, kw))
        return None

    monkeypatch.setattr(calibration_dir, "calibrate_into", trap)
    return calls


def _main(argv):
    try:
        return cli.main(argv)
    except SystemExit as e:  # argparse's usage errors
        return e.code


@pytest.mark.parametrize("extra, name, allowed", [
    (["--workers", "-1"], "--workers", "1..256"),
    (["--workers", "0"], "--workers", "1..256"),
    (["--max-runs", "0"], "--max-runs", "1..100"),
    (["--max-runs", "101"], "--max-runs", "1..100"),
    (["--compaction-runs", "-1"], "--compaction-runs", "0..100"),
    (["--variant", "teak", "8", "120"], "MATERIAL", "birch, oak, pine"),
    (["--variant", "oak", "9", "120"], "MC", "8 or 20"),
    (["--variant", "oak", "8", "nan"], "PRESSURE_MPA", "60 or 120"),
    (["--variant", "oak", "8", "100"], "PRESSURE_MPA", "60 or 120"),
    (["--variant", "oak", "8", "120", "--variant", "oak", "8.0", "120"], "--variant oak 8.0 120", "twice"),
    (["--set", "contact.nope=1"], "contact.nope", "allowed"),
    (["--set", "contact.mu=-1"], "contact.mu", "allowed 0 <= mu"),
    (["--set", "contact.mu=inf"], "contact.mu", "allowed 0 <= mu"),
    (["--set", "bond.sigma_c=9e6"], "bond.sigma_c", "allowed"),
    (["--set", "bond.youngs_modulus=9e6"], "bond.youngs_modulus", "allowed"),
    (["--set", "mu=0.4"], "--set", "contact.NAME"),
    (["--from", "nowhere"], "--from", "calibration.json"),
    (["--dask", " "], "--dask", "tcp://"),
    (["--preset", "huge"], "--preset", "tiny"),
    (["--max-runs", "2.5"], "--max-runs", "int"),
    (["--set", "contact.moisture_content=20"], "contact.moisture_content", "each condition's moisture"),
    (["--packings", "0"], "--packings", "1..64"),
    (["--packings", "65"], "--packings", "1..64"),
    (["--data", "example", "--packings", "1"], "--packings", "2..64"),
    (["--first-packing", "-1"], "--first-packing", "0..1000000"),
    (["--first-packing", "1000001"], "--first-packing", "0..1000000"),
    (["--first-packing", "4", "--data", "example"], "--first-packing", "manifest"),
    (["--set", "contact.wood_density=500"], "contact.wood_density", "particle density"),
    (["--fit", "wood_density_yield=0.3:4"], "--fit", "contact.NAME=LO:HI"),
    (["--fit", "contact.wood_density_yield=4:0.3"], "--fit", "0 < LO < HI"),
    (["--fit", "contact.wood_density_yield=-1:4"], "--fit", "0 < LO < HI or LO < HI < 0"),
    (["--fit", "contact.moisture_yield=-0.1:-0.2"], "--fit", "LO < HI < 0"),
    (["--fit", "contact.wood_density_yield=0.3:40"], "contact.wood_density_yield", "allowed"),
    (["--fit", "contact.k2=1e4:1e5"], "--fit", "k2 is not fitted"),
    (["--fit", "contact.moisture_content=5:20"], "contact.moisture_content", "each condition's moisture"),
    (["--fit", "contact.wood_density_yield=0.3:4", "--compaction-runs", "0"], "--fit", "--compaction-runs 1"),
    (["--fit", "contact.wood_density_yield=0.3:4", "--data", "example"], "--fit", "manifest"),
    (["--per-material", "--compaction-runs", "0"], "--per-material", "--compaction-runs 1"),
    (["--per-material", "--data", "example"], "--per-material", "manifest"),
])
def test_bad_arguments_exit_2_naming_the_argument_before_any_work(extra, name, allowed, no_calibration, capsys,
                                                                  tmp_path):
    out = tmp_path / "out"
    assert _main(["calibrate", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert name in err and allowed in err, err
    assert no_calibration == []
    assert not out.exists()


def test_out_dir_must_be_a_directory(no_calibration, capsys, tmp_path):
    (tmp_path / "file").write_text("x")
    for out in (str(tmp_path / "file"), " "):
        assert _main(["calibrate", out]) == 2
        assert "OUT_DIR" in capsys.readouterr().err
    assert _main(["calibrate"]) == 2
    assert "OUT_DIR" in capsys.readouterr().err
    assert no_calibration == []


def test_from_a_directory_that_holds_no_calibration(no_calibration, capsys, tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    (src / "calibration.json").write_text("{not json")
    assert _main(["calibrate", str(tmp_path / "out"), "--from", str(src)]) == 2
    assert "--from" in capsys.readouterr().err
    (src / "calibration.json").write_text(json.dumps({"contact": {"k1": -1.0}, "bond_start": {}}))
    assert _main(["calibrate", str(tmp_path / "out"), "--from", str(src)]) == 2
    assert "k1" in capsys.readouterr().err
    bad_start = {"oak MC 8% 120 MPa": {"E_b": "x"}}
    (src / "calibration.json").write_text(json.dumps({"contact": {}, "bond_start": bad_start}))
    assert _main(["calibrate", str(tmp_path / "out"), "--from", str(src)]) == 2
    assert "bond_start['oak MC 8% 120 MPa']['E_b']" in capsys.readouterr().err
    # the earlier calibration's k1 wins over --set: asking for both is refused
    (src / "calibration.json").write_text(json.dumps({"contact": {"k1": 4e4, "k2": 1.6e5}, "bond_start": {}}))
    assert _main(["calibrate", str(tmp_path / "out"), "--from", str(src), "--set", "contact.k1=5e4"]) == 2
    assert "contact.k1" in capsys.readouterr().err
    assert no_calibration == []


def test_dask_without_distributed_says_how_to_install_it(no_calibration, capsys, monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    assert _main(["calibrate", str(tmp_path / "out"), "--dask", "tcp://127.0.0.1:8786"]) == 2
    assert "pip install distributed" in capsys.readouterr().err
    assert no_calibration == []


def test_arguments_reach_the_calibration(no_calibration, monkeypatch, tmp_path):
    pytest.importorskip("distributed")
    import distributed

    clients = []

    class FakeClient:
        def __init__(self, address):
            self.address, self.closed = address, False
            clients.append(self)

        def close(self):
            self.closed = True

    monkeypatch.setattr(distributed, "Client", FakeClient)
    out = str(tmp_path / "out")
    assert _main(["calibrate", out, "--preset", "quick", "--variant", "pine", "20", "60", "--variant", "oak",
                  "8", "120.0", "--max-runs", "3", "--compaction-runs", "0", "--workers", "1",
                  "--set", "contact.mu=0.4", "--set", "bond.softening=1", "--dask", "tcp://sched:8786"]) == 0
    (got, kw), = no_calibration
    assert got == out
    assert [v.key for v in kw["variants"]] == [("pine", 20, 60), ("oak", 8, 120)]
    assert (kw["preset"], kw["max_runs"], kw["compaction_runs"], kw["max_workers"]) == ("quick", 3, 0, 1)
    assert kw["settings"] == {"contact.mu": 0.4, "bond.softening": 1.0}
    assert kw["executor"] is clients[0] and clients[0].address == "tcp://sched:8786" and clients[0].closed
    # defaults: tiny, all 12 variants, a local pool
    no_calibration.clear()
    assert _main(["calibrate", out]) == 0
    (_, kw), = no_calibration
    assert kw["preset"] == "tiny" and kw["variants"] is None and kw["executor"] is None and kw["source"] is None
    assert kw["packings"] == 1 and kw["first_packing"] == 0
    no_calibration.clear()
    assert _main(["calibrate", out, "--packings", "3", "--first-packing", "4"]) == 0
    assert (no_calibration[0][1]["packings"], no_calibration[0][1]["first_packing"]) == (3, 4)


def test_calibrate_help_lists_every_option(capsys):
    assert _main(["calibrate", "--help"]) == 0
    text = capsys.readouterr().out
    for opt in ("OUT_DIR", "--preset", "--variant", "--max-runs", "--compaction-runs", "--from", "--workers",
                "--dask", "--set", "--fit", "--per-material", "--packings", "--first-packing", "--data"):
        assert opt in text, opt


# --- the library call, on the fast stand-in for the engine ---------------------------------------

VARIANTS = [("oak", 8, 120), ("pine", 20, 60)]


def test_calibrate_into_writes_its_files_and_resumes_from_its_cache(tmp_path):
    CALLS.clear()
    out = tmp_path / "cal"
    first = calibration_dir.calibrate_into(out, VARIANTS, "tiny", max_runs=3, compaction_runs=2,
                                           settings={"contact.mu": 0.4}, executor="serial",
                                           runner=power_law_runner, log=lambda s: None)
    for name in FILES:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    saved = json.loads((out / "calibration.json").read_text())
    assert saved["set"] == {"contact.mu": 0.4} and saved["preset"] == "tiny"
    assert saved["variants"] == ["oak MC 8% 120 MPa", "pine MC 20% 60 MPa"]
    assert saved["n_simulations"] == first.n_simulations == len(CALLS) > 0
    assert set(saved["contact"]) == {"k1", "k2"}  # the compaction fit ran
    assert len(saved["sittings"]) == 1
    CALLS.clear()
    again = calibration_dir.calibrate_into(out, VARIANTS, "tiny", max_runs=3, compaction_runs=2,
                                           settings={"contact.mu": 0.4}, executor="serial",
                                           runner=power_law_runner, log=lambda s: None)
    assert CALLS == [] and again.n_simulations == 0 and again.n_cached == first.n_simulations
    assert again.bond_start() == first.bond_start()
    saved = json.loads((out / "calibration.json").read_text())
    assert [s["n_simulations"] for s in saved["sittings"]] == [first.n_simulations, 0]
    # another contact law is another set of runs
    other = calibration_dir.calibrate_into(out, VARIANTS, "tiny", max_runs=3, compaction_runs=2, executor="serial",
                                           runner=power_law_runner, log=lambda s: None)
    assert other.n_simulations > 0


def test_calibrate_into_averages_packings_and_gives_each_wood_its_density(tmp_path):
    """Packings differ by 10 kg/m^3 in density: the mean is 5 above packing 0's and its
    standard error 5; each variant's pellet is the solid fraction times its wood's BD_w, and
    the paper's variants run with the paper's overlap guard."""
    from pelletdem.loop_paper import PAPER_OVERLAP_GUARD
    from pelletdem.measured import variant

    guards = set()

    def runner(spec):
        guards.add(spec.preset.max_overlap_ratio)
        rec = power_law_runner(spec)
        rec["outputs"]["bulk_density_relaxed"] += 10.0 * spec.seed
        return rec

    rep = calibration_dir.calibrate_into(tmp_path / "cal", VARIANTS, "tiny", max_runs=2, compaction_runs=0,
                                         packings=2, executor="serial", runner=runner, log=lambda s: None)
    assert guards == {PAPER_OVERLAP_GUARD}
    saved = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    assert saved["packings"] == 2 and saved["agreement"] == rep.agreement()
    for (m, mc, sz), row in zip(VARIANTS, rep.table.itertuples()):
        v, solid = variant(m, mc, sz), 800.0 * (sz / 120) ** 0.25 + 5.0  # k1 is tiny's 1e5
        assert row.bd_sim == pytest.approx(solid * v.bd_wood / 680.0)
        assert row.bd_se == pytest.approx(5.0 * v.bd_wood / 680.0)
        sd = math.hypot(max(v.bd_pellet_sd, 0.01 * v.bd_pellet), row.bd_se)
        assert row.z_bd == pytest.approx((row.bd_sim - v.bd_pellet) / sd)
    with pytest.raises(ValueError, match="packings"):
        calibration_dir.calibrate_into(tmp_path / "bad", VARIANTS, "tiny", packings=0, runner=runner)


def test_calibrate_into_runs_the_packings_from_first_packing(tmp_path):
    """first_packing = 5 with two packings: every point averages seeds 5 and 6 (their
    densities 50 and 60 above seed 0's), and calibration.json says so."""
    from pelletdem.measured import variant

    seeds = set()

    def runner(spec):
        seeds.add(spec.seed)
        rec = power_law_runner(spec)
        rec["outputs"]["bulk_density_relaxed"] += 10.0 * spec.seed
        return rec

    kw = dict(max_runs=2, compaction_runs=0, packings=2, executor="serial", runner=runner, log=lambda s: None)
    first = calibration_dir.calibrate_into(tmp_path / "a", VARIANTS, "tiny", **kw)
    assert seeds == {0, 1}
    seeds.clear()
    later = calibration_dir.calibrate_into(tmp_path / "b", VARIANTS, "tiny", first_packing=5, **kw)
    assert seeds == {5, 6}
    assert json.loads((tmp_path / "b" / "calibration.json").read_text())["first_packing"] == 5
    scale = [variant(m, mc, sz).bd_wood / 680.0 for m, mc, sz in VARIANTS]
    np.testing.assert_allclose(later.table["bd_sim"] - first.table["bd_sim"], [50.0 * f for f in scale])
    for bad in (-1, 1_000_001, 2.0, True):
        with pytest.raises(ValueError, match="first_packing"):
            calibration_dir.calibrate_into(tmp_path / "bad", VARIANTS, "tiny", first_packing=bad, runner=runner)


def test_each_variant_runs_at_its_own_moisture_content(tmp_path):
    """The variant's MC is its contact law's: the diametral runs carry it, and a moisture
    effect that acts in compaction gives wet and dry pellets of their own."""
    seen = []

    def runner(spec):
        seen.append((spec.kind, spec.sigma_z, spec.preset.contact.moisture_content, spec.relax_key))
        return power_law_runner(spec)

    two = [("oak", 8, 120), ("oak", 20, 120)]
    calibration_dir.calibrate_into(tmp_path / "dry", two, "tiny", max_runs=1, compaction_runs=0, executor="serial",
                                   runner=runner, log=lambda s: None)
    assert {mc for kind, _, mc, _ in seen if kind == "diametral"} == {8.0, 20.0}
    assert len({rk for *_, rk in seen}) == 1  # no moisture effect: one relaxed pellet
    seen.clear()
    calibration_dir.calibrate_into(tmp_path / "wet", two, "tiny", max_runs=1, compaction_runs=0, executor="serial",
                                   settings={"contact.moisture_yield": 0.03}, runner=runner, log=lambda s: None)
    assert len({rk for kind, *_, rk in seen if kind == "compaction"}) == 2
    seen.clear()  # the shared k1 fit asks wet and dry pellets their own densities
    calibration_dir.calibrate_into(tmp_path / "fit", two, "tiny", max_runs=1, compaction_runs=2, executor="serial",
                                   settings={"contact.moisture_yield": 0.03}, runner=runner, log=lambda s: None)
    assert {mc for kind, _, mc, _ in seen if kind == "compaction"} == {8.0, 20.0}
    with pytest.raises(ValueError, match="moisture_content"):
        calibration_dir.calibrate_into(tmp_path / "bad", two, "tiny", settings={"contact.moisture_content": 20.0},
                                       runner=runner, log=lambda s: None)


def test_each_wood_relaxes_its_own_pellets_where_its_density_acts(tmp_path):
    """With wood_density_yield on, a variant's runs carry its wood's BD_w (Table 2) and each
    material relaxes its own pellets, and the k1 fit asks each wood its own density; off, the
    woods share one pellet."""
    from pelletdem.measured import variant

    seen = []

    def runner(spec):
        seen.append((spec.kind, spec.preset.contact.wood_density, spec.relax_key))
        return power_law_runner(spec)

    two = [("oak", 8, 120), ("pine", 8, 120)]
    calibration_dir.calibrate_into(tmp_path / "off", two, "tiny", max_runs=1, compaction_runs=0, executor="serial",
                                   runner=runner, log=lambda s: None)
    assert len({rk for *_, rk in seen}) == 1 and {w for _, w, _ in seen} == {680.0}
    seen.clear()
    calibration_dir.calibrate_into(tmp_path / "on", two, "tiny", max_runs=1, compaction_runs=2, executor="serial",
                                   settings={"contact.wood_density_yield": 1.5}, runner=runner, log=lambda s: None)
    woods = {variant(*k).bd_wood for k in two}
    assert {w for kind, w, _ in seen if kind == "diametral"} == woods
    assert {w for kind, w, _ in seen if kind == "compaction"} == woods
    assert len({rk for kind, _, rk in seen if kind == "compaction"}) >= 2
    with pytest.raises(ValueError, match="wood_density"):
        calibration_dir.calibrate_into(tmp_path / "bad", two, "tiny", settings={"contact.wood_density": 500.0},
                                       runner=runner, log=lambda s: None)
    # its strength fitted beside k1: every variant's runs then take the fitted law
    seen.clear()
    rep = calibration_dir.calibrate_into(tmp_path / "fit", two, "tiny", max_runs=1, compaction_runs=4,
                                         executor="serial", fit={"contact.wood_density_yield": (0.3, 4.0, 1.5)},
                                         runner=runner, log=lambda s: None)
    n = rep.contact["wood_density_yield"]
    assert 0.3 <= n <= 4.0 and {w for kind, w, _ in seen if kind == "diametral"} == woods
    assert json.loads((tmp_path / "fit" / "calibration.json").read_text())["fit"] == {
        "contact.wood_density_yield": [0.3, 4.0, 1.5]}
    with pytest.raises(ValueError, match="compaction"):
        calibration_dir.calibrate_into(tmp_path / "bad", two, "tiny", compaction_runs=0,
                                       fit={"contact.wood_density_yield": (0.3, 4.0)}, runner=runner)


def test_k1_per_material_is_fitted_on_each_woods_own_densities(tmp_path):
    """--per-material: one compaction fit per wood, on its own Table 2 densities. Each wood's
    runs take its own k1 (and relax their own pellets), the denser-compacting wood gets the
    softer k1, each wood's densities are met at least as well as with one k1 for both, and a
    later calibration --from it keeps each wood's k1."""
    two = [("oak", 8, 60), ("oak", 8, 120), ("pine", 8, 60), ("pine", 8, 120)]
    seen = []

    def runner(spec):
        seen.append((spec.kind, spec.preset.contact.k1))
        return power_law_runner(spec)

    kw = dict(max_runs=1, compaction_runs=6, executor="serial", runner=runner, log=lambda s: None)
    shared = calibration_dir.calibrate_into(tmp_path / "shared", two, "tiny", **kw)
    seen.clear()
    rep = calibration_dir.calibrate_into(tmp_path / "own", two, "tiny", per_material=True, **kw)
    assert rep.compaction is None and set(rep.compaction_by_material) == {"oak", "pine"}
    k1 = {m: law["k1"] for m, law in rep.contact_by_material.items()}
    assert k1["pine"] < k1["oak"]  # pine's pellets are denser against its BD_w (Table 2)
    assert all(law["k2"] == pytest.approx(4 * law["k1"]) for law in rep.contact_by_material.values())
    t = rep.table
    assert dict(zip(t["material"], t["k1"])) == k1
    assert {k for kind, k in seen if kind == "diametral"} == set(k1.values())
    for m in k1:
        own, one = (float(np.sum(r.table[r.table["material"] == m]["z_bd"] ** 2)) for r in (rep, shared))
        assert own <= one + 1e-9
    saved = json.loads((tmp_path / "own" / "calibration.json").read_text())
    assert saved["per_material"] and saved["contact_by_material"] == rep.contact_by_material
    assert "compaction fit of oak" in str(rep) and "compaction fit of pine" in str(rep)
    seen.clear()
    again = calibration_dir.calibrate_into(tmp_path / "again", two, "tiny", max_runs=1, source=tmp_path / "own",
                                           executor="serial", runner=runner, log=lambda s: None)
    assert dict(zip(again.table["material"], again.table["k1"])) == k1
    assert {k for _, k in seen} == set(k1.values())
    with pytest.raises(ValueError, match="per_material"):
        calibration_dir.calibrate_into(tmp_path / "bad", two, "tiny", per_material=True, compaction_runs=0,
                                       runner=runner)
    with pytest.raises(ValueError, match="'teak'"):
        calibrate_variants(two, "tiny", compaction=None, contact_by_material={"teak": {"k1": 3e4}},
                                           runner=runner)
    with pytest.raises(ValueError, match="pass one"):
        calibrate_variants(two, "tiny", contact_by_material={"oak": {"k1": 3e4}}, runner=runner)
    with pytest.raises(ValueError, match="k1"):
        calibrate_variants(two, "tiny", compaction=None, contact_by_material={"oak": {"k1": -1.0}},
                                           runner=runner)
    with pytest.raises(ValueError, match="moisture_content"):
        calibrate_variants(two, "tiny", compaction=None,
                                           contact_by_material={"oak": {"moisture_content": 12.0}}, runner=runner)


def test_k1_fitted_alone_keeps_k2(tmp_path):
    """--fit contact.k1: the compaction fit moves k1 and keeps the preset's k2 (its --set value),
    where the plain fit keeps k2 / k1; every run of the calibration takes that k2."""
    seen = []

    def runner(spec):
        seen.append((spec.kind, spec.preset.contact.k1, spec.preset.contact.k2))
        return power_law_runner(spec)

    two = [("oak", 8, 60), ("oak", 8, 120)]
    rep = calibration_dir.calibrate_into(tmp_path / "k1", two, "tiny", max_runs=1, compaction_runs=4,
                                         executor="serial", settings={"contact.k2": 2e5},
                                         fit={"contact.k1": (1e4, 1.5e5, 5e4)}, runner=runner, log=lambda s: None)
    assert set(rep.contact) == {"k1"} and 1e4 <= rep.contact["k1"] <= 1.5e5
    assert len({k1 for _, k1, _ in seen}) >= 2  # k1 moved
    assert {k2 for _, _, k2 in seen} == {2e5}  # k2 did not
    assert {k1 for kind, k1, _ in seen if kind == "diametral"} == {rep.contact["k1"]}
    seen.clear()
    plain = calibration_dir.calibrate_into(tmp_path / "plain", two, "tiny", max_runs=1, compaction_runs=4,
                                           executor="serial", settings={"contact.k2": 2e5}, runner=runner,
                                           log=lambda s: None)
    assert plain.contact["k2"] / plain.contact["k1"] == pytest.approx(2e5 / get_preset("tiny").contact.k1)


def _per_material_source(tmp_path):
    """An earlier calibration's directory with k1 per material, oak's and pine's below the
    preset's (N/m)."""
    src = tmp_path / "src"
    src.mkdir()
    (src / "calibration.json").write_text(json.dumps({
        "contact": {}, "contact_by_material": {"oak": {"k1": 1.5e4}, "pine": {"k1": 7e3}}, "bond_start": {}}))
    return src


def test_from_k1_per_material_allows_a_k2_below_the_presets_k1(no_calibration, capsys, tmp_path):
    """--set rows with --from go on the law they will run with: each wood's k1 from the
    earlier calibration (below the preset's 1e5 N/m here), so k2 = 6e4 is allowed, and
    refused, naming k2, where it is below a wood's own k1."""
    src = _per_material_source(tmp_path)
    args = [*("calibrate", str(tmp_path / "out"), "--from", str(src)), "--set", "contact.k2=6e4"]
    assert _main(args) == 0 and len(no_calibration) == 1
    assert _main([*args[:-1], "contact.k2=1e4"]) == 2
    assert "k2 = 10000 N/m is below k1 = 15000" in capsys.readouterr().err


def test_calibrate_into_from_k1_per_material_runs_each_wood_with_the_set_k2(tmp_path):
    """Every run takes its wood's k1 from the source and the set k2 (N/m)."""
    src = _per_material_source(tmp_path)
    seen = []

    def runner(spec):
        seen.append((spec.preset.contact.k1, spec.preset.contact.k2))
        return power_law_runner(spec)

    calibration_dir.calibrate_into(tmp_path / "out", [("oak", 8, 120), ("pine", 8, 120)], "tiny", max_runs=1,
                                   source=src, settings={"contact.k2": 6e4}, executor="serial", runner=runner,
                                   log=lambda s: None)
    assert set(seen) == {(1.5e4, 6e4), (7e3, 6e4)}
    seen.clear()  # a source calibrated on more woods than the variants passes on their woods' rows
    rep = calibration_dir.calibrate_into(tmp_path / "oak", [("oak", 8, 120)], "tiny", max_runs=1, source=src,
                                         settings={"contact.k2": 6e4}, executor="serial", runner=runner,
                                         log=lambda s: None)
    assert set(seen) == {(1.5e4, 6e4)} and set(rep.contact_by_material) == {"oak"}
    (src / "calibration.json").write_text(json.dumps({"contact": {"no_such_row": 1.0}, "bond_start": {}}))
    with pytest.raises(ValueError, match="its contact law is refused.*no_such_row"):
        calibration_dir.calibrate_into(tmp_path / "bad", [("oak", 8, 120)], "tiny", max_runs=1, source=src,
                                       executor="serial", runner=runner, log=lambda s: None)


def test_calibrate_into_from_an_earlier_calibration(tmp_path):
    calibration_dir.calibrate_into(tmp_path / "small", VARIANTS, "tiny", max_runs=4, executor="serial",
                                   runner=power_law_runner, log=lambda s: None)
    src = json.loads((tmp_path / "small" / "calibration.json").read_text())
    rep = calibration_dir.calibrate_into(tmp_path / "big", VARIANTS, "quick", max_runs=4, source=tmp_path / "small",
                                         executor="serial", runner=power_law_runner, log=lambda s: None)
    assert rep.compaction is None and rep.contact == src["contact"]
    saved = json.loads((tmp_path / "big" / "calibration.json").read_text())
    assert saved["from"] == str(tmp_path / "small") and saved["preset"] == "quick"


def test_calibration_sittings_add_up(tmp_path):
    """Wall time over sittings: a finished sitting counts start to end, a killed one (no end
    line) start to its last cache record before the next start."""
    (tmp_path / "cache" / "ab").mkdir(parents=True)
    rows = [{"time": 1000.0, "event": "start"},                       # killed after 2 records
            {"time": 5000.0, "event": "start"},                       # finished
            {"time": 5600.0, "event": "end", "n_simulations": 3, "n_cached": 2}]
    (tmp_path / "segments.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    for name, t in (("a", 1500.0), ("b", 1900.0), ("c", 5300.0)):
        f = tmp_path / "cache" / "ab" / f"{name}.json"
        f.write_text("{}")
        os.utime(f, (t, t))
    log = calibration_dir.Sittings(tmp_path)
    log.start()  # a third sitting, which ends at once
    out = log.finish(types.SimpleNamespace(n_simulations=0, n_cached=5))
    s = out["sittings"]
    assert [x["killed"] for x in s] == [True, False, False]
    assert s[0]["wall_time_s"] == 900.0 and s[0]["n_simulations"] == 2
    assert s[1]["wall_time_s"] == 600.0 and s[1]["n_simulations"] == 3
    assert 0.0 <= s[2]["wall_time_s"] < 60.0
    assert out["wall_time_total_s"] == sum(x["wall_time_s"] for x in s)


# --- the real engine, end to end ------------------------------------------------------------------

def test_a_tiny_calibration_from_the_command_line_then_again_from_its_cache(tmp_path):
    out = tmp_path / "cal"
    cmd = [sys.executable, "-m", "pelletdem.cli", "calibrate", str(out), "--variant", "oak", "8", "120",
           "--max-runs", "1", "--compaction-runs", "0", "--workers", "1"]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=_env(), cwd=tmp_path)
    assert first.returncode == 0, first.stderr[-4000:]
    for name in FILES:
        assert (out / name).is_file(), name
    saved = json.loads((out / "calibration.json").read_text())
    assert saved["n_simulations"] == 2  # one relaxed pellet, one bond point branched off it
    assert saved["n_relaxations"] == 1
    csv = (out / "calibration.csv").read_text().splitlines()
    assert len(csv) == 2 and csv[1].startswith("oak,8,120,")
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=_env(), cwd=tmp_path)
    assert again.returncode == 0, again.stderr[-4000:]
    assert again.stdout.startswith("calibration: 0 simulations run, 2 from the cache"), again.stdout[:300]
    resumed = json.loads((out / "calibration.json").read_text())
    assert (resumed["n_simulations"], resumed["n_cached"]) == (0, 2)
    assert resumed["bond_start"] == saved["bond_start"]
    assert [s["n_simulations"] for s in resumed["sittings"]] == [2, 0]


def test_data_and_variant_are_refused_together(no_calibration, capsys, tmp_path):
    rc = _main(["calibrate", str(tmp_path / "o"), "--data", "example", "--variant", "oak", "8", "120"])
    assert rc == 2 and "--variant" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_data_file_errors_name_the_file_before_any_work(no_calibration, capsys, tmp_path):
    bad = tmp_path / "data.toml"
    bad.write_text('[[condition]]\npressure_mpa = "high"\nsigma_f = { mean = 1e6, sd = 1e5, n = 3 }\n')
    rc = _main(["calibrate", str(tmp_path / "o"), "--data", str(bad)])
    err = capsys.readouterr().err
    assert rc == 2 and "data.toml" in err and "pressure_mpa" in err


def test_calibrate_on_a_users_data_fits_the_baseline_and_adds_nothing(tmp_path, monkeypatch):
    # The engine is replaced by the analytic pellet on the example's scale: this checks the
    # path from the command line to the report, not the physics.
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "loop"))
    from toy_pellet import example_toy

    from pelletdem import loop
    from pelletdem.loop_simulators import FunctionSimulator

    presets = []

    class Toy(FunctionSimulator):
        def __init__(self, preset, bond=None, contact=None, seeds=(0,), **kw):
            presets.append(preset)
            super().__init__(example_toy, seeds)

    monkeypatch.setattr(loop, "EngineSimulator", Toy)
    out = tmp_path / "cal"
    assert cli.main(["calibrate", str(out), "--data", "example", "--packings", "2", "--workers", "1"]) == 0
    from pelletdem.loop_manifest import example_manifest, load_manifest

    assert presets == [load_manifest(example_manifest()).preset]  # the manifest's, as none was given
    res = json.loads((out / "loop.json").read_text())
    assert res["chosen"] == [] and res["steps"][0]["screens"] == []
    lo, hi = res["final"]["interval_2sigma"]["E_b"]
    assert 2e7 <= lo <= res["final"]["params"]["E_b"] <= hi <= 2e8
    assert res["final"]["fit_packings_se"] is None  # two packings leave none to jackknife
    assert (out / "report.md").read_text().startswith("# Calibration on")
