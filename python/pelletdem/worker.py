"""Running one point, in a worker process: :func:`run_point` and the relaxed pellets it
branches from.

Fill, compaction, unloading, demoulding and relaxation depend only on (preset, contact law,
sigma_z, seed) (:attr:`pelletdem.runs.RunSpec.relax_key`), not on the bond law. The relaxed
``Pellet`` lives in memory: each worker process memoises the last few relaxed pellets per
relax key (:data:`RELAX_MEMO_SIZE`) and clones the world for every bond-parameter run
(:func:`clone_pellet`; a clone breaks exactly as a fresh relaxation does, bit for bit, at
threads=1). Across processes each worker relaxes a pellet once, the first time it gets a run
with that key: a scan submits its runs grouped by relax key so that a worker keeps getting
runs for the pellet it already holds. With ``relaxed_dir`` (a directory every worker can
reach) the relaxed pellets are also written there as checkpoints (:mod:`pelletdem.checkpoint`,
bit-exact, :func:`relaxed_path`), and a worker without one in memory loads it instead of
compacting again, now or in a later run. A run whose spec has a ``ladder`` of lower
pressures relaxes their pellets too, from its own piston stroke, and leaves them in
``relaxed_dir`` for the runs at those pressures (:func:`pelletdem.pipeline.relaxed_pellets`).

The failure of a simulated pellet is the first peak of sigma_1(dL/D) after which the
(lightly smoothed) curve falls by 10% (:func:`failure_point`): a small pellet can break and
then load up again as the plates crush it.
"""
from __future__ import annotations

import dataclasses
import json
import os
import socket
import threading
import time
import warnings
from collections import OrderedDict
from typing import Dict, Optional, Tuple, Union

import numpy as np

from .engine import ParameterError, SimulationError
from .h5io import jsonable
from .runs import RunSpec, canonical

__all__ = ["RELAX_MEMO_SIZE", "FAILURE_DROP", "clone_pellet", "clear_memo", "failure_point", "relaxed_path",
           "run_point"]

#: Relaxed pellets memoised per worker process (each holds a whole C++ world).
RELAX_MEMO_SIZE = int(os.environ.get("PELLETDEM_RELAX_MEMO", "4"))

_MEMO: "OrderedDict[str, tuple]" = OrderedDict()
_MEMO_LOCK = threading.Lock()
_KEY_LOCKS: Dict[str, threading.Lock] = {}


def clone_pellet(pellet):
    """A deep copy of a Pellet (its C++ world cloned, wall map copied, no snapshots) to run a
    bond law on while the original stays relaxed."""
    return dataclasses.replace(pellet, world=pellet.world.clone(), walls=dict(pellet.walls), snapshots={})


def _key_lock(key: str) -> threading.Lock:
    with _MEMO_LOCK:
        return _KEY_LOCKS.setdefault(key, threading.Lock())


def _decimate(n: int, m: int) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(n, m)).round().astype(int)) if n else np.zeros(0, int)


def _compaction_outputs(res) -> Tuple[dict, dict]:
    c, r, f = res.stages["compact"], res.stages["relax"], res.stages["fill"]
    s = c.series
    sig, bd = np.asarray(s["sigma_z"], float), np.asarray(s["bulk_density"], float)
    target = c.scalars["sigma_z_target"]
    sel = (sig >= 0.5 * target) & (sig > 0) & (bd > 0)
    slope = float("nan")
    if sel.sum() >= 3:
        slope = float(np.polyfit(np.log(sig[sel]), np.log(bd[sel]), 1)[0])
    out = {
        "n_particles": f.scalars["n_particles"], "h0": f.scalars["h0"],
        "bulk_density_fill": f.scalars["bulk_density"],
        "bulk_density_max": c.scalars["bulk_density_max"], "dh_h0_max": c.scalars["dh_h0_max"],
        "sigma_z_reached": c.scalars["sigma_z_reached"], "compaction_reached": c.scalars["reached"],
        "max_overlap_ratio": c.scalars["max_overlap_ratio"],
        "coordination_number_max": c.scalars["coordination_number_max"],
        "dlnbd_dlnsigma": slope,
        "bulk_density_relaxed": r.scalars["bulk_density"],
        "bulk_density_relaxed_extent": r.scalars["bulk_density_extent"],
        "bulk_density_relaxed_core": r.scalars["bulk_density_core"],
        "coordination_number_relaxed": r.scalars["coordination_number"],
        "coordination_number_relaxed_bulk": r.scalars["coordination_number_bulk"],
        "relaxed_converged": r.scalars["converged"],
        "relaxed_height": r.scalars["height"], "relaxed_diameter": r.scalars["diameter"],
    }
    k = _decimate(len(sig), 100)
    curve = {"dh_h0": np.asarray(s["dh_h0"])[k].tolist(), "sigma_z": sig[k].tolist(),
             "bulk_density": bd[k].tolist(),
             "coordination_number": np.asarray(s["coordination_number"])[k].tolist()}
    return out, curve


