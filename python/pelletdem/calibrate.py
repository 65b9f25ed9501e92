"""Calibration of the DEM micro-parameters against the paper's measurements (issue 5).

What the paper did (sections 3.1.4, 3.1.5, 3.2): one particle yield strength p_y (hence k1,
eq. 7) for all materials from the compaction curves, then, per variant, the bond modulus E_b
and strength sigma_c = tau_c (r_b = 20 um fixed) from the diametral stress-deformation curve
by minimising RRMSE (eq. 16): 8-10 runs per variant in two or three one-parameter sweeps
(Fig. 14), 80 runs for the 12 variants. This module does the same with less hand work:

Runs and their cache
    A run is a :class:`RunSpec`: the preset (geometry, particles, speeds, contact law), the
    compaction pressure sigma_z (Pa), the seed and, for a diametral run, the bond law. Its key
    (:attr:`RunSpec.key`) is a SHA-256 of every field that changes the result (all preset
    fields but the name, sigma_z, seed, bond law, the package version, the cache format and
    :func:`engine_fingerprint`, a hash of the compiled engine and of the Python stage code, so
    a rebuilt or edited engine never serves stale results), with numbers rounded to 12
    significant digits so 9e6 and exp(log(9e6)) are the same point.
    :class:`RunCache` keeps one small JSON file per run (its scalars and its sigma_1(dL/D)
    curve); a scan or fit pointed at the same directory resumes where it stopped and never
    runs a point twice. A failed run (overlap, escape, NaN) is cached too: it is deterministic.
    Workers always run with ``threads=1``; the thread count is not part of the key.

Relaxed-pellet reuse
    Fill, compaction, unloading, demoulding and relaxation depend only on (preset, contact law,
    sigma_z, seed) (:attr:`RunSpec.relax_key`), not on the bond law. The relaxed ``Pellet``
    lives in memory: each worker process memoises the last few relaxed pellets per relax key
    (:data:`RELAX_MEMO_SIZE`) and clones the world for every bond-parameter run
    (``pellet.world.clone()``; a clone breaks exactly as a fresh relaxation does, bit for bit,
    at threads=1). Across processes each worker relaxes a pellet once, the first time it gets a
    run with that key: a scan submits its runs grouped by relax key so that a worker keeps
    getting runs for the pellet it already holds. With ``relaxed_dir`` (a directory every
    worker can reach) the relaxed pellets are also written there as checkpoints
    (:mod:`pelletdem.checkpoint`, bit-exact), and a worker without one in memory loads it
    instead of compacting again, in this session or a later one. The number of relaxations
    actually done is reported (``n_relaxations``) next to the number of runs.

Objectives (small pure functions)
    :func:`diametral_error`: z-scores of the simulated sigma_f and dL_f/D against Table 3's
    mean and SD (:func:`pelletdem.metrics.sd_weighted_error`, SD floored at 1% of the mean).
    :func:`curve_error`: RRMSE of eq. 16 against a measured sigma_1(dL/D) curve.
    :func:`density_error`: z-score of the simulated bulk density (relaxed, or at the end of
    compaction) against Table 2. :func:`score` combines them for one :class:`Targets`.

Searching
    :func:`scan` runs a grid (like the paper's (E_b, sigma_c) maps, Fig. 14) on an executor.
    :func:`fit` needs fewer runs. Its default method, ``"scaling"``, is a Gauss-Newton
    iteration in log space on a local affine model of ln(outputs) against ln(parameters), whose
    slopes start at the exponents of the paper's scaling laws and are refitted, by weighted
    ridge regression towards those exponents, to every run made so far (a 400-particle
    pellet's sigma_f scatters by a few % between nearby bond laws, so slopes from two
    neighbouring runs alone would be noise):

    * a bond breaks at the strain sigma_c / E_b, so the deformation at failure goes as
      dL_f/D ~ sigma_c / E_b (exponents +1, -1), and the peak force as E_b times that strain,
      sigma_f ~ sigma_c (exponents +1, 0): at fixed E_b sigma_f grows about linearly with
      sigma_c (Figs. 12-14), so after one run at (E_b, sigma_c) the next sigma_c is
      sigma_c * sigma_f,target / sigma_f,sim and E_b follows from dL_f/D;
    * the response depends on the bond only through E_b r_b^2 and sigma_c r_b^2 (Fig. 12b;
      NOTES item 3), so the exponents in r_b are twice the sum of those in E_b and sigma_c;
    * with k2/k1 fixed (the restitution, eq. 8) the compaction of linear contacts depends on
      sigma_z / k1, so d ln BD / d ln k1 = -d ln BD / d ln sigma_z, read off the loading curve
      of the first run: no finite-difference run is needed for k1 (or p_y) either.

    The failure of a simulated pellet is the first peak of sigma_1(dL/D) after which the
    (lightly smoothed) curve falls by 10% (:func:`failure_point`): a small pellet can break and
    then load up again as the plates crush it. A test that ends before such a fall yields bounds of
    sigma_f and dL_f/D, not values (``peaked`` = 0): such a run is scored as if its peak came
    at 1.5 x the end of the test (:data:`CENSORED_DLF_FACTOR`), and its values count a thousand
    times less in the local model, whose slopes then stay at the scaling law's. Scans score
    such runs the same way. A parameter no scaling law covers gets one finite-difference run.
    Steps are limited to a factor 4 per parameter and per iteration and projected on the
    bounds; a step that does not improve halves the step limit. The fit stops when the rms
    z-score is below ``tol`` (default 0.5: within half a measured SD), after ``max_runs``
    parameter points, or when the next step would change no parameter by more than
    ``min_step`` (2%). ``method="nelder-mead"`` runs scipy's Nelder-Mead on the loss in log
    space instead (more runs; use it for a curve criterion or parameters with no scaling law).

Executors
    Runs go to a ``concurrent.futures`` executor: a local ``ProcessPoolExecutor`` (spawn,
    ``max_workers``) by default, ``executor="serial"`` to run in this process, any
    ``concurrent.futures.Executor``, or a Dask ``distributed.Client`` (its
    ``get_executor(pure=False)`` is used). The process pool starts its workers with 'spawn'
    (a forked OpenMP runtime can hang), so a script that calls :func:`scan`, :func:`fit` or
    :func:`calibrate_variants` with it must keep its work under ``if __name__ == "__main__":``.
    :func:`calibrate_variants` drives the 12 per-variant fits concurrently (one driver thread
    each, all submitting to the same executor). The run cache is written by the driver, so
    Dask workers need no shared file system (``relaxed_dir`` does need one).

Units: SI everywhere (Pa, m, N/m, kg/m^3); tables shown to people carry the unit in the column
name (``_mpa``).
"""
from __future__ import annotations

import concurrent.futures as cf
import contextlib
import dataclasses
import hashlib
import itertools
import json
import math
import multiprocessing
import os
import socket
import tempfile
import threading
import time
import warnings
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from ._version import __version__
from .engine import BondLaw, ParameterError, SimulationError, k1_from_yield_strength
from .h5io import jsonable
from .metrics import DEFAULT_REL_SD_FLOOR
from .presets import Preset, get_preset

__all__ = [
    "PARAMETERS", "SCALING_EXPONENTS", "CACHE_FORMAT", "RELAX_MEMO_SIZE",
    "RunSpec", "make_spec", "cache_key", "engine_fingerprint", "RunCache", "run_point", "clone_pellet",
    "failure_point", "FAILURE_DROP",
    "Targets", "diametral_error", "curve_error", "density_error", "score",
    "compaction_targets", "ScanResult", "scan", "FitResult", "fit",
    "CalibrationReport", "calibrate_variants",
]

CACHE_FORMAT = 3  # 2: sigma_f / dLf_D at the first failure; 3: after-relax fields honoured
#: Relaxed pellets memoised per worker process (each holds a whole C++ world).
RELAX_MEMO_SIZE = int(os.environ.get("PELLETDEM_RELAX_MEMO", "4"))

#: Parameters a scan or fit can vary: name -> (unit, meaning).
PARAMETERS: Dict[str, Tuple[str, str]] = {
    "E_b": ("Pa", "bond Young's modulus (BondLaw.youngs_modulus)"),
    "sigma_c": ("Pa", "bond tensile strength; tau_c follows it (sigma_c = tau_c, as in the paper) "
                      "unless tau_c is varied too"),
    "tau_c": ("Pa", "bond shear strength"),
    "r_b": ("m", "bond radius"),
    "k1": ("N/m", "contact loading stiffness; k2 follows it so k2/k1 (the restitution, eq. 8) is kept"),
    "p_y": ("Pa", "particle yield strength; k1 = 5 r_mean p_y (eq. 7, engine.k1_from_yield_strength), "
                  "k2/k1 kept"),
    "sigma_z": ("Pa", "compaction pressure"),
}
_SCAN_ONLY = {"seed": ("-", "packing seed (scan only)")}

#: d ln(output) / d ln(parameter) from the paper's scaling laws (see the module docstring).
#: None: read off the run's own compaction curve (d ln BD / d ln sigma_z).
SCALING_EXPONENTS: Dict[str, Dict[str, Optional[float]]] = {
    "sigma_f": {"sigma_c": 1.0, "E_b": 0.0, "tau_c": 0.0, "r_b": 2.0},
    "dLf_D": {"sigma_c": 1.0, "E_b": -1.0, "tau_c": 0.0, "r_b": 0.0},
    "bulk_density": {"k1": None, "p_y": None, "sigma_z": None},
}

_MPA = 1e6


# --------------------------------------------------------------------------------------
# Run specification and its key
# --------------------------------------------------------------------------------------

# Preset fields that do not change fill..relax (they act in the bond and diametral stages).
_AFTER_RELAX_FIELDS = ("name", "plate_speed", "max_dLD", "break_drop", "break_from_dLD", "bond_ramp_time")
# Contact-law fields that act only on the diametral plates (crushable walls).
_AFTER_RELAX_CONTACT = ("plate_yield_stress",)


def _canon(v, where: str = "value"):
    """Plain JSON values with every number a float rounded to 12 significant digits."""
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        v = dataclasses.asdict(v)
    if isinstance(v, Mapping):
        return {str(k): _canon(x, f"{where}.{k}") for k, x in sorted(v.items(), key=lambda kv: str(kv[0]))}
    if isinstance(v, (list, tuple)):
        return [_canon(x, where) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, float, np.integer, np.floating)):
        f = float(v)
        if not math.isfinite(f):
            raise ValueError(f"{where} = {f!r} must be finite")
        return float(f"{f:.12g}") + 0.0  # + 0.0: -0.0 -> 0.0
    if v is None or isinstance(v, str):
        return v
    raise TypeError(f"{where}: cannot key a {type(v).__name__}")


