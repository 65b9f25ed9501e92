"""Calibration machinery (pelletdem.calibrate): cache keys, resumable scans, executors (local
process pool, Dask), objectives, input checks, and parameter recovery.

Most tests use a fast stand-in for the engine (`power_law_runner`: sigma_f, dL_f/D and the bulk
density as power laws of the parameters, exponents deliberately off the paper's scaling laws)
so the machinery is tested in milliseconds; test_calibrate_engine.py runs the real engine on
the 'tiny' pellet.
"""
import json
import math
import os
import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from pelletdem import calibrate as C
from pelletdem import measured, runs
from pelletdem.engine import BondLaw
from pelletdem.presets import get_preset

# --- a fast stand-in for the engine ---------------------------------------------------------

# sigma_f = SF0 (sigma_c/9 MPa)^1.3 (E_b/30 MPa)^-0.2, dL_f/D = DL0 (sigma_c/9)^0.9 (E_b/30)^-0.8
SF0, DL0 = 80e3, 0.08
CALLS = []
CALLS_LOCK = threading.Lock()


def power_law_outputs(spec):
    e = spec.bond.youngs_modulus / 30e6 if spec.bond is not None else 1.0
    s = spec.bond.sigma_c / 9e6 if spec.bond is not None else 1.0
    k = spec.preset.contact.k1 / 1e5
    x = spec.sigma_z / 120e6 / k
    out = {"bulk_density_relaxed": 800.0 * x**0.25, "bulk_density_max": 1000.0 * x**0.3,
           "dlnbd_dlnsigma": 0.3, "coordination_number_relaxed": 10.0 * x**0.2}
    if spec.bond is not None:
        sf, dl, m = SF0 * s**1.3 * e**-0.2, DL0 * s**0.9 * e**-0.8, spec.preset.max_dLD
        if dl > m:  # the test ends before the peak: bounds, like the engine's
            sf, dl = sf * m / dl, m
        out.update(sigma_f=sf, dLf_D=dl, peaked=float(dl < m))
    return out


def power_law_runner(spec):
    with CALLS_LOCK:
        CALLS.append(spec.key)
    out = power_law_outputs(spec)
    curve = {}
    if "sigma_f" in out:
        x = np.linspace(0, 1.5 * out["dLf_D"], 50)
        curve = {"dL_D": x.tolist(), "sigma_1": (out["sigma_f"] * np.sin(np.pi / 2 * x / out["dLf_D"])).tolist()}
    return {"key": spec.key, "relax_key": spec.relax_key, "spec": runs.canonical(spec.payload()), "ok": True,
            "error": None, "outputs": out, "curve": curve, "compaction_curve": {}, "relaxed_reused": False,
            "wall_time_s": 0.0, "worker": str(os.getpid())}


def failing_after(n):
    """A runner that crashes (like a killed scan) after n successful runs."""
    count = [0]

    def run(spec):
        if count[0] >= n:
            raise RuntimeError("worker killed")
        count[0] += 1
        return power_law_runner(spec)
    return run


@pytest.fixture(autouse=True)
def _reset_calls():
    CALLS.clear()
    yield


def synthetic_targets(e_b, sigma_c, rel_sd=0.05, sigma_z=120e6):
    spec = C.make_spec({"E_b": e_b, "sigma_c": sigma_c}, sigma_z=sigma_z)
    out = power_law_outputs(spec)
    return C.Targets(sigma_z=sigma_z, sigma_f=out["sigma_f"], sigma_f_sd=rel_sd * out["sigma_f"],
                     dLf_D=out["dLf_D"], dLf_D_sd=rel_sd * out["dLf_D"], label="synthetic")


# --- cache keys ------------------------------------------------------------------------------

def test_cache_key_is_stable():
    a = C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, sigma_z=120e6)
    b = C.make_spec({"E_b": 30000000, "sigma_c": 9000000}, sigma_z=120_000_000)
    assert a.key == b.key == C.cache_key(a)
    # a number the engine receives differently is another run (a DEM run is chaotic: 0.1 and
    # exp(log(0.1)) gave pellets of 401.9 and 395.8 kg/m^3), so it must not share a key
    c = C.make_spec({"E_b": 30e6, "sigma_c": math.exp(math.log(9e6))}, sigma_z=120e6)
    assert c.key != a.key and c.relax_key == a.relax_key
    d = C.make_spec({"E_b": 30e6, "sigma_c": 9e6, "p_y": math.exp(math.log(0.1)) * 1e8}, sigma_z=120e6)
    e = C.make_spec({"E_b": 30e6, "sigma_c": 9e6, "p_y": 0.1 * 1e8}, sigma_z=120e6)
    assert (d.preset.contact.k1 == e.preset.contact.k1) == (d.relax_key == e.relax_key)
    assert len(a.key) == 64 and int(a.key, 16) >= 0
    # the same in another process (no dependence on hash seeds, dict order, object ids)
    code = ("from pelletdem import calibrate as C; "
            "print(C.make_spec({'sigma_c': 9e6, 'E_b': 30e6}, sigma_z=120e6).key)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONHASHSEED": "123"})
    assert out.stdout.strip() == a.key