def relaxed_path(relaxed_dir, key: str) -> str:
    """The checkpoint file of the relaxed pellet with relax key ``key`` in ``relaxed_dir``."""
    return os.path.join(os.fspath(relaxed_dir), key + ".h5")


def _load_relaxed(spec: RunSpec, path: str):
    """(pellet, outputs, curve) from a relaxed-pellet checkpoint, or None if unusable."""
    from .checkpoint import CheckpointError, read_state
    from .engine import World
    from .stages import Pellet

    try:
        state, extra = read_state(path)
        if extra.get("relax_key") != spec.relax_key:
            raise CheckpointError(f"{path}: written for another relax key")
        world = World.from_state(state, threads=1)
    except (OSError, ValueError, KeyError) as e:
        warnings.warn(f"relaxed pellet {path} not usable ({e}); relaxing again", stacklevel=2)
        return None
    pellet = Pellet(world, spec.preset, {k: int(v) for k, v in extra["walls"].items()}, extra["mould_radius"],
                    extra["mass"], h0=extra["h0"], diameter=extra["diameter"], height=extra["height"])
    return pellet, extra["outputs"], extra["curve"]


def _save_relaxed(spec: RunSpec, path: str, pellet, outs: dict, curve: dict) -> None:
    from .checkpoint import save_world

    extra = {"relax_key": spec.relax_key, "walls": dict(pellet.walls), "mould_radius": pellet.mould_radius,
             "mass": pellet.mass, "h0": pellet.h0, "diameter": pellet.diameter, "height": pellet.height,
             "outputs": outs, "curve": curve}
    try:
        save_world(pellet.world, path, extra=json.loads(json.dumps(extra, default=jsonable)))
    except OSError as e:  # a full or read-only disk costs a relaxation later, not this run
        warnings.warn(f"could not save the relaxed pellet to {path}: {e}", stacklevel=2)


def _relaxed(spec: RunSpec, relaxed_dir=None):
    """(pellet, compaction outputs, compaction curve, source, relaxations) for the spec's relax
    key; source is 'memory', 'disk' (a checkpoint in relaxed_dir) or '' (relaxed now, with
    relaxations the pellets relaxed: its ladder's too)."""
    key = spec.relax_key
    with _key_lock(key):
        with _MEMO_LOCK:
            hit = _MEMO.get(key)
            if hit is not None:
                _MEMO.move_to_end(key)
        if hit is not None:
            return (*hit, "memory", 0)
        source, made = "", 0
        got = None
        if relaxed_dir is not None and os.path.exists(relaxed_path(relaxed_dir, key)):
            got = _load_relaxed(spec, relaxed_path(relaxed_dir, key))
            source = "disk" if got is not None else ""
        if got is None:
            got, made = _relax_ladder(spec, relaxed_dir)
        with _MEMO_LOCK:
            _MEMO[key] = got
            while len(_MEMO) > max(RELAX_MEMO_SIZE, 1):
                _MEMO.popitem(last=False)
        return (*got, source, made)


def _relax_ladder(spec: RunSpec, relaxed_dir) -> Tuple[tuple, int]:
    """Relax the spec's pellet, and with a ``relaxed_dir`` those of its ``ladder`` pressures
    that the directory lacks, from one piston stroke (:func:`pipeline.relaxed_pellets`; each
    bit for bit its own compaction's), saving each there. Returns the spec's (pellet,
    outputs, curve) and how many pellets were relaxed."""
    from . import pipeline

    pressures = sorted({float(sz) for sz in spec.ladder if float(sz) < spec.sigma_z}) if relaxed_dir else []
    lower = [s for s in (dataclasses.replace(spec, sigma_z=sz, bond=None, ladder=()) for sz in pressures)
             if not os.path.exists(relaxed_path(relaxed_dir, s.relax_key))]
    specs = lower + [spec]
    made = pipeline.relaxed_pellets(spec.preset, [s.sigma_z for s in specs], seed=spec.seed, threads=1,
                                    progress=False)
    got = None
    for s, (pellet, res) in zip(specs, made):
        outs, curve = _compaction_outputs(res)
        outs = {k: float(v) for k, v in outs.items()}
        if relaxed_dir is not None:
            _save_relaxed(s, relaxed_path(relaxed_dir, s.relax_key), pellet, outs, curve)
        got = (pellet, outs, curve)
    return got, len(specs)


def clear_memo() -> None:
    """Forget this process's relaxed pellets."""
    with _MEMO_LOCK:
        _MEMO.clear()


#: A failure is a peak of the smoothed sigma_1(dL/D) after which it falls by this fraction.
FAILURE_DROP = 0.10


