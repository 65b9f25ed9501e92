"""Run specifications and their cache keys.

A run is a :class:`RunSpec`: the preset (geometry, particles, speeds, contact law), the
compaction pressure sigma_z (Pa), the seed and, for a diametral run, the bond law.
:func:`make_spec` builds one from named parameters (:data:`PARAMETERS`, SI units). Its key
(:attr:`RunSpec.key`) is a SHA-256 of every field that changes the result (all preset fields
but the name, sigma_z, seed, bond law, the package version, the cache format and
:func:`engine_fingerprint`, a hash of the compiled engine and of the Python stage code, so a
rebuilt or edited engine never serves stale results), with every number exactly as the engine
receives it (:func:`canonical`): 0.1 and exp(log(0.1)) = 0.10000000000000002 give different
pellets (a DEM run is chaotic), so they are different runs. Workers
always run with ``threads=1``; the thread count is not part of the key.

Fill, compaction, unloading, demoulding and relaxation depend only on (preset, contact law,
sigma_z, seed): :attr:`RunSpec.relax_key` leaves out the fields that act after relaxation
(those of the diametral test, and the contact-law fields of the effects that
:data:`pelletdem.effects.EFFECTS` declares to act in it), so that one relaxed pellet serves
every bond law and diametral setting.

A scan or fit shares one :class:`RunSetup` (preset, base laws, seeds) across its points;
:func:`parse_bounds` reads the bounds a fit is given for the named parameters.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, Mapping, Optional, Sequence, Tuple

import numpy as np

from ._version import __version__
from .effects import EFFECTS
from .engine import BondLaw, ContactLaw, k1_from_yield_strength
from .presets import Preset, get_preset
from .stage_laws import with_stable_time_step

__all__ = [
    "PARAMETERS", "SCAN_ONLY_PARAMETERS", "CACHE_FORMAT", "RunSpec", "make_spec", "cache_key",
    "engine_fingerprint", "canonical", "as_preset", "check_positive", "check_names", "parse_bounds", "bound_signs",
    "RunSetup", "run_setup",
]

CACHE_FORMAT = 4  # 2: sigma_f / dLf_D at the first failure; 3: after-relax fields honoured; 4: exact numbers
# Of the diametral test alone, so that relaxed pellets stay valid: 2: samples at a fixed dL/D
# spacing whatever the test's length.
DIAMETRAL_FORMAT = 2

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
#: Parameters a scan can vary besides :data:`PARAMETERS`: name -> (unit, meaning).
SCAN_ONLY_PARAMETERS: Dict[str, Tuple[str, str]] = {"seed": ("-", "packing seed (scan only)")}

# Preset fields that do not change fill..relax (they act in the bond and diametral stages).
_AFTER_RELAX_FIELDS = ("name", "plate_speed", "max_dLD", "break_drop", "break_from_dLD", "bond_ramp_time")
# Contact-law fields that act only in the diametral test (the plates' crushing), read from
# the effects library, so that a new diametral contact effect needs no second edit here.
_AFTER_RELAX_CONTACT = tuple(e.param[len("contact."):] for e in EFFECTS.values()
                             if e.stage == "diametral" and e.param.startswith("contact."))
# The moisture content reaches compaction only through an effect that reads it
# (ContactLaw.to_core().moisture_acts()); otherwise wet and dry share one relaxed pellet.
_MOISTURE_CONTACT = ("moisture_content", "moisture_reference")


def canonical(v, where: str = "value"):
    """``v`` as plain JSON values (dataclasses as dicts, keys sorted, tuples as lists), every
    number a float with its exact value (JSON writes the shortest repr that reads back to the
    same double), units unchanged: what a cache key hashes.
    ``where`` names the value in the ValueError for a NaN or infinite number (TypeError for a
    type JSON cannot hold)."""
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        v = dataclasses.asdict(v)
    if isinstance(v, Mapping):
        return {str(k): canonical(x, f"{where}.{k}") for k, x in sorted(v.items(), key=lambda kv: str(kv[0]))}
    if isinstance(v, (list, tuple)):
        return [canonical(x, where) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, float, np.integer, np.floating)):
        f = float(v)
        if not math.isfinite(f):
            raise ValueError(f"{where} = {f!r} must be finite")
        return f + 0.0  # + 0.0: -0.0 -> 0.0 (the engine cannot tell them apart)
    if v is None or isinstance(v, str):
        return v
    raise TypeError(f"{where}: cannot key a {type(v).__name__}")


_FINGERPRINT: Optional[str] = None
_FINGERPRINT_FILES = ("engine.py", "laws.py", "world.py", "checks.py", "caliper.py", "pellet_measures.py", "stages.py",
                      "stage_laws.py", "pipeline.py", "presets.py")


def engine_fingerprint() -> str:
    """First 16 hex digits of a SHA-256 over the compiled engine (``_core``) and the Python
    files that run a pellet's stages (_FINGERPRINT_FILES): part of every cache
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
    text = json.dumps(canonical(payload), sort_keys=True, separators=(",", ":"))
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
    #: Lower pressures (Pa) whose relaxed pellets this run makes from its own piston stroke
    #: when it relaxes its pellet, for a ``relaxed_dir`` to keep (the worker's ``ladder``).
    #: Not an input of the run's result: not in its key.
    ladder: Tuple[float, ...] = field(default=(), compare=False)

    @property
    def kind(self) -> str:
        """'diametral' (bond given) or 'compaction' (fill..relax only)."""
        return "compaction" if self.bond is None else "diametral"

    def relax_payload(self) -> dict:
        """Everything that determines the relaxed pellet (plain values)."""
        p = {k: v for k, v in self.preset.as_dict().items() if k not in _AFTER_RELAX_FIELDS}
        # the plates' crushing acts in the diametral test only: one relaxed pellet serves all
        after = _after_relax_contact(self.preset.contact)
        p["contact"] = {k: v for k, v in p["contact"].items() if k not in after}
        return {"format": CACHE_FORMAT, "version": __version__, "engine": engine_fingerprint(), "preset": p,
                "sigma_z": float(self.sigma_z), "seed": int(self.seed)}

    def payload(self) -> dict:
        """Everything that determines this run's result (plain values)."""
        d = self.relax_payload()
        d["kind"] = self.kind
        if self.bond is not None:
            d["diametral_format"] = DIAMETRAL_FORMAT
            d["bond"] = dataclasses.asdict(self.bond)
            d["after_relax"] = {k: getattr(self.preset, k) for k in _AFTER_RELAX_FIELDS if k != "name"}
            d["after_relax"].update({k: getattr(self.preset.contact, k)
                                     for k in _after_relax_contact(self.preset.contact)})
        return d

    @property
    def key(self) -> str:
        """Stable SHA-256 hex key of :meth:`payload` (the cache file name)."""
        return _digest(self.payload())

    @property
    def relax_key(self) -> str:
        """Key of the relaxed pellet this run starts from (shared by all bond laws)."""
        return _digest(self.relax_payload())

    @property
    def stroke_key(self) -> str:
        """Key of the piston stroke this run's pellet comes from: shared by the runs that
        differ only in sigma_z (one stroke can relax all their pellets, ``ladder``)."""
        return _digest({**self.relax_payload(), "sigma_z": None})


