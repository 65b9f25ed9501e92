"""Command line: `pelletdem run --preset quick --out DIR` runs one pellet from fill to
breakage and writes result.h5, result.xdmf, PNG plots and summary.json into DIR."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time


def _run(args) -> int:
    from . import plots
    from .measured import variant
    from .pipeline import run_pellet

    t0 = time.perf_counter()
    v = variant(args.material, args.mc, args.sigma_z)  # validates the variant before any work
    res = run_pellet(preset=args.preset, material=args.material, mc=args.mc,
                     sigma_z_mpa=args.sigma_z, seed=args.seed, threads=args.threads,
                     n_particles=args.particles, progress=False if args.quiet else None)
    os.makedirs(args.out, exist_ok=True)
    res.save(os.path.join(args.out, "result.h5"))
    pngs = plots.save_all(res, args.out, variant=v)
    summary = res.summary()
    summary.update({"preset": args.preset, "material": args.material, "mc_percent": args.mc,
                    "sigma_z_mpa": args.sigma_z, "threads": args.threads,
                    "measured_sigma_f_mpa": v.sigma_f / 1e6, "measured_dLf_D": v.dLf_D,
                    "total_wall_time_s": round(time.perf_counter() - t0, 3),
                    "plots": [os.path.basename(p) for p in pngs]})
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    print(json.dumps(summary, indent=2))
    return 0


def main(argv=None) -> int:
    """Entry point of the `pelletdem` command; returns the exit status."""
    ap = argparse.ArgumentParser(prog="pelletdem", description=__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="one pellet from fill to breakage")
    r.add_argument("--preset", default="quick", choices=["tiny", "quick", "paper"])
    r.add_argument("--out", required=True, help="output directory")
    r.add_argument("--material", default="oak", choices=["birch", "oak", "pine"])
    r.add_argument("--mc", type=int, default=8, choices=[8, 20], help="moisture content, %%")
    r.add_argument("--sigma-z", type=int, default=120, choices=[60, 120], help="compaction pressure, MPa")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--threads", type=int, default=min(2, os.cpu_count() or 1))
    r.add_argument("--particles", type=int, default=None, help="override the preset's particle count")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    args = ap.parse_args(argv)
    if args.command == "run":
        if args.threads < 1:
            ap.error(f"--threads = {args.threads} must be >= 1")
        if args.particles is not None and args.particles < 1:
            ap.error(f"--particles = {args.particles} must be >= 1")
        if args.seed < 0:
            ap.error(f"--seed = {args.seed} must be >= 0")
        return _run(args)
    return 2


if __name__ == "__main__":
    sys.exit(main())
