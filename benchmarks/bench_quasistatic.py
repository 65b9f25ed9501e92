#!/usr/bin/env python3
"""What each quasi-static speed-up changes in a pellet, against today's settings, packing by
packing: a speed-up is adopted only where it stays within the packing scatter.

Run:  python3 benchmarks/bench_quasistatic.py --preset tiny --seeds 8
      python3 benchmarks/bench_quasistatic.py --preset paper --seeds 2 --variants today fill_dt clear

One law and one set of bonds throughout: the chosen model's contact law (docs/calibration.md,
run R: oak's k1, k_p = 50 k2, moisture_yield, hardening, densified_yield 100,
interlocking_friction 2, overlap guard 2) and Table 5's oak 8 % 120 MPa bonds. For each
variant and packing (seed) one pellet at 120 MPa: its relaxed density (as a caliper reads it),
bulk CN, spring-back (1 - relaxed / peak density), sigma_f and dL_f/D, and the steps and wall
time of each stage. The plate-speed variants break today's relaxed pellet (a clone), so they
differ from today's in the test alone.

The table gives each quantity's mean and SD over the packings, and the mean paired difference
from today's in units of the SD between packings (the scatter of one packing, pooled over
every variant's pellets) and over its own standard error (t): a variant is within the scatter
when every |difference| <= 1 SD; t says whether a shift inside it is systematic all the same.
Results are cached per (preset, variant, seed) in benchmarks/.cache/quasistatic/ (or
--cache DIR: a folder outside the work tree carries a study at the paper's size, an hour of a
core per pellet, from one sitting to the next), so a run can be extended or resumed; the rows
quoted in the docs are committed in results/.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
CACHE = os.path.join(HERE, ".cache", "quasistatic")
CHOSEN_LAW = dict(k1=1.504e4, k2=9.6e4, plastic_stiffness_ratio=50.0, moisture_yield=-0.0398, hardening=0.68,
                  hardening_exponent=2.0, densified_yield=100.0, interlocking_friction=2.0)
QUANTITIES = ("bulk_density", "cn_bulk", "spring_back", "sigma_f", "dLf_D")
# Variants: preset changes (factors on today's values where a name ends in _x; the piston's
# inertia number at the target pressure), or a plate speed factor for the test alone.
VARIANTS = {
    "today": {},
    "fill_dt": {"fill_dt_x": 4.0},
    "clear": {"clear_at_once": True},
    "dt": {"dt_x": 1.35},
    "piston_x0.5": {"piston_speed_x": 0.5},
    "piston_x2": {"piston_speed_x": 2.0},
    # the fill's step, the walls cleared at once, dt at 1.35 times today's and the piston at
    # the speed that gives the inertia number 5e-3 at the target (today: 5.7e-3 on tiny)
    "fast": {"fill_dt_x": 4.0, "clear_at_once": True, "dt_x": 1.35, "piston_inertia": 5e-3},
    "plates_x0.25": {"plates": 0.25},
    "plates_x0.5": {"plates": 0.5},
    "plates_x2": {"plates": 2.0},
}


def preset_for(name: str, changes: dict):
    """The preset `name` with the chosen law and the variant's changes (plate speed aside)."""
    from pelletdem import ContactLaw
    from pelletdem.presets import get_preset

    base = get_preset(name)
    p = base.with_(contact=ContactLaw(**CHOSEN_LAW), max_overlap_ratio=2.0)
    kw = {}
    for key, value in changes.items():
        if key == "plates":
            continue
        if key.endswith("_x"):
            field = key[:-2]
            kw[field] = value * getattr(base, field if field != "fill_dt" else "dt")
        else:
            kw[key] = value
    return p.with_(**kw)


def _at_peak(series: dict, name: str) -> float:
    """``series[name]`` where sigma_1 peaks (nan for an empty test)."""
    s1 = np.asarray(series["sigma_1"])
    return float(np.asarray(series[name])[int(np.argmax(s1))]) if s1.size else float("nan")


def _measure(relaxed_res, broken_res) -> dict:
    compact, relax = relaxed_res.stages["compact"].scalars, relaxed_res.stages["relax"].scalars
    d = broken_res.stages["diametral"].scalars
    stages_all = {**relaxed_res.stages, **broken_res.stages}
    return {"bulk_density": relax["bulk_density"], "cn_bulk": relax["coordination_number_bulk"],
            "spring_back": 1.0 - relax["bulk_density"] / compact["bulk_density_max"],
            "sigma_f": d["sigma_f"], "dLf_D": d["dLf_D"],
            "inertia_compact": compact["inertia_number_at_target"],
            "inertia_diametral": float(_at_peak(broken_res.stages["diametral"].series, "inertia_number")),
            "steps": {k: int(s.steps) for k, s in stages_all.items()},
            "wall_s": {k: float(s.wall_time_s) for k, s in stages_all.items()}}


