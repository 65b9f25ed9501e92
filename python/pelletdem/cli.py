"""Command line: `pelletdem run --preset quick --out DIR` runs one pellet from fill to
breakage and writes result.h5, result.xdmf, PNG plots and summary.json into DIR.

The bonds are the paper's Table 5 values for the variant (--material, --mc, --sigma-z 60 or
120) unless --E-b and --sigma-c give them; then any pressure is allowed, and the measured
values of Table 3 are compared only where the variant has them.

The run is checkpointed to DIR/checkpoint.h5 at every stage end and every
--checkpoint-interval seconds inside a stage; the same command again on the same DIR resumes
from the last checkpoint (a killed run ends with the same bits as one never stopped), other
arguments are refused, and --restart starts afresh.

`pelletdem calibrate OUT_DIR` fits the paper's variants to its Tables 2 and 3 (calibrate_cli.py)
and `pelletdem loop` runs the discrepancy loop (loop_cli.py)."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

# The arguments that define a run: a checkpoint made with other values is not resumed.
RUN_ARGS = ("preset", "material", "mc", "sigma_z", "seed", "threads", "particles", "E_b", "sigma_c",
            "tau_c", "r_b", "max_dld", "break_drop", "set")


def _bond_law(args):
    """The run's BondLaw: explicit (--E-b, --sigma-c, --tau-c in MPa, --r-b in um) or Table 5's."""
    from .engine import BondLaw
    from .pipeline import bond_law_for

    if args.E_b is None:
        law = bond_law_for(args.material, args.mc, args.sigma_z)
        if args.r_b is not None:
            law.radius = args.r_b * 1e-6
        return law
    tau_c = args.sigma_c if args.tau_c is None else args.tau_c
    law = BondLaw(youngs_modulus=args.E_b * 1e6, sigma_c=args.sigma_c * 1e6, tau_c=tau_c * 1e6)
    if args.r_b is not None:
        law.radius = args.r_b * 1e-6
    return law


def _with_settings(preset, law, settings):
    """The preset's contact law and the bond law with ``--set`` values applied."""
    from .law_settings import apply_settings

    contact, law = apply_settings(preset.contact, law, settings)
    return preset.with_(contact=contact), law


def _variant_or_none(args):
    """The paper's variant for (material, mc, sigma_z), or None where Table 3 has none."""
    from .measured import variant

    try:
        return variant(args.material, args.mc, args.sigma_z)
    except ValueError:
        return None