def test_cache_key_is_sensitive_to_every_input(monkeypatch):
    base = dict(sigma_z=120e6, seed=0)
    ref = C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, **base)
    variants = {
        "E_b": C.make_spec({"E_b": 31e6, "sigma_c": 9e6}, **base),
        "sigma_c": C.make_spec({"E_b": 30e6, "sigma_c": 9.1e6}, **base),
        "tau_c": C.make_spec({"E_b": 30e6, "sigma_c": 9e6, "tau_c": 8e6}, **base),
        "r_b": C.make_spec({"E_b": 30e6, "sigma_c": 9e6, "r_b": 21e-6}, **base),
        "k1": C.make_spec({"E_b": 30e6, "sigma_c": 9e6, "k1": 9e4}, **base),
        "contact.mu": C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, contact={"mu": 0.4}, **base),
        "sigma_z": C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, sigma_z=60e6),
        "seed": C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, sigma_z=120e6, seed=1),
        "max_dLD": C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, max_dLD=0.15, **base),
        "break_drop": C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, preset=get_preset("tiny").with_(
            break_drop=0.7, break_from_dLD=0.02), **base),
        "preset": C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, preset="quick", **base),
        "kind": C.make_spec({}, diametral=False, **base),
        "gap": C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, bond=BondLaw(gap_tolerance=1e-6), **base),
        "mc": C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, contact={"moisture_content": 20.0}, **base),
        "mc+yield": C.make_spec({"E_b": 30e6, "sigma_c": 9e6},
                                contact={"moisture_content": 20.0, "moisture_yield": 0.03}, **base),
    }
    keys = {name: s.key for name, s in variants.items()}
    assert ref.key not in keys.values()
    assert len(set(keys.values())) == len(keys)
    # the relaxed pellet does not depend on the bond law or the diametral test's settings ...
    # nor on the moisture content where no effect reads it during compaction ...
    for name in ("E_b", "sigma_c", "tau_c", "r_b", "max_dLD", "break_drop", "kind", "gap", "mc"):
        assert variants[name].relax_key == ref.relax_key, name
    # ... but does on the contact law, the pressure, the seed and the preset
    for name in ("k1", "contact.mu", "sigma_z", "seed", "preset", "mc+yield"):
        assert variants[name].relax_key != ref.relax_key, name
    # the package version and the engine build are part of the key
    ref_key = ref.key
    monkeypatch.setattr(runs, "__version__", "9.9.9")
    assert C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, **base).key != ref_key
    monkeypatch.undo()
    monkeypatch.setattr(runs, "engine_fingerprint", lambda: "0" * 16)
    assert C.make_spec({"E_b": 30e6, "sigma_c": 9e6}, **base).key != ref_key
    monkeypatch.undo()
    assert ref.key == ref_key


def test_make_spec_ties_tau_c_and_keeps_restitution():
    s = C.make_spec({"sigma_c": 5e6, "k1": 5e4})
    assert s.bond.tau_c == 5e6 and s.bond.sigma_c == 5e6
    assert s.preset.contact.k2 / s.preset.contact.k1 == pytest.approx(4.0)
    s = C.make_spec({"p_y": 50e6})
    assert s.preset.contact.k1 == pytest.approx(5 * 2e-4 * 50e6)


def test_run_cache_roundtrip_and_corrupt_file(tmp_path):
    cache = C.RunCache(tmp_path)
    rec = power_law_runner(C.make_spec({"E_b": 30e6}))
    cache.put(rec)
    again = C.RunCache(tmp_path)
    assert again.get(rec["key"])["outputs"] == pytest.approx(rec["outputs"])
    assert again.keys() == [rec["key"]]
    with open(cache.path(rec["key"]), "w") as fh:
        fh.write("{truncated")
    with pytest.warns(UserWarning, match="unreadable"):
        assert C.RunCache(tmp_path).get(rec["key"]) is None