_FINGERPRINT: Optional[str] = None
_FINGERPRINT_FILES = ("engine.py", "stages.py", "pipeline.py", "presets.py")


def engine_fingerprint() -> str:
    """First 16 hex digits of a SHA-256 over the compiled engine (``_core``) and the Python
    files that run a pellet's stages (engine, stages, pipeline, presets): part of every cache
    key, so results of another build are never reused. Computed once per process."""
    global _FINGERPRINT
    if _FINGERPRINT is None:
        from . import _core

        h = hashlib.sha256()
        here = os.path.dirname(os.path.abspath(__file__))
        for path in [_core.__file__] + [os.path.join(here, f) for f in _FINGERPRINT_FILES]:
            with open(path, "rb") as fh:
                h.update(hashlib.sha256(fh.read()).digest())
        _FINGERPRINT = h.hexdigest()[:16]
    return _FINGERPRINT


def _digest(payload) -> str:
    text = json.dumps(_canon(payload), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class RunSpec:
    """One simulation: fill -> compact to ``sigma_z`` (Pa) -> unload -> demould -> relax, and if
    ``bond`` is given, bond -> diametral test (to ``preset.max_dLD``, at ``preset.plate_speed``).

    ``preset`` carries geometry, particle sizes, speeds and the contact law; ``seed`` the
    packing. Build one with :func:`make_spec` from named parameters.
    """

    preset: Preset
    sigma_z: float
    seed: int = 0
    bond: Optional[BondLaw] = None

    @property
    def kind(self) -> str:
        """'diametral' (bond given) or 'compaction' (fill..relax only)."""
        return "compaction" if self.bond is None else "diametral"

    def relax_payload(self) -> dict:
        """Everything that determines the relaxed pellet (plain values)."""
        p = {k: v for k, v in self.preset.as_dict().items() if k not in _AFTER_RELAX_FIELDS}
        # the plates' crushing acts in the diametral test only: one relaxed pellet serves all
        p["contact"] = {k: v for k, v in p["contact"].items() if k not in _AFTER_RELAX_CONTACT}
        return {"format": CACHE_FORMAT, "version": __version__, "engine": engine_fingerprint(), "preset": p,
                "sigma_z": float(self.sigma_z), "seed": int(self.seed)}

    def payload(self) -> dict:
        """Everything that determines this run's result (plain values)."""
        d = self.relax_payload()
        d["kind"] = self.kind
        if self.bond is not None:
            d["bond"] = dataclasses.asdict(self.bond)
            d["after_relax"] = {k: getattr(self.preset, k) for k in _AFTER_RELAX_FIELDS if k != "name"}
            d["after_relax"].update({k: getattr(self.preset.contact, k) for k in _AFTER_RELAX_CONTACT})
        return d

    @property
    def key(self) -> str:
        """Stable SHA-256 hex key of :meth:`payload` (the cache file name)."""
        return _digest(self.payload())

    @property
    def relax_key(self) -> str:
        """Key of the relaxed pellet this run starts from (shared by all bond laws)."""
        return _digest(self.relax_payload())


def cache_key(spec: RunSpec) -> str:
    """The cache key of a run (same as ``spec.key``): SHA-256 hex of all its inputs."""
    return spec.key


def _as_preset(preset) -> Preset:
    if isinstance(preset, Preset):
        return preset
    return get_preset(preset)


def _check_finite_positive(name: str, value, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r} must be a number ({unit})") from None
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} = {value!r} must be finite and > 0 ({unit})")
    return v


def _check_names(names: Iterable[str], allowed: Mapping[str, Any], what: str = "parameter") -> None:
    for n in names:
        if n not in allowed:
            raise ValueError(f"unknown {what} {n!r}: allowed {sorted(allowed)}")


def make_spec(params: Optional[Mapping[str, float]] = None, *, preset="tiny", sigma_z: float = 120e6,
              seed: int = 0, bond: Optional[BondLaw] = None, diametral: bool = True,
              contact: Optional[Mapping[str, Any]] = None, max_dLD: Optional[float] = None) -> RunSpec:
    """A :class:`RunSpec` from named parameters (see :data:`PARAMETERS`, SI units).

    ``preset``: name or Preset. ``contact``: ContactLaw field overrides (e.g. ``{"k1": 5e4,
    "k2": 2e5}``) applied before ``params``. ``bond``: the base BondLaw (default BondLaw());
    ``params`` E_b, sigma_c, tau_c, r_b change it, k1 / p_y change the contact law (k2/k1 kept),
    sigma_z (Pa) the pressure. ``diametral=False`` gives a compaction-only run (no bond).
    ``max_dLD``: end of the diametral test (default the preset's). Raises ValueError naming a
    bad parameter.
    """
    params = dict(params or {})
    _check_names(params, {**PARAMETERS, **_SCAN_ONLY})
    p = _as_preset(preset)
    if contact:
        _check_names(contact, {f.name: f for f in dataclasses.fields(p.contact)}, "contact law field")
        p = p.with_(contact=dataclasses.replace(p.contact, **dict(contact)))
    if max_dLD is not None:
        p = p.with_(max_dLD=_check_finite_positive("max_dLD", max_dLD, "-"))
    for name, v in params.items():
        if name == "seed":
            if isinstance(v, float) and v.is_integer():
                v = int(v)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"seed = {v!r} must be an integer >= 0")
            params[name] = int(v)
        else:
            params[name] = _check_finite_positive(name, v, PARAMETERS[name][0])
    if "k1" in params and "p_y" in params:
        raise ValueError("give k1 or p_y, not both (k1 = 5 r p_y)")
    k1 = params.get("k1")
    if "p_y" in params:
        k1 = k1_from_yield_strength(params["p_y"], p.radius_mean)
    if k1 is not None:
        ratio = p.contact.k2 / p.contact.k1
        p = p.with_(contact=dataclasses.replace(p.contact, k1=k1, k2=k1 * ratio))
    p.contact.to_core()  # validates (ParameterError is a ValueError)
    sz = _check_finite_positive("sigma_z", params.get("sigma_z", sigma_z), "Pa")
    seed = params.get("seed", seed)
    law = None
    if diametral:
        law = dataclasses.replace(bond) if bond is not None else BondLaw()
        if "E_b" in params:
            law.youngs_modulus = params["E_b"]
        if "sigma_c" in params:
            law.sigma_c = params["sigma_c"]
            if "tau_c" not in params:
                law.tau_c = params["sigma_c"]
        if "tau_c" in params:
            law.tau_c = params["tau_c"]
        if "r_b" in params:
            law.radius = params["r_b"]
        law.to_core()
    return RunSpec(preset=p, sigma_z=sz, seed=int(seed), bond=law)


# --------------------------------------------------------------------------------------
# The cache
# --------------------------------------------------------------------------------------

class RunCache:
    """Run records on disk, one JSON file per run key: ``<directory>/<key[:2]>/<key>.json``.

    A record holds the run's inputs (``spec``), its scalar outputs (SI), its sigma_1(dL/D) and
    compaction curves (a few hundred points), whether it succeeded, and its wall time (s).
    Writes are atomic (temporary file, then rename), so a killed scan leaves whole files; an
    unreadable file is treated as missing (and rewritten). ``directory=None``: memory only.
    """

    def __init__(self, directory: Optional[Union[str, os.PathLike]] = None):
        self.directory = None if directory is None else os.fspath(directory)
        self._memory: Dict[str, dict] = {}
        self._lock = threading.Lock()
        if self.directory is not None:
            os.makedirs(self.directory, exist_ok=True)

    def path(self, key: str) -> Optional[str]:
        """File of `key` (None for a memory-only cache)."""
        if self.directory is None:
            return None
        return os.path.join(self.directory, key[:2], key + ".json")

    def get(self, key: str) -> Optional[dict]:
        """The record of `key`, or None."""
        with self._lock:
            if key in self._memory:
                return self._memory[key]
        path = self.path(key)
        if path is None or not os.path.exists(path):
            return None
        try:
            with open(path) as fh:
                rec = json.load(fh)
            if rec.get("key") != key:
                raise ValueError("key mismatch")
        except (OSError, ValueError) as e:
            warnings.warn(f"{path}: unreadable cache record ({e}); it will be recomputed")
            return None
        with self._lock:
            self._memory[key] = rec
        return rec

    def put(self, record: dict) -> None:
        """Store a record (it must have a 'key')."""
        key = record["key"]
        with self._lock:
            self._memory[key] = record
        path = self.path(key)
        if path is None:
            return
        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".json", dir=os.path.dirname(path))
        try:
            with os.fdopen(fd, "w") as fh:
                json.dump(record, fh, default=jsonable)
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.remove(tmp)
            raise

    def __contains__(self, key: str) -> bool:
        return self.get(key) is not None

    def keys(self) -> List[str]:
        """All keys on disk (and in memory)."""
        keys = set(self._memory)
        if self.directory is not None:
            for sub in os.listdir(self.directory):
                d = os.path.join(self.directory, sub)
                if os.path.isdir(d):
                    keys.update(f[:-5] for f in os.listdir(d) if f.endswith(".json") and not f.startswith("."))
        return sorted(keys)

    def __len__(self) -> int:
        return len(self.keys())


# --------------------------------------------------------------------------------------
# Running one point (in a worker)
# --------------------------------------------------------------------------------------

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


def _relaxed_path(relaxed_dir, key: str) -> str:
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
        warnings.warn(f"relaxed pellet {path} not usable ({e}); relaxing again")
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
        warnings.warn(f"could not save the relaxed pellet to {path}: {e}")


