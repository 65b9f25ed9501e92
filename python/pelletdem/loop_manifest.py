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
    particle_density = { oak = 675.0 }   # kg/m^3 per material (default the preset's)

    [[condition]]
    pressure_mpa = 120          # may instead come from the curve files' "# pressure_mpa=120" header
    moisture_percent = 8
    material = "oak"
    held_out = false
    diametral = "oak_120_diametral.csv"     # paths relative to the manifest
    compaction = "oak_120_compaction.csv"
    bulk_density = { mean = 1105.0, sd = 12.0, n = 5 }   # kg/m^3

A condition needs its pressure (in the manifest or in a curve file's header; where both give
it they must agree) and at least one measurement; a scalar needs its replicate SD (``n``, the
replicates, defaults to 1: the SD is then the standard error of the mean given). At least one
condition must be fitted. :func:`load_manifest` reads and checks it; every error names the
file, the line and the field. :func:`example_manifest` is the shipped example (made with the
engine by ``scripts/make_loop_example.py``).
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

from .loop_data import QUANTITIES, Condition, Dataset, Observation

__all__ = ["ManifestError", "Manifest", "load_manifest", "example_manifest", "CONDITION_FIELDS", "DEFAULT_BOUNDS"]

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
#: A condition's keys a curve file's header may give, with their allowed ranges.
_HEADER_NUMBERS = {"pressure_mpa": (0.1, 1000.0), "moisture_percent": (0.0, 100.0)}


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
    base parameters' ``bounds`` (SI), law ``settings`` ({'contact.X': v}), the ``preset`` name,
    the data's ``name`` and the particles' density per material, kg/m^3
    (``particle_density``; a material not listed keeps the preset's)."""

    dataset: Dataset
    held_out: Tuple[Condition, ...]
    bounds: Dict[str, Tuple[float, float]]
    settings: Dict[str, object] = field(default_factory=dict)
    preset: str = "tiny"
    name: str = "data"
    particle_density: Dict[str, float] = field(default_factory=dict)


def example_manifest() -> str:
    """The path of the shipped example manifest (``pelletdem/data/loop_example/loop_example.toml``:
    oak at 8 % moisture, 60, 90 and 120 MPa, made with the engine with an effect it does not
    declare; its README.md there says which)."""
    from importlib import resources

    # joinpath chained (not joinpath("a", "b")) to work on Python 3.10
    ref = resources.files(__package__).joinpath("data").joinpath("loop_example").joinpath("loop_example.toml")
    path = os.fspath(str(ref))
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: the example data are not installed with this copy of pelletdem")
    return path


class _Lines:
    """Line numbers of a TOML text's tables and keys, for error messages."""

    def __init__(self, text: str):
        self.lines = text.splitlines()
        self.headers = [k for k, ln in enumerate(self.lines) if re.match(r"\s*\[", ln)]
        self.conditions = [k + 1 for k, ln in enumerate(self.lines) if re.match(r"\s*\[\[\s*condition\s*\]\]", ln)]

    def _end(self, lo: int) -> int:
        """The 0-based index of the first table header at or after ``lo`` (the end of a table)."""
        return next((k for k in self.headers if k >= lo), len(self.lines))

    def key(self, key: str, table: Optional[str] = None, index: Optional[int] = None) -> Optional[int]:
        """The 1-based line of ``key``: at the top level (or its ``[key]`` header), in ``[table]``, or
        in the ``index``-th [[condition]] (its header's line when the key is not written there)."""
        if index is not None:
            if index >= len(self.conditions):
                return None
            lo = self.conditions[index]
        elif table is not None:
            starts = [k for k in self.headers if re.match(rf"\s*\[\s*{re.escape(table)}\s*\]", self.lines[k])]
            if not starts:
                return None
            lo = starts[0] + 1
        else:
            lo = 0
        for k in range(lo, self._end(lo)):
            if re.match(rf"\s*[\"']?{re.escape(key)}[\"']?\s*=", self.lines[k]):
                return k + 1
        if index is not None:
            return lo
        if table is None:
            for k in self.headers:
                if re.match(rf"\s*\[\[?\s*{re.escape(key)}\s*[\].]", self.lines[k]):
                    return k + 1
        return None

    def key_on(self, line: Optional[int]) -> Optional[str]:
        """The key or table written on the 1-based ``line`` (None when there is none)."""
        if line is None or not 1 <= line <= len(self.lines):
            return None
        m = re.match(r"\s*(?:\[\[?\s*([\w.\-\"']+)|[\"']?([\w.\-\[\]]+)[\"']?\s*=)", self.lines[line - 1])
        return (m.group(1) or m.group(2)).strip("\"'") if m else None


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
    if not isinstance(v, dict) or set(v) - {"mean", "sd", "n"} or not {"mean", "sd"} <= set(v):
        raise ManifestError(path, "expected { mean = ..., sd = ..., n = ... }: the mean and the replicates' SD "
                            f"({QUANTITIES[q][0]}), n optional (default 1)", line, q)
    mean = _number(v["mean"], path, line, q, 0.0)
    sd = _number(v["sd"], path, line, q, 0.0)
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
    """The condition a curve file's header declares (pressure_mpa, moisture_percent, material),
    checked: ManifestError naming the manifest's line of the curve file and the header key."""
    out: Dict[str, object] = {}
    for key, (lo, hi) in _HEADER_NUMBERS.items():
        if key in curve.metadata:
            v = curve.metadata[key]
            if isinstance(v, str) or not lo <= v <= hi:
                raise ManifestError(path, f"the header of {curve.source} gives {key}={v}: it must be a number in "
                                    f"[{lo:g}, {hi:g}]", line, fld)
            out[key] = float(v)
    if "material" in curve.metadata:
        out["material"] = str(curve.metadata["material"])
    return out


def _same(key: str, a, b) -> bool:
    if key == "material":
        return str(a) == str(b)
    return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)


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
        line = int(m.group(1)) if m else (len(lines.lines) or None)  # "at end of document"
        raise ManifestError(path, f"not valid TOML: {e}", line, lines.key_on(line)) from None
    for k in doc:
        if k not in _TOP:
            raise ManifestError(path, f"unknown top-level key; allowed {sorted(_TOP)}", lines.key(k), k)
    bounds = _bounds(doc, lines, path)
    settings, preset, density = _model(doc, lines, path)
    conds = doc.get("condition", [])
    if not isinstance(conds, list) or not conds:
        raise ManifestError(path, "no [[condition]] tables: the manifest lists no measurements",
                            lines.key("condition"), "condition")
    base = os.path.dirname(os.path.abspath(path))
    obs: List[Observation] = []
    held: List[Condition] = []
    first_line: Dict[Condition, Optional[int]] = {}
    for i, c in enumerate(conds):
        where = lines.conditions[i] if i < len(lines.conditions) else lines.key("condition")
        if not isinstance(c, dict):
            raise ManifestError(path, "each condition must be a [[condition]] table", where, "condition")
        cond, cobs = _condition(c, i, where, lines, base, path)
        if cond in first_line:
            raise ManifestError(path, f"{cond.label} is listed twice (first at line {first_line[cond]})", where,
                                "condition")
        first_line[cond] = where
        obs += cobs
        if c.get("held_out", False):
            held.append(cond)
    name = doc.get("name", os.path.basename(path))
    ds = Dataset(obs, str(name))
    if len(held) == len(ds.conditions):
        raise ManifestError(path, "every condition is held out: nothing is left to fit",
                            lines.key("held_out", index=len(conds) - 1), "held_out")
    materials = {c.material for c in ds.conditions}
    for m in density:
        if m not in materials:
            raise ManifestError(path, f"no condition is of material {m!r}; the conditions' materials: "
                                f"{sorted(materials)}", lines.key("particle_density", "model"),
                                f"model.particle_density.{m}")
    return Manifest(ds, tuple(held), bounds, settings, preset, str(name), density)