# --- scans: resume, executors ----------------------------------------------------------------

GRID = {"E_b": [20e6, 30e6, 45e6], "sigma_c": [6e6, 9e6]}


def test_resumed_scan_runs_no_simulation_twice(tmp_path):
    tg = synthetic_targets(30e6, 9e6)
    # a scan whose runner dies after 2 of its 6 runs completes, the other 4 reported failed
    # (each tried twice) and not cached ...
    res = C.scan(GRID, tg, cache_dir=tmp_path, executor="serial", runner=failing_after(2))
    assert res.n_failed == 4 and res.n_retried == 4 and len(res.failures) == 4
    assert (~res.runs["ok"]).sum() == 4
    assert res.runs.loc[~res.runs["ok"], "error"].str.contains("worker killed").all()
    assert len(CALLS) == 2 and len(C.RunCache(tmp_path)) == 2
    # ... resumes: only the 4 missing runs are done
    res = C.scan(GRID, tg, cache_dir=tmp_path, executor="serial", runner=power_law_runner)
    assert res.n_simulations == 4 and res.n_cached == 2
    assert len(CALLS) == 6 and len(set(CALLS)) == 6  # every point run exactly once
    # and a third pass runs nothing
    res = C.scan(GRID, tg, cache_dir=tmp_path, executor=ThreadPoolExecutor(2), runner=power_law_runner)
    assert res.n_simulations == 0 and res.n_cached == 6 and len(CALLS) == 6
    assert res.best == {"E_b": 30e6, "sigma_c": 9e6}
    assert res.points["loss"].min() == pytest.approx(0.0, abs=1e-9)
    assert len(res.runs) == 6 and res.runs["cached"].all()


# --- failed points: retried once, then reported; the rest of the scan completes ---------------

def failing_for(e_b):
    """A runner that raises for every point with E_b == e_b (deterministic failure)."""
    def run(spec):
        if abs(spec.bond.youngs_modulus / e_b - 1) < 1e-9:  # a fit's log-space point is not exact
            raise RuntimeError(f"cannot run E_b = {e_b}")
        return power_law_runner(spec)
    return run


def failing_once():
    """A runner whose first attempt at every point raises (a transient fault)."""
    seen, lock = set(), threading.Lock()

    def run(spec):
        with lock:
            first = spec.key not in seen
            seen.add(spec.key)
        if first:
            raise OSError("transient: node lost")
        return power_law_runner(spec)
    return run


def test_a_point_that_always_fails_is_retried_once_then_reported(tmp_path):
    res = C.scan(GRID, synthetic_targets(30e6, 9e6), cache_dir=tmp_path, executor=ThreadPoolExecutor(2),
                 runner=failing_for(45e6))
    assert res.n_failed == 2 and res.n_retried == 2
    bad = res.runs[~res.runs["ok"]]
    assert sorted(bad["E_b"]) == [45e6, 45e6]
    assert bad["error"].str.contains("failed 2 times").all()
    assert bad["error"].str.contains("cannot run E_b = 45000000.0").all()
    assert {f["attempts"] for f in res.failures} == {2}
    # the other points ran, were scored and cached; failed points are not cached
    assert res.runs["ok"].sum() == 4 and len(C.RunCache(tmp_path)) == 4
    assert res.best == {"E_b": 30e6, "sigma_c": 9e6}
    assert not res.points.loc[res.points["E_b"] == 45e6, "ok"].any()


def test_a_point_that_fails_once_succeeds_on_its_retry():
    res = C.scan(GRID, synthetic_targets(30e6, 9e6), executor=ThreadPoolExecutor(2), runner=failing_once())
    assert res.n_retried == 6 and res.n_failed == 0
    assert res.runs["ok"].all()
    assert res.best == {"E_b": 30e6, "sigma_c": 9e6}


def test_fit_reports_a_failed_point_and_goes_on():
    tg = synthetic_targets(30e6, 9e6)
    r = C.fit({"E_b": (1e6, 1e9, 120e6), "sigma_c": (1e5, 1e9, 36e6)}, tg, executor="serial",
              runner=failing_for(120e6), tol=0.3)
    assert r.n_failed >= 1 and r.n_retried >= r.n_failed
    assert not r.history["ok"].iloc[0] and "failed 2 times" in r.history["error"].iloc[0]