def _after_relax_contact(contact) -> Tuple[str, ...]:
    """The fields of the ContactLaw ``contact`` that do not change fill..relax."""
    if contact.to_core().moisture_acts():
        return _AFTER_RELAX_CONTACT
    return _AFTER_RELAX_CONTACT + _MOISTURE_CONTACT


def cache_key(spec: RunSpec) -> str:
    """The cache key of a run (same as ``spec.key``): SHA-256 hex of all its inputs."""
    return spec.key


def as_preset(preset) -> Preset:
    """``preset`` itself if it is a Preset, else the named preset (:func:`pelletdem.presets.get_preset`)."""
    if isinstance(preset, Preset):
        return preset
    return get_preset(preset)


def check_positive(name: str, value, unit: str) -> float:
    """``value`` as a float if it is a finite number > 0; else ValueError naming ``name`` and
    its ``unit`` (e.g. 'Pa')."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r} must be a number ({unit})") from None
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} = {value!r} must be finite and > 0 ({unit})")
    return v


def check_names(names: Iterable[str], allowed: Mapping[str, Any], what: str = "parameter") -> None:
    """ValueError naming the first of ``names`` that is not a key of ``allowed`` (``what`` it
    is, for the message), with the allowed names."""
    for n in names:
        if n not in allowed:
            raise ValueError(f"unknown {what} {n!r}: allowed {sorted(allowed)}")


def contact_row_unit(name: str) -> Optional[str]:
    """The unit of ``name`` when it is a contact-law row given as ``contact.<field>`` (a fit or
    scan may vary one, e.g. a yield effect's strength), else None."""
    if not name.startswith("contact."):
        return None
    rows = {r.name: r for r in ContactLaw.rows()}
    field = name[len("contact."):]
    if field not in rows:
        raise ValueError(f"unknown contact law row {name!r}: allowed contact.<field> with a field of "
                         f"{sorted(rows)}")
    return rows[field].unit


def parameter_unit(name: str) -> str:
    """The SI unit of a fit or scan parameter: one of :data:`PARAMETERS`, or a contact-law row
    ``contact.<field>``; ValueError naming an unknown one and the allowed names."""
    unit = contact_row_unit(name)
    if unit is not None:
        return unit
    check_names([name], {**PARAMETERS, **SCAN_ONLY_PARAMETERS})
    return {**PARAMETERS, **SCAN_ONLY_PARAMETERS}[name][0]


def make_spec(params: Optional[Mapping[str, float]] = None, *, preset="tiny", sigma_z: float = 120e6,
              seed: int = 0, bond: Optional[BondLaw] = None, diametral: bool = True,
              contact: Optional[Mapping[str, Any]] = None, max_dLD: Optional[float] = None) -> RunSpec:
    """A :class:`RunSpec` from named parameters (see :data:`PARAMETERS`, SI units).

    ``preset``: name or Preset. ``contact``: ContactLaw field overrides (e.g. ``{"k1": 5e4,
    "k2": 2e5}``) applied before ``params``. ``bond``: the base BondLaw (default BondLaw());
    ``params`` E_b, sigma_c, tau_c, r_b change it, k1 / p_y change the contact law (k2/k1 kept),
    ``contact.<field>`` sets that contact-law row (after ``contact``), sigma_z (Pa) the
    pressure. ``diametral=False`` gives a compaction-only run (no bond).
    ``max_dLD``: end of the diametral test (default the preset's). Raises ValueError naming a
    bad parameter.
    """
    params = dict(params or {})
    for name in params:
        parameter_unit(name)  # a known name
    rows = {n[len("contact."):]: params.pop(n) for n in list(params) if n.startswith("contact.")}
    p = as_preset(preset)
    contact = {**dict(contact or {}), **rows}
    if contact:
        check_names(contact, {f.name: f for f in dataclasses.fields(p.contact)}, "contact law field")
        p = p.with_(contact=dataclasses.replace(p.contact, **contact))
    if max_dLD is not None:
        p = p.with_(max_dLD=check_positive("max_dLD", max_dLD, "-"))
    for name, v in params.items():
        if name == "seed":
            if isinstance(v, float) and v.is_integer():
                v = int(v)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"seed = {v!r} must be an integer >= 0")
            params[name] = int(v)
        else:
            params[name] = check_positive(name, v, PARAMETERS[name][0])
    if "k1" in params and "p_y" in params:
        raise ValueError("give k1 or p_y, not both (k1 = 5 r p_y)")
    k1 = params.get("k1")
    if "p_y" in params:
        k1 = k1_from_yield_strength(params["p_y"], p.radius_mean)
    if k1 is not None:
        ratio = p.contact.k2 / p.contact.k1
        p = p.with_(contact=dataclasses.replace(p.contact, k1=k1, k2=k1 * ratio))
    p.contact.to_core()  # validates (ParameterError is a ValueError)
    p = with_stable_time_step(p)  # a law's springs the preset's dt cannot hold get a stable step
    sz = check_positive("sigma_z", params.get("sigma_z", sigma_z), "Pa")
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