def _relaxed(spec: RunSpec, relaxed_dir=None):
    """(pellet, compaction outputs, compaction curve, source) for the spec's relax key; source is
    'memory', 'disk' (a checkpoint in relaxed_dir) or '' (relaxed now)."""
    from . import pipeline

    key = spec.relax_key
    with _key_lock(key):
        with _MEMO_LOCK:
            hit = _MEMO.get(key)
            if hit is not None:
                _MEMO.move_to_end(key)
        if hit is not None:
            return (*hit, "memory")
        source = ""
        got = None
        if relaxed_dir is not None and os.path.exists(_relaxed_path(relaxed_dir, key)):
            got = _load_relaxed(spec, _relaxed_path(relaxed_dir, key))
            source = "disk" if got is not None else ""
        if got is None:
            pellet, res = pipeline.relaxed_pellet(spec.preset, sigma_z=spec.sigma_z, seed=spec.seed,
                                                  threads=1, progress=False)
            outs, curve = _compaction_outputs(res)
            outs = {k: float(v) for k, v in outs.items()}
            if relaxed_dir is not None:
                _save_relaxed(spec, _relaxed_path(relaxed_dir, key), pellet, outs, curve)
            got = (pellet, outs, curve)
        with _MEMO_LOCK:
            _MEMO[key] = got
            while len(_MEMO) > max(RELAX_MEMO_SIZE, 1):
                _MEMO.popitem(last=False)
        return (*got, source)


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
    ``sigma_f_max`` / ``dLf_D_max`` the curve's global maximum, bond counts), ``curve`` ({dL_D, sigma_1 (Pa)}), ``compaction_curve``,
    ``relaxed_reused`` (False when this run relaxed the pellet), ``relaxed_from`` ('memory',
    'disk' or ''), ``wall_time_s`` (s), ``worker``.
    """
    from . import pipeline

    t0 = time.perf_counter()
    rec = {"key": spec.key, "relax_key": spec.relax_key, "spec": _canon(spec.payload()),
           "ok": False, "error": None, "outputs": {}, "curve": {}, "compaction_curve": {},
           "relaxed_reused": False, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    try:
        pellet, outs, ccurve, source = _relaxed(spec, relaxed_dir)
        rec["relaxed_reused"] = bool(source)
        rec["relaxed_from"] = source
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


# --------------------------------------------------------------------------------------
# Executors and the evaluator (the driver side)
# --------------------------------------------------------------------------------------

class _SerialExecutor(cf.Executor):
    """Runs each call at submit, in the calling thread, one at a time."""

    _lock = threading.Lock()

    def submit(self, fn, *args, **kwargs):
        fut = cf.Future()
        with self._lock:
            try:
                fut.set_result(fn(*args, **kwargs))
            except BaseException as e:  # noqa: BLE001 (handed to the future)
                fut.set_exception(e)
        return fut


def _is_dask_client(obj) -> bool:
    return type(obj).__module__.startswith("distributed") and hasattr(obj, "get_executor")


class _RespawningPool(cf.Executor):
    """A process pool that survives its workers: when one dies the pool is broken (every
    pending future fails with BrokenProcessPool and submit refuses), so the next submit gets a
    fresh pool of the same size. ``submit_isolated`` runs a call alone in a one-worker pool of
    its own (at most ``max_workers`` at a time): a retried point that kills its worker again
    then takes no other point down with it."""

    def __init__(self, pool: cf.ProcessPoolExecutor, own: bool):
        self._pool, self._own = pool, own
        self._max_workers = getattr(pool, "_max_workers", None) or os.cpu_count() or 1
        self._mp_context = getattr(pool, "_mp_context", None) or multiprocessing.get_context("spawn")
        self._lock = threading.Lock()
        self._made: List[cf.ProcessPoolExecutor] = []  # replacement pools, shut down with us
        self._queue: List[tuple] = []
        self._running = 0
        self._isolated: set = set()

    def submit(self, fn, *args, **kwargs):
        with self._lock:
            pool = self._pool
        try:
            return pool.submit(fn, *args, **kwargs)
        except cf.BrokenExecutor:
            with self._lock:
                if self._pool is pool:
                    self._pool = cf.ProcessPoolExecutor(max_workers=self._max_workers, mp_context=self._mp_context)
                    self._made.append(self._pool)
                pool = self._pool
            return pool.submit(fn, *args, **kwargs)

    def submit_isolated(self, fn, *args) -> cf.Future:
        out = cf.Future()
        with self._lock:
            self._queue.append((fn, args, out))
        self._pump()
        return out

    def _pump(self) -> None:
        while True:
            with self._lock:
                if not self._queue or self._running >= self._max_workers:
                    return
                fn, args, out = self._queue.pop(0)
                self._running += 1
                pool = cf.ProcessPoolExecutor(max_workers=1, mp_context=self._mp_context)
                self._isolated.add(pool)
            try:
                inner = pool.submit(fn, *args)
            except BaseException as e:  # noqa: BLE001 (handed to the future)
                self._isolated_done(None, pool, out, e)
                continue
            inner.add_done_callback(lambda f, pool=pool, out=out: self._isolated_done(f, pool, out))

    def _isolated_done(self, f, pool, out: cf.Future, error=None) -> None:
        # Called in the pool's own manager thread: shut it down without waiting for itself.
        pool.shutdown(wait=False)
        with self._lock:
            self._running -= 1
            self._isolated.discard(pool)
        try:
            if error is None:
                error = f.exception()
            if error is None:
                out.set_result(f.result())
            else:
                out.set_exception(error)
        except cf.InvalidStateError:  # cancelled meanwhile
            pass
        self._pump()

    def shutdown(self, wait=True, *, cancel_futures=False):
        with self._lock:
            pools = list(self._made) + list(self._isolated) + ([self._pool] if self._own else [])
            for _, _, out in self._queue:
                out.cancel()
            self._queue.clear()
        for pool in pools:
            pool.shutdown(wait=wait, cancel_futures=cancel_futures)


@contextlib.contextmanager
def _open_executor(executor, max_workers: Optional[int]):
    if executor is None:
        n = max_workers or os.cpu_count() or 1
        if not isinstance(n, int) or n < 1:
            raise ValueError(f"max_workers = {max_workers!r} must be an integer >= 1")
        ex = _RespawningPool(cf.ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn")),
                             own=True)
        try:
            yield ex
        finally:
            ex.shutdown(wait=True, cancel_futures=True)
    elif isinstance(executor, cf.ProcessPoolExecutor):
        # The caller's pool, kept alive by us only until it breaks; our replacements are ours.
        ex = _RespawningPool(executor, own=False)
        try:
            yield ex
        finally:
            ex.shutdown(wait=True)
    elif isinstance(executor, str):
        if executor != "serial":
            raise ValueError(f"executor = {executor!r}: pass 'serial', None (a process pool), a "
                             "concurrent.futures.Executor or a distributed.Client")
        yield _SerialExecutor()
    elif _is_dask_client(executor):
        yield executor.get_executor(pure=False)
    elif hasattr(executor, "submit"):
        yield executor
    else:
        raise ValueError(f"executor = {executor!r} has no submit(); pass a concurrent.futures.Executor "
                         "or a distributed.Client")


def _with_relaxed_dir(runner, relaxed_dir):
    """run_point bound to relaxed_dir (a picklable partial); other runners unchanged."""
    if relaxed_dir is None or runner is not run_point:
        return runner
    import functools

    os.makedirs(os.fspath(relaxed_dir), exist_ok=True)
    return functools.partial(run_point, relaxed_dir=os.path.abspath(os.fspath(relaxed_dir)))


class _Evaluator:
    """Submits runs, serves cached ones, never runs a key twice, writes the cache.

    A run whose future raises (its worker process died: BrokenProcessPool; or the runner
    raised) is retried once, alone in a fresh worker when the executor is a process pool; if
    the retry fails too the point gets a failed record (``ok`` False, ``error`` with both
    errors, ``worker_failure`` True) that is not cached, so a resumed scan tries it again, and
    the rest of the scan goes on. KeyboardInterrupt and SystemExit are not retried."""

    RETRIES = 1

    def __init__(self, cache: RunCache, executor, runner: Callable[[RunSpec], dict]):
        self.cache, self.executor, self.runner = cache, executor, runner
        self._lock = threading.Lock()
        self._inflight: Dict[str, cf.Future] = {}
        self.n_run = 0          # runs executed now
        self.n_cached = 0       # runs served from the cache
        self.n_relaxations = 0  # relaxations done by the runs executed now
        self.sim_time_s = 0.0
        self.n_retried = 0      # runs submitted again after their first attempt failed
        self.failures: List[dict] = []  # points that failed every attempt: key, error, attempts

    def submit(self, spec: RunSpec, rerun: bool = False) -> cf.Future:
        """The run's record as a future: from the cache, or run now (``rerun``: run even when
        cached, e.g. to recreate a relaxed pellet whose checkpoint is gone; deterministic, so
        the record comes out the same)."""
        key = spec.key
        with self._lock:
            if key in self._inflight:
                return self._inflight[key]
            rec = None if rerun else self.cache.get(key)
            out = cf.Future()
            if rec is not None:
                self.n_cached += 1
                rec = dict(rec, cached=True)
                out.set_result(rec)
                self._inflight[key] = out
                return out
            self._inflight[key] = out
            self.n_run += 1
        try:
            fut = self.executor.submit(self.runner, spec)
        except BaseException as e:
            with self._lock:
                self._inflight.pop(key, None)
                self.n_run -= 1
            out.set_exception(e)
            return out
        fut.add_done_callback(lambda f: self._done(spec, f, out, []))
        return out

    def _done(self, spec: RunSpec, fut, out: cf.Future, errors: List[str]) -> None:
        key = spec.key
        try:
            rec = fut.result()
        except BaseException as e:  # noqa: BLE001
            retry = isinstance(e, Exception) and not isinstance(e, cf.CancelledError) and not out.cancelled()
            if retry:
                errors = errors + [f"{type(e).__name__}: {e}"]
                if len(errors) <= self.RETRIES:
                    self._retry(spec, out, errors)
                    return
                rec = self._failed_record(spec, errors)
                with self._lock:
                    self._inflight.pop(key, None)
                    self.failures.append({"key": key, "error": rec["error"], "attempts": len(errors)})
                _set(out, result=rec)
                return
            with self._lock:
                self._inflight.pop(key, None)
            _set(out, error=e)
            return
        try:
            self.cache.put(rec)
        except Exception as e:  # noqa: BLE001 (a full disk must not lose the result)
            warnings.warn(f"could not write cache record {key}: {e}")
        with self._lock:
            self.n_relaxations += 0 if rec.get("relaxed_reused") else 1
            self.sim_time_s += float(rec.get("wall_time_s", 0.0))
        _set(out, result=dict(rec, cached=False, attempts=len(errors) + 1))

    def _retry(self, spec: RunSpec, out: cf.Future, errors: List[str]) -> None:
        with self._lock:
            self.n_retried += 1
        try:
            isolated = getattr(self.executor, "submit_isolated", None)
            fut = isolated(self.runner, spec) if isolated else self.executor.submit(self.runner, spec)
        except Exception as e:  # noqa: BLE001 (an executor that refuses counts as a failed attempt)
            fut = cf.Future()
            fut.set_exception(e)
        fut.add_done_callback(lambda f: self._done(spec, f, out, errors))

    @staticmethod
    def _failed_record(spec: RunSpec, errors: List[str]) -> dict:
        return {"key": spec.key, "relax_key": spec.relax_key, "spec": _canon(spec.payload()), "ok": False,
                "error": f"failed {len(errors)} times, " + "; then ".join(errors),
                "outputs": {}, "curve": {}, "compaction_curve": {}, "relaxed_reused": True,
                "relaxed_from": "", "wall_time_s": 0.0, "worker": "", "cached": False,
                "attempts": len(errors), "worker_failure": True}

    def run_all(self, specs: Sequence[RunSpec]) -> List[dict]:
        """Records of all specs (submitted grouped by relax key), in the order given."""
        order = sorted(range(len(specs)), key=lambda i: (specs[i].relax_key, i))
        futs = {i: self.submit(specs[i]) for i in order}
        try:
            return [futs[i].result() for i in range(len(specs))]
        except BaseException:
            for f in futs.values():
                f.cancel()
            raise

    def stats(self) -> dict:
        return {"n_simulations": self.n_run, "n_cached": self.n_cached,
                "n_relaxations": self.n_relaxations, "simulation_time_s": self.sim_time_s,
                "n_retried": self.n_retried, "n_failed": len(self.failures),
                "failures": list(self.failures)}


def _set(fut: cf.Future, result=None, error=None) -> None:
    # A future cancelled by run_all (another point raised) takes no result.
    try:
        if error is not None:
            fut.set_exception(error)
        else:
            fut.set_result(result)
    except cf.InvalidStateError:
        pass


# --------------------------------------------------------------------------------------
# Targets and objectives
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Targets:
    """What one simulated pellet is scored against (SI units).

    ``sigma_z``: compaction pressure of the pellet, Pa. ``sigma_f`` / ``sigma_f_sd``: tensile
    strength, Pa; ``dLf_D`` / ``dLf_D_sd``: deformation at failure, -; ``curve``: a measured
    diametral ``measured.Curve`` or an ``(x, y)`` pair (dL/D, sigma_1 in Pa) for eq. 16;
    ``bulk_density`` / ``bulk_density_sd``: kg/m^3 of the pellet ``density_state`` 'relaxed'
    (Table 2's pellets) or 'max' (at the end of compaction). Leave out what is not measured.
    """

    sigma_z: float
    sigma_f: Optional[float] = None
    sigma_f_sd: float = 0.0
    dLf_D: Optional[float] = None
    dLf_D_sd: float = 0.0
    bulk_density: Optional[float] = None
    bulk_density_sd: float = 0.0
    density_state: str = "relaxed"
    curve: Any = None
    label: str = ""

    def __post_init__(self):
        _check_finite_positive("sigma_z", self.sigma_z, "Pa")
        for name in ("sigma_f", "dLf_D", "bulk_density"):
            v = getattr(self, name)
            if v is not None:
                _check_finite_positive(name, v, "target")
            sd = getattr(self, name + "_sd")
            try:
                ok = math.isfinite(float(sd)) and float(sd) >= 0
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(f"{name}_sd = {sd!r} must be finite and >= 0")
        if self.density_state not in ("relaxed", "max"):
            raise ValueError(f"density_state = {self.density_state!r}: allowed 'relaxed', 'max'")
        if not (self.diametral or self.bulk_density is not None):
            raise ValueError("a Targets needs sigma_f, dLf_D, a curve or bulk_density")

    @property
    def diametral(self) -> bool:
        """True when a diametral test is needed to score against this target."""
        return self.sigma_f is not None or self.dLf_D is not None or self.curve is not None

    @classmethod
    def from_variant(cls, v, *, diametral: bool = True, density: bool = False, curve=None) -> "Targets":
        """Targets of one of the paper's variants (a ``measured.Variant`` or its key
        (material, mc %, sigma_z MPa)): Table 3's sigma_f and dL_f/D if ``diametral``, Table 2's
        relaxed pellet bulk density if ``density``, and an optional measured ``curve``."""
        from .measured import Variant, variant

        if not isinstance(v, Variant):
            v = variant(*v)
        kw = {}
        if diametral:
            kw.update(sigma_f=v.sigma_f, sigma_f_sd=v.sigma_f_sd, dLf_D=v.dLf_D, dLf_D_sd=v.dLf_D_sd)
        if density:
            kw.update(bulk_density=v.bd_pellet, bulk_density_sd=v.bd_pellet_sd)
        return cls(sigma_z=v.sigma_z, curve=curve, label=v.label, **kw)


def diametral_error(sigma_f: float, dLf_D: float, target: Targets) -> dict:
    """z-scores of a simulated tensile strength ``sigma_f`` (Pa) and deformation at failure
    ``dLf_D`` (-) against the target's mean and SD (SD floored at 1% of the mean, see
    metrics.sd_weighted_error): {'z_sigma_f', 'z_dLf_D'} for the targets given (-)."""
    from .metrics import sd_weighted_error

    out = {}
    for name, sim in (("sigma_f", sigma_f), ("dLf_D", dLf_D)):
        mean = getattr(target, name)
        if mean is not None:
            out["z_" + name] = float(sd_weighted_error(mean, getattr(target, name + "_sd"), sim).z[0])
    return out


def curve_error(dL_D, sigma_1, target: Targets) -> float:
    """RRMSE (eq. 16, -) of a simulated sigma_1(dL/D) curve (dL_D -, sigma_1 Pa) against the
    target's measured curve: the replicates' mean curve for a ``measured.Curve``, the points
    for an (x, y) pair. NaN when the target has no curve."""
    from .metrics import rrmse_curve, rrmse_replicates

    if target.curve is None:
        return float("nan")
    x, y = np.asarray(dL_D, float), np.asarray(sigma_1, float)
    if hasattr(target.curve, "per_replicate"):
        return float(rrmse_replicates(target.curve, x, y).mean_curve)
    mx, my = target.curve
    return float(rrmse_curve(mx, my, x, y))


def density_error(bulk_density: float, target: Targets) -> float:
    """z-score (-) of a simulated bulk density (kg/m^3) against the target's (Table 2), SD
    floored at 1% of the mean. NaN when the target has no density."""
    from .metrics import sd_weighted_error

    if target.bulk_density is None:
        return float("nan")
    return float(sd_weighted_error(target.bulk_density, target.bulk_density_sd, bulk_density).z[0])


def score(outputs: Mapping[str, float], target: Targets, curve: Optional[Mapping] = None) -> dict:
    """All errors of one simulated pellet against ``target``.

    ``outputs``: a run record's outputs (sigma_f Pa, dLf_D, bulk_density_relaxed /
    bulk_density_max kg/m^3); ``curve``: its {dL_D, sigma_1 (Pa)}. Returns z-scores
    (z_sigma_f, z_dLf_D, z_bulk_density, -), their root mean square ``rms_z`` and ``rrmse``
    (eq. 16, NaN without a measured curve).
    """
    out = {}
    if target.diametral and "sigma_f" in outputs:
        out.update(diametral_error(outputs["sigma_f"], outputs["dLf_D"], target))
    if target.bulk_density is not None:
        out["z_bulk_density"] = density_error(outputs["bulk_density_" + target.density_state], target)
    zs = [v for k, v in out.items() if k.startswith("z_")]
    out["rms_z"] = float(math.sqrt(np.mean(np.square(zs)))) if zs else float("nan")
    out["rrmse"] = float("nan")
    if target.curve is not None and curve:
        try:
            out["rrmse"] = curve_error(curve["dL_D"], curve["sigma_1"], target)
        except ValueError:  # too little overlap with the measured curve
            out["rrmse"] = float("inf")
    return out


def compaction_targets(variants=None, state: str = "relaxed") -> List[Targets]:
    """One bulk-density target per compaction pressure, shared by all materials (Table 2).

    For each pressure of ``variants`` (default the 12): the mean of the variants' pellet bulk
    densities (kg/m^3), and as SD sqrt(mean within-variant SD^2 + SD between the variants'
    means^2): one contact law for all woods cannot do better than the spread between them.
    """
    from .measured import variants as all_variants

    vs = _variants(variants) if variants is not None else all_variants()
    out = []
    for sz in sorted({v.sigma_z for v in vs}):
        group = [v for v in vs if v.sigma_z == sz]
        means = np.array([v.bd_pellet for v in group])
        sds = np.array([v.bd_pellet_sd for v in group])
        between = float(np.std(means, ddof=1)) if len(means) > 1 else 0.0
        sd = float(math.sqrt(np.mean(sds**2) + between**2))
        out.append(Targets(sigma_z=sz, bulk_density=float(means.mean()), bulk_density_sd=sd,
                           density_state=state, label=f"BD at {sz / _MPA:g} MPa (mean of {len(group)})"))
    return out


def _variants(variants) -> list:
    from .measured import Variant, variant
    from .measured import variants as all_variants

    if variants is None:
        return all_variants()
    out = []
    for v in variants:
        out.append(v if isinstance(v, Variant) else variant(*v))
    if not out:
        raise ValueError("variants is empty")
    return out


# --------------------------------------------------------------------------------------
# Problems: parameter point -> runs -> residuals
# --------------------------------------------------------------------------------------

def _as_targets(targets, sigma_z: Optional[float] = None) -> List[Targets]:
    if targets is None:
        return []
    if isinstance(targets, Targets):
        return [targets]
    out = list(targets)
    for t in out:
        if not isinstance(t, Targets):
            raise ValueError(f"targets must be Targets objects; got {type(t).__name__}")
    if not out:
        raise ValueError("targets is empty")
    return out


@dataclass
class _Setup:
    preset: Preset
    bond: Optional[BondLaw]
    contact: Optional[Mapping]
    seeds: Tuple[int, ...]
    max_dLD: Optional[float]

    def spec(self, params: Mapping[str, float], sigma_z: float, seed: int, diametral: bool) -> RunSpec:
        return make_spec(params, preset=self.preset, sigma_z=sigma_z, seed=seed, bond=self.bond,
                         diametral=diametral, contact=self.contact, max_dLD=self.max_dLD)


def _setup(preset, bond, contact, seeds, max_dLD) -> _Setup:
    if isinstance(seeds, (int, np.integer)):
        seeds = (int(seeds),)
    seeds = tuple(seeds)
    if not seeds or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in seeds):
        raise ValueError(f"seeds = {seeds!r} must be integers >= 0")
    if bond is not None and not isinstance(bond, BondLaw):
        raise ValueError(f"bond must be a BondLaw; got {type(bond).__name__}")
    return _Setup(_as_preset(preset), bond, contact, seeds, max_dLD)


def _mean_outputs(records: Sequence[dict]) -> Tuple[dict, dict, bool, str]:
    """Outputs averaged over seeds (and the first record's curve)."""
    bad = [r for r in records if not r["ok"]]
    if bad:
        return {}, {}, False, bad[0]["error"] or "failed"
    keys = set.intersection(*(set(r["outputs"]) for r in records))
    outs = {k: float(np.mean([r["outputs"][k] for r in records])) for k in keys}
    return outs, records[0].get("curve") or {}, True, ""


#: A diametral test that ended before its peak is scored as if the peak came this many times
#: later than the end of the test (its dL_f/D is a lower bound; see the module docstring).
CENSORED_DLF_FACTOR = 1.5


def _effective_outputs(outs: Mapping[str, float]) -> dict:
    """Outputs as scored: dLf_D of a test that ended before its peak (peaked < 1) is taken as
    CENSORED_DLF_FACTOR x the end of the test; the raw value stays under 'dLf_D_end'."""
    out = dict(outs)
    if "dLf_D" in out and out.get("peaked", 1.0) < 1.0:
        out["dLf_D_end"] = out["dLf_D"]
        out["dLf_D"] = out["dLf_D"] * CENSORED_DLF_FACTOR
    return out


@dataclass
class _Point:
    params: dict
    records: List[dict]
    scores: List[dict]
    outputs: List[dict]
    ok: bool
    error: str
    loss: float
    rms_z: float
    rrmse: float
    residual: np.ndarray   # weighted log-ratios, ~z
    weight: np.ndarray
    names: List[str]
    slopes: np.ndarray     # d ln BD / d ln sigma_z of the loading curve, per residual
    censored: np.ndarray   # residuals that are bounds (diametral test ended before the peak)


class _Problem:
    """Parameter point -> the runs its targets need (x seeds) -> scores and residuals."""

    def __init__(self, names, targets: List[Targets], setup: _Setup, criterion: str, fixed=None):
        self.names = list(names)
        self.targets = targets
        self.setup = setup
        self.fixed = dict(fixed or {})
        if criterion == "auto":
            diam = [t for t in targets if t.diametral]
            criterion = "rrmse" if diam and all(t.curve is not None for t in diam) else "z"
        if criterion not in ("z", "rrmse"):
            raise ValueError(f"criterion = {criterion!r}: allowed 'auto', 'z', 'rrmse'")
        self.criterion = criterion

    def specs(self, params: Mapping[str, float]) -> List[List[RunSpec]]:
        p = {**self.fixed, **params}
        return [[self.setup.spec(p, t.sigma_z, s, t.diametral) for s in self.setup.seeds] for t in self.targets]

    def evaluate(self, params: Mapping[str, float], ev: _Evaluator) -> _Point:
        groups = self.specs(params)
        futs = [[ev.submit(s) for s in g] for g in groups]
        recs = [[f.result() for f in g] for g in futs]
        scores, outputs, res, wts, names, slopes, censored = [], [], [], [], [], [], []
        ok, err = True, ""
        for t, rs in zip(self.targets, recs):
            outs, curve, good, e = _mean_outputs(rs)
            outputs.append(outs)
            if not good:
                ok, err = False, e
                scores.append({})
                continue
            outs = _effective_outputs(outs)
            sc = score(outs, t, curve)
            scores.append(sc)
            for name, out_name in (("sigma_f", "sigma_f"), ("dLf_D", "dLf_D"),
                                   ("bulk_density", "bulk_density_" + t.density_state)):
                mean = getattr(t, name)
                if mean is None:
                    continue
                # the SD of metrics.sd_weighted_error (floored at 1% of the mean), so that
                # w * ln(sim / mean) ~ z for small errors
                w = mean / max(getattr(t, name + "_sd"), DEFAULT_REL_SD_FLOOR * mean)
                res.append(w * math.log(max(outs[out_name], 1e-300) / mean))
                wts.append(w)
                names.append(name)
                slopes.append(outs.get("dlnbd_dlnsigma", float("nan")))
                # a diametral test that ended before sigma_1 fell past its peak gives lower
                # bounds of sigma_f and dL_f/D, not values
                censored.append(name != "bulk_density" and outs.get("peaked", 1.0) < 1.0)
        if ok:
            zs = [v for s in scores for k, v in s.items() if k.startswith("z_")]
            rms_z = float(math.sqrt(np.mean(np.square(zs)))) if zs else float("nan")
            rr = [s["rrmse"] for s in scores if not math.isnan(s.get("rrmse", float("nan")))]
            rrmse = float(np.mean(rr)) if rr else float("nan")
            loss = rrmse if self.criterion == "rrmse" else rms_z
        else:
            rms_z = rrmse = loss = float("inf")
        return _Point(dict(params), [r for rs in recs for r in rs], scores, outputs, ok, err, loss,
                      rms_z, rrmse, np.asarray(res), np.asarray(wts), names, np.asarray(slopes),
                      np.asarray(censored, dtype=bool))

    def prior_jacobian(self, point: _Point) -> np.ndarray:
        """d ln(output) / d ln(param) from SCALING_EXPONENTS; NaN where no law applies."""
        J = np.full((len(point.names), len(self.names)), np.nan)
        slopes = point.slopes
        for i, out in enumerate(point.names):
            law = SCALING_EXPONENTS.get(out, {})
            for j, p in enumerate(self.names):
                if p not in law:
                    continue
                e = law[p]
                if e is None:  # compaction: BD depends on sigma_z / k1
                    s = slopes[i]
                    e = s if p == "sigma_z" else -s
                J[i, j] = e
        # diametral outputs do not depend on k1 / p_y / sigma_z by any law we know; bulk
        # density does not depend on bond parameters at all (exactly 0: bonds come later).
        for i, out in enumerate(point.names):
            for j, p in enumerate(self.names):
                if out == "bulk_density" and p in ("E_b", "sigma_c", "tau_c", "r_b"):
                    J[i, j] = 0.0
        return J


# --------------------------------------------------------------------------------------
# Bounds
# --------------------------------------------------------------------------------------

def _parse_bounds(params: Mapping[str, Sequence[float]], start: Optional[Mapping[str, float]] = None):
    """names, log-lo, log-hi, log-start from {name: (lo, hi) or (lo, hi, start)}."""
    if not isinstance(params, Mapping) or not params:
        raise ValueError("params must be a non-empty mapping {name: (lo, hi)} or {name: (lo, hi, start)}")
    _check_names(params, PARAMETERS)
    if start is not None:
        _check_names(start, params, "start parameter (not among the fitted ones)")
    names, lo, hi, x0 = [], [], [], []
    for name, b in params.items():
        unit = PARAMETERS[name][0]
        try:
            vals = [float(v) for v in b]
        except (TypeError, ValueError):
            raise ValueError(f"bounds of {name!r} must be (lo, hi) or (lo, hi, start) numbers in {unit}; "
                             f"got {b!r}") from None
        if len(vals) not in (2, 3):
            raise ValueError(f"bounds of {name!r} must be (lo, hi) or (lo, hi, start); got {b!r}")
        if any(not math.isfinite(v) for v in vals):
            raise ValueError(f"bounds of {name!r} = {b!r} must be finite (no NaN or inf)")
        if vals[0] <= 0:
            raise ValueError(f"lower bound of {name!r} = {vals[0]!r} {unit} must be > 0 (the search is in log space)")
        if not vals[0] < vals[1]:
            raise ValueError(f"bounds of {name!r} are reversed or empty: lo = {vals[0]!r} >= hi = {vals[1]!r} {unit}")
        s = vals[2] if len(vals) == 3 else None
        if start is not None and name in start:
            s = start[name]
        if s is None:
            s = math.sqrt(vals[0] * vals[1])
        try:
            s = float(s)
        except (TypeError, ValueError):
            raise ValueError(f"start of {name!r} = {s!r} must be a number") from None
        if not math.isfinite(s) or not vals[0] <= s <= vals[1]:
            raise ValueError(f"start of {name!r} = {s!r} {unit} is outside its bounds [{vals[0]!r}, {vals[1]!r}]")
        names.append(name)
        lo.append(math.log(vals[0]))
        hi.append(math.log(vals[1]))
        x0.append(math.log(s))
    return names, np.array(lo), np.array(hi), np.array(x0)


# --------------------------------------------------------------------------------------
# Scan
# --------------------------------------------------------------------------------------

@dataclass
class ScanResult:
    """A finished scan.

    ``runs``: one row per run (parameters in SI, seed, sigma_z Pa, target label, outputs,
    errors, ok, error, cached, key). ``points``: one row per parameter point (outputs averaged
    over seeds, ``rms_z``, ``rrmse``, ``loss`` over all targets). ``best``: the parameters of
    the lowest loss (empty without targets). ``n_simulations``: runs executed now;
    ``n_cached``: runs read from the cache; ``n_relaxations``: relaxed pellets computed now;
    ``wall_time_s``: s. ``n_retried``: runs tried again after a failed attempt (a worker
    died or the runner raised); ``failures``: the runs that failed again ({key, error,
    attempts}; their rows in ``runs`` have ok False and the error text), ``n_failed`` of them.
    """

    runs: Any
    points: Any
    best: dict
    n_simulations: int
    n_cached: int
    n_relaxations: int
    wall_time_s: float
    n_retried: int = 0
    n_failed: int = 0
    failures: list = field(default_factory=list)


def _grid(param_grid: Mapping[str, Sequence[float]]) -> Tuple[List[str], List[dict]]:
    if not isinstance(param_grid, Mapping) or not param_grid:
        raise ValueError("param_grid must be a non-empty mapping {name: [values]}")
    _check_names(param_grid, {**PARAMETERS, **_SCAN_ONLY})
    names = list(param_grid)
    axes = []
    for n in names:
        vals = param_grid[n]
        vals = [vals] if np.ndim(vals) == 0 else list(vals)
        if not vals:
            raise ValueError(f"param_grid[{n!r}] is empty")
        for v in vals:
            try:
                f = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"param_grid[{n!r}] holds {v!r}, not a number") from None
            if not math.isfinite(f) or (f <= 0 and n != "seed") or (n == "seed" and f < 0):
                raise ValueError(f"param_grid[{n!r}] holds {v!r}: values must be finite and > 0")
        axes.append(vals)
    return names, [dict(zip(names, combo)) for combo in itertools.product(*axes)]


