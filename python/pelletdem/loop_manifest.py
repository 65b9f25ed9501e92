"""A loop data manifest: a user's measurements for ``pelletdem loop --data FILE``.

A small TOML file lists, per condition, the curve files (in the format of
:func:`pelletdem.measured.load_curve`) and scalar measurements, and which conditions are held
out of the fit::

    name = "oak, 8 % moisture"

    [fit]                       # bounds of the base parameters fitted (SI); these are the defaults
    E_b = [2e7, 2e8]            # Pa
    sigma_c = [3e6, 3e7]        # Pa

    [model]                     # optional
    preset = "tiny"
    set = { "contact.mu" = 0.5 }   # law parameters, checked against the laws' tables

    [[condition]]
    pressure_mpa = 120          # may instead come from the curve files' "# pressure_mpa=120" header
    moisture_percent = 8
    material = "oak"
    held_out = false
    diametral = "oak_120_diametral.csv"     # paths relative to the manifest
    compaction = "oak_120_compaction.csv"
    bulk_density = { mean = 1105.0, sd = 12.0, n = 5 }   # kg/m^3

A condition needs its pressure (in the manifest or in a curve file's header; where both give
it they must agree) and at least one measurement. :func:`load_manifest` reads and checks it;
every error names the file, the line and the field.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

from .loop_data import QUANTITIES, Condition, Dataset, Observation

__all__ = ["ManifestError", "Manifest", "load_manifest", "CONDITION_FIELDS", "DEFAULT_BOUNDS"]

#: The fields of a [[condition]] table: name -> meaning.
CONDITION_FIELDS = {
    "pressure_mpa": "compaction pressure sigma_z, MPa",
    "moisture_percent": "moisture content, % (default 8)",
    "material": "material name (default '')",
    "held_out": "true: kept out of every fit, used to check it (default false)",
    "diametral": "diametral-compression curve file (replicates in one file)",
    "compaction": "compaction curve file",
    "sigma_f": "tensile strength {mean, sd, n}, Pa",
    "dLf_D": "deformation at failure {mean, sd, n}, -",
    "bulk_density": "bulk density of the relaxed pellet {mean, sd, n}, kg/m^3",
}
#: Base-parameter bounds when the manifest has no [fit] table (SI).
DEFAULT_BOUNDS = {"E_b": (2e7, 2e8), "sigma_c": (3e6, 3e7)}
_TOP = {"name", "fit", "model", "condition"}
_SCALARS = ("sigma_f", "dLf_D", "bulk_density")


class ManifestError(ValueError):
    """A manifest or a file it names is wrong: ``path``, ``line`` (1-based, None when not
    known) and ``field``."""

    def __init__(self, path: str, problem: str, line: Optional[int] = None, fld: Optional[str] = None):
        self.path, self.line, self.field, self.problem = path, line, fld, problem
        where = path + (f", line {line}" if line else "") + (f", field {fld!r}" if fld else "")
        super().__init__(f"{where}: {problem}")


@dataclass
class Manifest:
    """A loaded manifest: the ``dataset`` (all conditions), the ``held_out`` conditions, the
    base parameters' ``bounds`` (SI), law ``settings`` ({'contact.X': v}), the ``preset`` name
    and the data's ``name``."""

    dataset: Dataset
    held_out: Tuple[Condition, ...]
    bounds: Dict[str, Tuple[float, float]]
    settings: Dict[str, object] = field(default_factory=dict)
    preset: str = "tiny"
    name: str = "data"


class _Lines:
    """Line numbers of a TOML text's tables and keys, for error messages."""

    def __init__(self, text: str):
        self.lines = text.splitlines()
        self.conditions = [k + 1 for k, ln in enumerate(self.lines) if re.match(r"\s*\[\[\s*condition\s*\]\]", ln)]

    def key(self, key: str, table: Optional[str] = None, index: Optional[int] = None) -> Optional[int]:
        lo, hi = 0, len(self.lines)
        if index is not None and index < len(self.conditions):
            lo = self.conditions[index]
            hi = self.conditions[index + 1] - 1 if index + 1 < len(self.conditions) else len(self.lines)
        elif table is not None:
            starts = [k for k, ln in enumerate(self.lines) if re.match(rf"\s*\[\s*{table}\s*\]", ln)]
            if starts:
                lo = starts[0] + 1
        for k in range(lo, hi):
            if re.match(rf"\s*\"?{re.escape(key)}\"?\s*=", self.lines[k]):
                return k + 1
        return (lo if index is not None else None) or None


