"""A calibration of the paper's variants written to a directory, resumable: :func:`calibrate_into`.

What ``pelletdem calibrate OUT_DIR`` and ``examples/03_calibration.py OUT_DIR`` run. OUT_DIR gets
calibration.csv (the fitted values beside Table 5 and the errors against Tables 2 and 3),
calibration.json (the contact law, the bond fits, the ``--set`` values, runs, wall time and
how many variants agree with the paper, ``CalibrationReport.agreement``),
fig15_measured_vs_simulated.png, fig15_curves.png (each variant's fitted sigma_1(dL/D) with
Table 3's point) and fig10_relaxed.png (the relaxed pellets on the paper's Fig. 10).
OUT_DIR/cache holds one record per run and OUT_DIR/relaxed the relaxed
pellets the bond runs branch off, so the same calibration run again reads its runs back
instead of simulating them. OUT_DIR/segments.jsonl marks the start and end of every sitting
(:class:`Sittings`): calibration.json's ``sittings`` and ``wall_time_total_s`` add up the wall
time of all of them, killed ones included (up to their last finished run, a lower bound).
"""
from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path
from typing import Callable, Mapping, Optional, Sequence, Union

from .law_settings import apply_settings
from .laws import BondLaw
from .objectives import as_variants
from .run_cache import RunCache
from .runs import PARAMETERS, RunSpec, check_positive
from .variants import CalibrationReport, calibrate_variants
from .worker import run_point

__all__ = ["CALIBRATION_FILE", "Sittings", "load_calibration", "calibrate_into"]

#: The file in OUT_DIR another calibration starts from (``source=``, ``--from``).
CALIBRATION_FILE = "calibration.json"
#: Largest seed of a calibration's first packing (``first_packing``).
FIRST_PACKING_MAX = 1_000_000


class Sittings:
    """Wall time of a calibration that ran in several sittings: ``out/segments.jsonl`` holds a
    line at each start and end. A sitting that was killed has no end line; its end is taken as
    the last cache record (``out/cache``) written before the next start (a lower bound: the
    runs in flight when it was killed are not counted)."""

    def __init__(self, out: Union[str, os.PathLike]):
        out = Path(out)
        self.path, self.cache = out / "segments.jsonl", out / "cache"

    def _append(self, **row):
        with open(self.path, "a") as fh:
            fh.write(json.dumps({"time": time.time(), **row}) + "\n")

    def start(self) -> None:
        """Marks the start of a sitting (wall clock, s since the epoch)."""
        self._append(event="start")

    def finish(self, report) -> dict:
        """Marks the end; returns calibration.json's fields on every sitting and their sum (s)."""
        self._append(event="end", n_simulations=report.n_simulations, n_cached=report.n_cached)
        rows = [json.loads(line) for line in self.path.read_text().splitlines() if line.strip()]
        mtimes = sorted(f.stat().st_mtime for f in self.cache.rglob("*.json"))
        sittings = []
        for k, row in enumerate(rows):
            if row["event"] != "start":
                continue
            nxt = rows[k + 1] if k + 1 < len(rows) else None
            if nxt is not None and nxt["event"] == "end":
                sittings.append({"start": row["time"], "wall_time_s": nxt["time"] - row["time"],
                                 "killed": False, "n_simulations": nxt["n_simulations"]})
            else:  # killed: it ran until its last record, at least
                stop = nxt["time"] if nxt is not None else float("inf")
                done = [t for t in mtimes if row["time"] <= t < stop]
                sittings.append({"start": row["time"], "wall_time_s": (max(done) - row["time"]) if done else 0.0,
                                 "killed": True, "n_simulations": len(done)})
        return {"sittings": sittings, "wall_time_total_s": sum(s["wall_time_s"] for s in sittings)}


def load_calibration(directory: Union[str, os.PathLike]) -> dict:
    """The calibration.json an earlier :func:`calibrate_into` wrote to ``directory``, checked
    to hold the contact law and the bond fits; ValueError saying what is missing."""
    path = Path(directory) / CALIBRATION_FILE
    if not path.is_file():
        raise ValueError(f"{directory}: no {CALIBRATION_FILE} there (write one with pelletdem calibrate)")
    try:
        source = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a readable calibration ({e})") from None
    if not (isinstance(source, dict) and isinstance(source.get("contact"), dict)
            and isinstance(source.get("bond_start"), dict)):
        raise ValueError(f"{path}: not a calibration (no 'contact' and 'bond_start' mappings)")
    by_material = source.get("contact_by_material") or {}
    if not (isinstance(by_material, dict) and all(isinstance(r, dict) for r in by_material.values())):
        raise ValueError(f"{path}: contact_by_material = {by_material!r} is not a mapping {{material: {{row: value}}}}")
    for label, params in source["bond_start"].items():
        if not isinstance(params, dict):
            raise ValueError(f"{path}: bond_start[{label!r}] = {params!r} is not a mapping {{name: value}}")
        for name, v in params.items():
            check_positive(f"{path}: bond_start[{label!r}][{name!r}]", v, PARAMETERS.get(name, ("-",))[0])
    return source