def _run(args) -> int:
    from . import pipeline, plots
    from ._version import __version__
    from .checkpoint import RunCheckpoint
    from .law_settings import parse_settings

    t0 = time.perf_counter()
    v = _variant_or_none(args)
    law = _bond_law(args)  # checked in main() before any work
    os.makedirs(args.out, exist_ok=True)
    # A run killed while writing leaves its temporary file (h5io.atomic_h5) behind: the file
    # it was replacing is whole, the temporary is not, and nothing else reads it.
    for name in os.listdir(args.out):
        if (name.startswith(".tmp-") and (name.endswith(".h5") or name == ".tmp-summary.json")) or \
                name.endswith(".xdmf.tmp"):
            os.remove(os.path.join(args.out, name))
    ck_path = os.path.join(args.out, "checkpoint.h5")
    if args.restart and os.path.exists(ck_path):
        os.remove(ck_path)
    run_args = {k: getattr(args, k) for k in RUN_ARGS}
    run_args["version"] = __version__
    ck = RunCheckpoint(ck_path, run_args, interval=args.checkpoint_interval)
    preset = pipeline.get_preset(args.preset)
    preset, law = _with_settings(preset, law, parse_settings(args.set))
    if args.max_dld is not None:
        preset = preset.with_(max_dLD=args.max_dld)
    if args.break_drop is not None:
        preset = preset.with_(break_drop=args.break_drop)
    res = pipeline.run_pellet(preset=preset, material=args.material, mc=args.mc,
                              sigma_z_mpa=args.sigma_z, seed=args.seed, threads=args.threads,
                              bond_law=law, n_particles=args.particles,
                              progress=False if args.quiet else None, checkpoint=ck)
    res.save(os.path.join(args.out, "result.h5"))
    pngs = plots.save_all(res, args.out, variant=v)
    summary = res.summary()
    summary.update({"preset": args.preset, "material": args.material, "mc_percent": args.mc,
                    "sigma_z_mpa": args.sigma_z, "threads": args.threads,
                    "bond": {"E_b_mpa": law.youngs_modulus / 1e6, "sigma_c_mpa": law.sigma_c / 1e6,
                             "tau_c_mpa": law.tau_c / 1e6, "r_b_um": law.radius * 1e6,
                             "source": "table5" if args.E_b is None else "command line"},
                    "set": parse_settings(args.set),
                    "measured_sigma_f_mpa": v.sigma_f / 1e6 if v is not None else None,
                    "measured_dLf_D": v.dLf_D if v is not None else None,
                    "total_wall_time_s": round(max(ck.wall_time_s, time.perf_counter() - t0), 3),
                    "plots": [os.path.basename(p) for p in pngs]})
    # Written beside and renamed, like the HDF5 files: a kill never leaves half a summary.
    tmp = os.path.join(args.out, ".tmp-summary.json")
    with open(tmp, "w") as fh:
        json.dump(summary, fh, indent=2)
    os.replace(tmp, os.path.join(args.out, "summary.json"))
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
    r.add_argument("--sigma-z", type=float, default=120.0,
                   help="compaction pressure, MPa (0 < sigma_z <= 1000; 60 or 120 for Table 5's bonds)")
    r.add_argument("--E-b", dest="E_b", type=float, default=None, metavar="MPA",
                   help="bond modulus E_b, MPa (with --sigma-c; default: Table 5's for the variant)")
    r.add_argument("--sigma-c", type=float, default=None, metavar="MPA", help="bond tensile strength, MPa")
    r.add_argument("--tau-c", type=float, default=None, metavar="MPA",
                   help="bond shear strength, MPa (default: sigma_c, as in the paper)")
    r.add_argument("--r-b", dest="r_b", type=float, default=None, metavar="UM",
                   help="bond radius r_b, um (default 20)")
    r.add_argument("--max-dld", type=float, default=None, metavar="DL_D",
                   help="end of the diametral test, dL/D (0 < max_dld <= 0.5; default: the preset's)")
    r.add_argument("--break-drop", type=float, default=None, metavar="FRACTION",
                   help="end the diametral test earlier, once the plate force has fallen to this fraction "
                        "of its peak (0 <= break_drop < 1; default 0: run to max_dld)")
    r.add_argument("--set", action="append", default=[], metavar="LAW.NAME=VALUE",
                   help="set a contact or bond law parameter, e.g. contact.mu=0.4 or bond.softening=1 "
                        "(SI units; repeatable; checked against the laws' parameter tables)")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--threads", type=int, default=min(2, os.cpu_count() or 1))
    r.add_argument("--particles", type=int, default=None, help="override the preset's particle count")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    r.add_argument("--checkpoint-interval", type=float, default=300.0, metavar="SECONDS",
                   help="wall time between checkpoints (DIR/checkpoint.h5) inside a stage, s; "
                        "one is written at every stage end too (default 300)")
    r.add_argument("--restart", action="store_true",
                   help="discard DIR's checkpoint and start again (by default a run resumes from it)")
    from . import calibrate_cli, loop_cli

    loop_cli.add_parser(sub)
    calibrate_cli.add_parser(sub)
    args = ap.parse_args(argv)
    if args.command == "loop":
        try:
            return loop_cli.run(args)
        except (ValueError, RuntimeError) as e:  # a bad argument or data file, named before any work
            print(f"pelletdem loop: error: {e}", file=sys.stderr)
            return 2
    if args.command == "calibrate":
        try:
            return calibrate_cli.run(args)
        except (ValueError, OSError) as e:  # a bad argument, before any work; an unwritable OUT_DIR
            print(f"pelletdem calibrate: error: {e}", file=sys.stderr)
            return 2
    if args.command == "run":
        if not args.out.strip() or (os.path.exists(args.out) and not os.path.isdir(args.out)):
            ap.error(f"--out = {args.out!r} must name a directory (it is empty or an existing file)")
        if not (args.checkpoint_interval >= 0):  # also NaN
            ap.error(f"--checkpoint-interval = {args.checkpoint_interval} must be >= 0 s")
        if args.threads < 1 or args.threads > 1024:
            ap.error(f"--threads = {args.threads} is out of range: allowed 1 <= threads <= 1024")
        if args.particles is not None and args.particles < 1:
            ap.error(f"--particles = {args.particles} must be >= 1")
        if args.particles is not None and args.particles > 10_000_000:
            ap.error(f"--particles = {args.particles} is out of range: allowed 1 <= particles <= 10000000")
        if args.seed < 0 or args.seed > 2**62:
            ap.error(f"--seed = {args.seed} is out of range: allowed 0 <= seed <= 2**62")
        if not 0.0 < args.sigma_z <= 1000.0:  # also NaN
            ap.error(f"--sigma-z = {args.sigma_z} MPa is out of range: allowed 0 < sigma_z <= 1000 MPa")
        for flag, value in (("--E-b", args.E_b), ("--sigma-c", args.sigma_c), ("--tau-c", args.tau_c),
                            ("--r-b", args.r_b)):
            if value is not None and not (math.isfinite(value) and value > 0.0):
                ap.error(f"{flag} = {value} must be a finite number > 0")
        if (args.E_b is None) != (args.sigma_c is None) or (args.tau_c is not None and args.E_b is None):
            ap.error("give --E-b and --sigma-c together (and --tau-c only with them), or none of them "
                     "for Table 5's bonds")
        if args.max_dld is not None and not 0.0 < args.max_dld <= 0.5:
            ap.error(f"--max-dld = {args.max_dld} is out of range: allowed 0 < max_dld <= 0.5")
        if args.break_drop is not None and not 0.0 <= args.break_drop < 1.0:
            ap.error(f"--break-drop = {args.break_drop} is out of range: allowed 0 <= break_drop < 1")
        if args.E_b is None and _variant_or_none(args) is None:
            ap.error(f"--sigma-z = {args.sigma_z:g} MPa (with --material {args.material}, --mc {args.mc}) "
                     f"has no Table 5 bonds: allowed 60 or 120 MPa, or give the bonds with --E-b and --sigma-c")
        try:
            _bond_law(args).to_core()  # a bond law the engine refuses, named before any work
        except ValueError as e:
            ap.error(f"bond parameters: {e}")
        from .law_settings import parse_settings
        from .pipeline import get_preset

        try:
            _with_settings(get_preset(args.preset), _bond_law(args), parse_settings(args.set))
        except ValueError as e:
            ap.error(str(e))
        from .checkpoint import CheckpointError

        try:
            return _run(args)
        except (CheckpointError, OSError) as e:
            # A checkpoint of another run or a damaged one, an --out that cannot be written, a
            # full disk: say what is wrong, no traceback (the last checkpoint stays whole).
            print(f"pelletdem: error: {e}", file=sys.stderr)
            return 2
    return 2


if __name__ == "__main__":
    sys.exit(main())