def dying_runner(spec, marker_dir=None):
    """Kills its worker process (os._exit, like a segfault or the OOM killer) for the point
    E_b = 45 MPa, sigma_c = 9 MPa: every time, or only the first time when `marker_dir` is
    given (the marker file says it has died once already)."""
    if spec.bond.youngs_modulus == 45e6 and spec.bond.sigma_c == 9e6:
        marker = None if marker_dir is None else os.path.join(marker_dir, "died")
        if marker is None or not os.path.exists(marker):
            if marker is not None:
                open(marker, "w").close()
            os._exit(3)
    return power_law_runner(spec)


def test_a_worker_process_that_dies_is_retried_and_reported(tmp_path):
    res = C.scan(GRID, synthetic_targets(30e6, 9e6), cache_dir=tmp_path, max_workers=2, runner=dying_runner)
    # the killer point died twice (its retry ran alone, so it took no other point with it) ...
    assert res.n_failed == 1
    (bad,) = res.runs[~res.runs["ok"]].to_dict("records")
    assert (bad["E_b"], bad["sigma_c"]) == (45e6, 9e6)
    assert "BrokenProcessPool" in bad["error"] and "failed 2 times" in bad["error"]
    # ... and every other point completed, including those in flight when the pool broke
    assert res.runs["ok"].sum() == 5 and len(C.RunCache(tmp_path)) == 5
    assert res.best == {"E_b": 30e6, "sigma_c": 9e6}


def test_a_worker_process_that_dies_once_is_retried_successfully(tmp_path):
    import functools

    res = C.scan(GRID, synthetic_targets(30e6, 9e6), max_workers=2,
                 runner=functools.partial(dying_runner, marker_dir=str(tmp_path)))
    assert (tmp_path / "died").exists()
    assert res.n_failed == 0 and res.n_retried >= 1
    assert res.runs["ok"].all()


def test_scan_with_duplicate_points_runs_each_once(tmp_path):
    # A point one ulp away is another simulation: the engine builds another pellet from it.
    C.scan({"sigma_c": [9e6, 9e6, 9.0e6 * (1 + 1e-15)]}, synthetic_targets(30e6, 9e6),
           executor=ThreadPoolExecutor(3), runner=power_law_runner)
    assert len(CALLS) == 2


def test_scan_on_default_process_pool(tmp_path):
    res = C.scan(GRID, synthetic_targets(30e6, 9e6), cache_dir=tmp_path, max_workers=2, runner=power_law_runner)
    assert res.n_simulations == 6
    assert res.best == {"E_b": 30e6, "sigma_c": 9e6}
    assert len(C.RunCache(tmp_path)) == 6