def _bounds(doc, lines: _Lines, path: str) -> Dict[str, Tuple[float, float]]:
    """The [fit] table's bounds (SI), or :data:`DEFAULT_BOUNDS`."""
    fit = doc.get("fit", {})
    if not isinstance(fit, dict):
        raise ManifestError(path, "[fit] must be a table of name = [lo, hi]", lines.key("fit"), "fit")
    if not fit:
        return dict(DEFAULT_BOUNDS)
    from .runs import PARAMETERS

    bounds = {}
    for k, b in fit.items():
        ln = lines.key(k, "fit")
        if k.partition("[")[0] not in PARAMETERS:
            raise ManifestError(path, f"unknown base parameter; allowed {sorted(PARAMETERS)} (per material: "
                                "'NAME[material]')", ln, f"fit.{k}")
        if not (isinstance(b, list) and len(b) == 2):
            raise ManifestError(path, "bounds must be [lo, hi]", ln, f"fit.{k}")
        lo, hi = (_number(x, path, ln, f"fit.{k}", 0.0) for x in b)
        if not 0 < lo < hi:
            raise ManifestError(path, f"bounds [{lo:g}, {hi:g}] must have 0 < lo < hi", ln, f"fit.{k}")
        bounds[k] = (lo, hi)
    return bounds