def scan(param_grid: Mapping[str, Sequence[float]], targets=None, *, preset="tiny",
         sigma_z: float = 120e6, seeds=(0,), bond: Optional[BondLaw] = None,
         contact: Optional[Mapping[str, Any]] = None, max_dLD: Optional[float] = None,
         diametral: bool = True, criterion: str = "auto",
         cache_dir: Optional[Union[str, os.PathLike]] = None, executor=None,
         max_workers: Optional[int] = None, runner: Callable[[RunSpec], dict] = run_point,
         relaxed_dir: Optional[Union[str, os.PathLike]] = None) -> ScanResult:
    """Run every combination of ``param_grid`` ({name: values}, SI, names from
    :data:`PARAMETERS` plus 'seed') and score it against ``targets``.

    ``targets``: a :class:`Targets`, a list of them (each at its own sigma_z), or None to only
    run at ``sigma_z`` (Pa; a compaction-only run when ``diametral`` is False). ``seeds``: the
    packing seeds each point is run with (outputs averaged). ``preset``, ``bond`` (base
    BondLaw), ``contact`` (ContactLaw overrides), ``max_dLD``: see :func:`make_spec`.
    ``cache_dir``: where run records live (resume by pointing at it again; None: memory only).
    ``executor``: None (a spawn ProcessPoolExecutor of ``max_workers``), 'serial', a
    concurrent.futures.Executor, or a distributed.Client. ``runner``: the function run per
    RunSpec (default :func:`run_point`; replace it for tests). ``relaxed_dir``: a directory all
    workers can reach where relaxed pellets are kept as checkpoints, so a worker (or a later
    session) that lacks one in memory loads it instead of compacting again (None: memory
    only). Returns :class:`ScanResult`.
    """
    import pandas as pd

    t0 = time.perf_counter()
    names, points = _grid(param_grid)
    tg = _as_targets(targets)
    setup = _setup(preset, bond, contact, seeds, max_dLD)
    if not tg:
        tg = [None]
    cache = RunCache(cache_dir)
    specs, index = [], []
    for pi, p in enumerate(points):
        for ti, t in enumerate(tg):
            sz = t.sigma_z if t is not None else sigma_z
            dia = t.diametral if t is not None else diametral
            seed_list = [p["seed"]] if "seed" in p else setup.seeds
            for s in seed_list:
                specs.append(setup.spec({k: v for k, v in p.items() if k != "seed"}, sz, s, dia))
                index.append((pi, ti, s))
    with _open_executor(executor, max_workers) as ex:
        ev = _Evaluator(cache, ex, _with_relaxed_dir(runner, relaxed_dir))
        records = ev.run_all(specs)
    crit = _Problem([], tg, setup, criterion).criterion if tg[0] is not None else "z"
    rows = []
    for (pi, ti, s), spec, rec in zip(index, specs, records):
        t = tg[ti]
        row = {**points[pi], "seed": s, "sigma_z": spec.sigma_z, "target": t.label if t else "",
               "ok": rec["ok"], "error": rec["error"], "cached": rec.get("cached", False), "key": rec["key"]}
        row.update(rec["outputs"])
        if t is not None and rec["ok"]:
            row.update(score(_effective_outputs(rec["outputs"]), t, rec.get("curve")))
        rows.append(row)
    runs = pd.DataFrame(rows)
    prows = []
    for pi, p in enumerate(points):
        prow = dict(p)
        zs, rr, ok = [], [], True
        for ti, t in enumerate(tg):
            recs = [records[k] for k, (a, b, _) in enumerate(index) if a == pi and b == ti]
            outs, curve, good, err = _mean_outputs(recs)
            ok &= good
            suffix = "" if len(tg) == 1 else f"@{(t.sigma_z if t else sigma_z) / _MPA:g}MPa#{ti}"
            for k in ("sigma_f", "dLf_D", "peaked", "bulk_density_relaxed", "bulk_density_max",
                      "coordination_number_relaxed", "coordination_number_relaxed_bulk"):
                if k in outs:
                    prow[k + suffix] = outs[k]
            if t is not None and good:
                sc = score(_effective_outputs(outs), t, curve)
                for k, v in sc.items():
                    prow[k + suffix] = v
                zs += [v for k, v in sc.items() if k.startswith("z_")]
                if not math.isnan(sc["rrmse"]):
                    rr.append(sc["rrmse"])
        prow["ok"] = ok
        if tg[0] is not None:
            prow["rms_z"] = float(math.sqrt(np.mean(np.square(zs)))) if ok and zs else float("inf")
            prow["rrmse"] = float(np.mean(rr)) if ok and rr else (float("nan") if ok else float("inf"))
            prow["loss"] = prow["rrmse"] if crit == "rrmse" else prow["rms_z"]
        prows.append(prow)
    pts = pd.DataFrame(prows)
    best = {}
    if tg[0] is not None and len(pts) and np.isfinite(pts["loss"]).any():
        b = pts.loc[pts["loss"].idxmin()]
        best = {n: float(b[n]) for n in names}
    st = ev.stats()
    return ScanResult(runs=runs, points=pts, best=best, n_simulations=st["n_simulations"],
                      n_cached=st["n_cached"], n_relaxations=st["n_relaxations"],
                      wall_time_s=time.perf_counter() - t0, n_retried=st["n_retried"],
                      n_failed=st["n_failed"], failures=st["failures"])