def test_scan_on_dask_local_cluster(tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        res = C.scan(GRID, synthetic_targets(30e6, 9e6), cache_dir=tmp_path, executor=client,
                     runner=power_law_runner)
    assert res.n_simulations == 6 and res.best == {"E_b": 30e6, "sigma_c": 9e6}
    assert len(C.RunCache(tmp_path)) == 6


# --- objectives ----------------------------------------------------------------------------

def test_objectives_are_z_scores_and_rrmse():
    t = C.Targets(sigma_z=120e6, sigma_f=1.0e6, sigma_f_sd=0.1e6, dLf_D=0.06, dLf_D_sd=0.003,
                  bulk_density=1000.0, bulk_density_sd=20.0, curve=([0.02, 0.04, 0.06], [0.4e6, 0.8e6, 1.0e6]))
    z = C.diametral_error(1.2e6, 0.057, t)
    assert z == pytest.approx({"z_sigma_f": 2.0, "z_dLf_D": -1.0})
    assert C.density_error(960.0, t) == pytest.approx(-2.0)
    assert C.curve_error([0.0, 0.06], [0.0, 1.0e6], t) == pytest.approx(
        math.sqrt(((0.4 - 1 / 3) / 0.4) ** 2 / 3 + ((0.8 - 2 / 3) / 0.8) ** 2 / 3))
    sc = C.score({"sigma_f": 1.2e6, "dLf_D": 0.057, "bulk_density_relaxed": 960.0}, t,
                 {"dL_D": [0.0, 0.06], "sigma_1": [0.0, 1.0e6]})
    assert sc["rms_z"] == pytest.approx(math.sqrt((4 + 1 + 4) / 3))
    assert sc["rrmse"] > 0
    # SD floor: a zero SD is floored at 1% of the mean
    assert C.density_error(1010.0, C.Targets(sigma_z=60e6, bulk_density=1000.0)) == pytest.approx(1.0)


def test_failure_point_is_the_first_peak_with_a_real_fall():
    x = np.linspace(0, 0.15, 301)
    rng = np.random.default_rng(0)
    jitter = 1 + 0.03 * rng.standard_normal(x.size)
    # rise, peak at 0.06, fall to 60%, then the crushed pellet loads up again past the peak
    y = np.where(x < 0.06, x / 0.06, np.where(x < 0.09, 1 - 0.4 * (x - 0.06) / 0.03, 0.6 + 20 * (x - 0.09)))
    y[x < 0.002] = 0.2  # the spike of the plates' first contacts is not a failure
    sf, dl, peaked = C.failure_point(x, 1e6 * y * jitter)
    assert peaked and dl == pytest.approx(0.06, abs=0.004) and sf == pytest.approx(1e6, rel=0.1)
    # the stage's global maximum would be at the end
    assert np.argmax(y) == x.size - 1
    # a rising curve with 3% jitter (dips of single bond breaks) has not failed: bounds
    sf, dl, peaked = C.failure_point(x, 1e6 * x * jitter)
    assert not peaked and dl > 0.14
    # a curve that rises to the very end is not failed by the zero-padding of a smoother
    sf, dl, peaked = C.failure_point(x, x)
    assert not peaked and dl == x[-1] and sf == x[-1]
    assert C.failure_point([], [])[2] is False


def test_compaction_targets_pool_table2():
    from pelletdem.measured import variants

    tg = C.compaction_targets()
    assert [t.sigma_z for t in tg] == [60e6, 120e6]
    bd60 = [v.bd_pellet for v in variants() if v.sigma_z == 60e6]
    assert tg[0].bulk_density == pytest.approx(np.mean(bd60))
    assert tg[0].bulk_density_sd > np.std(bd60, ddof=1)


def test_compaction_targets_ask_one_solid_fraction_of_woods_of_different_density():
    from pelletdem.measured import variants

    at = {v.key: 680.0 * v.bd_pellet / v.bd_wood for v in variants()}  # BD_p / BD_w at 680 kg/m^3
    tg = C.compaction_targets(particle_density=680.0)
    assert tg[1].bulk_density == pytest.approx(np.mean([d for k, d in at.items() if k[2] == 120]))
    oak = [("oak", 8, 60), ("oak", 20, 60)]
    one = C.compaction_targets(oak, particle_density=675.0)  # oak's own BD_w: Table 2 unchanged
    assert one[0].bulk_density == pytest.approx(np.mean([v.bd_pellet for v in variants() if v.key in oak]))
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="particle_density"):
            C.compaction_targets(particle_density=bad)


def test_compaction_targets_by_moisture_content():
    """With a moisture effect, wet and dry ask their own densities: the mean of each (pressure,
    MC) group, the between-wood spread in the SD, the MC on the target for its runs."""
    from pelletdem.measured import variants

    tg = C.compaction_targets(by_mc=True)
    assert [(t.sigma_z, t.mc_percent) for t in tg] == [(60e6, 8.0), (60e6, 20.0), (120e6, 8.0), (120e6, 20.0)]
    wet120 = [v.bd_pellet for v in variants() if v.key[1:] == (20, 120)]
    assert tg[3].bulk_density == pytest.approx(np.mean(wet120))
    assert tg[3].bulk_density_sd > np.std(wet120, ddof=1)
    assert all(t.mc_percent is None for t in C.compaction_targets())
    for bad in (-1.0, 101.0, "8"):
        with pytest.raises(ValueError, match="mc_percent"):
            C.Targets(sigma_z=60e6, bulk_density=800.0, mc_percent=bad)


def test_compaction_targets_by_material_carry_the_woods_density():
    from pelletdem.measured import variants

    tg = C.compaction_targets(particle_density=680.0, by_mc=True, by_material=True)
    assert len(tg) == 12
    pine = [t for t in tg if "pine" in t.label and t.sigma_z == 60e6 and t.mc_percent == 8.0][0]
    v = [v for v in variants() if v.key == ("pine", 8, 60)][0]
    assert pine.wood_density == v.bd_wood
    assert pine.bulk_density == pytest.approx(680.0 * v.bd_pellet / v.bd_wood)
    assert pine.condition_rows() == {"moisture_content": 8.0, "wood_density": v.bd_wood}
    with pytest.raises(ValueError, match="wood_density"):
        C.Targets(sigma_z=60e6, bulk_density=800.0, wood_density=-1.0)