def failure_point(dL_D, sigma_1, drop: float = FAILURE_DROP,
                  min_fraction: float = 0.5) -> Tuple[float, float, bool]:
    """The pellet's failure on a diametral curve: (sigma_f (Pa), dL_f/D (-), peaked).

    The first peak of sigma_1 (Pa) against dL/D (-) of at least ``min_fraction`` of the
    curve's maximum (which skips the spike of the plates' first contacts) after which the
    curve, smoothed over ~2.5% of its points to ignore the jitter of single bond breaks,
    falls by ``drop`` (10%) of the peak: sigma_f is the largest raw sigma_1 up to that fall
    and dL_f/D where it is reached.
    A small pellet can break and then load up again as the plates crush it, so the global
    maximum (the stage's ``sigma_f``) can come after the failure. ``peaked`` is False when no
    such fall happens before the test ends: the values returned (the global maximum) are then
    lower bounds.
    """
    x, y = np.asarray(dL_D, float), np.asarray(sigma_1, float)
    n = len(y)
    if n == 0:
        return float("nan"), float("nan"), False
    w = max(1, n // 40)
    box = np.ones(2 * w + 1)
    ys = np.convolve(y, box, mode="same") / np.convolve(np.ones(n), box, mode="same")  # edges: mean of fewer
    floor = min_fraction * float(ys.max())  # ignore the toe (first contacts of the plates)
    m, end = -np.inf, None
    for i, v in enumerate(ys):
        if v > m:
            m = v
        elif m > 0 and m >= floor and v < (1.0 - drop) * m:
            end = i
            break
    seg = slice(0, n if end is None else end + 1)
    k = int(np.argmax(y[seg]))
    return float(y[k]), float(x[k]), end is not None


def run_point(spec: RunSpec, relaxed_dir: Optional[Union[str, os.PathLike]] = None) -> dict:
    """Run one :class:`RunSpec` (threads=1) and return its cache record (plain JSON values).

    The relaxed pellet comes from this process's memo when it holds the spec's relax key, else
    from a checkpoint ``<relaxed_dir>/<relax_key>.h5`` when ``relaxed_dir`` is given and has it,
    and is computed (memoised, and saved to ``relaxed_dir``) otherwise. Record fields: ``key``, ``relax_key``, ``spec``
    (inputs), ``ok``, ``error`` (the engine's message when a run failed), ``outputs``
    (compaction: bulk densities kg/m^3, coordination numbers, dlnbd_dlnsigma; diametral:
    ``sigma_f`` Pa and ``dLf_D`` at the failure (:func:`failure_point`), ``peaked`` 1.0 when
    the failure came before the test ended (0.0: the values are lower bounds),
    ``sigma_f_max`` / ``dLf_D_max`` the curve's global maximum, bond counts), ``curve``
    ({dL_D, sigma_1 (Pa)}), ``compaction_curve``,
    ``relaxed_reused`` (False when this run relaxed the pellet), ``relaxed_from`` ('memory',
    'disk' or ''), ``relaxations`` (pellets this run relaxed: 0, 1, or more with the spec's
    ``ladder``), ``wall_time_s`` (s), ``worker``.
    """
    from . import pipeline

    t0 = time.perf_counter()
    rec = {"key": spec.key, "relax_key": spec.relax_key, "spec": canonical(spec.payload()),
           "ok": False, "error": None, "outputs": {}, "curve": {}, "compaction_curve": {},
           "relaxed_reused": False, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    try:
        pellet, outs, ccurve, source, made = _relaxed(spec, relaxed_dir)
        rec["relaxed_reused"] = bool(source)
        rec["relaxed_from"] = source
        rec["relaxations"] = made
        rec["outputs"].update(outs)
        rec["compaction_curve"] = ccurve
        if spec.bond is not None:
            with _key_lock(spec.relax_key):
                branch = clone_pellet(pellet)
            # the relaxed pellet may come from a spec that differs in the after-relax fields
            # (plate speed, max_dLD, bond ramp): the stages read them from the pellet's preset
            branch.preset = spec.preset
            res = pipeline.break_pellet(branch, spec.bond, progress=False)
            b, d = res.stages["bond"].scalars, res.stages["diametral"]
            sig1 = np.asarray(d.series["sigma_1"], float)
            dl = np.asarray(d.series["dL_D"], float)
            sf, dlf, peaked = failure_point(dl, sig1)
            rec["outputs"].update({
                "sigma_f": sf, "dLf_D": dlf, "peaked": float(peaked),
                "sigma_f_max": d.scalars["sigma_f"], "dLf_D_max": d.scalars["dLf_D"],
                "bonds_per_particle": b["bonds_per_particle"], "n_bonds": b["n_bonds"],
                "largest_cluster_fraction": b["largest_cluster_fraction"],
                "broken_during_ramp": b["broken_during_ramp"], "bonds_broken": d.scalars["bonds_broken"],
                "diameter": d.scalars["diameter"], "height": d.scalars["height"]})
            rec["curve"] = {"dL_D": dl.tolist(), "sigma_1": sig1.tolist()}
        rec["ok"] = True
    except (SimulationError, ParameterError) as e:
        rec["error"] = f"{type(e).__name__}: {e}"
    rec["outputs"] = {k: float(v) for k, v in rec["outputs"].items()}
    rec["wall_time_s"] = time.perf_counter() - t0
    return rec

