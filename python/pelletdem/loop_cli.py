"""`pelletdem loop`: the discrepancy loop from the command line.

    pelletdem loop --data FILE.toml --out DIR              # a user's data (see loop_manifest)
    pelletdem loop --data example --out DIR                # the shipped example (pelletdem/data/loop_example)
    pelletdem loop --data paper --out DIR                  # the paper's Tables 2 and 3 (oak)
    pelletdem loop --synthetic bond_softening=1 --out DIR  # engine data with a hidden effect
    pelletdem loop --synthetic none --out DIR              # the control: no effect

Synthetic data are made as a laboratory's: five replicate pellets per condition from packings
the fits never use (--draw picks another five and another noise), 2 % measurement noise,
diametral curves, compaction curves and densities at 60, 90 and 120 MPa, 90 MPa held out;
where the hidden effect needs the moisture to vary (moisture_bonds, moisture_yield, or
bond.moisture_coefficient=0 as its control), 60 and 120 MPa at MC 8 and 20 %, 60 MPa at 20 %
held out. Writes DIR/report.md with its figures and DIR/loop.json; DIR/cache keeps every
simulation, so a rerun resumes.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import time
from typing import Any, NamedTuple, Optional

from .loop_synthetic import DATA_SEEDS

#: The bond law of synthetic data (and the loop's base law for them): the 'tiny' pellet
#: fails at dL/D 0.05-0.10 between 60 and 120 MPa, well inside the test window.
SYNTHETIC_BOND = {"youngs_modulus": 60e6, "sigma_c": 9e6, "tau_c": 9e6}
SYNTHETIC_BOUNDS = {"E_b": (2e7, 2e8), "sigma_c": (3e6, 3e7)}
SYNTHETIC_PRESSURES = (60e6, 120e6, 90e6)
#: (sigma_z Pa, MC %) of synthetic data whose hidden effect needs the moisture to vary, the
#: last held out: the paper's design (two moisture contents at two pressures).
SYNTHETIC_MOISTURE = ((60e6, 8.0), (120e6, 8.0), (120e6, 20.0), (60e6, 20.0))
#: The diametral test window (dL/D) the loop starts with (synthetic data are made to it); it is
#: then fitted to the data's reach, and widened when the fitted model does not fail inside.
WINDOW = 0.25
#: Relative measurement noise of synthetic data (--noise), and the compaction curve points
#: each synthetic condition gives.
NOISE = 0.02
COMPACTION_POINTS = 4


def add_parser(sub) -> None:
    """Register the `loop` subcommand on an argparse subparsers object."""
    from .effects import EFFECTS

    p = sub.add_parser("loop", help="fit, trace the residual to a missing effect, add it, report",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--data", default=None, metavar="FILE|example|paper",
                   help="a loop data manifest (TOML, see docs/loop.md), 'example' for the shipped example "
                        "(made with the engine, an effect hidden in it) or 'paper' for the paper's tables")
    p.add_argument("--synthetic", default=None, metavar="EFFECT[=VALUE]",
                   help="make the data with the engine, with this effect hidden in it "
                        f"({', '.join(EFFECTS)}, none, or any contact.X=V / bond.X=V)")
    p.add_argument("--draw", type=int, default=0, help="synthetic data: which replicate packings and noise (0..999)")
    p.add_argument("--noise", type=float, default=NOISE, help="synthetic data: relative measurement noise")
    p.add_argument("--materials", default="oak", help="paper data: comma-separated materials")
    p.add_argument("--held-out", default=None, metavar="KEY=V[,KEY=V]",
                   help="paper data: the variants held out, by mc (%%), sigma_z (MPa) and material "
                        "(default mc=20,sigma_z=60)")
    p.add_argument("--fit", action="append", default=[], metavar="NAME=LO:HI",
                   help="paper data: a base parameter fitted once for every variant besides the bonds per "
                        "material (k1, p_y, r_b, tau_c or contact.X / bond.X; SI; repeatable)")
    p.add_argument("--set", action="append", default=[], metavar="LAW.NAME=VALUE",
                   help="a contact or bond law parameter of the model (repeatable)")
    p.add_argument("--preset", default=None, choices=["tiny", "quick", "paper"],
                   help="pellet size of the model (default tiny, or the manifest's)")
    p.add_argument("--packings", type=int, default=4, help="packings every prediction averages (fit seeds)")
    p.add_argument("--max-effects", type=int, default=2, help="effects forward selection may add")
    p.add_argument("--window", type=float, default=WINDOW,
                   help="diametral test window, dL/D (then fitted to the data's reach)")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1), help="worker processes")
    p.add_argument("--dask", default=None, metavar="ADDRESS", help="a Dask scheduler to run the simulations on")
    p.add_argument("--cache", default=None, help="run cache directory (default OUT/cache): a rerun resumes")


def synthetic_truth(spec: str) -> dict:
    """The hidden parameters of ``--synthetic SPEC`` (an effect name with an optional strength,
    'none', or a law parameter LAW.NAME=V); ValueError naming what is wrong."""
    from .effects import EFFECTS
    from .law_settings import parse_setting

    if spec == "none":
        return {}
    name, _, value = spec.partition("=")
    if name in EFFECTS:
        e = EFFECTS[name]
        if e.needs == "material":
            raise ValueError(f"--synthetic {spec!r}: {name} acts between woods of different densities, and "
                             "synthetic data are of one material: use --data paper --materials oak,birch,pine "
                             "or a manifest of several materials")
        try:
            v = float(value) if value else e.probe
        except ValueError:
            raise ValueError(f"--synthetic {spec!r}: {value!r} is not a number") from None
        if not e.lo <= v <= e.hi:
            raise ValueError(f"--synthetic {spec!r}: allowed {e.lo:g} <= {e.param} <= {e.hi:g}")
        return e.settings(v)
    if (name.startswith("contact.") or name.startswith("bond.")) and value:
        from .loop_simulators import refuse_condition_rows

        try:
            refuse_condition_rows([name])
            return dict([parse_setting(name, value)])
        except ValueError as e:
            raise ValueError(f"--synthetic {spec!r}: {e}") from None
    raise ValueError(f"--synthetic {spec!r}: allowed an effect name ({', '.join(EFFECTS)}), 'none', "
                     "or contact.X=V / bond.X=V")


def synthetic_design(truth: dict, draw: int):
    """(conditions, held-out conditions, {condition: replicate packings}) of synthetic data
    hiding ``truth`` in draw ``draw``: 60, 120 and 90 MPa (held out) at MC 8 %; where the
    hidden law field belongs to an effect that needs the moisture to vary, 60 and 120 MPa at
    8 and 20 % (60 MPa at 20 % held out), the wetter pellets pressed from other packings (a
    laboratory's pellets of two moisture contents are other pellets)."""
    from . import loop
    from .effects import EFFECTS

    wet = any(e.needs == "mc" and e.param in truth for e in EFFECTS.values())
    if wet:
        conds = [loop.Condition(p, mc) for p, mc in SYNTHETIC_MOISTURE]
    else:
        conds = [loop.Condition(p) for p in SYNTHETIC_PRESSURES]
    offset = {mc: 500 * k for k, mc in enumerate(sorted({c.mc for c in conds}))}
    seeds = {c: tuple(s + 10 * draw + offset[c.mc] for s in DATA_SEEDS) for c in conds}
    return conds, (conds[-1],), seeds


def synthetic_data(sim, truth: dict, draw: int, noise: float = NOISE):
    """(Dataset, hidden parameters (SI)) of ``--synthetic`` data hiding the law fields
    ``truth`` (:func:`synthetic_truth`) in draw ``draw``, made by ``sim`` with relative
    measurement noise ``noise`` (-) as :func:`synthetic_design` lays them out."""
    from . import loop

    conds, _, seeds = synthetic_design(truth, draw)
    hidden = {"E_b": SYNTHETIC_BOND["youngs_modulus"], "sigma_c": SYNTHETIC_BOND["sigma_c"], **truth}
    data = loop.synthetic_dataset(sim, hidden, conds, seeds=seeds, noise=noise, compaction_points=COMPACTION_POINTS,
                                  seed=draw)
    return data, hidden


def _check(args) -> None:
    """ValueError naming the first bad argument, before any work."""
    from .law_settings import parse_settings

    if (args.data is None) == (args.synthetic is None):
        raise ValueError("give --data FILE|example|paper or --synthetic EFFECT, one of them")
    for name, lo, hi in (("packings", 2, 64), ("workers", 1, 256), ("max_effects", 0, 10), ("draw", 0, 999)):
        v = getattr(args, name)
        if not lo <= v <= hi:
            raise ValueError(f"--{name.replace('_', '-')} = {v} is out of range: allowed {lo}..{hi}")
    if not (0.0 <= args.noise < 0.5):
        raise ValueError(f"--noise = {args.noise} is out of range: allowed 0 <= noise < 0.5")
    if not (0.0 < args.window <= 0.5):
        raise ValueError(f"--window = {args.window} is out of range: allowed 0 < window <= 0.5")
    from .loop_simulators import refuse_condition_rows

    refuse_condition_rows(parse_settings(args.set), "--set")
    refuse_condition_rows([f.partition("=")[0].strip() for f in args.fit or ()], "--fit")
    if args.synthetic is not None:
        synthetic_truth(args.synthetic)
    if args.data != "paper" and (args.held_out is not None or args.fit):
        raise ValueError("--held-out and --fit are for --data paper (a manifest says both itself)")
    if args.data == "paper":
        from .loop_paper import DEFAULT_HELD_OUT, paper_problem

        paper_problem(_materials(args), args.held_out or DEFAULT_HELD_OUT, args.fit)


def _materials(args) -> list:
    return [m.strip() for m in args.materials.split(",") if m.strip()]


class _Problem(NamedTuple):
    """What a loop runs on: ``data`` (a Dataset, or (conditions, truth) for synthetic data made
    in the run), the ``held`` conditions, the base parameters' ``bounds`` (SI), a ``start``,
    the base ``bond`` law, law ``settings``, the ``preset`` (name or Preset), the ``subject``
    (what the data are, for the report's title) and the ``density`` of the particles per
    material, kg/m^3 (None: the preset's for every material)."""

    data: Any
    held: tuple
    bounds: dict
    start: Optional[dict]
    bond: Any
    settings: dict
    preset: Any
    subject: str
    density: Optional[dict]


def _problem(args) -> _Problem:
    """The :class:`_Problem` of the parsed ``args``."""
    from .engine import BondLaw
    from .law_settings import parse_settings

    settings = parse_settings(args.set)
    if args.synthetic is not None:
        truth = synthetic_truth(args.synthetic)
        conds, held, _ = synthetic_design(truth, args.draw)
        subject = f"synthetic data ({'hidden: ' + args.synthetic if truth else 'control'})"
        return _Problem((conds, truth), held, dict(SYNTHETIC_BOUNDS), None, BondLaw(**SYNTHETIC_BOND), settings,
                        args.preset or "tiny", subject, None)
    if args.data == "paper":
        from .loop_paper import DEFAULT_HELD_OUT, paper_preset, paper_problem, particle_densities

        data, held, bounds = paper_problem(_materials(args), args.held_out or DEFAULT_HELD_OUT, args.fit)
        return _Problem(data, held, bounds, None, BondLaw(), settings, paper_preset(args.preset or "tiny"),
                        "the paper's measurements", particle_densities(_materials(args)))
    from .loop_manifest import example_manifest, load_manifest

    m = load_manifest(example_manifest() if args.data == "example" else args.data)
    for k, v in m.settings.items():
        settings.setdefault(k, v)  # the command line's --set wins
    return _Problem(m.dataset, m.held_out, m.bounds, None, BondLaw(), settings, args.preset or m.preset,
                    str(m.name), m.particle_density or None)


def _executor(args):
    if args.dask:
        from distributed import Client

        return Client(args.dask)
    return None


def run(args, title: str = "Discrepancy loop on") -> int:
    """Run `pelletdem loop` with parsed ``args``; returns the exit status. ``title``: the
    report's title, followed by what the data are (`pelletdem
    calibrate --data` runs this with no effect to add)."""
    import dataclasses

    from . import loop
    from .loop_report import summary, write_report
    from .loop_simulators import refuse_condition_rows

    _check(args)
    data, held, bounds, start, bond, settings, preset, subject, density = _problem(args)  # a bad file fails here
    refuse_condition_rows(settings, "a manifest's setting")
    t0 = time.perf_counter()
    os.makedirs(args.out, exist_ok=True)
    cache = args.cache or os.path.join(args.out, "cache")
    log_path = os.path.join(args.out, "loop.log")
    contact = {k[8:]: v for k, v in settings.items() if k.startswith("contact.")}
    bond = dataclasses.replace(bond, **{k[5:]: v for k, v in settings.items() if k.startswith("bond.")})
    with open(log_path, "a") as log:
        def say(s: str) -> None:
            print(s, flush=True)
            log.write(s + "\n")
            log.flush()

        client = _executor(args)
        with loop.EngineSimulator(preset, bond=bond, contact=contact, seeds=tuple(range(args.packings)),
                                  max_dLD=args.window, executor=client, max_workers=args.workers,
                                  cache_dir=cache, relaxed_dir=os.path.join(cache, "relaxed"),
                                  particle_density=density) as sim:
            if isinstance(data, tuple):
                data = synthetic_data(sim, data[1], args.draw, args.noise)[0]
            res = loop.close_loop(sim, data, bounds, start, held_out=lambda c: c in held,
                                  fit_seeds=tuple(range(args.packings)),
                                  check_seeds=tuple(100 + k for k in range(args.packings)),
                                  max_effects=args.max_effects, log=say)
        if client is not None:
            client.close()
        report = write_report(res, args.out, f"{title} {subject}")
        out = summary(res)
        out.update({"preset": getattr(preset, "name", preset), "packings": args.packings, "hidden": args.synthetic,
                    "draw": args.draw, "data": args.data, "report": report,
                    "total_wall_time_s": round(time.perf_counter() - t0, 1)})
        with open(os.path.join(args.out, "loop.json"), "w") as fh:
            json.dump(_plain(out), fh, indent=2)
        say(res.table())
        say(f"report: {report}")
    return 0


def _plain(v):
    """``v`` with numpy values as Python ones and non-finite floats as None (valid JSON)."""
    import numpy as np

    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_plain(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, (np.integer, np.bool_)):
        return v.item()
    return v