def _toml():
    try:
        import tomllib
    except ModuleNotFoundError:  # Python < 3.11
        import tomli as tomllib
    return tomllib


def _number(v, path, line, fld, lo=-math.inf, hi=math.inf) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
        raise ManifestError(path, f"{v!r} must be a number in [{lo:g}, {hi:g}]", line, fld)
    return float(v)


def _scalar(cond: Condition, q: str, v, path, line) -> Observation:
    if not isinstance(v, dict) or set(v) - {"mean", "sd", "n"} or "mean" not in v:
        raise ManifestError(path, "expected { mean = ..., sd = ..., n = ... } (sd and n optional)", line, q)
    mean = _number(v["mean"], path, line, q, 0.0)
    sd = _number(v.get("sd", 0.0), path, line, q, 0.0)
    n = v.get("n", 1)
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 10000:
        raise ManifestError(path, f"n = {n!r} must be an integer in [1, 10000]", line, q)
    return Observation(cond, q, math.nan, mean, sd, n)


def _curve(base: str, rel, kind: str, path: str, line, fld):
    from .measured import load_curve

    if not isinstance(rel, str) or not rel:
        raise ManifestError(path, "expected the path of a curve file", line, fld)
    full = rel if os.path.isabs(rel) else os.path.join(base, rel)
    if not os.path.isfile(full):
        raise ManifestError(path, f"no such file: {full}", line, fld)
    try:
        return load_curve(full, kind)
    except ValueError as e:  # MeasuredDataError names its own row and column
        raise ManifestError(path, f"{e}", line, fld) from None


def _header_condition(curve, path, line, fld) -> Dict[str, object]:
    """The condition a curve file's header declares (pressure_mpa, moisture_percent, material)."""
    out = {}
    for key in ("pressure_mpa", "moisture_percent", "material"):
        if key in curve.metadata:
            out[key] = curve.metadata[key]
    return out