def test_a_targets_moisture_content_reaches_its_runs():
    from pelletdem.runs import run_setup

    setup = run_setup("tiny", None, {"moisture_yield": 0.03}, (0,), None)
    wet = setup.spec({}, 60e6, 0, False, C.Targets(sigma_z=60e6, bulk_density=1.0, mc_percent=20.0).condition_rows())
    assert wet.preset.contact.moisture_content == 20.0
    assert setup.spec({}, 60e6, 0, False).preset.contact.moisture_content == 8.0
    assert wet.relax_key != setup.spec({}, 60e6, 0, False).relax_key


def test_agreement_counts_the_variants_that_meet_each_criterion():
    import pandas as pd

    from pelletdem.variants import CalibrationReport

    nan = float("nan")
    table = pd.DataFrame({
        "z_sigma_f": [0.5, -1.0, 1.01, nan], "z_dLf_D": [0.0, 2.0, -0.2, 0.3],
        "z_bd": [-2.0, 2.5, 0.0, nan],
        "E_b_mpa": [100.0, 241.0, 60.0, 50.0], "E_b_mpa_paper": [120.0, 120.0, 120.0, 120.0],  # x2 is 240
        "sigma_c_mpa": [36.0, 36.0, 18.0, 17.0], "sigma_c_mpa_paper": [36.0, 36.0, 36.0, 36.0],
        "cn_sim": [12.9, 11.62, 14.18, 14.3], "cn_paper": [12.9, 12.9, 12.9, 12.9],  # 10 % of 12.9 is 1.29
    })
    rep = CalibrationReport(table=table, compaction=None, contact={}, fits={}, n_simulations=0, n_cached=0,
                            n_relaxations=0, wall_time_s=0.0)
    assert rep.agreement() == {"variants": 4, "sigma_f_within_1sd": 2, "dLf_D_within_1sd": 3,
                               "density_within_2sd": 2, "bonds_within_factor": 2, "cn_within_tolerance": 3}


# --- fits ----------------------------------------------------------------------------------

def test_fit_recovers_two_parameters_of_power_law_model():
    tg = synthetic_targets(25e6, 7e6, rel_sd=0.02)
    r = C.fit({"E_b": (1e6, 1e9, 120e6), "sigma_c": (1e5, 1e9, 36e6)}, tg, runner=power_law_runner, tol=0.3)
    assert r.converged, r.message
    assert r.params["E_b"] == pytest.approx(25e6, rel=0.03)
    assert r.params["sigma_c"] == pytest.approx(7e6, rel=0.03)
    assert r.n_points <= 6  # the paper needed 8-10 runs per variant
    assert r.n_simulations == r.n_points and len(r.history) == r.n_points


def test_fit_starting_before_the_peak_is_reached():
    # at the start the test ends (max_dLD = 0.1) long before the peak (dL_f/D = 0.19):
    # sigma_f and dL_f/D are only bounds there
    tg = synthetic_targets(25e6, 7e6, rel_sd=0.03)
    assert tg.dLf_D < 0.1
    start = C.make_spec({"E_b": 10e6, "sigma_c": 7e6})
    assert power_law_outputs(start)["peaked"] == 0.0
    r = C.fit({"E_b": (1e6, 1e9, 10e6), "sigma_c": (1e5, 1e9, 7e6)}, tg, runner=power_law_runner,
              max_dLD=0.1, tol=0.5)
    assert r.converged, (r.message, r.history)
    assert r.params["E_b"] == pytest.approx(25e6, rel=0.05)


def test_fit_nelder_mead_also_gets_there():
    tg = synthetic_targets(25e6, 7e6, rel_sd=0.05)
    r = C.fit({"E_b": (1e6, 1e9, 60e6), "sigma_c": (1e5, 1e9, 20e6)}, tg, method="nelder-mead",
              runner=power_law_runner, tol=1.0, max_runs=60)
    assert r.loss <= 1.0
    assert r.params["sigma_c"] == pytest.approx(7e6, rel=0.1)


def test_fit_compaction_k1_uses_loading_curve_slope():
    # BD_relaxed = 800 (sigma_z / 120 MPa / (k1 / 1e5))^0.25: hit 800 at 60 MPa -> k1 = 5e4
    tg = [C.Targets(sigma_z=60e6, bulk_density=800.0, bulk_density_sd=8.0)]
    r = C.fit({"k1": (1e4, 1e6, 1e5)}, tg, runner=power_law_runner, tol=0.2)
    assert r.converged and r.params["k1"] == pytest.approx(5e4, rel=0.02)


