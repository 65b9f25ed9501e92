""""Measured" data made by a simulator the way a laboratory makes them (to test the loop).

A laboratory tests a few replicate pellets per condition, each pressed from its own sawdust,
and reports the mean and SD of what it measured. :func:`synthetic_dataset` does the same with
a simulator and a hidden parameter set: each replicate is one packing (seeds the loop's fits
never use), each of its measured numbers carries relative measurement noise, and the dataset
holds the replicates' means, SDs and counts: sigma_1 at :data:`pelletdem.loop_data.DIAMETRAL_GRID`
fractions of the replicates' mean dL_f/D, sigma_f, dL_f/D, the relaxed bulk density and,
optionally, sigma_z along the compaction curve. Nothing in the dataset says what made it.
"""
from __future__ import annotations

import math
from typing import Dict, List, Mapping, Sequence, Tuple, Union

import numpy as np

from .loop_data import COMPACTION_SPLIT, DIAMETRAL_GRID, Condition, Dataset, Observation, diametral_part
from .loop_simulators import Prediction, Simulator, next_window

__all__ = ["DATA_SEEDS", "synthetic_dataset"]

#: Packings of the synthetic replicates: far from the fits' seeds (0, 1, ...) and the checks'.
DATA_SEEDS = (1000, 1001, 1002, 1003, 1004)


def _curve_at(xy, x: float) -> float:
    xs, ys = np.asarray(xy[0], float), np.asarray(xy[1], float)
    order = np.argsort(xs, kind="stable")
    return float(np.interp(x, xs[order], ys[order]))


def _unfailed(ensembles) -> int:
    """Replicates that did not fail within the test window, over every condition."""
    return sum(m.scalars.get("peaked", 1.0) < 1.0 for e in ensembles.values() if e.ok for m in e.members)


def _predict(sim: Simulator, truth: Mapping[str, float], seeds: Mapping[Condition, Tuple[int, ...]]):
    # conditions that share their replicate packings are simulated together
    groups: Dict[Tuple[int, ...], list] = {}
    for c, s in seeds.items():
        groups.setdefault(s, []).append(c)
    out = {}
    for s, conds in groups.items():
        out.update(sim.predict(dict(truth), conds, s))
    return out


def _tested_to_failure(sim: Simulator, truth: Mapping[str, float], seeds: Mapping[Condition, Tuple[int, ...]]):
    """The replicates' ensembles (``seeds``: each condition's replicate packings), each test
    run until its pellet broke, as a laboratory runs it: where a replicate has not failed by
    the end of the window and the simulator can widen it, the window is widened
    (:func:`pelletdem.loop_simulators.next_window`) and the truth simulated again; the
    simulator keeps the wider window."""
    ensembles = _predict(sim, truth, seeds)
    while _unfailed(ensembles) and next_window(sim) is not None:
        sim.widen(next_window(sim))
        ensembles = _predict(sim, truth, seeds)
    return ensembles


def _replicate_seeds(seeds, conditions: Sequence[Condition]) -> Dict[Condition, Tuple[int, ...]]:
    """{condition: its replicate packings} from one sequence for all or a mapping."""
    if isinstance(seeds, Mapping):
        missing = [c.label for c in conditions if c not in seeds]
        if missing:
            raise ValueError(f"seeds: no replicate packings given for {', '.join(missing)}")
        per = {c: seeds[c] for c in conditions}
    else:
        per = {c: seeds for c in conditions}
    out = {}
    for c, s in per.items():
        s = tuple(int(k) for k in s)
        if len(s) < 2:
            raise ValueError(f"seeds = {s!r} ({c.label}): at least 2 replicate packings are needed for an SD")
        out[c] = s
    return out


def _same_packings(seeds: Mapping[Condition, Tuple[int, ...]]) -> Tuple[Tuple[Condition, ...], ...]:
    """The groups of conditions whose replicates share a packing (linked through any seed)."""
    groups: List[List[Condition]] = []
    for c, s in seeds.items():
        linked = [g for g in groups if any(set(s) & set(seeds[d]) for d in g)]
        merged = [c] + [d for g in linked for d in g]
        groups = [g for g in groups if g not in linked] + [merged]
    order = {c: k for k, c in enumerate(seeds)}
    return tuple(tuple(sorted(g, key=order.get)) for g in groups if len(g) >= 2)