def parse_bounds(params: Mapping[str, Sequence[float]], start: Optional[Mapping[str, float]] = None):
    """(names, ln lo, ln hi, ln start) of ``params`` {name: (lo, hi) or (lo, hi, start)} (SI,
    names from :data:`PARAMETERS`); ``start`` {name: value} overrides the
    third entries, and a missing start is the geometric mean of the bounds; a contact-law row
    ``contact.<field>`` may be fitted too, a strength of one sign: where both its bounds are
    negative (a signed row such as moisture_yield's c), the coordinate is the log of its
    magnitude (:func:`bound_signs` gives the signs). ValueError naming the parameter for bad
    names, reversed bounds, bounds of a PARAMETER that are not positive or of a row that
    straddle zero, NaN, or a start outside."""
    if not isinstance(params, Mapping) or not params:
        raise ValueError("params must be a non-empty mapping {name: (lo, hi)} or {name: (lo, hi, start)}")
    for name in params:
        if contact_row_unit(name) is None:
            check_names([name], PARAMETERS)
    if start is not None:
        check_names(start, params, "start parameter (not among the fitted ones)")
    names, lo, hi, x0 = [], [], [], []
    for name, b in params.items():
        unit = parameter_unit(name)
        try:
            vals = [float(v) for v in b]
        except (TypeError, ValueError):
            raise ValueError(f"bounds of {name!r} must be (lo, hi) or (lo, hi, start) numbers in {unit}; "
                             f"got {b!r}") from None
        if len(vals) not in (2, 3):
            raise ValueError(f"bounds of {name!r} must be (lo, hi) or (lo, hi, start); got {b!r}")
        if any(not math.isfinite(v) for v in vals):
            raise ValueError(f"bounds of {name!r} = {b!r} must be finite (no NaN or inf)")
        if not vals[0] < vals[1]:
            raise ValueError(f"bounds of {name!r} are reversed or empty: lo = {vals[0]!r} >= hi = {vals[1]!r} {unit}")
        negative = contact_row_unit(name) is not None and vals[1] < 0
        if vals[0] <= 0 and not negative:
            raise ValueError(f"bounds of {name!r} = {b!r} {unit} must both be > 0"
                             + (" or both < 0" if contact_row_unit(name) is not None else "")
                             + " (the search is in log space of the magnitude)")
        s = vals[2] if len(vals) == 3 else None
        if start is not None and name in start:
            s = start[name]
        if s is None:
            s = math.copysign(math.sqrt(vals[0] * vals[1]), vals[1])
        try:
            s = float(s)
        except (TypeError, ValueError):
            raise ValueError(f"start of {name!r} = {s!r} must be a number") from None
        if not math.isfinite(s) or not vals[0] <= s <= vals[1]:
            raise ValueError(f"start of {name!r} = {s!r} {unit} is outside its bounds [{vals[0]!r}, {vals[1]!r}]")
        names.append(name)
        lo.append(math.log(min(abs(vals[0]), abs(vals[1]))))
        hi.append(math.log(max(abs(vals[0]), abs(vals[1]))))
        x0.append(math.log(abs(s)))
    return names, np.array(lo), np.array(hi), np.array(x0)