# --------------------------------------------------------------------------------------
# Fit
# --------------------------------------------------------------------------------------

@dataclass
class FitResult:
    """A finished fit.

    ``params``: best parameters (SI). ``loss``: its loss (rms z-score, or RRMSE with the
    'rrmse' criterion); ``rms_z``, ``rrmse``: both measures at the best point (-).
    ``outputs``: the simulated outputs at the best point, one dict per target (SI).
    ``scores``: the errors per target. ``history``: one row per parameter point tried
    (parameters, outputs, errors, ok). ``converged``: the loss reached ``tol``;
    ``message``: why the fit stopped. ``n_points``: parameter points evaluated;
    ``n_simulations`` / ``n_cached`` / ``n_relaxations``: runs executed / read from the cache /
    relaxations done; ``wall_time_s``: s. ``method``: 'scaling' or 'nelder-mead'.
    ``n_retried`` / ``n_failed``: runs tried again after a failed attempt / that failed again
    (their points have ok False and the error text in ``history``).
    """

    params: dict
    loss: float
    rms_z: float
    rrmse: float
    outputs: list
    scores: list
    history: Any
    converged: bool
    message: str
    n_points: int
    n_simulations: int
    n_cached: int
    n_relaxations: int
    wall_time_s: float
    method: str
    targets: list = field(default_factory=list)
    n_retried: int = 0
    n_failed: int = 0


