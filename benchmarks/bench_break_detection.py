#!/usr/bin/env python3
"""What the diametral test's break detection saves: each variant's bonds run on the same
relaxed pellet with the test run to max_dLD and with it stopped at the break.

Usage (one worker; ~5 minutes for four `quick` variants, most of it two relaxations):

    python benchmarks/bench_break_detection.py --from OUT_DIR          # a calibration's fits
    python benchmarks/bench_break_detection.py --preset tiny --variants 6

`--from` takes the contact law and the fitted bonds of `examples/03_calibration.py OUT_DIR`
(its calibration.json, on the same preset); without it the preset's own contact law and
Table 5's bonds are used. The tests end as `calibrate_variants` ends them: max_dLD = 1.5 x
(mean + 2 SD) of Table 3's dL_f/D, at least the preset's; with `--drop` (0.7) the peak is kept
from half the lowest measured dL_f/D on. Each run is timed once, the two cases back to back on
the same relaxed pellet (a clone each); the time ratio is printed beside the diametral test's
end (dL/D) and the failure point of each, which must agree (`calibrate.failure_point`).
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--from", dest="source", type=Path, default=None, help="a calibration's OUT_DIR")
    ap.add_argument("--preset", default=None, help="tiny, quick or paper (default: the calibration's, else quick)")
    ap.add_argument("--variants", type=int, default=4, help="how many of the 12 variants (spread over them)")
    ap.add_argument("--drop", type=float, default=0.7, help="break_drop, 0 < drop < 1")
    args = ap.parse_args(argv)
    if not 0.0 < args.drop < 1.0:
        ap.error(f"--drop = {args.drop} is out of range: allowed 0 < drop < 1")
    if not 1 <= args.variants <= 12:
        ap.error(f"--variants = {args.variants} is out of range: allowed 1..12")

    from pelletdem import calibrate as C
    from pelletdem import measured
    from pelletdem.pipeline import bond_law_for
    from pelletdem.presets import get_preset

    cal = json.loads((args.source / "calibration.json").read_text()) if args.source else None
    preset = get_preset(args.preset or (cal["preset"] if cal else "quick"))
    contact = cal["contact"] if cal else None
    vs = measured.variants()
    vs = [vs[k] for k in np.linspace(0, len(vs) - 1, args.variants).round().astype(int)]
    print(f"preset {preset.name}, break_drop {args.drop}, contact {contact or 'the preset'}")
    print("variant | test end (dL/D) full / stopped | sigma_f (MPa) full / stopped | dL_f/D full / stopped "
          "| time stopped / full")
    ratios = []
    for v in vs:
        if cal:
            params = cal["bond_start"][v.label]
        else:
            b = bond_law_for(v.material, v.mc_percent, v.sigma_z_mpa)
            params = {"E_b": b.youngs_modulus, "sigma_c": b.sigma_c}
        mdl = max(preset.max_dLD, round(1.5 * (v.dLf_D + 2 * v.dLf_D_sd), 3))
        # the relaxed pellet once per pressure (the process's memo), untimed
        C.run_point(C.make_spec({}, preset=preset, sigma_z=v.sigma_z, seed=0, contact=contact, diametral=False))
        got = []
        for drop in (0.0, args.drop):
            p = preset.with_(break_drop=drop, break_from_dLD=round(0.5 * max(v.dLf_D - 2 * v.dLf_D_sd, 0.0), 4))
            spec = C.make_spec(params, preset=p, sigma_z=v.sigma_z, seed=0, contact=contact, max_dLD=mdl)
            t0 = time.perf_counter()
            rec = C.run_point(spec)
            if not rec["ok"]:
                raise SystemExit(f"{v.label}: {rec['error']}")
            got.append((rec["curve"]["dL_D"][-1], rec["outputs"]["sigma_f"], rec["outputs"]["dLf_D"],
                        time.perf_counter() - t0))
        (e0, s0, d0, t0_), (e1, s1, d1, t1) = got
        ratios.append(t1 / t0_)
        same = "" if (s0, d0) == (s1, d1) else "  <- failure points differ"
        print(f"{v.label} | {e0:.3f} / {e1:.3f} | {s0 / 1e6:.4f} / {s1 / 1e6:.4f} | {d0:.4f} / {d1:.4f} | "
              f"{t1:.1f} s / {t0_:.1f} s = {t1 / t0_:.2f}{same}", flush=True)
    print(f"time with break detection / without: mean {np.mean(ratios):.2f}, range {min(ratios):.2f}-{max(ratios):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