def bound_signs(params: Mapping[str, Sequence[float]]) -> np.ndarray:
    """The sign (+1 or -1) of each parameter of ``params`` (as :func:`parse_bounds` reads them,
    in its order): a fit's value is sign * exp(coordinate)."""
    return np.array([-1.0 if float(b[1]) < 0 else 1.0 for b in params.values()])


@dataclass
class RunSetup:
    """What every run of a scan, fit or simulator shares: the ``preset``, the base ``bond``
    law (None: BondLaw()), ``contact`` law overrides, the packing ``seeds`` averaged per point
    and ``max_dLD`` (end of the diametral test, -; None: the preset's)."""

    preset: Preset
    bond: Optional[BondLaw]
    contact: Optional[Mapping]
    seeds: Tuple[int, ...]
    max_dLD: Optional[float]

    def spec(self, params: Mapping[str, float], sigma_z: float, seed: int, diametral: bool,
             condition: Optional[Mapping[str, float]] = None) -> RunSpec:
        """The :class:`RunSpec` of ``params`` (SI, see :func:`make_spec`) at ``sigma_z`` (Pa)
        and ``seed``; a compaction-only run unless ``diametral``. ``condition``: contact-law
        rows the condition sets over the setup's (its ``moisture_content``, ``wood_density``:
        :meth:`pelletdem.objectives.Targets.condition_rows`)."""
        contact = {**(self.contact or {}), **(condition or {})} if condition else self.contact
        return make_spec(params, preset=self.preset, sigma_z=sigma_z, seed=seed, bond=self.bond,
                         diametral=diametral, contact=contact, max_dLD=self.max_dLD)


def run_setup(preset, bond, contact, seeds, max_dLD) -> RunSetup:
    """A checked :class:`RunSetup`: ``preset`` a name or Preset, ``bond`` a BondLaw or None,
    ``contact`` ContactLaw overrides, ``seeds`` an integer >= 0 or a sequence of them,
    ``max_dLD`` (-) or None. ValueError for bad seeds or a bond that is not a BondLaw."""
    if isinstance(seeds, (int, np.integer)):
        seeds = (int(seeds),)
    seeds = tuple(seeds)
    if not seeds or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in seeds):
        raise ValueError(f"seeds = {seeds!r} must be integers >= 0")
    if bond is not None and not isinstance(bond, BondLaw):
        raise ValueError(f"bond must be a BondLaw; got {type(bond).__name__}")
    return RunSetup(as_preset(preset), bond, contact, seeds, max_dLD)