def _model(doc, lines: _Lines, path: str) -> Tuple[Dict[str, object], str, Dict[str, float]]:
    """(law settings, preset, particle density per material kg/m^3) of the [model] table."""
    model = doc.get("model", {})
    if not isinstance(model, dict):
        raise ManifestError(path, "[model] must be a table (preset, set, particle_density)", lines.key("model"),
                            "model")
    from .law_settings import parse_setting

    for k in model:
        if k not in ("preset", "set", "particle_density"):
            raise ManifestError(path, "allowed keys: preset, set, particle_density", lines.key(k, "model"),
                                f"model.{k}")
    preset = model.get("preset", "tiny")
    if preset not in ("tiny", "quick", "paper"):
        raise ManifestError(path, "allowed presets: tiny, quick, paper", lines.key("preset", "model"), "model.preset")
    sets = model.get("set", {})
    if not isinstance(sets, dict):
        raise ManifestError(path, 'expected a table of law parameters, e.g. { "contact.mu" = 0.5 }',
                            lines.key("set", "model"), "model.set")
    settings: Dict[str, object] = {}
    for k, v in _flat(sets).items():
        try:
            name, val = parse_setting(k, v)
        except ValueError as e:
            line = lines.key("set", "model") or lines.key(k, "model.set")  # inline, or a [model.set] table
            raise ManifestError(path, str(e).removeprefix("--set "), line, f"model.set.{k}") from None
        settings[name] = val
    rho = model.get("particle_density", {})
    line = lines.key("particle_density", "model")
    if not isinstance(rho, dict):
        raise ManifestError(path, "expected a table of material = kg/m^3, e.g. { oak = 675.0 }", line,
                            "model.particle_density")
    density = {str(m): _number(v, path, line, f"model.particle_density.{m}", 1.0, 3.0e4) for m, v in rho.items()}
    return settings, str(preset), density


def _flat(d: dict, prefix: str = "") -> dict:
    """{"contact": {"mu": 0.5}} -> {"contact.mu": 0.5}: TOML reads an unquoted dotted key as nested tables."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _condition(c: dict, i: int, where, lines: _Lines, base: str, path: str) -> Tuple[Condition, List[Observation]]:
    """The ``i``-th [[condition]] table ``c`` (header on line ``where``) as a Condition and its
    observations."""
    for k in c:
        if k not in CONDITION_FIELDS:
            raise ManifestError(path, f"unknown field; allowed {sorted(CONDITION_FIELDS)}", lines.key(k, index=i), k)
    curves = {kind: _curve(base, c[kind], kind, path, lines.key(kind, index=i), kind)
              for kind in ("diametral", "compaction") if kind in c}
    meta: Dict[str, object] = {}
    for kind, cv in curves.items():
        for key, v in _header_condition(cv, path, lines.key(kind, index=i), kind).items():
            if key in meta and not _same(key, meta[key], v):
                raise ManifestError(path, f"the curve files' headers disagree on {key} ({meta[key]} vs {v})",
                                    lines.key(kind, index=i), kind)
            meta[key] = v
    line = {k: lines.key(k, index=i) for k in ("pressure_mpa", "moisture_percent", "material", "held_out")}
    p = c.get("pressure_mpa", meta.get("pressure_mpa"))
    if p is None:
        raise ManifestError(path, "the condition's pressure is neither here nor in its curve files' headers",
                            where, "pressure_mpa")
    sz = _number(p, path, line["pressure_mpa"], "pressure_mpa", *_HEADER_NUMBERS["pressure_mpa"]) * 1e6
    mc = _number(c.get("moisture_percent", meta.get("moisture_percent", 8.0)), path, line["moisture_percent"],
                 "moisture_percent", *_HEADER_NUMBERS["moisture_percent"])
    mat = c.get("material", meta.get("material", ""))
    if not isinstance(mat, str):
        raise ManifestError(path, "must be a string", line["material"], "material")
    for key in ("pressure_mpa", "moisture_percent", "material"):
        if key in c and key in meta and not _same(key, c[key], meta[key]):
            raise ManifestError(path, f"{c[key]!r} here but {meta[key]!r} in a curve file's header",
                                line[key], key)
    cond = Condition(sz, mc, mat)
    if not isinstance(c.get("held_out", False), bool):
        raise ManifestError(path, "must be true or false", line["held_out"], "held_out")
    obs: List[Observation] = []
    for kind, cv in curves.items():
        try:
            obs += Dataset.from_curves({cond: cv}).observations
        except ValueError as e:
            raise ManifestError(path, f"{cv.source}: {e}", lines.key(kind, index=i), kind) from None
    for q in _SCALARS:
        if q in c:
            if q in ("sigma_f", "dLf_D") and "diametral" in curves:
                raise ManifestError(path, f"{q} comes from the diametral curves; give it one way",
                                    lines.key(q, index=i), q)
            obs.append(_scalar(cond, q, c[q], path, lines.key(q, index=i)))
    if not obs:
        raise ManifestError(path, "the condition has no measurement: give a curve file (diametral, compaction) "
                            "or a scalar (sigma_f, dLf_D, bulk_density)", where, "condition")
    return cond, obs