def load_manifest(path) -> Manifest:
    """Read and check a loop data manifest (see the module docstring). Raises
    :class:`ManifestError` naming the file, line and field of the first problem."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as e:
        raise ManifestError(path, f"cannot read: {e.strerror or e}") from None
    text = raw.decode("utf-8", errors="replace")
    lines = _Lines(text)
    try:
        doc = _toml().loads(text)
    except Exception as e:  # tomllib.TOMLDecodeError: its message has the line and column
        m = re.search(r"line (\d+)", str(e))
        raise ManifestError(path, f"not valid TOML: {e}", int(m.group(1)) if m else None) from None
    for k in doc:
        if k not in _TOP:
            raise ManifestError(path, f"unknown top-level key; allowed {sorted(_TOP)}", lines.key(k), k)
    base = os.path.dirname(os.path.abspath(path))
    bounds = dict(DEFAULT_BOUNDS)
    fit = doc.get("fit", {})
    if not isinstance(fit, dict):
        raise ManifestError(path, "[fit] must be a table of name = [lo, hi]", lines.key("fit"), "fit")
    if fit:
        from .runs import PARAMETERS

        bounds = {}
        for k, b in fit.items():
            ln = lines.key(k, "fit")
            if k not in PARAMETERS and "[" not in k:
                raise ManifestError(path, f"unknown base parameter; allowed {sorted(PARAMETERS)}", ln, f"fit.{k}")
            if not (isinstance(b, list) and len(b) == 2):
                raise ManifestError(path, "bounds must be [lo, hi]", ln, f"fit.{k}")
            lo, hi = (_number(x, path, ln, f"fit.{k}", 0.0) for x in b)
            if not 0 < lo < hi:
                raise ManifestError(path, f"bounds [{lo:g}, {hi:g}] must have 0 < lo < hi", ln, f"fit.{k}")
            bounds[k] = (lo, hi)
    model = doc.get("model", {})
    settings: Dict[str, object] = {}
    preset = "tiny"
    if model:
        from .law_settings import parse_setting

        for k in model:
            if k not in ("preset", "set"):
                raise ManifestError(path, "allowed keys: preset, set", lines.key(k, "model"), f"model.{k}")
        preset = model.get("preset", "tiny")
        if preset not in ("tiny", "quick", "paper"):
            raise ManifestError(path, "allowed presets: tiny, quick, paper", lines.key("preset", "model"),
                                "model.preset")
        for k, v in (model.get("set") or {}).items():
            try:
                name, val = parse_setting(k, v)
            except ValueError as e:
                raise ManifestError(path, str(e), lines.key("set", "model"), f"model.set.{k}") from None
            settings[name] = val
    conds = doc.get("condition", [])
    if not isinstance(conds, list) or not conds:
        raise ManifestError(path, "no [[condition]] tables: the manifest lists no measurements")
    obs: List[Observation] = []
    held: List[Condition] = []
    for i, c in enumerate(conds):
        where = lines.conditions[i] if i < len(lines.conditions) else None
        for k in c:
            if k not in CONDITION_FIELDS:
                raise ManifestError(path, f"unknown field; allowed {sorted(CONDITION_FIELDS)}",
                                    lines.key(k, index=i), k)
        curves = {kind: _curve(base, c[kind], kind, path, lines.key(kind, index=i), kind)
                  for kind in ("diametral", "compaction") if kind in c}
        meta: Dict[str, object] = {}
        for kind, cv in curves.items():
            for key, v in _header_condition(cv, path, lines.key(kind, index=i), kind).items():
                if key in meta and meta[key] != v:
                    raise ManifestError(path, f"the curve files disagree on {key} ({meta[key]} vs {v})",
                                        lines.key(kind, index=i), kind)
                meta[key] = v
        for key in ("pressure_mpa", "moisture_percent", "material"):
            if key in c and key in meta and (str(meta[key]) != str(c[key]) if key == "material"
                                             else float(meta[key]) != float(c[key])):
                raise ManifestError(path, f"{c[key]!r} here but {meta[key]!r} in a curve file's header",
                                    lines.key(key, index=i), key)
        p = c.get("pressure_mpa", meta.get("pressure_mpa"))
        if p is None:
            raise ManifestError(path, "the condition's pressure is neither here nor in its curve files' headers",
                                where, "pressure_mpa")
        sz = _number(p, path, lines.key("pressure_mpa", index=i), "pressure_mpa", 0.1, 1000.0) * 1e6
        mc = _number(c.get("moisture_percent", meta.get("moisture_percent", 8.0)), path,
                     lines.key("moisture_percent", index=i), "moisture_percent", 0.0, 100.0)
        mat = c.get("material", meta.get("material", ""))
        if not isinstance(mat, str):
            raise ManifestError(path, "must be a string", lines.key("material", index=i), "material")
        cond = Condition(sz, mc, mat)
        ho = c.get("held_out", False)
        if not isinstance(ho, bool):
            raise ManifestError(path, "must be true or false", lines.key("held_out", index=i), "held_out")
        before = len(obs)
        if curves:
            try:
                for cv in curves.values():
                    obs += Dataset.from_curves({cond: cv}).observations
            except ValueError as e:
                raise ManifestError(path, str(e), where) from None
        for q in _SCALARS:
            if q in c:
                if q in ("sigma_f", "dLf_D") and "diametral" in curves:
                    raise ManifestError(path, f"{q} comes from the diametral curves; give it one way",
                                        lines.key(q, index=i), q)
                obs.append(_scalar(cond, q, c[q], path, lines.key(q, index=i)))
        if len(obs) == before:
            raise ManifestError(path, "the condition has no measurement (curve files or scalars)", where)
        if cond in [o.condition for o in obs[:before]]:
            raise ManifestError(path, f"{cond.label} is listed twice", where)
        if ho:
            held.append(cond)
    name = doc.get("name", os.path.basename(path))
    assert set(QUANTITIES) >= {o.quantity for o in obs}
    ds = Dataset(obs, str(name))
    if len(held) == len(ds.conditions):
        raise ManifestError(path, "every condition is held out: nothing is left to fit", None, "held_out")
    return Manifest(ds, tuple(held), bounds, settings, preset, str(name))
