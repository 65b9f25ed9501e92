#!/usr/bin/env python3
"""What a contact effect costs: whole `tiny` pellet lives (fill, compaction to 120 MPa,
unloading, demoulding, relaxation, bonding, diametral test; one thread, as the loop's workers
run them) with each contact effect of the library switched on, against the paper's law in the
same run.

Run:  python3 benchmarks/bench_effect_kernel.py
      python3 benchmarks/bench_effect_kernel.py --seeds 3 --repeats 2

A compaction candidate of the discrepancy loop re-simulates every pellet from its fill, so
what an effect costs per life sets what its loop costs. The four-lane pair kernel runs the
contact effects' hooks lane by lane; before it did, every pair of a pellet with an effect on
went through the scalar kernel, and a life cost 2.5 times the paper's law's. The cases run in
turn, `--repeats` rounds, the best time of each (seed, case) kept, since the machine is shared
and noisy; the figure is the ratio of each effect's total to the paper's law's, target <= 1.3.
"""
from __future__ import annotations

import argparse
import time

#: Each contact effect at the strength its loop probes (pelletdem.effects), as ContactLaw fields.
EFFECTS = {
    "paper's law": {},
    "hardening": {"hardening": 0.05},
    "unloading_growth": {"unloading_growth": 7.0},
    "saturating_unloading": {"plastic_stiffness_ratio": 5.0},
    "moisture_yield": {"moisture_yield": 0.03, "moisture_content": 20.0},
    "wood_density_yield": {"wood_density_yield": 1.5, "wood_density": 510.0},
}

#: Largest ratio of an effect's life to the paper's law's.
TARGET = 1.3


def life_time(contact: dict, seed: int) -> float:
    """Wall time (s) of one `tiny` pellet's life with the contact law fields ``contact``."""
    from pelletdem.runs import make_spec
    from pelletdem.worker import clear_memo, run_point

    spec = make_spec({"E_b": 6e7, "sigma_c": 9e6}, preset="tiny", sigma_z=120e6, seed=seed, contact=contact)
    clear_memo()  # a life from its fill, not from a memoised relaxed pellet
    t = time.perf_counter()
    rec = run_point(spec)
    if not rec["ok"]:
        raise RuntimeError(f"{contact}: {rec['error']}")
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="packings per case")
    ap.add_argument("--repeats", type=int, default=2, help="rounds; the best time of each kept")
    a = ap.parse_args()
    if a.seeds < 1 or a.repeats < 1:
        raise SystemExit("--seeds and --repeats must be >= 1")
    best = {(name, s): float("inf") for name in EFFECTS for s in range(a.seeds)}
    for _ in range(a.repeats):
        for s in range(a.seeds):
            for name, contact in EFFECTS.items():
                best[(name, s)] = min(best[(name, s)], life_time(contact, 100 + s))
    ref = sum(best[("paper's law", s)] for s in range(a.seeds))
    print(f"| effect | life, s (mean of {a.seeds}) | over the paper's law | target |")
    print("|---|---|---|---|")
    for name in EFFECTS:
        tot = sum(best[(name, s)] for s in range(a.seeds))
        ok = "" if name == "paper's law" else ("met" if tot / ref <= TARGET else "NOT met")
        print(f"| {name} | {tot / a.seeds:.2f} | {tot / ref:.2f} | <= {TARGET} {ok} |")


if __name__ == "__main__":
    main()