def _history_row(names, point: _Point, targets) -> dict:
    row = {n: point.params[n] for n in names}
    for i, (t, outs, sc) in enumerate(zip(targets, point.outputs, point.scores)):
        sfx = "" if len(targets) == 1 else f"#{i}"
        for k in ("sigma_f", "dLf_D", "peaked", "sigma_f_max", "dLf_D_max", "bulk_density_relaxed",
                  "bulk_density_max", "coordination_number_relaxed", "coordination_number_relaxed_bulk"):
            if k in outs:
                row[k + sfx] = outs[k]
        for k, v in sc.items():
            row[k + sfx] = v
    row.update(ok=point.ok, error=point.error, loss=point.loss, rms_z=point.rms_z, rrmse=point.rrmse)
    return row


def _local_model(xs: np.ndarray, ys: np.ndarray, xb: np.ndarray, prior: np.ndarray, ridge: float,
                 width: float, censored: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Affine model y ~ a + J (x - xb) of the log outputs near xb, by weighted least squares
    over the evaluated points (weight exp(-|x - xb|^2 / 2 width^2)) with J pulled towards the
    scaling-law ``prior`` (ridge). Censored values (bounds, not measurements; a boolean array
    shaped like ``ys``) count a thousand times less, so they anchor the model only where
    nothing better is known. Returns (a, J)."""
    n = xs.shape[1]
    dx = xs - xb
    w = np.exp(-np.sum(dx * dx, axis=1) / (2.0 * width * width))
    X = np.hstack([np.ones((len(xs), 1)), dx])           # [intercept, slopes]
    R = np.diag([1e-9] + [ridge] * n)                      # ridge on the slopes only
    a, J = np.zeros(ys.shape[1]), np.zeros((ys.shape[1], n))
    for i in range(ys.shape[1]):
        wi = w if censored is None else w * np.where(censored[:, i], 1e-3, 1.0)
        lhs = X.T @ (wi[:, None] * X) + R
        rhs = X.T @ (wi * ys[:, i]) + R @ np.concatenate([[0.0], prior[i]])
        coef = np.linalg.solve(lhs, rhs)
        a[i], J[i] = coef[0], coef[1:]
    return a, J


def _scaling_search(problem: _Problem, ev: _Evaluator, names, lo, hi, x0, tol, max_runs, max_step,
                    min_step, log: Callable) -> Tuple[List[_Point], str, bool]:
    """Gauss-Newton in log space on a local affine model of the log outputs whose slopes start
    at the scaling-law exponents and are refitted to every run so far (noise-tolerant)."""
    pts: List[_Point] = []
    xs: List[np.ndarray] = []

    def run(x):
        p = problem.evaluate({n: float(math.exp(v)) for n, v in zip(names, x)}, ev)
        pts.append(p)
        xs.append(np.array(x, dtype=float))
        log(p)
        return p

    def logs(p: _Point) -> np.ndarray:  # ln(sim / measured) per residual
        return p.residual / p.weight

    x = np.clip(x0, lo, hi)
    cur = run(x)
    if not cur.ok:
        return pts, f"the start point failed: {cur.error}", False
    if cur.loss <= tol:
        return pts, f"loss {cur.loss:.3g} <= tol {tol} at the start point", True
    prior = problem.prior_jacobian(cur)
    # parameters no scaling law covers: one finite-difference run each
    for j in range(len(names)):
        col = prior[:, j]
        if np.all(np.isfinite(col)) and np.any(col != 0):
            continue
        if len(pts) >= max_runs:
            return pts, "max_runs reached while probing parameters without a scaling law", False
        h = math.log(1.3) if x[j] + math.log(1.3) <= hi[j] else -math.log(1.3)
        xp = x.copy()
        xp[j] += h
        p = run(xp)
        if not p.ok:
            return pts, f"finite-difference run for {names[j]!r} failed: {p.error}", False
        prior[:, j] = (logs(p) - logs(cur)) / h
    prior = np.nan_to_num(prior)
    good = lambda: [k for k, p in enumerate(pts) if p.ok]  # noqa: E731
    ib = min(good(), key=lambda k: pts[k].loss)
    radius = max_step
    while len(pts) < max_runs:
        best, xb = pts[ib], xs[ib]
        if best.loss <= tol:
            return pts, f"loss {best.loss:.3g} <= tol {tol}", True
        g = good()
        a, J = _local_model(np.array([xs[k] for k in g]), np.array([logs(pts[k]) for k in g]), xb, prior,
                            ridge=0.01, width=math.log(2.0),
                            censored=np.array([pts[k].censored for k in g]))
        W = best.weight
        A = W[:, None] * J
        r = W * a  # weighted model residual at xb
        lam = 1e-6 * max(float(np.trace(A.T @ A)), 1e-12)
        try:
            dx = -np.linalg.solve(A.T @ A + lam * np.eye(len(names)), A.T @ r)
        except np.linalg.LinAlgError:
            return pts, "singular Jacobian", False
        dx = dx / max(1.0, float(np.max(np.abs(dx))) / radius)
        xn = np.clip(xb + dx, lo, hi)
        if float(np.max(np.abs(xn - xb))) < min_step:
            at_bound = np.any((np.abs(xn - lo) < 1e-12) | (np.abs(xn - hi) < 1e-12))
            why = "the bounds stop the step" if at_bound else "the model's optimum is within min_step of the best point"
            return pts, f"{why}; best loss {best.loss:.3g}", bool(best.loss <= tol)
        p = run(xn)
        if p.ok and p.loss < best.loss:
            ib = len(pts) - 1
            radius = min(max_step, 1.5 * radius)
        else:
            radius = 0.5 * float(np.max(np.abs(xn - xb)))
            if radius < min_step:
                return pts, (f"no better point within a {100 * (math.exp(min_step) - 1):.0f}% step; "
                             f"best loss {best.loss:.3g}"), bool(best.loss <= tol)
    best = pts[ib]
    ok = best.loss <= tol
    return pts, (f"loss {best.loss:.3g} <= tol {tol}" if ok else f"max_runs = {max_runs} reached"), ok


def _nelder_mead(problem: _Problem, ev: _Evaluator, names, lo, hi, x0, tol, max_runs, log):
    from scipy.optimize import minimize

    pts: List[_Point] = []
    span = hi - lo

    class _Done(Exception):
        pass

    def f(u):
        x = lo + np.clip(u, 0, 1) * span
        p = problem.evaluate({n: float(math.exp(v)) for n, v in zip(names, x)}, ev)
        pts.append(p)
        log(p)
        if p.loss <= tol:
            raise _Done
        return p.loss if math.isfinite(p.loss) else 1e6

    u0 = (x0 - lo) / span
    simplex = [u0]
    for j in range(len(names)):
        u = u0.copy()
        u[j] = u[j] + 0.15 if u[j] + 0.15 <= 1 else u[j] - 0.15
        simplex.append(u)
    try:
        res = minimize(f, u0, method="Nelder-Mead", bounds=[(0, 1)] * len(names),
                       options={"maxfev": max_runs, "initial_simplex": np.array(simplex),
                                "xatol": 0.005, "fatol": 0.01})
        msg = str(res.message)
    except _Done:
        msg = f"loss <= tol {tol}"
    best = min(pts, key=lambda p: p.loss)
    return pts, msg, best.loss <= tol


def fit(params: Mapping[str, Sequence[float]], targets, *, start: Optional[Mapping[str, float]] = None,
        method: str = "scaling", tol: float = 0.5, max_runs: int = 10, max_step: float = 4.0,
        min_step: float = 1.02,
        preset="tiny", seeds=(0,), bond: Optional[BondLaw] = None, fixed: Optional[Mapping[str, float]] = None,
        contact: Optional[Mapping[str, Any]] = None, max_dLD: Optional[float] = None,
        criterion: str = "auto", cache_dir: Optional[Union[str, os.PathLike]] = None, executor="serial",
        max_workers: Optional[int] = None, runner: Callable[[RunSpec], dict] = run_point,
        relaxed_dir: Optional[Union[str, os.PathLike]] = None,
        verbose: bool = False, _evaluator: Optional[_Evaluator] = None) -> FitResult:
    """Fit ``params`` ({name: (lo, hi)} or {name: (lo, hi, start)}, SI, names from
    :data:`PARAMETERS`) so the simulations match ``targets`` (a :class:`Targets` or a list,
    each at its own sigma_z).

    ``method``: 'scaling' (default: log-space Gauss-Newton started from the paper's scaling
    laws, see the module docstring; 3-6 runs for (E_b, sigma_c)) or 'nelder-mead' (scipy, in
    log space scaled to the bounds). ``start``: start values (default the bounds' third entry,
    else their geometric mean). ``tol``: stop when the loss is at most this (rms z-score, -;
    or RRMSE with criterion 'rrmse'). ``max_runs``: most parameter points to evaluate (each is
    one run per target and seed). ``max_step``: the largest factor a parameter changes by in
    one step; ``min_step`` the smallest worth a run (default 1.02: a 400-particle pellet's
    sigma_f scatters by a few % between nearby bond laws). ``fixed``: parameters held at a value (SI). ``seeds``: packing seeds averaged per
    point. ``criterion``: 'z' (rms z of sigma_f, dL_f/D, bulk density), 'rrmse' (eq. 16 on the
    targets' curves; the scaling steps still use the z residuals, the best point is picked by
    RRMSE) or 'auto' (rrmse when every diametral target has a curve). ``executor``: 'serial'
    by default (a fit is sequential; the relaxed pellet stays in this process), or as in
    :func:`scan`, as are ``cache_dir``, ``runner`` and ``relaxed_dir``. Returns
    :class:`FitResult`. Bad names, reversed bounds or NaN raise
    ValueError naming the parameter.
    """
    import pandas as pd

    t0 = time.perf_counter()
    if method not in ("scaling", "nelder-mead"):
        raise ValueError(f"method = {method!r}: allowed 'scaling', 'nelder-mead'")
    names, lo, hi, x0 = _parse_bounds(params, start)
    if fixed:
        _check_names(fixed, PARAMETERS, "fixed parameter")
        for n, v in fixed.items():
            if n in names:
                raise ValueError(f"parameter {n!r} is both fitted and fixed")
            _check_finite_positive(n, v, PARAMETERS[n][0])
    _check_finite_positive("tol", tol, "-")
    _check_finite_positive("max_step", max_step, "-")
    _check_finite_positive("min_step", min_step, "-")
    if not 1 < min_step < max_step:
        raise ValueError(f"min_step = {min_step!r} and max_step = {max_step!r} must be factors with "
                         "1 < min_step < max_step")
    if isinstance(max_runs, bool) or not isinstance(max_runs, (int, np.integer)) or max_runs < 1:
        raise ValueError(f"max_runs = {max_runs!r} must be an integer >= 1")
    tg = _as_targets(targets)
    if not tg:
        raise ValueError("targets is empty: nothing to fit against")
    setup = _setup(preset, bond, contact, seeds, max_dLD)
    problem = _Problem(names, tg, setup, criterion, fixed)
    problem.specs({n: float(math.exp(v)) for n, v in zip(names, x0)})  # validate before running

    def log(p: _Point):
        if verbose:
            ps = ", ".join(f"{n}={p.params[n]:.4g}" for n in names)
            tag = " + ".join(t.label for t in tg if t.label) or "fit"
            print(f"[{tag}] {ps}: loss={p.loss:.3g} rms_z={p.rms_z:.3g}" + ("" if p.ok else f" FAILED {p.error}"),
                  flush=True)

    def go(ev):
        if method == "scaling":
            return _scaling_search(problem, ev, names, lo, hi, x0, tol, max_runs, math.log(max_step),
                                   math.log(min_step), log)
        return _nelder_mead(problem, ev, names, lo, hi, x0, tol, max_runs, log)

    if _evaluator is not None:
        ev = _evaluator
        before = ev.stats()
        pts, msg, conv = go(ev)
    else:
        with _open_executor(executor, max_workers) as ex:
            ev = _Evaluator(RunCache(cache_dir), ex, _with_relaxed_dir(runner, relaxed_dir))
            before = ev.stats()
            pts, msg, conv = go(ev)
    after = ev.stats()
    good = [p for p in pts if p.ok]
    best = min(good, key=lambda p: p.loss) if good else pts[-1]
    hist = pd.DataFrame([_history_row(names, p, tg) for p in pts])
    return FitResult(params=dict(best.params), loss=best.loss, rms_z=best.rms_z, rrmse=best.rrmse,
                     outputs=best.outputs, scores=best.scores, history=hist, converged=bool(conv),
                     message=msg, n_points=len(pts),
                     n_simulations=after["n_simulations"] - before["n_simulations"],
                     n_cached=after["n_cached"] - before["n_cached"],
                     n_relaxations=after["n_relaxations"] - before["n_relaxations"],
                     wall_time_s=time.perf_counter() - t0, method=method, targets=tg,
                     n_retried=after["n_retried"] - before["n_retried"],
                     n_failed=after["n_failed"] - before["n_failed"])


# --------------------------------------------------------------------------------------
# The paper's procedure for the 12 variants
# --------------------------------------------------------------------------------------

@dataclass
class CalibrationReport:
    """What :func:`calibrate_variants` found.

    ``table``: one row per variant (pandas DataFrame): the fitted E_b and sigma_c (MPa) beside
    the paper's Table 5 values, the simulated sigma_f (MPa) and dL_f/D beside Table 3's mean and
    SD with their z-scores, the simulated relaxed bulk density (kg/m^3) beside Table 2's with its
    z-score, the simulated coordination number beside Table 5's, runs used and convergence.
    ``compaction``: the shared k1 / p_y fit (:class:`FitResult`, None if skipped) and
    ``contact``: the contact-law overrides used for the bond fits. ``fits``: label ->
    :class:`FitResult`. ``n_simulations``, ``n_cached``, ``n_relaxations``: runs executed, read
    from the cache, relaxations done; ``wall_time_s``: s.
    """

    table: Any
    compaction: Optional[FitResult]
    contact: dict
    fits: Dict[str, FitResult]
    n_simulations: int
    n_cached: int
    n_relaxations: int
    wall_time_s: float

    def bond_start(self) -> Dict[str, Dict[str, float]]:
        """The fitted bond parameters per variant, {label: {name: value}} (SI units), to start
        another calibration from (``calibrate_variants(start=...)``)."""
        return {label: dict(f.params) for label, f in self.fits.items()}

    def __str__(self) -> str:
        import pandas as pd

        with pd.option_context("display.width", 200, "display.max_columns", 40):
            head = (f"calibration: {self.n_simulations} simulations run, {self.n_cached} from the cache, "
                    f"{self.n_relaxations} relaxations, {self.wall_time_s:.0f} s\n")
            if self.compaction is not None:
                c = self.compaction
                head += (f"compaction fit: {', '.join(f'{k}={v:.4g}' for k, v in c.params.items())}, "
                         f"rms z {c.rms_z:.3g} ({c.message})\n")
            return head + self.table.to_string(float_format=lambda v: f"{v:.4g}")


def calibrate_variants(variants=None, preset="tiny", *,
                       compaction: Optional[Mapping[str, Sequence[float]]] = "default",
                       compaction_state: str = "relaxed",
                       bond_params: Optional[Mapping[str, Sequence[float]]] = None,
                       start="table5", seeds=(0,), tol: float = 0.5, max_runs: int = 8,
                       compaction_max_runs: int = 6, max_dLD: Optional[float] = None,
                       break_drop: float = 0.7, bond: Optional[BondLaw] = None, contact: Optional[Mapping[str, float]] = None,
                       cache_dir: Optional[Union[str, os.PathLike]] = None,
                       executor=None, max_workers: Optional[int] = None,
                       runner: Callable[[RunSpec], dict] = run_point,
                       relaxed_dir: Optional[Union[str, os.PathLike]] = None,
                       verbose: bool = False) -> CalibrationReport:
    """The paper's calibration for ``variants`` (default all 12; Variants or (material, mc %,
    sigma_z MPa) keys) on ``preset``.

    1. Compaction, shared by all materials: fit ``compaction`` ({'k1': (lo, hi)} in N/m or
       {'p_y': (lo, hi)} in Pa; 'default' = k1 within a factor 10 of the preset's; None skips
       it) so the simulated ``compaction_state`` ('relaxed' or 'max') bulk density at each
       pressure matches the mean of Table 2's pellet densities over the variants at that
       pressure (SD: within- and between-variant spread, :func:`compaction_targets`); k2/k1
       stays fixed (e = 0.5). The paper fitted p_y to the compaction curves instead; Table 2 is
       what ships with the package.
    2. Per variant, with that contact law: fit ``bond_params`` (default E_b in [1e5, 1e10] Pa,
       sigma_c in [1e4, 1e10] Pa, tau_c = sigma_c) against Table 3's sigma_f and dL_f/D with
       :func:`fit` (scaling method, ``tol``, ``max_runs`` points), starting from ``start``:
       'table5' (the paper's values, clipped to the bounds) or {label or key: {name: value}}.
       The diametral test runs to ``max_dLD`` (default per variant: 1.5 x (mean + 2 SD) of
       Table 3's dL_f/D, at least the preset's), so the peak is inside it; a run that ends
       before its peak gives bounds, which the fit trusts less than values.
       Each test stops early once the plate force has fallen to ``break_drop`` (0.7) of its
       peak, kept from half the lowest measured dL_f/D (mean - 2 SD) on: the fit reads only
       the failure point (:func:`failure_point`, a 10 % fall), so the rest of the curve would
       cost time for nothing (0, or a preset with its own ``break_drop``, keeps the preset's).
       The 12 fits run concurrently on one executor (default a process pool of
       ``max_workers``). Before them, one compaction-only run per pressure (and seed) relaxes
       each pellet once, in parallel; the fits branch off those pellets (a worker that does
       not hold one loads it from ``relaxed_dir`` when given, else relaxes it itself).

    ``contact``: ContactLaw field overrides used as they are, in place of step 1 (so not with
    a ``compaction`` mapping): e.g. ``report.contact`` of a calibration on a smaller preset of the
    same radii, whose pellets' densities under a pressure should be close to the larger ones'
    (the table's ``bd_sim`` shows how close); pass ``start=report.bond_start()`` as well to
    begin the bond fits where the smaller preset's ended.

    ``seeds``: packing seeds averaged per point. ``cache_dir``, ``executor``, ``max_workers``,
    ``runner``, ``relaxed_dir``: as in :func:`scan`. ``verbose``: print every point.

    Returns :class:`CalibrationReport` (its ``table`` is Table 5 side by side with the fit, and
    the errors against Tables 2 and 3).
    """
    import pandas as pd

    t0 = time.perf_counter()
    vs = _variants(variants)
    p = _as_preset(preset)
    p.with_(break_drop=break_drop)  # checks it (0 <= break_drop < 1) before any work
    if compaction == "default":
        compaction = None if contact is not None else {"k1": (p.contact.k1 / 10, p.contact.k1 * 10, p.contact.k1)}
    if bond_params is None:
        bond_params = {"E_b": (1e5, 1e10), "sigma_c": (1e4, 1e10)}
    _parse_bounds(bond_params)
    if compaction is not None:
        _parse_bounds(compaction)
    if contact is not None:
        if compaction is not None:
            raise ValueError("contact = {...} fixes the contact law; compaction = {...} fits it: pass one")
        if not isinstance(contact, Mapping):
            raise ValueError(f"contact = {contact!r}: pass a mapping of ContactLaw fields, e.g. {{'k1': 4e4, 'k2': 1.6e5}}")
        make_spec({}, preset=p, diametral=False, contact=contact)  # names and values checked
    if not isinstance(start, (str, Mapping)) or (isinstance(start, str) and start != "table5"):
        raise ValueError(f"start = {start!r}: pass 'table5' or a mapping {{label: {{name: value}}}}")
    vlog = (lambda *a: print(*a, flush=True)) if verbose else (lambda *a: None)

    with _open_executor(executor, max_workers) as ex:
        ev = _Evaluator(RunCache(cache_dir), ex, _with_relaxed_dir(runner, relaxed_dir))
        contact = dict(contact or {})
        comp_fit = None
        if compaction is not None:
            vlog("[calibrate] compaction fit")
            comp_fit = fit(compaction, compaction_targets(vs, compaction_state), preset=p, seeds=seeds,
                           tol=tol, max_runs=compaction_max_runs, _evaluator=ev, verbose=verbose)
            (name, val), = comp_fit.params.items()
            k1 = val if name == "k1" else k1_from_yield_strength(val, p.radius_mean)
            contact = {"k1": k1, "k2": k1 * p.contact.k2 / p.contact.k1}

        # Densities of every variant's pressure under the shared contact law, first: these
        # runs relax one pellet per pressure and seed, all at once on the workers, and each
        # variant's fit waits for its own pressure's, so that it starts from them (with
        # relaxed_dir, any worker loads them) instead of several workers relaxing the same
        # pellet at the same time. A cached run whose relaxed pellet is missing from
        # relaxed_dir (deleted, or a killed sitting) is run again to put it back.
        sizes = sorted({v.sigma_z for v in vs})
        keep = relaxed_dir is not None and runner is run_point

        def missing(spec):
            return keep and not os.path.exists(_relaxed_path(relaxed_dir, spec.relax_key))

        pre = {sz: [make_spec({}, preset=p, sigma_z=sz, seed=s, diametral=False, contact=contact)
                    for s in _setup(p, None, None, seeds, None).seeds] for sz in sizes}
        pending = {sz: [ev.submit(sp, rerun=missing(sp)) for sp in specs] for sz, specs in pre.items()}

        def one(v):
            for f in pending[v.sigma_z]:
                f.result()
            st = {}
            if start == "table5":
                st = {"E_b": v.e_b, "sigma_c": v.sigma_c}
            elif isinstance(start, Mapping):
                st = dict(start.get(v.label, start.get(v.key, {})))
            names_ = list(bond_params)
            sp = {}
            for n in names_:
                b = bond_params[n]
                if n in st:
                    sp[n] = float(np.clip(st[n], b[0], b[1]))
            tg = Targets.from_variant(v, diametral=True)
            # the test must run past the peak: 1.5 x (mean + 2 SD) of dL_f/D, at least the preset's
            mdl = max_dLD if max_dLD is not None else max(p.max_dLD, round(1.5 * (v.dLf_D + 2 * v.dLf_D_sd), 3))
            pv = p
            if break_drop and not p.break_drop:
                pv = p.with_(break_drop=break_drop, break_from_dLD=round(0.5 * max(v.dLf_D - 2 * v.dLf_D_sd, 0.0), 4))
            vlog(f"[calibrate] {v.label}: start {sp}, max_dLD {mdl}, break at {pv.break_drop} of the peak")
            return fit(bond_params, tg, start=sp or None, preset=pv, seeds=seeds, bond=bond, contact=contact,
                       max_dLD=mdl, tol=tol, max_runs=max_runs, _evaluator=ev, verbose=verbose)

        with cf.ThreadPoolExecutor(max_workers=len(vs), thread_name_prefix="calibrate") as drivers:
            fits = dict(zip([v.label for v in vs], drivers.map(one, vs)))
        dens = {}
        for sz in sizes:
            outs, _, good, _ = _mean_outputs([f.result() for f in pending[sz]])
            dens[sz] = outs if good else {}

        stats = ev.stats()

    rows = []
    for v in vs:
        f = fits[v.label]
        outs = f.outputs[0] if f.outputs else {}
        bd = dens.get(v.sigma_z, {}).get("bulk_density_" + compaction_state, float("nan"))
        # The paper's CN (Table 5) is compared with the bulk's, away from the free surfaces.
        cn = dens.get(v.sigma_z, {}).get("coordination_number_relaxed_bulk", float("nan"))
        sc = f.scores[0] if f.scores else {}
        rows.append({
            "material": v.material, "mc_percent": v.mc_percent, "sigma_z_mpa": v.sigma_z_mpa,
            "E_b_mpa": f.params.get("E_b", float("nan")) / _MPA, "E_b_mpa_paper": v.e_b / _MPA,
            "sigma_c_mpa": f.params.get("sigma_c", float("nan")) / _MPA, "sigma_c_mpa_paper": v.sigma_c / _MPA,
            "sigma_f_mpa_sim": outs.get("sigma_f", float("nan")) / _MPA, "sigma_f_mpa_exp": v.sigma_f / _MPA,
            "sigma_f_mpa_sd": v.sigma_f_sd / _MPA, "z_sigma_f": sc.get("z_sigma_f", float("nan")),
            "dLf_D_sim": outs.get("dLf_D", float("nan")), "dLf_D_exp": v.dLf_D, "dLf_D_sd": v.dLf_D_sd,
            "z_dLf_D": sc.get("z_dLf_D", float("nan")), "rms_z": f.rms_z,
            "peaked": bool(outs.get("peaked", 0.0)),
            "bd_sim": bd, "bd_exp": v.bd_pellet, "bd_sd": v.bd_pellet_sd,
            "z_bd": float((bd - v.bd_pellet) / max(v.bd_pellet_sd, 0.01 * v.bd_pellet)) if math.isfinite(bd) else float("nan"),
            "cn_sim": cn, "cn_paper": v.cn, "rrmse_paper": v.rrmse,
            "n_points": f.n_points, "converged": f.converged,
        })
    table = pd.DataFrame(rows)
    return CalibrationReport(table=table, compaction=comp_fit, contact=contact, fits=fits,
                             n_simulations=stats["n_simulations"], n_cached=stats["n_cached"],
                             n_relaxations=stats["n_relaxations"], wall_time_s=time.perf_counter() - t0)