def synthetic_dataset(sim: Simulator, truth: Mapping[str, float], conditions: Sequence[Condition], *,
                      seeds: Union[Sequence[int], Mapping[Condition, Sequence[int]]] = DATA_SEEDS,
                      noise: float = 0.02,
                      quantities: Sequence[str] = ("sigma_1", "sigma_f", "dLf_D", "bulk_density"),
                      compaction_points: int = 0, seed: int = 0, name: str = "synthetic") -> Dataset:
    """Data of ``conditions`` made by ``sim`` under ``truth`` (SI; it may switch on any
    effect, in the library or not): one replicate per packing of ``seeds`` (at least 2; one
    sequence for every condition, or {condition: sequence}, where other packings make each
    condition's pellets other pellets, as a laboratory's are; conditions sharing a packing
    are recorded in the dataset's ``same_packings``), each
    number of each replicate times (1 + ``noise`` N(0, 1)) (``seed`` seeds that noise), then
    the replicates' mean, SD and count per number. A replicate that has not failed by the end
    of the diametral window is tested further where the simulator can widen its window (to
    dL/D 0.5 at most), as a laboratory tests until the pellet breaks. ``quantities``: of sigma_1 (curve points),
    sigma_f, dLf_D, bulk_density; ``compaction_points``: sigma_z at that many dh/h0 from 0.3 of
    the compaction curve's range to its end (0: none)."""
    if not (isinstance(noise, (int, float)) and 0 <= noise < 1):
        raise ValueError(f"noise = {noise!r} is out of range: allowed 0 <= noise < 1")
    seeds = _replicate_seeds(seeds, conditions)
    bad = set(quantities) - {"sigma_1", "sigma_f", "dLf_D", "bulk_density"}
    if bad:
        raise ValueError(f"quantities {sorted(bad)}: allowed sigma_1, sigma_f, dLf_D, bulk_density")
    rng = np.random.default_rng(seed)
    ensembles = _tested_to_failure(sim, truth, seeds)
    obs = []

    def measured(values, x=float("nan"), quantity="sigma_f", part="scalar", cond=None):
        v = np.asarray(values, float) * (1.0 + noise * rng.standard_normal(len(values)))
        obs.append(Observation(cond, quantity, float(x), float(v.mean()), float(v.std(ddof=1)), len(v), part))

    for c in conditions:
        ens = ensembles[c]
        if not ens.ok:
            raise RuntimeError(f"the truth's simulation of {c.label} failed: {ens.error}")
        members: Sequence[Prediction] = ens.members
        if any(m.scalars.get("peaked", 1.0) < 1.0 for m in members):
            raise ValueError(f"{c.label}: {sum(m.scalars.get('peaked', 1.0) < 1.0 for m in members)} of the "
                             f"{len(members)} replicates do not fail within the diametral test window: a laboratory's "
                             "pellets break; widen the window (EngineSimulator max_dLD) or choose stronger bonds")
        x_f = float(np.mean([m.scalars.get("dLf_D", math.nan) for m in members]))
        if "sigma_1" in quantities and all(m.curve is not None and len(m.curve[0]) for m in members):
            top = min(float(np.max(m.curve[0])) for m in members)
            for f in DIAMETRAL_GRID:
                if f * x_f <= top:
                    measured([_curve_at(m.curve, f * x_f) for m in members], f * x_f, "sigma_1",
                             diametral_part(f * x_f, x_f), c)
        if compaction_points and all(m.compaction is not None and len(m.compaction[0]) for m in members):
            end = min(float(np.max(m.compaction[0])) for m in members)
            for x in np.linspace(0.3 * end, end, compaction_points):
                measured([_curve_at(m.compaction, x) for m in members], x, "sigma_z",
                         "compaction-low" if x < COMPACTION_SPLIT else "compaction-high", c)
        for q in ("sigma_f", "dLf_D", "bulk_density"):
            if q in quantities:
                vals = [m.scalars.get(q, math.nan) for m in members]
                if all(math.isfinite(v) for v in vals):
                    measured(vals, quantity=q, cond=c)
    return Dataset(obs, name, _same_packings(seeds))
