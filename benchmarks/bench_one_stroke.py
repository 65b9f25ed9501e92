#!/usr/bin/env python3
"""What one piston stroke through both pressures saves: the relaxed pellets of 60 and 120 MPa
from one bed and one stroke (`pipeline.relaxed_pellets`) against each from its own bed and
stroke (`pipeline.relaxed_pellet` twice), on the same packings, one thread, timed back to back.

Usage (one core; `quick`: 3-6 minutes per packing, the softer the law the longer):

    python benchmarks/bench_one_stroke.py --preset quick --packings 2
    python benchmarks/bench_one_stroke.py --preset tiny --packings 4 --set contact.k1=1.5e4

The preset carries the calibration's overlap guard. Prints per packing the two wall times
and their ratio (one stroke / two), and that the pellets are the same to the bit (positions
and velocities of both pressures). `--set contact.NAME=V` runs another contact law (SI
units; repeatable), e.g. a softer k1 that strokes further.
"""
import argparse
import time

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--preset", default="quick", help="tiny, quick or paper (default quick)")
    ap.add_argument("--packings", type=int, default=2, help="packings (seeds 0..N-1), 1..64")
    ap.add_argument("--set", dest="settings", action="append", default=[], metavar="contact.NAME=VALUE")
    args = ap.parse_args(argv)
    if not 1 <= args.packings <= 64:
        ap.error(f"--packings = {args.packings} is out of range: allowed 1..64")

    from pelletdem import pipeline
    from pelletdem.engine import BondLaw
    from pelletdem.law_settings import apply_settings, parse_settings
    from pelletdem.loop_paper import paper_preset

    preset = paper_preset(args.preset)  # the overlap guard the calibration runs with
    try:
        contact, _ = apply_settings(preset.contact, BondLaw(), parse_settings(args.settings))
    except ValueError as e:
        ap.error(str(e))
    preset = preset.with_(contact=contact)
    pressures = (60e6, 120e6)
    print(f"preset {preset.name}, {args.packings} packings, pressures 60 and 120 MPa, one thread")
    print("packing | one stroke (s) | two strokes (s) | ratio | same bits")
    ratios = []
    for seed in range(args.packings):
        t0 = time.perf_counter()
        one = pipeline.relaxed_pellets(preset, pressures, seed=seed, progress=False)
        t1 = time.perf_counter()
        two = [pipeline.relaxed_pellet(preset, sigma_z=sz, seed=seed, progress=False) for sz in pressures]
        t2 = time.perf_counter()
        same = all(np.array_equal(np.asarray(getattr(a.world, q)), np.asarray(getattr(b.world, q)))
                   for (a, _), (b, _) in zip(one, two) for q in ("x", "v"))
        ratios.append((t1 - t0) / (t2 - t1))
        print(f"{seed} | {t1 - t0:.1f} | {t2 - t1:.1f} | {ratios[-1]:.3f} | {same}", flush=True)
    print(f"one stroke / two: mean {np.mean(ratios):.3f}, range {min(ratios):.3f}-{max(ratios):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