def calibrate_into(out: Union[str, os.PathLike], variants=None, preset="tiny", *, max_runs: int = 4,
                   compaction_runs: int = 2, packings: int = 1, first_packing: int = 0,
                   source: Optional[Union[str, os.PathLike]] = None,
                   settings: Optional[Mapping[str, object]] = None,
                   fit: Optional[Mapping[str, Sequence[float]]] = None, per_material: bool = False, executor=None,
                   max_workers: Optional[int] = None, runner: Callable[[RunSpec], dict] = run_point,
                   log: Callable[[str], None] = print) -> CalibrationReport:
    """Calibrate ``variants`` (default all 12; Variants or (material, mc %, sigma_z MPa) keys)
    on ``preset`` with :func:`pelletdem.variants.calibrate_variants` and write the results to
    ``out`` (see the module docstring); the same call again resumes from ``out/cache``.

    ``max_runs``: parameter points per variant's bond fit (E_b, sigma_c = tau_c).
    ``packings``: packings every point averages (1..64): a small pellet's
    own scatter is large, and more packings give the density its standard error.
    ``first_packing``: the first packing's seed (0..FIRST_PACKING_MAX): packings
    first_packing..first_packing+packings-1, so that a fit can be repeated on other pellets.
    ``compaction_runs``: k1 points of the shared compaction fit, within a factor 10 of the
    preset's k1 (0: keep the preset's). ``source``: the ``out`` of an earlier calibration,
    on a smaller preset: its contact law (k1, k2) and bond fits are used in place of the
    compaction fit and Table 5's starting values, so one pellet per pressure is relaxed.
    ``settings``: {'contact.X': v, 'bond.Y': w} (SI; :mod:`pelletdem.law_settings`) applied
    to the preset's contact law and the base bond law before fitting. ``fit``:
    {'contact.<field>': (lo, hi) or (lo, hi, start)}: contact-law rows fitted beside k1 in the
    compaction fit, each of one sign, in log space of its magnitude (``contact.k1`` in k1's
    place: k1 fitted with k2 kept). ``per_material``: that fit runs per material, on its own
    densities (k1 a material parameter; calibration.json's ``contact_by_material``, which
    ``source`` passes on for the variants' woods). ``executor``,
    ``max_workers``, ``runner``: as in ``calibrate_variants`` (a Dask ``distributed.Client``
    is an executor). ``log``: where the report's text goes. The preset runs with the paper's
    overlap guard (:func:`pelletdem.loop_paper.paper_preset`), as the loop's paper variants
    do. Returns the :class:`pelletdem.variants.CalibrationReport`.
    """
    from . import plots
    from .loop_paper import paper_preset

    if isinstance(packings, bool) or not isinstance(packings, int) or not 1 <= packings <= 64:
        raise ValueError(f"packings = {packings!r}: allowed an integer 1..64")
    if isinstance(first_packing, bool) or not isinstance(first_packing, int) \
            or not 0 <= first_packing <= FIRST_PACKING_MAX:
        raise ValueError(f"first_packing = {first_packing!r}: allowed an integer 0..{FIRST_PACKING_MAX}")
    if fit and (source is not None or not compaction_runs):
        raise ValueError("fit = {...} needs the compaction fit: compaction_runs >= 1 and no source")
    if per_material and (source is not None or not compaction_runs):
        raise ValueError("per_material = True needs the compaction fit: compaction_runs >= 1 and no source")
    p = paper_preset(preset)
    settings = dict(settings or {})
    src = load_calibration(source) if source is not None else None
    vs = as_variants(variants)
    base, by_material = p.contact, {}
    if src is not None:
        # a source calibrated on more woods than these variants passes on their woods' rows
        materials = {v.material for v in vs}
        by_material = {m: r for m, r in (src.get("contact_by_material") or {}).items() if m in materials}
        # the settings go on the law they run with: the source's, with its first material's
        # rows where it has k1 per material (that k1 may be below the preset's, and a set k2
        # then below the preset's k1); calibrate_variants puts each material's own in force
        rows = next(iter(by_material.values()), {})
        try:
            base = dataclasses.replace(p.contact, **{**src["contact"], **rows})
        except TypeError as e:  # a row the contact law does not have
            raise ValueError(f"source = {os.fspath(source)!r}: its contact law is refused: {e}") from None
    contact, bond = apply_settings(base, BondLaw(), settings)
    p = p.with_(contact=contact)
    if src is not None:
        setup = dict(compaction=None, contact=src["contact"], start=src["bond_start"],
                     contact_by_material=by_material or None)
    elif compaction_runs:
        k1 = p.contact.k1
        # contact.k1 fits k1 with k2 kept; plain k1 keeps k2 / k1 (eq. 8's restitution)
        own = {} if "contact.k1" in (fit or {}) else {"k1": (k1 / 10, k1 * 10, k1)}
        setup = dict(compaction={**own, **dict(fit or {})}, compaction_max_runs=compaction_runs,
                     per_material=per_material)
    else:
        setup = dict(compaction=None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sittings = Sittings(out)
    sittings.start()
    seeds = tuple(range(first_packing, first_packing + packings))
    report = calibrate_variants(vs, p, max_runs=max_runs, seeds=seeds, cache_dir=out / "cache",
                                relaxed_dir=out / "relaxed",
                                executor=executor, max_workers=max_workers, runner=runner, bond=bond, **setup)
    log(str(report))
    report.table.to_csv(out / "calibration.csv", index=False)
    (out / CALIBRATION_FILE).write_text(json.dumps({
        "preset": p.name, "variants": [v.label for v in vs], "packings": packings, "first_packing": first_packing,
        "set": settings,
        "fit": {k: list(v) for k, v in (fit or {}).items()},
        "per_material": per_material, "contact": report.contact, "contact_by_material": report.contact_by_material,
        "bond_start": report.bond_start(), "from": os.fspath(source) if source is not None else None,
        "n_simulations": report.n_simulations, "n_cached": report.n_cached,
        "n_relaxations": report.n_relaxations, "wall_time_s": report.wall_time_s, "agreement": report.agreement(),
        **sittings.finish(report)}, indent=1))

    cache = RunCache(out / "cache")
    records = [cache.get(k) for k in cache.keys()]
    plots.save_calibration(report, vs, records, out)
    log("wrote " + ", ".join(sorted(f.name for f in out.iterdir() if f.is_file())))
    return report
