"""`pelletdem calibrate OUT_DIR`: the paper's calibration of its 12 variants from the command line.

    pelletdem calibrate OUT_DIR                                    # tiny, all 12 variants: minutes
    pelletdem calibrate OUT_DIR --variant oak 8 120 --max-runs 2   # one variant
    pelletdem calibrate QUICK --preset quick --compaction-runs 6 --max-runs 8       # ~20 min, 2 cores
    pelletdem calibrate PAPER --preset paper --max-runs 8 --from QUICK --dask HOST:8786   # hours
    pelletdem calibrate OUT_DIR --data FILE.toml                   # a user's data (a loop manifest)

One shared loading stiffness k1 against Table 2's pellet densities (with --fit, contact-law
rows beside it: a yield effect's strength), then E_b and sigma_c per variant against Table
3's sigma_f and dL_f/D. Writes calibration.csv, calibration.json, the
Fig. 15 plots and Fig. 10 for the relaxed pellets into OUT_DIR (pelletdem.calibration_dir).
Every run is cached in OUT_DIR/cache: the same command again resumes where a stopped one
ended and runs nothing twice. --from DIR starts from an earlier calibration (its k1 and bond
fits, on a smaller preset) in place of the compaction fit and Table 5's values. Every
argument is checked before any simulation.

With --data FILE (a loop data manifest, docs/loop.md; 'example' for the shipped one) the
manifest's [fit] parameters are fitted to its conditions that are not held out, as the
discrepancy loop fits its baseline: means over --packings packings, a Gaussian-process
emulator of a space-filling design, intervals from its profile, and the errors on fresh
packings for the fitted and held-out conditions (OUT_DIR/report.md, loop.json). No effect is
added; `pelletdem loop` looks for one.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import math
import os
from typing import Optional

#: Default points per variant's bond fit and of the shared compaction fit (0: keep the
#: preset's k1): 'tiny' with these takes a few minutes on two cores.
MAX_RUNS = 4
COMPACTION_RUNS = 2
#: Packings every prediction averages with --data (the loop's baseline needs at least two).
DATA_PACKINGS = 4
#: Allowed ranges of the counts, inclusive.
LIMITS = {"max_runs": (1, 100), "compaction_runs": (0, 100), "workers": (1, 256)}
#: Bond-law parameters the calibration fits, so --set cannot fix them (tau_c follows sigma_c).
FITTED = {"bond.youngs_modulus": "E_b", "bond.sigma_c": "sigma_c", "bond.tau_c": "tau_c = sigma_c"}


def add_arguments(p: argparse.ArgumentParser, *, preset: str = "tiny", max_runs: int = MAX_RUNS,
                  compaction_runs: int = COMPACTION_RUNS, workers: Optional[int] = None) -> None:
    """Add the calibration's arguments (OUT_DIR and options, with these defaults) to ``p``;
    shared by the `calibrate` subcommand and examples/03_calibration.py."""
    workers = workers or min(2, os.cpu_count() or 1)
    p.add_argument("out", metavar="OUT_DIR", help="output directory (created; its cache/ makes a rerun resume)")
    p.add_argument("--preset", default=None, choices=["tiny", "quick", "paper"],
                   help=f"pellet size (default {preset}; with --data the manifest's, else tiny)")
    p.set_defaults(preset_default=preset)
    p.add_argument("--variant", nargs=3, action="append", default=None, metavar=("MATERIAL", "MC", "PRESSURE_MPA"),
                   help="calibrate only this variant, e.g. oak 8 120 (birch/oak/pine, MC 8 or 20 %%, "
                        "60 or 120 MPa; repeatable; default all 12)")
    p.add_argument("--max-runs", type=int, default=max_runs, metavar="N",
                   help=f"parameter points per variant's bond fit (1..100; default {max_runs})")
    p.add_argument("--compaction-runs", type=int, default=compaction_runs, metavar="N",
                   help=f"k1 points of the shared compaction fit (0..100, 0: keep the preset's k1; "
                        f"default {compaction_runs})")
    p.add_argument("--from", dest="source", default=None, metavar="DIR",
                   help="OUT_DIR of an earlier calibration: its k1 and bond fits are the start here")
    p.add_argument("--workers", type=int, default=workers, metavar="N",
                   help=f"local worker processes (1..256; default {workers})")
    p.add_argument("--dask", default=None, metavar="ADDRESS",
                   help="run the simulations on this Dask scheduler (e.g. tcp://host:8786; needs distributed)")
    p.add_argument("--data", default=None, metavar="FILE|example",
                   help="calibrate against a user's data (a loop manifest, docs/loop.md) instead of the "
                        "paper's variants")
    p.add_argument("--packings", type=int, default=None, metavar="N",
                   help=f"packings every point averages (the paper's variants: 1..64, default 1; "
                        f"with --data: 2..64, default {DATA_PACKINGS})")
    p.add_argument("--first-packing", type=int, default=0, metavar="N",
                   help="seed of the first packing: the points average packings N..N+P-1 (0..1000000, "
                        "default 0); another set of packings shows how far a fit moves with the "
                        "pellets' own scatter")
    p.add_argument("--fit", action="append", default=[], metavar="contact.NAME=LO:HI",
                   help="fit this contact-law row too, beside k1 in the shared compaction fit (a strength "
                        "of one sign, in log space of its magnitude; starts at its --set value), e.g. "
                        "contact.wood_density_yield=0.3:4 (repeatable)")
    p.add_argument("--per-material", action="store_true",
                   help="fit k1 (and the --fit rows) per material, each on its own wood's densities: the "
                        "yield a material parameter, as the bonds are per variant (default: one for all)")
    p.add_argument("--set", action="append", default=[], metavar="LAW.NAME=VALUE",
                   help="set a contact or bond law parameter, e.g. contact.mu=0.4 (SI units; repeatable; "
                        "not the fitted bond.youngs_modulus, bond.sigma_c, bond.tau_c)")


def add_parser(sub) -> None:
    """Register the `calibrate` subcommand on an argparse subparsers object."""
    p = sub.add_parser("calibrate", help="fit the bonds (and k1) of the paper's variants to Tables 2 and 3",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(p)


def _number(text: str, what: str, allowed) -> int:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v.is_integer() and int(v) in allowed):
        raise ValueError(f"{what} = {text!r} is not allowed: allowed {' or '.join(map(str, allowed))}")
    return int(v)


def parse_variants(items):
    """The measured Variants of ``--variant MATERIAL MC PRESSURE_MPA`` triples (None: all 12);
    ValueError naming the first unknown or repeated one and the allowed values."""
    from .measured import COMPACTION_PRESSURES_MPA, MATERIALS, MOISTURE_CONTENTS_PERCENT, variant

    if not items:
        return None
    out = []
    for m, mc, sz in items:
        where = f"--variant {m} {mc} {sz}"
        if m not in MATERIALS:
            raise ValueError(f"{where}: MATERIAL = {m!r} is unknown: allowed {', '.join(MATERIALS)}")
        v = variant(m, _number(mc, f"{where}: MC (%)", MOISTURE_CONTENTS_PERCENT),
                    _number(sz, f"{where}: PRESSURE_MPA", COMPACTION_PRESSURES_MPA))
        if v.key in [x.key for x in out]:
            raise ValueError(f"{where}: given twice")
        out.append(v)
    return out


def parse_fit(items, settings, compaction_runs: int) -> dict:
    """{'contact.<field>': (lo, hi, start)} of ``--fit contact.NAME=LO:HI`` items: rows of the
    contact law fitted beside k1 (``contact.k1``: k1 itself, with k2 kept at its --set value
    instead of following it), in log space of the magnitude (0 < LO < HI, or LO < HI < 0
    for a negative strength), started at their ``settings`` value (--set) where it lies
    inside, else at the bounds' geometric mean. ValueError naming
    the first bad item."""
    from .law_settings import parse_setting
    from .loop_simulators import refuse_condition_rows

    out = {}
    for item in items or ():
        name, eq, rng = str(item).partition("=")
        name = name.strip()
        lo_text, colon, hi_text = rng.partition(":")
        if not eq or not colon or not name.startswith("contact."):
            raise ValueError(f"--fit {item!r}: expected contact.NAME=LO:HI (a contact-law row)")
        refuse_condition_rows([name], "--fit")
        if name == "contact.k2":
            raise ValueError(f"--fit {item!r}: k2 is not fitted (set it with --set; --fit contact.k1 fits k1 "
                             f"with k2 kept)")
        try:
            lo, hi = float(lo_text), float(hi_text)
        except ValueError:
            raise ValueError(f"--fit {item!r}: LO and HI must be numbers") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and (0.0 < lo < hi or lo < hi < 0.0)):
            raise ValueError(f"--fit {item!r}: need 0 < LO < HI or LO < HI < 0, finite (the fit is in log space "
                             f"of the magnitude)")
        parse_setting(name, lo)  # the row exists and takes both ends
        parse_setting(name, hi)
        if name in out:
            raise ValueError(f"--fit {name} given twice")
        given = settings.get(name)
        out[name] = (lo, hi, float(given) if given is not None and lo <= given <= hi
                     else math.copysign(math.sqrt(lo * hi), hi))
    if out and not compaction_runs:
        raise ValueError("--fit needs the compaction fit: --compaction-runs 1 or more")
    return out


def check(args) -> dict:
    """The keyword arguments of :func:`pelletdem.calibration_dir.calibrate_into` for ``args``;
    ValueError naming the first bad argument and its allowed range, before any work."""
    from .calibration_dir import FIRST_PACKING_MAX, load_calibration
    from .law_settings import apply_settings, parse_settings
    from .laws import BondLaw
    from .loop_simulators import refuse_condition_rows
    from .presets import get_preset

    out = str(args.out)
    if not out.strip() or (os.path.exists(out) and not os.path.isdir(out)):
        raise ValueError(f"OUT_DIR = {out!r} must name a directory (it is empty or an existing file)")
    for name, (lo, hi) in LIMITS.items():
        v = getattr(args, name)
        if not lo <= v <= hi:
            raise ValueError(f"--{name.replace('_', '-')} = {v} is out of range: allowed {lo}..{hi}")
    variants = parse_variants(args.variant)
    settings = parse_settings(args.set)
    fit_rows = parse_fit(args.fit, settings, args.compaction_runs)
    if fit_rows and args.source is not None:
        raise ValueError("--fit with --from: the contact law comes from that calibration, no compaction fit runs")
    if args.per_material and (args.source is not None or not args.compaction_runs):
        raise ValueError("--per-material fits k1 per material: it needs the compaction fit "
                         "(--compaction-runs 1 or more, no --from)")
    if args.data is not None:
        for flag, given in (("--variant", args.variant), ("--from", args.source), ("--fit", args.fit),
                            ("--per-material", args.per_material), ("--first-packing", args.first_packing)):
            if given:
                raise ValueError(f"{flag} is for the paper's variants; with --data the manifest says what is fitted")
        if args.packings is not None and not 2 <= args.packings <= 64:
            raise ValueError(f"--packings = {args.packings} is out of range: allowed 2..64 with --data")
    elif args.packings is not None and not 1 <= args.packings <= 64:
        raise ValueError(f"--packings = {args.packings} is out of range: allowed 1..64")
    if not 0 <= args.first_packing <= FIRST_PACKING_MAX:
        raise ValueError(f"--first-packing = {args.first_packing} is out of range: allowed 0..{FIRST_PACKING_MAX}")
    refuse_condition_rows(settings, "--set")
    for name in settings:
        if name in FITTED:
            raise ValueError(f"--set {name}: the calibration fits {FITTED[name]} per variant; "
                             f"allowed: the other bond parameters and any contact.X")
    preset = get_preset(args.preset or args.preset_default)
    laws = [{}]  # the contact laws the --set rows go on: the preset's, or each of --from's
    if args.source is not None:
        try:
            src = load_calibration(args.source)
        except ValueError as e:
            raise ValueError(f"--from {e}") from None
        by_material = (src.get("contact_by_material") or {}).values()
        # with k1 per material the shared law alone never runs
        laws = [{**src["contact"], **rows} for rows in by_material] or [src["contact"]]
        given = sorted({k for law in laws for k in law})
        fixed = [f"contact.{k}" for k in given if f"contact.{k}" in settings]
        if fixed:
            raise ValueError(f"--set {', '.join(fixed)} with --from {args.source}: the contact law's "
                             f"{', '.join(given)} come from that calibration")
    for law in laws:
        # checked on the law they will run with: --from's k1 (per material) may be below the
        # preset's, and a --set k2 is then allowed below the preset's k1
        try:
            contact = dataclasses.replace(preset.contact, **law)
        except TypeError as e:
            raise ValueError(f"--from {args.source}: its contact law is refused: {e}") from None
        try:
            apply_settings(contact, BondLaw(), settings)
        except ValueError as e:
            if not law:
                raise
            raise ValueError(f"--from {args.source}: its contact law is refused with the --set rows: {e}") from None
    if args.dask is not None:
        if not args.dask.strip():
            raise ValueError("--dask ADDRESS is empty: give the scheduler's address, e.g. tcp://host:8786")
        if importlib.util.find_spec("distributed") is None:
            raise ValueError("--dask needs Dask's distributed package, which is not installed: "
                             "pip install distributed")
    return dict(variants=variants, preset=args.preset or args.preset_default, max_runs=args.max_runs,
                compaction_runs=args.compaction_runs, packings=args.packings or 1,
                first_packing=args.first_packing, source=args.source,
                settings=settings, fit=fit_rows, per_material=args.per_material, max_workers=args.workers)


def run(args) -> int:
    """Run `pelletdem calibrate` with parsed ``args``; returns the exit status. ValueError
    (a bad argument, before any work) or OSError (OUT_DIR not writable, no Dask scheduler at
    the address) say what is wrong."""
    from . import calibration_dir

    kw = check(args)
    if args.data is not None:
        return _fit_user_data(args)
    client = None
    if args.dask is not None:
        from distributed import Client

        try:
            client = Client(args.dask)
        except OSError as e:  # no scheduler there (after distributed's connect timeout)
            raise OSError(f"--dask {args.dask}: {e}") from None
    try:
        calibration_dir.calibrate_into(args.out, executor=client, **kw)
    finally:
        if client is not None:
            client.close()
    return 0


def _fit_user_data(args) -> int:
    """``--data``: the discrepancy loop's baseline fit alone (no effect is looked for)."""
    from . import loop_cli

    ns = argparse.Namespace(out=args.out, data=args.data, synthetic=None, draw=0, noise=0.02, materials="oak",
                            held_out=None, fit=[],
                            set=list(args.set), preset=args.preset,
                            packings=args.packings or DATA_PACKINGS, max_effects=0, window=loop_cli.WINDOW,
                            workers=args.workers, dask=args.dask, cache=None)
    return loop_cli.run(ns, title="Calibration on")
