#!/usr/bin/env python3
"""How much a pellet's measured values scatter between packings, by size: the model's own noise,
against which the discrepancy loop must see an effect.

Run:  python3 benchmarks/bench_packing_scatter.py                  (400, 2,500 and 10,000)
      python3 benchmarks/bench_packing_scatter.py --sizes 40000 --seeds 2

For each size it runs whole pellet lives (oak, MC 8 %, 120 MPa; Table 4's contact law; bonds
strong enough to break the small pellets: E_b 860 MPa, sigma_c = tau_c 107.2 MPa) on packings
(seeds) 0, 1, ..., and reports over them, for sigma_f, dL_f/D, the relaxed bulk density (as a
caliper reads it), the bulk coordination number, sigma_1 at dL/D = 0.25, 0.5 and 0.75 of the
mean dL_f/D and sigma_z at dh/h0 = 0.3 and 0.4: the mean, the coefficient of variation between
packings (CV, the scatter of one packing), and the standard error of a mean over k packings
(CV / sqrt(k)) for k = 1, 2, 4, 8. Results are cached per (size, seed) in
benchmarks/.cache/scatter/, so a run can be extended. The 400 and 2,500 pellets use the `tiny`
and `quick` presets; 10,000 and 40,000 use the 5 mm and 10 mm moulds.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
CACHE = os.path.join(HERE, ".cache", "scatter")
BOND = dict(radius=2e-5, youngs_modulus=860e6, sigma_c=107.2e6, tau_c=107.2e6)
FRACTIONS = (0.25, 0.5, 0.75)      # of the mean dL_f/D
COMPACTION_AT = (0.3, 0.4)         # dh/h0


def preset_for(n: int):
    """The run size for n particles: tiny, quick, or the paper's particles in a 5 or 10 mm mould."""
    from pelletdem.presets import get_preset

    if n == 400:
        return get_preset("tiny")
    if n == 2500:
        return get_preset("quick")
    base = get_preset("quick") if n <= 10000 else get_preset("paper")
    return base.with_(name=f"n{n}", n_particles=n)


def life(n: int, seed: int, threads: int) -> dict:
    """One whole life (cached): the curves and scalars the table is made from."""
    os.makedirs(CACHE, exist_ok=True)
    path = os.path.join(CACHE, f"n{n}_s{seed}.json")
    if os.path.exists(path):
        with open(path) as fh:
            return json.load(fh)
    from pelletdem import BondLaw, pipeline

    t0 = time.perf_counter()
    res = pipeline.run_pellet(preset_for(n), seed=seed, threads=threads, bond_law=BondLaw(**BOND),
                              progress=False)
    d, r, c = res.stages["diametral"], res.stages["relax"].scalars, res.stages["compact"].series
    out = {"sigma_f": d.scalars["sigma_f"], "dLf_D": d.scalars["dLf_D"], "bulk_density": r["bulk_density"],
           "cn_bulk": r["coordination_number_bulk"], "dL_D": np.asarray(d.series["dL_D"]).tolist(),
           "sigma_1": np.asarray(d.series["sigma_1"]).tolist(), "dh_h0": np.asarray(c["dh_h0"]).tolist(),
           "sigma_z": np.asarray(c["sigma_z"]).tolist(), "wall_time_s": time.perf_counter() - t0}
    with open(path, "w") as fh:
        json.dump(out, fh)
    return out


def table(n: int, lives: list) -> dict:
    """Mean, CV between packings and the quantities' names for one size."""
    x_f = float(np.mean([lv["dLf_D"] for lv in lives]))
    values: dict = {q: [lv[q] for lv in lives] for q in ("sigma_f", "dLf_D", "bulk_density", "cn_bulk")}
    for f in FRACTIONS:
        values[f"sigma_1 at {f:g} dLf/D"] = [float(np.interp(f * x_f, lv["dL_D"], lv["sigma_1"])) for lv in lives]
    for h in COMPACTION_AT:
        values[f"sigma_z at dh/h0 {h:g}"] = [float(np.interp(h, lv["dh_h0"], lv["sigma_z"])) for lv in lives]
    rows = {}
    for q, v in values.items():
        v = np.asarray(v, float)
        mean = float(v.mean())
        cv = float(v.std(ddof=1) / abs(mean)) if len(v) > 1 and mean else float("nan")
        rows[q] = {"mean": mean, "cv": cv}
    return {"n": n, "k": len(lives), "rows": rows,
            "wall_time_s": float(np.mean([lv["wall_time_s"] for lv in lives]))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="400,2500,10000", help="particle counts, comma-separated")
    ap.add_argument("--seeds", type=int, default=0, help="packings per size (0: 8, 6, 3, 2 by size)")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args(argv)
    default_k = {400: 8, 2500: 6, 10000: 3, 40000: 2}
    for n in [int(s) for s in a.sizes.split(",")]:
        k = a.seeds or default_k.get(n, 3)
        lives = [life(n, s, a.threads) for s in range(k)]
        t = table(n, lives)
        print(f"# {n} particles, {t['k']} packings, {t['wall_time_s']:.0f} s per life")
        print(f"{'quantity':<24} {'mean':>11} {'CV':>7} " + " ".join(f"{'SE k=' + str(m):>8}" for m in (1, 2, 4, 8)))
        for q, row in t["rows"].items():
            se = " ".join(f"{row['cv'] / np.sqrt(m):8.3f}" for m in (1, 2, 4, 8))
            print(f"{q:<24} {row['mean']:11.4g} {row['cv']:7.3f} {se}")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