def test_fit_stops_at_bounds():
    tg = synthetic_targets(25e6, 7e6)
    r = C.fit({"sigma_c": (8e6, 2e7, 1e7)}, tg, fixed={"E_b": 25e6}, runner=power_law_runner)
    assert not r.converged and r.params["sigma_c"] == pytest.approx(8e6)
    assert "bound" in r.message


def test_calibrate_variants_machinery(tmp_path):
    # two variants, fake engine: the shared k1 fit, the per-variant fits, the report
    rep = C.calibrate_variants([("oak", 8, 120), ("pine", 20, 60)], "tiny", cache_dir=tmp_path,
                               executor=ThreadPoolExecutor(2), runner=power_law_runner, max_runs=6)
    t = rep.table
    assert list(t["material"]) == ["oak", "pine"]
    for col in ("E_b_mpa", "E_b_mpa_paper", "sigma_c_mpa", "sigma_c_mpa_paper", "sigma_f_mpa_sim",
                "sigma_f_mpa_exp", "z_sigma_f", "dLf_D_sim", "z_dLf_D", "bd_sim", "bd_exp", "z_bd",
                "n_points", "converged"):
        assert col in t
    assert (t["z_sigma_f"].abs() < 1).all() and (t["z_dLf_D"].abs() < 1).all()
    assert rep.compaction is not None and "k1" in rep.contact
    assert rep.n_simulations == len(set(CALLS)) == len(CALLS)
    assert "simulations run" in str(rep)
    # every diametral test stops at its break (30 % fall), the peak kept from half the lowest
    # measured dL_f/D of its variant on (Table 3: oak 8 % 120 MPa 0.061 +- 0.006)
    recs = [json.loads(f.read_text()) for f in tmp_path.rglob("*.json")]
    bond_presets = [r["spec"]["after_relax"] for r in recs if r["spec"].get("bond")]
    assert bond_presets and all(pr["break_drop"] == pytest.approx(0.7) for pr in bond_presets)
    both = (measured.variant("oak", 8, 120), measured.variant("pine", 20, 60))
    assert {round(pr["break_from_dLD"], 4) for pr in bond_presets} <= {
        round(0.5 * (v.dLf_D - 2 * v.dLf_D_sd), 4) for v in both}
    with pytest.raises(ValueError, match="break_drop"):
        C.calibrate_variants([("oak", 8, 120)], "tiny", break_drop=1.5, executor="serial", runner=power_law_runner)
    # everything is cached: a second call runs nothing
    rep2 = C.calibrate_variants([("oak", 8, 120), ("pine", 20, 60)], "tiny", cache_dir=tmp_path,
                                executor="serial", runner=power_law_runner, max_runs=6)
    assert rep2.n_simulations == 0
    assert rep2.table["E_b_mpa"].tolist() == pytest.approx(t["E_b_mpa"].tolist())


def test_calibrate_variants_transfers_a_contact_law_and_warm_starts(tmp_path):
    # A calibration on one preset hands its k1 and bond fits to another: every run of the
    # second uses that k1 (no compaction fit), and starting at the first's bond parameters
    # needs fewer runs than starting at Table 5's.
    vs = [("oak", 8, 120), ("pine", 20, 60)]
    first = C.calibrate_variants(vs, "tiny", executor="serial", runner=power_law_runner, max_runs=8)
    k1 = first.contact["k1"]
    assert first.bond_start().keys() == first.fits.keys()
    CALLS.clear()
    cold = C.calibrate_variants(vs, "quick", contact=first.contact, executor="serial",
                                runner=power_law_runner, max_runs=8)
    runs_cold = len(CALLS)
    assert cold.compaction is None and cold.contact == first.contact
    CALLS.clear()
    warm = C.calibrate_variants(vs, "quick", compaction=None, contact=first.contact,
                                start=first.bond_start(), cache_dir=tmp_path, executor="serial",
                                runner=power_law_runner, max_runs=8)
    seen = [runs.canonical(json.loads(p.read_text())["spec"]) for p in tmp_path.rglob("*.json")]
    assert seen and all(s["preset"]["contact"]["k1"] == pytest.approx(k1, rel=1e-9) for s in seen)
    assert len(CALLS) < runs_cold
    assert (warm.table["z_sigma_f"].abs() < 1).all() and (warm.table["z_dLf_D"].abs() < 1).all()
    with pytest.raises(ValueError, match="pass one"):
        C.calibrate_variants(vs, "tiny", contact={"k1": 4e4}, compaction={"k1": (1e4, 1e5)},
                             runner=power_law_runner)
    with pytest.raises(ValueError, match="k_1"):
        C.calibrate_variants(vs, "tiny", compaction=None, contact={"k_1": 4e4}, runner=power_law_runner)
    with pytest.raises(ValueError, match="k1"):
        C.calibrate_variants(vs, "tiny", compaction=None, contact={"k1": -1.0}, runner=power_law_runner)


