#!/usr/bin/env python3
"""Why a loop added the twin of a hidden effect: the truth, the true law's fit and its rival's
fit simulated on many fresh packings and scored against the draw's own data.

Run:  python3 benchmarks/bench_twin_diagnosis.py --out OUT --case saturating_unloading --draw 2
      python3 benchmarks/bench_twin_diagnosis.py --out OUT --case unloading_growth --draw 4 --packings 16

OUT is a directory of `bench_loop_acceptance.py` (OUT/CASE/dD/loop.json and the run cache
OUT/cache, so the draw's data and every packing already simulated are reused). The models are
the hidden truth and every candidate the draw's first step fitted in full, each at its fitted
parameters. For each it prints, on packings 100 .. 100 + packings - 1 (the loop's check seeds
and more):

- chi2 as the loop's check computes it (Welch z-scores: the data's SE and the ensemble's),
  in all and by quantity;
- D between every two models (:func:`pelletdem.loop_separation.separation`).

and, for the truth, how far the draw's replicate packings lie from the fresh ones (the data's
own luck): per observation, (mean on the data's packings - mean on the fresh ones) over the
standard error of that difference, without the measurement noise. Writes OUT/CASE/dD/twins.md.
A truth that scores worse than the fits shows that the data's luck, which the fits take up,
decides; two fits D apart below 10.8 are a coin flip whatever rule picks one.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys

import numpy as np


def models_of(out: dict, truth: dict) -> dict:
    """{label: parameters (SI)}: the truth and each full fit of the loop's first step."""
    models = {"truth": truth}
    for t in out["steps"][0]["trials"]:
        models[f"{t['effect']} (fit)"] = t["model"]["params"]
    return models


def data_luck(sim, truth, data, seeds, fresh) -> list:
    """Rows (condition, quantity, x, z) of the truth's mean on the data's own packings against
    its mean on the ``fresh`` packings, in the standard error of their difference."""
    rows = []
    for c in dict.fromkeys(o.condition for o in data.observations):
        own = sim.predict(truth, [c], tuple(seeds[c]))[c]
        new = sim.predict(truth, [c], tuple(fresh))[c]
        for o in data.observations:
            if o.condition != c:
                continue
            a, b = own.values(o), new.values(o)
            se = math.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
            rows.append((c.label, o.quantity, o.x, (a.mean() - b.mean()) / se if se > 0 else math.nan))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="a bench_loop_acceptance.py output directory")
    ap.add_argument("--case", required=True, help="the hidden case, e.g. saturating_unloading")
    ap.add_argument("--draw", type=int, required=True)
    ap.add_argument("--packings", type=int, default=12, help="fresh packings (2..64)")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    if not 2 <= a.packings <= 64:
        ap.error(f"--packings = {a.packings} is out of range: allowed 2..64")
    path = os.path.join(a.out, a.case.replace("=", "_"), f"d{a.draw}")
    if not os.path.exists(os.path.join(path, "loop.json")):
        ap.error(f"{path}/loop.json not found: run bench_loop_acceptance.py --cases {a.case} first")

    from pelletdem import loop
    from pelletdem.engine import BondLaw
    from pelletdem.loop_cli import SYNTHETIC_BOND, WINDOW, synthetic_data, synthetic_design, synthetic_truth
    from pelletdem.loop_models import chi2_of, ensemble_z
    from pelletdem.loop_selection import fit_window
    from pelletdem.loop_separation import separation

    with open(os.path.join(path, "loop.json")) as fh:
        out = json.load(fh)
    hidden = synthetic_truth(a.case)
    conds, held, seeds = synthetic_design(hidden, a.draw)
    fresh = tuple(100 + j for j in range(a.packings))
    cache = os.path.join(a.out, "cache")
    lines = [f"# {a.case}, draw {a.draw}: the models on {a.packings} fresh packings", ""]
    with loop.EngineSimulator("tiny", bond=BondLaw(**SYNTHETIC_BOND), contact={}, seeds=tuple(range(out["packings"])),
                              max_dLD=WINDOW, max_workers=a.workers, cache_dir=cache,
                              relaxed_dir=os.path.join(cache, "relaxed")) as sim:
        data, truth = synthetic_data(sim, hidden, a.draw)
        fit_window(sim, data.split(lambda c: c in held)[0], lambda s: None)
        models = models_of(out, truth)
        ens = {m: sim.predict(p, conds, fresh) for m, p in models.items()}
        quantities = ("sigma_1", "sigma_z", "sigma_f", "dLf_D", "bulk_density")
        lines += ["| model | chi2 | of it: " + ", ".join(quantities) + " | parameters |", "|---|---|---|---|"]
        for m, e in ens.items():
            z = ensemble_z(e, data)
            parts = [float(np.sum(z[[o.quantity == q for o in data.observations]] ** 2)) for q in quantities]
            lines.append(f"| {m} | {chi2_of(z):.1f} | " + ", ".join(f"{v:.1f}" for v in parts) + " | "
                         + ", ".join(f"{k} {v:.4g}" for k, v in models[m].items()) + " |")
        names = list(ens)
        lines += ["", f"{len(data)} observations. D between the models (in the data's SE, less the packings' "
                  "noise):", ""]
        lines += [f"- {names[i]} and {names[j]}: D = {separation(ens[names[i]], ens[names[j]], data):.1f}"
                  for i in range(len(names)) for j in range(i + 1, len(names))]
        luck = data_luck(sim, truth, data, seeds, fresh)
        lines += ["", "The data's own packings against the fresh ones (the truth, no measurement noise; "
                  "|z| > 1.5):", ""]
        lines += [f"- {c}, {q}" + (f" at {x:.3f}" if math.isfinite(x) else "") + f": z = {z:+.2f}"
                  for c, q, x, z in luck if abs(z) > 1.5]
        lines += ["", f"simulations run: {sim.n_simulations}"]
    text = "\n".join(lines) + "\n"
    with open(os.path.join(path, "twins.md"), "w") as fh:
        fh.write(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