def run_seed(preset: str, seed: int, variants, threads: int, cache: str = CACHE) -> dict:
    """Every variant's pellet of packing `seed` (cached), sharing today's relaxed pellet
    among the plate-speed variants."""
    from pelletdem import BondLaw, pipeline
    from pelletdem.worker import clone_pellet

    os.makedirs(cache, exist_ok=True)
    out, today = {}, None
    for name in variants:
        path = os.path.join(cache, f"{preset}_{name}_s{seed}.json")
        if os.path.exists(path):
            with open(path) as fh:
                out[name] = json.load(fh)
            continue
        changes = dict(VARIANTS[name])
        if "piston_inertia" in changes:  # I grows with the speed: scaled from today's at the target
            changes["piston_speed_x"] = changes.pop("piston_inertia") / out["today"]["inertia_compact"]
        law = BondLaw(radius=2e-5, youngs_modulus=120e6, sigma_c=36e6, tau_c=36e6)
        t0 = time.perf_counter()
        if "plates" in changes:
            if today is None:
                today = pipeline.relaxed_pellet(preset_for(preset, {}), 120e6, seed=seed, threads=threads,
                                                progress=False)
            pellet, res = today
            p = pellet.preset
            broken = pipeline.break_pellet(clone_pellet(pellet), law, plate_speed=changes["plates"] * p.plate_speed,
                                           progress=False)
            row = _measure(res, broken)
        else:
            pellet, res = pipeline.relaxed_pellet(preset_for(preset, changes), 120e6, seed=seed, threads=threads,
                                                  progress=False)
            if name == "today":
                today = (clone_pellet(pellet), res)
            row = _measure(res, pipeline.break_pellet(pellet, law, progress=False))
        row["total_s"] = time.perf_counter() - t0
        with open(path, "w") as fh:
            json.dump(row, fh)
        out[name] = row
        print(f"  {preset} seed {seed} {name}: {row['total_s']:.0f} s, density {row['bulk_density']:.1f}, "
              f"CN {row['cn_bulk']:.2f}, sigma_f {row['sigma_f'] / 1e6:.3f} MPa, dLf/D {row['dLf_D']:.4f}",
              flush=True)
    return out


def table(rows: dict, variants) -> str:
    """rows[seed][variant] -> the markdown table of means, SDs and paired differences."""
    seeds = sorted(rows)
    lines = ["| variant | " + " | ".join(QUANTITIES) + " | steps (relaxed / whole life) | within the scatter |",
             "|---|" + "---|" * (len(QUANTITIES) + 2)]
    base = {q: np.array([rows[s]["today"][q] for s in seeds]) for q in QUANTITIES}
    # The scatter of one packing, pooled over every variant's packings: each pellet is a
    # specimen, and a breakage is chaotic in the fourth digit of anything, so today's few
    # packings alone can fall close together by chance (quick's sigma_f: 0.8 % on 4 against
    # 4.3 % on 6 in "The model's scatter between packings").
    pooled = {q: float(np.sqrt(np.mean([np.var([rows[s][v][q] for s in seeds], ddof=1) for v in variants])))
              if len(seeds) > 1 else float("nan") for q in QUANTITIES}
    for name in variants:
        cells, within = [], True
        for q in QUANTITIES:
            v = np.array([rows[s][name][q] for s in seeds])
            sd0 = pooled[q]
            scale = 1e-6 if q == "sigma_f" else 1.0
            cell = f"{v.mean() * scale:.4g} ± {v.std(ddof=1) * scale if len(seeds) > 1 else float('nan'):.2g}"
            if name != "today":
                diff = v - base[q]
                z = diff.mean() / sd0
                within &= bool(abs(z) <= 1.0)
                # the paired difference over its own standard error: a shift the packings'
                # common part does not hide (|t| > ~2.4 on 8 packings, ~3.2 on 4 at 95 %)
                t = diff.mean() / (diff.std(ddof=1) / np.sqrt(len(diff))) if diff.std(ddof=1) > 0 else 0.0
                cell += f" ({z:+.2f} SD, t {t:+.1f})"
            cells.append(cell)
        relaxed = np.mean([sum(n for k, n in rows[s][name]["steps"].items() if k not in ("bond", "diametral"))
                           for s in seeds])
        whole = np.mean([sum(rows[s][name]["steps"].values()) for s in seeds])
        verdict = "-" if name == "today" else ("yes" if within else "no")
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {relaxed:,.0f} / {whole:,.0f} | {verdict} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="tiny", choices=("tiny", "quick", "paper"))
    ap.add_argument("--seeds", type=int, default=8, help="packings 0..N-1 (default 8)")
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--cache", default=CACHE, help="folder of the per-pellet rows (default %(default)s)")
    args = ap.parse_args(argv)
    variants = ["today"] + [v for v in args.variants if v != "today"]
    rows = {}
    for seed in range(args.seeds):
        rows[seed] = run_seed(args.preset, seed, variants, args.threads, args.cache)
    print(f"\n{args.preset}, the chosen law, Table 5's oak 8 % 120 MPa bonds, packings 0-{args.seeds - 1}:\n")
    print(table(rows, variants))
    print("\nthe SD column: each variant's own over the packings; (SD): the paired difference from today's "
          "over the scatter of one packing, pooled over every variant's pellets")
    return 0


if __name__ == "__main__":
    sys.exit(main())