def test_calibration_plots(tmp_path):
    from pelletdem import plots

    rep = C.calibrate_variants([("oak", 8, 120), ("birch", 8, 60)], "tiny", compaction=None,
                               executor="serial", runner=power_law_runner, max_runs=4)
    fig = plots.calibration_measured_vs_simulated(rep)
    fig.savefig(tmp_path / "mvs.png")
    res = C.scan(GRID, synthetic_targets(30e6, 9e6), executor="serial", runner=power_law_runner)
    fig = plots.calibration_parameter_map(res.points)
    fig.savefig(tmp_path / "map.png")
    fig = plots.calibration_parameter_map(rep.fits["oak MC 8% 120 MPa"].history)
    fig.savefig(tmp_path / "path.png")
    assert all((tmp_path / f).stat().st_size > 0 for f in ("mvs.png", "map.png", "path.png"))


# --- bad inputs ------------------------------------------------------------------------------

@pytest.mark.parametrize("params, match", [
    ({"E_bond": (1e6, 1e8)}, "E_bond"),
    ({"sigma_c": (1e8, 1e6)}, "sigma_c.*reversed"),
    ({"sigma_c": (1e6, 1e6)}, "sigma_c.*reversed"),
    ({"E_b": (float("nan"), 1e8)}, "E_b.*finite"),
    ({"E_b": (1e6, float("inf"))}, "E_b.*finite"),
    ({"E_b": (0.0, 1e8)}, "E_b.*> 0"),
    ({"E_b": (1e6, 1e8, 1e9)}, "start of 'E_b'"),
    ({"E_b": (1e6,)}, "E_b"),
    ({"E_b": "abc"}, "E_b"),
    ({}, "non-empty"),
])
def test_fit_rejects_bad_parameters(params, match):
    with pytest.raises(ValueError, match=match):
        C.fit(params, synthetic_targets(30e6, 9e6), runner=power_law_runner)
    assert CALLS == []


def test_other_bad_inputs_name_the_parameter():
    tg = synthetic_targets(30e6, 9e6)
    with pytest.raises(ValueError, match="sigma_cc"):
        C.scan({"sigma_cc": [1e6]}, tg, executor="serial", runner=power_law_runner)
    with pytest.raises(ValueError, match="E_b"):
        C.scan({"E_b": [1e6, float("nan")]}, tg, executor="serial", runner=power_law_runner)
    with pytest.raises(ValueError, match="sigma_c"):
        C.make_spec({"sigma_c": float("nan")})
    with pytest.raises(ValueError, match="sigma_f"):
        C.Targets(sigma_z=120e6, sigma_f=float("nan"))
    with pytest.raises(ValueError, match="dLf_D_sd"):
        C.Targets(sigma_z=120e6, dLf_D=0.05, dLf_D_sd=-1.0)
    with pytest.raises(ValueError, match="sigma_z"):
        C.Targets(sigma_z=float("nan"), sigma_f=1e6)
    with pytest.raises(ValueError, match="'E_b' is both fitted and fixed"):
        C.fit({"E_b": (1e6, 1e8)}, tg, fixed={"E_b": 3e7}, runner=power_law_runner)
    with pytest.raises(ValueError, match="unknown fixed parameter 'Eb'"):
        C.fit({"sigma_c": (1e6, 1e8)}, tg, fixed={"Eb": 3e7}, runner=power_law_runner)
    with pytest.raises(ValueError, match="unknown start parameter"):
        C.fit({"sigma_c": (1e6, 1e8)}, tg, start={"E_b": 3e7}, runner=power_law_runner)
    with pytest.raises(ValueError, match="mu_x"):
        C.make_spec({}, contact={"mu_x": 0.3})
    with pytest.raises(ValueError, match="executor"):
        C.scan(GRID, tg, executor="dask", runner=power_law_runner)
    with pytest.raises(ValueError, match="method"):
        C.fit({"sigma_c": (1e6, 1e8)}, tg, method="bfgs", runner=power_law_runner)
    with pytest.raises(ValueError, match="material"):
        C.calibrate_variants([("teak", 8, 120)], runner=power_law_runner)
    assert CALLS == []
