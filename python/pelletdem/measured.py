"""Measured data: the paper's tables and the user's own test curves.

Two halves live here.

* The paper's Tables 1-5 ship as CSV package data (``pelletdem/data``). The loaders
  return tidy :class:`pandas.DataFrame` objects with the units of the CSV (named in
  the column names: ``_mpa``, ``_percent``; densities in kg/m3), and
  :func:`variant` collects every measured scalar of one of the 12 experimental
  variants into a :class:`Variant` in SI units (Pa, kg/m3, fractions).
* User measurements: :func:`load_curve` reads a diametral-compression or compaction
  curve from CSV, checks it and returns a :class:`Curve` in SI units (dimensionless
  deformation, stress in Pa); :func:`save_curve` writes it back losslessly.

A malformed user file raises :class:`MeasuredDataError` naming the file, the data row
(1-based, counting data rows only, not the header or ``#`` comment lines) and the
column, so the user can go straight to the offending cell.
"""

from __future__ import annotations

import csv
import math
import re
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from io import StringIO
from pathlib import Path
from typing import Iterable, Mapping, NamedTuple, Sequence

import numpy as np
import pandas as pd

__all__ = [
    "MATERIALS",
    "MOISTURE_CONTENTS_PERCENT",
    "COMPACTION_PRESSURES_MPA",
    "CURVE_KINDS",
    "load_table",
    "table_provenance",
    "solid_density",
    "bulk_density",
    "bulk_density_long",
    "tensile_strength",
    "dem_parameters",
    "best_fit_dem",
    "Variant",
    "variant",
    "variants",
    "MeasuredDataError",
    "Curve",
    "MeanCurve",
    "Peak",
    "load_curve",
    "save_curve",
    "concat_curves",
    "interp_curve",
]

# `__package__` is empty when this file is imported by path (tests, scripts).
_PACKAGE = __package__ or "pelletdem"
_MPA = 1.0e6
_MM = 1.0e-3

_TABLE_FILES = {
    1: "table1_solid_density.csv",
    2: "table2_bulk_density.csv",
    3: "table3_tensile_strength.csv",
    4: "table4_dem_parameters.csv",
    5: "table5_best_fit_dem.csv",
}

# The experimental design (Table 3): 3 woods x 2 moisture contents x 2 pressures.
MATERIALS: tuple[str, ...] = ("birch", "oak", "pine")
MOISTURE_CONTENTS_PERCENT: tuple[int, ...] = (8, 20)
COMPACTION_PRESSURES_MPA: tuple[int, ...] = (60, 120)
# Intact wood was measured at one moisture content only (Table 2).
_WOOD_MC_PERCENT = 8


# --------------------------------------------------------------------------------------
# Shipped tables
# --------------------------------------------------------------------------------------


def _split_comment_lines(text: str) -> tuple[list[str], str]:
    """Separate the ``#`` provenance lines from the CSV body."""
    comments, body = [], []
    for line in text.splitlines():
        if line.lstrip().startswith("#"):
            comments.append(line.lstrip()[1:].strip())
        else:
            body.append(line)
    return comments, "\n".join(body)


@lru_cache(maxsize=None)
def _shipped_text(filename: str) -> str:
    # joinpath chained (not joinpath("data", filename)) to work on Python 3.10.
    ref = resources.files(_PACKAGE).joinpath("data").joinpath(filename)
    return ref.read_text(encoding="utf-8")


@lru_cache(maxsize=None)
def _shipped_frame(n: int) -> pd.DataFrame:
    _, body = _split_comment_lines(_shipped_text(_TABLE_FILES[n]))
    # Table 4's value column mixes numbers with ranges ("3e6..40e6"): keep it text.
    dtype = {"value": str, "note": str} if n == 4 else None
    frame = pd.read_csv(StringIO(body), dtype=dtype, keep_default_na=(n != 4))
    if "material" in frame.columns:
        frame["material"] = frame["material"].astype(str).str.strip().str.lower()
    for col in ("mc_percent", "sigma_z_mpa"):
        if col in frame.columns:
            frame[col] = frame[col].astype(int)
    return frame


def _check_table_number(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n not in _TABLE_FILES:
        raise ValueError(f"n must be one of {sorted(_TABLE_FILES)} (the paper's table number); got {n!r}")
    return int(n)


def table_provenance(n: int) -> str:
    """The ``#`` header text of shipped table ``n`` (1-5): units and source."""
    comments, _ = _split_comment_lines(_shipped_text(_TABLE_FILES[_check_table_number(n)]))
    return "\n".join(comments)


def _key_columns_first(frame: pd.DataFrame) -> pd.DataFrame:
    keys = [c for c in ("material", "mc_percent", "sigma_z_mpa") if c in frame.columns]
    return frame[keys + [c for c in frame.columns if c not in keys]]


def solid_density() -> pd.DataFrame:
    """Table 1: helium-pycnometry solid density of intact wood and sawdust.

    Columns: ``material``, ``rho_wood_solid_mean``, ``rho_wood_solid_sd``,
    ``rho_sawdust_solid_mean``, ``rho_sawdust_solid_sd`` (all kg/m3; mean and SD of
    five replicates).
    """
    return _shipped_frame(1).copy()


def bulk_density() -> pd.DataFrame:
    """Table 2 as printed (wide): one row per (material, mc_percent).

    Bulk densities ``bd_*`` in kg/m3, porosities ``p_*`` in percent; ``*_wood_*`` is
    reported at MC 8% only (NaN at MC 20%), ``*_pellet_60_*`` / ``*_pellet_120_*``
    are pellets compacted at 60 / 120 MPa. See :func:`bulk_density_long` for the
    tidy form.
    """
    return _key_columns_first(_shipped_frame(2).copy())


# (state, compaction pressure in MPa or None, CSV column prefix for BD, for porosity)
_TABLE2_STATES = (
    ("wood", None, "bd_wood", "p_wood"),
    ("sawdust", None, "bd_sawdust", "p_sawdust"),
    ("pellet", 60, "bd_pellet_60", "p_pellet_60"),
    ("pellet", 120, "bd_pellet_120", "p_pellet_120"),
)


def bulk_density_long() -> pd.DataFrame:
    """Table 2, tidy: one row per (material, mc_percent, state, sigma_z_mpa).

    ``state`` is ``"wood"`` (intact wood), ``"sawdust"`` (initial bulk in the mould)
    or ``"pellet"``; ``sigma_z_mpa`` is the compaction pressure in MPa for pellets
    and NaN for wood and sawdust. Columns ``bd_mean``, ``bd_sd`` (kg/m3) and
    ``porosity_mean``, ``porosity_sd`` (percent, as printed). Intact wood was
    measured at MC 8% only, so there is no wood row at MC 20% (21 rows in all).
    """
    rows = []
    for rec in bulk_density().to_dict("records"):
        for state, sigma_z, bd, por in _TABLE2_STATES:
            if pd.isna(rec[f"{bd}_mean"]):
                continue  # not reported (intact wood at MC 20%)
            rows.append(
                {
                    "material": rec["material"],
                    "mc_percent": int(rec["mc_percent"]),
                    "state": state,
                    "sigma_z_mpa": float("nan") if sigma_z is None else float(sigma_z),
                    "bd_mean": float(rec[f"{bd}_mean"]),
                    "bd_sd": float(rec[f"{bd}_sd"]),
                    "porosity_mean": float(rec[f"{por}_mean"]),
                    "porosity_sd": float(rec[f"{por}_sd"]),
                }
            )
    return pd.DataFrame(rows)


def tensile_strength() -> pd.DataFrame:
    """Table 3: diametral compression, one row per variant (12 rows).

    Columns ``material``, ``mc_percent`` (%), ``sigma_z_mpa`` (compaction pressure,
    MPa), ``dLf_D_mean``, ``dLf_D_sd`` (deformation at failure, -),
    ``sigma_f_mpa_mean``, ``sigma_f_mpa_sd`` (tensile strength, MPa); mean and SD of
    five replicates.
    """
    return _key_columns_first(_shipped_frame(3).copy())


def _parse_parameter_value(text: str) -> tuple[float, float, float]:
    """(value, min, max) of a Table 4 value cell: a number, "a..b" or "a;b;c"."""
    text = text.strip()
    try:
        v = float(text)
        return v, v, v
    except ValueError:
        pass
    parts = re.split(r"\.\.|;", text)
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        return math.nan, math.nan, math.nan
    return math.nan, min(nums), max(nums)


def dem_parameters() -> pd.DataFrame:
    """Table 4: DEM parameters of the paper, SI units unless ``unit`` says otherwise.

    Columns ``parameter``, ``symbol``, ``value`` (float; NaN where the paper gives a
    range or a list), ``value_min``, ``value_max`` (equal to ``value`` for single
    numbers), ``value_text`` (the cell as printed, e.g. ``"3e6..40e6"``), ``unit``,
    ``note``.
    """
    frame = _shipped_frame(4).copy()
    parsed = [_parse_parameter_value(t) for t in frame["value"]]
    frame = frame.rename(columns={"value": "value_text"})
    frame.insert(2, "value", [p[0] for p in parsed])
    frame.insert(3, "value_min", [p[1] for p in parsed])
    frame.insert(4, "value_max", [p[2] for p in parsed])
    return frame[["parameter", "symbol", "value", "value_min", "value_max", "value_text", "unit", "note"]]


def best_fit_dem() -> pd.DataFrame:
    """Table 5: the paper's best-fitting DEM parameters per variant (r_b = 20 um).

    Columns ``material``, ``mc_percent`` (%), ``sigma_z_mpa`` (MPa), ``cn``
    (coordination number, -), ``e_b_mpa`` (bond Young's modulus, MPa),
    ``sigma_c_mpa`` (bond tensile = shear strength, MPa), ``rrmse`` (eq. 16, -).
    """
    return _key_columns_first(_shipped_frame(5).copy())


_LOADERS = {1: solid_density, 2: bulk_density, 3: tensile_strength, 4: dem_parameters, 5: best_fit_dem}


def load_table(n: int) -> pd.DataFrame:
    """Shipped table ``n`` (1-5) of the paper; same as the named loader.

    1 :func:`solid_density`, 2 :func:`bulk_density` (wide), 3 :func:`tensile_strength`,
    4 :func:`dem_parameters`, 5 :func:`best_fit_dem`.
    """
    return _LOADERS[_check_table_number(n)]()


# --------------------------------------------------------------------------------------
# Variants
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Variant:
    """Every measured scalar of one experimental variant, in SI units.

    Identification: ``material``, ``mc_percent`` (moisture content, %) and
    ``sigma_z`` (compaction pressure, Pa; ``sigma_z_mpa`` gives MPa).

    Diametral compression (Table 3): ``sigma_f`` / ``sigma_f_sd`` tensile strength
    (Pa), ``dLf_D`` / ``dLf_D_sd`` deformation at failure (-).

    Densities (Tables 1, 2): ``bd_pellet`` / ``bd_pellet_sd`` bulk density of the
    pellet, ``bd_sawdust`` / ``bd_sawdust_sd`` initial bulk density of the sawdust in
    the mould (same material and MC), ``bd_wood`` / ``bd_wood_sd`` bulk density of the
    intact wood, ``rho_sawdust_solid`` / ``rho_wood_solid`` (+ ``_sd``) solid densities
    from helium pycnometry; all kg/m3. The porosities ``porosity_*`` are fractions
    (0-1), not percent. Intact wood was measured at MC 8% only, so ``bd_wood`` and
    ``porosity_wood`` come from the MC 8% row of the material for both moisture
    contents.

    The paper's fit (Table 5): ``cn`` coordination number (-), ``e_b`` bond Young's
    modulus (Pa), ``sigma_c`` bond tensile (= shear) strength (Pa), ``rrmse`` fit
    error of eq. 16 (-).
    """

    material: str
    mc_percent: int
    sigma_z: float
    sigma_f: float
    sigma_f_sd: float
    dLf_D: float
    dLf_D_sd: float
    bd_pellet: float
    bd_pellet_sd: float
    porosity_pellet: float
    porosity_pellet_sd: float
    bd_sawdust: float
    bd_sawdust_sd: float
    porosity_sawdust: float
    porosity_sawdust_sd: float
    bd_wood: float
    bd_wood_sd: float
    porosity_wood: float
    porosity_wood_sd: float
    rho_sawdust_solid: float
    rho_sawdust_solid_sd: float
    rho_wood_solid: float
    rho_wood_solid_sd: float
    cn: float
    e_b: float
    sigma_c: float
    rrmse: float

    @property
    def sigma_z_mpa(self) -> int:
        """Compaction pressure in MPa, as the paper labels the variant."""
        return int(round(self.sigma_z / _MPA))

    @property
    def key(self) -> tuple[str, int, int]:
        """(material, mc_percent, sigma_z_mpa): the arguments of :func:`variant`."""
        return (self.material, self.mc_percent, self.sigma_z_mpa)

    @property
    def label(self) -> str:
        """Short human-readable name, e.g. ``"oak MC 8% 120 MPa"``."""
        return f"{self.material} MC {self.mc_percent}% {self.sigma_z_mpa} MPa"

    @property
    def bd_ratio(self) -> float:
        """BD_p / BD_w (-), the abscissa of the paper's Fig. 10."""
        return self.bd_pellet / self.bd_wood


def _allowed_error(name: str, value, allowed: Sequence, unit: str, hint: str = "") -> ValueError:
    msg = f"{name} must be one of {list(allowed)} ({unit}); got {value!r}"
    return ValueError(msg + (f"; {hint}" if hint else ""))


def _check_material(material) -> str:
    name = str(material).strip().lower() if isinstance(material, str) else None
    if name not in MATERIALS:
        raise _allowed_error("material", material, MATERIALS, "wood species")
    return name


def _check_choice(name: str, value, allowed: Sequence[int], unit: str, scale_hint) -> int:
    """Match ``value`` to one of ``allowed`` numbers, with a hint for unit slips."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise _allowed_error(name, value, allowed, unit) from None
    for a in allowed:
        if math.isclose(v, a, rel_tol=1e-9):
            return int(a)
    raise _allowed_error(name, value, allowed, unit, scale_hint(v, allowed))


def _mc_hint(v: float, allowed) -> str:
    if any(math.isclose(v * 100.0, a) for a in allowed):
        return "looks like a fraction; pass percent"
    return ""


def _sigma_z_hint(v: float, allowed) -> str:
    if any(math.isclose(v / _MPA, a) for a in allowed):
        return "looks like Pa; pass MPa"
    return ""


def _one_row(frame: pd.DataFrame, **where) -> dict:
    mask = np.ones(len(frame), dtype=bool)
    for col, val in where.items():
        mask &= (frame[col] == val).to_numpy()
    rows = frame[mask].to_dict("records")
    if len(rows) != 1:  # the shipped tables are complete; this guards against edits
        raise LookupError(f"expected one row for {where} in the shipped table, found {len(rows)}")
    return rows[0]


def variant(material: str, mc, sigma_z) -> Variant:
    """All measured scalars of one variant, see :class:`Variant`.

    ``material``: ``"birch"``, ``"oak"`` or ``"pine"`` (case-insensitive);
    ``mc``: moisture content in percent (8 or 20); ``sigma_z``: compaction pressure
    in MPa (60 or 120). Anything else raises :class:`ValueError` naming the
    parameter and the allowed values.
    """
    mat = _check_material(material)
    mc_p = _check_choice("mc", mc, MOISTURE_CONTENTS_PERCENT, "moisture content in percent", _mc_hint)
    sz = _check_choice("sigma_z", sigma_z, COMPACTION_PRESSURES_MPA, "compaction pressure in MPa",
                       _sigma_z_hint)
    return _variant(mat, mc_p, sz)


@lru_cache(maxsize=None)
def _variant(mat: str, mc_p: int, sz: int) -> Variant:
    t1 = _one_row(_shipped_frame(1), material=mat)
    t2 = _one_row(_shipped_frame(2), material=mat, mc_percent=mc_p)
    wood = _one_row(_shipped_frame(2), material=mat, mc_percent=_WOOD_MC_PERCENT)
    t3 = _one_row(_shipped_frame(3), material=mat, mc_percent=mc_p, sigma_z_mpa=sz)
    t5 = _one_row(_shipped_frame(5), material=mat, mc_percent=mc_p, sigma_z_mpa=sz)
    return Variant(
        material=mat,
        mc_percent=mc_p,
        sigma_z=sz * _MPA,
        sigma_f=float(t3["sigma_f_mpa_mean"]) * _MPA,
        sigma_f_sd=float(t3["sigma_f_mpa_sd"]) * _MPA,
        dLf_D=float(t3["dLf_D_mean"]),
        dLf_D_sd=float(t3["dLf_D_sd"]),
        bd_pellet=float(t2[f"bd_pellet_{sz}_mean"]),
        bd_pellet_sd=float(t2[f"bd_pellet_{sz}_sd"]),
        # Table 2 prints porosity in percent; Variant holds fractions.
        porosity_pellet=float(t2[f"p_pellet_{sz}_mean"]) / 100.0,
        porosity_pellet_sd=float(t2[f"p_pellet_{sz}_sd"]) / 100.0,
        bd_sawdust=float(t2["bd_sawdust_mean"]),
        bd_sawdust_sd=float(t2["bd_sawdust_sd"]),
        porosity_sawdust=float(t2["p_sawdust_mean"]) / 100.0,
        porosity_sawdust_sd=float(t2["p_sawdust_sd"]) / 100.0,
        bd_wood=float(wood["bd_wood_mean"]),
        bd_wood_sd=float(wood["bd_wood_sd"]),
        porosity_wood=float(wood["p_wood_mean"]) / 100.0,
        porosity_wood_sd=float(wood["p_wood_sd"]) / 100.0,
        rho_sawdust_solid=float(t1["rho_sawdust_solid_mean"]),
        rho_sawdust_solid_sd=float(t1["rho_sawdust_solid_sd"]),
        rho_wood_solid=float(t1["rho_wood_solid_mean"]),
        rho_wood_solid_sd=float(t1["rho_wood_solid_sd"]),
        cn=float(t5["cn"]),
        e_b=float(t5["e_b_mpa"]) * _MPA,
        sigma_c=float(t5["sigma_c_mpa"]) * _MPA,
        rrmse=float(t5["rrmse"]),
    )


def variants() -> list[Variant]:
    """The 12 variants of the paper, in the order of Table 3."""
    t3 = _shipped_frame(3)
    return [
        _variant(m, int(mc), int(sz))
        for m, mc, sz in zip(t3["material"], t3["mc_percent"], t3["sigma_z_mpa"], strict=True)
    ]


# --------------------------------------------------------------------------------------
# User curves: errors and raw CSV reading
# --------------------------------------------------------------------------------------


class MeasuredDataError(ValueError):
    """A user data file is malformed.

    Attributes ``path``, ``row`` (1-based data row: the first row after the header is
    1; ``#`` comment lines and blank lines are not counted; None for whole-file
    problems), ``line`` (1-based line in the file, or None) and ``column``.
    """

    def __init__(self, path, problem: str, *, row: int | None = None, line: int | None = None,
                 column: str | None = None):
        self.path = str(path)
        self.row = row
        self.line = line
        self.column = column
        self.problem = problem
        where = [f"{self.path}"]
        if row is not None:
            extra = f", line {line} of the file" if line is not None else ""
            where.append(f"data row {row} (1-based, header and comment lines not counted{extra})")
        if column is not None:
            where.append(f"column '{column}'")
        super().__init__(", ".join(where) + ": " + problem)


@dataclass
class _RawTable:
    """A CSV file split into header, text cells and comment metadata."""

    path: str
    columns: list[str]
    rows: list[list[str]]
    lines: list[int]  # file line of each data row
    meta: dict[str, str]

    def col(self, *names: str) -> str | None:
        """The column as written in the file matching one of ``names`` (any case)."""
        lowered = {c.lower(): c for c in self.columns}
        hits = [lowered[n.lower()] for n in names if n.lower() in lowered]
        if len(hits) > 1:
            raise MeasuredDataError(self.path, f"columns {hits} are alternatives; give only one of them")
        return hits[0] if hits else None

    def error(self, problem: str, row_index: int | None = None, column: str | None = None):
        row = None if row_index is None else row_index + 1
        line = None if row_index is None else self.lines[row_index]
        return MeasuredDataError(self.path, problem, row=row, line=line, column=column)


_META_ITEM = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.*?)\s*$")
_RESERVED_META = ("kind",)


def _comment_metadata(comment: str) -> dict[str, str]:
    """``key=value`` pairs of a ``#`` line; free text (no identifier key) is ignored."""
    pairs = {}
    for part in re.split(r"[,;]", comment):
        m = _META_ITEM.match(part)
        if m:
            pairs[m.group(1)] = m.group(2)
    return pairs


def _delimiter(header_line: str) -> str:
    # Test-machine software exports tab- or semicolon-separated files as often as CSV.
    for d in (",", "\t", ";"):
        if d in header_line:
            return d
    return ","


def _read_raw(path) -> _RawTable:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # -sig: Excel writes a BOM
    except OSError as exc:
        raise MeasuredDataError(path, f"cannot read the file ({exc.strerror or exc})") from exc
    except UnicodeDecodeError as exc:
        raise MeasuredDataError(path, f"is not UTF-8 text (byte {exc.start}: {exc.reason}); export the "
                                "data as UTF-8 CSV") from None
    if "\x00" in text:
        # csv refuses NUL bytes with its own error type; a binary file is not a table.
        raise MeasuredDataError(path, f"contains a NUL byte at character {text.index(chr(0))}: not a text table")
    meta: dict[str, str] = {}
    header: list[str] | None = None
    delim = ","
    rows, lines = [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            meta.update(_comment_metadata(stripped[1:]))
            continue
        if header is None:
            delim = _delimiter(line)
            header = [c.strip() for c in next(csv.reader([line], delimiter=delim))]
            continue
        cells = next(csv.reader([line], delimiter=delim))
        if len(cells) != len(header):
            raise MeasuredDataError(
                path, f"has {len(cells)} cells but the header has {len(header)} columns {header}",
                row=len(rows) + 1, line=lineno)
        rows.append(cells)
        lines.append(lineno)
    if header is None:
        raise MeasuredDataError(path, "no header row found (the file is empty or only comments)")
    return _RawTable(str(path), header, rows, lines, meta)


def _numeric_columns(raw: _RawTable, columns: Sequence[str]) -> dict[str, np.ndarray]:
    """Parse ``columns`` as finite floats, reporting the first bad cell in file order."""
    index = [raw.columns.index(c) for c in columns]
    out = {c: np.empty(len(raw.rows)) for c in columns}
    for r, cells in enumerate(raw.rows):
        for c, i in zip(columns, index, strict=True):
            text = cells[i].strip()
            if not text:
                raise raw.error("empty cell; a number is required", r, c)
            try:
                v = float(text)
            except ValueError:
                raise raw.error(f"non-numeric value {text!r}", r, c) from None
            if not math.isfinite(v):
                raise raw.error(f"value {text!r} is NaN or infinite", r, c)
            out[c][r] = v
    return out


def _replicate_column(raw: _RawTable, column: str | None, default: str) -> np.ndarray:
    if column is None:
        return np.full(len(raw.rows), str(default), dtype=object).astype(str)
    i = raw.columns.index(column)
    ids = []
    for r, cells in enumerate(raw.rows):
        rid = cells[i].strip()
        if not rid:
            raise raw.error("empty replicate id", r, column)
        ids.append(rid)
    return np.asarray(ids, dtype=str)


def _groups(replicate: np.ndarray) -> dict[str, np.ndarray]:
    """Row indices of each replicate, in order of first appearance."""
    groups: dict[str, list[int]] = {}
    for i, rid in enumerate(replicate):
        groups.setdefault(str(rid), []).append(i)
    return {k: np.asarray(v, dtype=int) for k, v in groups.items()}


# --------------------------------------------------------------------------------------
# User curves: checks
# --------------------------------------------------------------------------------------

MIN_POINTS_PER_REPLICATE = 3
# Load-cell noise around zero load: a few times the paper's +-0.02 N accuracy.
FORCE_NOISE_N = 0.05
# Stress noise around zero, as a fraction of the file's peak stress.
STRESS_NOISE_FRACTION = 1.0e-3
# A stress column in MPa above this is surely Pa (1 GPa is beyond any pellet).
_MPA_COLUMN_MAX = 1.0e3
# A stress column in Pa whose peak is below 1 kPa is surely MPa: on a 10 mm pellet
# 1 kPa is ~0.1 N, the load cell's noise level, not a breakage curve.
_PA_COLUMN_MIN_PEAK = 1.0e3
# A pellet diameter or height above 1 m given "in metres" is surely millimetres.
_MAX_LENGTH_M = 1.0


def _check_not_negative(raw, values, column, tolerance, what):
    bad = np.flatnonzero(values < -tolerance)
    if bad.size:
        r = int(bad[0])
        raise raw.error(f"negative {what} {float(values[r])!r}; compression must be positive "
                        "(if the machine exports compression as negative, negate the column)", r, column)


def _check_stress_units(raw, stress, column, in_mpa: bool):
    if in_mpa:
        bad = np.flatnonzero(stress > _MPA_COLUMN_MAX)
        if bad.size:
            r = int(bad[0])
            raise raw.error(f"value {float(stress[r])!r} MPa is above {_MPA_COLUMN_MAX:g} MPa; looks like Pa "
                            "(rename the column to the _pa form or convert)", r, column)
    elif stress.size and stress.max() < _PA_COLUMN_MIN_PEAK:
        r = int(np.argmax(stress))
        raise raw.error(f"largest value {float(stress[r])!r} Pa is below {_PA_COLUMN_MIN_PEAK:g} Pa; "
                        "looks like MPa (rename the column to the _mpa form or convert)", r, column)


def _check_fraction(raw, values, column, what):
    """Dimensionless deformations must lie in [0, 1]; above 1 is percent or a length."""
    bad = np.flatnonzero((values < 0.0) | (values > 1.0))
    if bad.size:
        r = int(bad[0])
        hint = "looks like percent or a length; give it as a fraction" if values[r] > 1.0 else "must be >= 0"
        raise raw.error(f"{what} {float(values[r])!r} is outside [0, 1]; {hint}", r, column)


def _check_monotonic(raw, values, groups, column, what):
    """Non-decreasing within each replicate (repeated values are sensor resolution)."""
    for rid, idx in groups.items():
        steps = np.diff(values[idx])
        bad = np.flatnonzero(steps < 0.0)
        if bad.size:
            r, prev = int(idx[bad[0] + 1]), int(idx[bad[0]])
            raise raw.error(
                f"{what} decreases from {float(values[prev])!r} (data row {prev + 1}) to "
                f"{float(values[r])!r} in replicate {rid!r}; it must be non-decreasing within a replicate "
                "(give an unloading branch as a separate file or replicate)", r, column)


def _check_point_count(raw, groups, column):
    for rid, idx in groups.items():
        if idx.size < MIN_POINTS_PER_REPLICATE:
            raise raw.error(f"replicate {rid!r} has {idx.size} point(s); at least "
                            f"{MIN_POINTS_PER_REPLICATE} are required", int(idx[0]) if idx.size else None,
                            column)
    if not groups:
        raise raw.error(f"no data rows; at least {MIN_POINTS_PER_REPLICATE} are required", None, column)


_DIAMETRAL_FORMS = ("either ['dL_D', 'sigma_1_mpa' or 'sigma_1_pa'] or a test-machine export "
                    "['displacement_mm' or 'displacement_m', 'force_n'] (optional 'time_s', 'replicate')")
_REQUIRED = {"diametral": _DIAMETRAL_FORMS,
             "compaction": "['dh_h0', 'sigma_z_mpa' or 'sigma_z_pa'] (optional 'replicate')"}


def _missing_columns(raw, kind: str):
    return raw.error(f"missing required columns; found {raw.columns}, required for a {kind} curve: "
                     f"{_REQUIRED[kind]}")


# --------------------------------------------------------------------------------------
# User curves: the Curve type
# --------------------------------------------------------------------------------------

CURVE_KINDS: tuple[str, ...] = ("diametral", "compaction")
# Column names written by save_curve, and the x column read for each kind.
_X_COLUMN = {"diametral": "dL_D", "compaction": "dh_h0"}
_Y_COLUMN = {"diametral": "sigma_1", "compaction": "sigma_z"}


def _check_kind(kind) -> str:
    if kind not in CURVE_KINDS:
        raise ValueError(f"kind must be one of {list(CURVE_KINDS)}; got {kind!r}")
    return kind


def _frozen_array(values, dtype) -> np.ndarray:
    arr = np.array(values, dtype=dtype)  # a copy, so freezing it cannot affect the caller
    arr.setflags(write=False)
    return arr


def interp_curve(x, y, at) -> np.ndarray:
    """Linear interpolation of a curve ``y(x)`` at the points ``at``; NaN outside.

    ``x`` must be non-decreasing; points with equal ``x`` (sensor resolution) are
    averaged first so that the result does not depend on their order. Units pass
    through: ``y`` and the result share them, ``x`` and ``at`` share theirs.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    at = np.asarray(at, dtype=float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"x and y must be 1-D of equal length; got shapes {x.shape} and {y.shape}")
    if x.size == 0:
        return np.full(at.shape, np.nan)
    if np.any(np.diff(x) < 0):
        raise ValueError("x must be non-decreasing")
    ux, inverse = np.unique(x, return_inverse=True)
    uy = np.bincount(inverse, weights=y) / np.bincount(inverse)
    return np.interp(at, ux, uy, left=np.nan, right=np.nan)


def _sample_sd(values, axis=None) -> np.ndarray:
    """Sample SD (ddof = 1, as for the paper's replicate SDs) ignoring NaN; NaN below 2 values."""
    values = np.asarray(values, dtype=float)
    n = np.sum(np.isfinite(values), axis=axis)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices: the answer is NaN
        mean = np.nanmean(values, axis=axis, keepdims=True)
        ss = np.nansum((values - mean) ** 2, axis=axis)
    return np.where(n >= 2, np.sqrt(ss / np.maximum(n - 1, 1)), np.nan)


def _nanmean(values, axis=None) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices: the answer is NaN
        return np.nanmean(values, axis=axis)


class MeanCurve(NamedTuple):
    """Replicates interpolated on a common grid.

    ``x`` the grid (-), ``mean`` and ``sd`` the mean and sample SD of ``y`` over the
    replicates covering each grid point (Pa; SD NaN where fewer than 2 do), ``n`` how
    many replicates cover each point.
    """

    x: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    n: np.ndarray


@dataclass(frozen=True, eq=False)
class Peak:
    """Peak of each replicate of a diametral curve (the paper's Table 3 quantities).

    ``replicate`` ids; ``sigma_f`` tensile strength = the maximum sigma_1 (Pa) and
    ``dLf_D`` the deformation at which it is first reached (-), one per replicate;
    the ``*_mean`` / ``*_sd`` properties give mean and sample SD over replicates
    (SD NaN for a single replicate).
    """

    replicate: tuple[str, ...]
    sigma_f: np.ndarray
    dLf_D: np.ndarray

    @property
    def sigma_f_mean(self) -> float:
        """Mean tensile strength over the replicates, Pa."""
        return float(np.mean(self.sigma_f))

    @property
    def sigma_f_sd(self) -> float:
        """Sample SD of the tensile strength over the replicates, Pa (NaN for one)."""
        return float(_sample_sd(self.sigma_f))

    @property
    def dLf_D_mean(self) -> float:
        """Mean deformation at failure over the replicates (-)."""
        return float(np.mean(self.dLf_D))

    @property
    def dLf_D_sd(self) -> float:
        """Sample SD of the deformation at failure over the replicates (-; NaN for one)."""
        return float(_sample_sd(self.dLf_D))


@dataclass(frozen=True, eq=False)
class Curve:
    """A measured stress-deformation curve, possibly several replicates, in SI units.

    ``x``: dimensionless deformation (dL/D for ``kind="diametral"``, dh/h0 for
    ``kind="compaction"``). ``y``: stress in Pa (sigma_1 of eq. 4, or the compaction
    pressure sigma_z). ``replicate``: one string id per point. ``metadata``:
    ``key -> value`` pairs from the file's ``#`` header plus what the loader derived
    (``diameter_m``, ``height_m`` for test-machine exports). ``source``: the file it
    was read from (not part of equality). Arrays are stored read-only.
    """

    x: np.ndarray
    y: np.ndarray
    replicate: np.ndarray | None = None
    kind: str = "diametral"
    metadata: Mapping[str, object] = field(default_factory=dict)
    source: str | None = None

    def __post_init__(self):
        _check_kind(self.kind)
        x = _frozen_array(self.x, float)
        y = _frozen_array(self.y, float)
        if x.ndim != 1 or x.shape != y.shape:
            raise ValueError(f"x and y must be 1-D of equal length; got shapes {x.shape} and {y.shape}")
        rep = np.full(x.shape, "1") if self.replicate is None else [str(r).strip() for r in self.replicate]
        rep = _frozen_array(rep, str)
        if rep.shape != x.shape:
            raise ValueError(f"replicate must have one id per point; got {rep.shape} for {x.shape} points")
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)
        object.__setattr__(self, "replicate", rep)
        object.__setattr__(self, "metadata", dict(self.metadata))

    def __eq__(self, other):
        if not isinstance(other, Curve):
            return NotImplemented
        return (self.kind == other.kind and np.array_equal(self.x, other.x)
                and np.array_equal(self.y, other.y) and np.array_equal(self.replicate, other.replicate)
                and dict(self.metadata) == dict(other.metadata))

    __hash__ = None  # mutable-looking (arrays): not hashable

    def __len__(self) -> int:
        return int(self.x.size)

    @property
    def replicates(self) -> tuple[str, ...]:
        """Replicate ids in order of first appearance."""
        return tuple(_groups(self.replicate))

    def select(self, replicate) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of one replicate (x dimensionless, y in Pa)."""
        idx = _groups(self.replicate).get(str(replicate))
        if idx is None:
            raise ValueError(f"replicate must be one of {list(self.replicates)}; got {replicate!r}")
        return self.x[idx], self.y[idx]

    def per_replicate(self):
        """Yield (replicate id, x, y) for each replicate, in order of first appearance."""
        for rid, idx in _groups(self.replicate).items():
            yield rid, self.x[idx], self.y[idx]

    def common_range(self) -> tuple[float, float]:
        """The x interval covered by every replicate (lo > hi if there is none)."""
        spans = [(xs.min(), xs.max()) for _, xs, _ in self.per_replicate()]
        return float(max(s[0] for s in spans)), float(min(s[1] for s in spans))

    def mean_curve(self, grid=None) -> MeanCurve:
        """Interpolate each replicate on ``grid`` (-) and average.

        Default grid: 101 points over the x range covered by every replicate. Grid
        points outside a replicate's range do not count for that replicate (see
        ``MeanCurve.n``). Returns :class:`MeanCurve` (stress in Pa).
        """
        if grid is None:
            lo, hi = self.common_range()
            if lo > hi:
                raise ValueError("the replicates share no x range; pass an explicit grid")
            grid = np.linspace(lo, hi, 101)
        grid = np.asarray(grid, dtype=float)
        stack = np.vstack([interp_curve(xs, ys, grid) for _, xs, ys in self.per_replicate()])
        n = np.sum(np.isfinite(stack), axis=0)
        return MeanCurve(grid, _nanmean(stack, axis=0), _sample_sd(stack, axis=0), n)

    def peak(self) -> Peak:
        """Tensile strength sigma_f (Pa) and dL_f/D (-) of each replicate.

        Only for diametral curves: the peak of sigma_1 is the failure point of eq. 4.
        """
        if self.kind != "diametral":
            raise ValueError(f"peak() applies to diametral curves; this curve is {self.kind!r}")
        ids, sig, dl = [], [], []
        for rid, xs, ys in self.per_replicate():
            ids.append(rid)
            i = int(np.argmax(ys))  # first maximum: failure is where the peak is reached
            sig.append(ys[i])
            dl.append(xs[i])
        return Peak(tuple(ids), np.asarray(sig), np.asarray(dl))


# --------------------------------------------------------------------------------------
# User curves: loading and saving
# --------------------------------------------------------------------------------------


def _parse_meta_value(text: str):
    try:
        v = float(text)
    except ValueError:
        return text
    return v if math.isfinite(v) else text


def _length_from(raw: _RawTable, arg, name: str) -> float:
    """Pellet diameter or height in metres, from the argument or the ``#`` header."""
    if arg is not None:
        try:
            value = float(arg)
        except (TypeError, ValueError):
            raise MeasuredDataError(raw.path, f"argument {name}={arg!r} is not a number (metres)") from None
        source = f"argument {name}"
        if value > _MAX_LENGTH_M:
            raise MeasuredDataError(raw.path, f"{source}={value!r} m is above {_MAX_LENGTH_M:g} m; "
                                    "looks like millimetres (pass metres)")
    else:
        key_mm, key_m = f"{name}_mm", f"{name}_m"
        if key_mm in raw.meta and key_m in raw.meta:
            raise MeasuredDataError(raw.path, f"header gives both {key_mm} and {key_m}; give one")
        key = key_mm if key_mm in raw.meta else key_m if key_m in raw.meta else None
        if key is None:
            raise MeasuredDataError(raw.path, f"pellet {name} not given: pass {name}= (metres) or add a "
                                    f"'# {name}_mm=...' header line")
        source = f"header '{key}={raw.meta[key]}'"
        try:
            value = float(raw.meta[key]) * (_MM if key == key_mm else 1.0)
        except ValueError:
            raise MeasuredDataError(raw.path, f"{source} is not a number") from None
    if not math.isfinite(value) or value <= 0.0:
        raise MeasuredDataError(raw.path, f"{source}: pellet {name} must be positive and finite")
    return value


def _metadata(raw: _RawTable, drop=()) -> dict:
    return {k: _parse_meta_value(v) for k, v in raw.meta.items() if k not in drop and k not in _RESERVED_META}


def _stress_column(raw: _RawTable, stem: str) -> tuple[str | None, bool]:
    """The ``<stem>_mpa`` or ``<stem>_pa`` column and whether it is in MPa."""
    mpa = raw.col(f"{stem}_mpa")
    pa = raw.col(f"{stem}_pa")
    if mpa and pa:
        raise raw.error(f"both {mpa!r} and {pa!r} given; give one stress column")
    return (mpa, True) if mpa else (pa, False)


def _stress_curve(raw: _RawTable, kind: str, x_name: str, replicate_default: str) -> Curve:
    """Form (a) diametral files and compaction files: x and a stress column."""
    y_stem = _Y_COLUMN[kind]
    xcol = raw.col(x_name)
    ycol, in_mpa = _stress_column(raw, y_stem)
    rcol = raw.col("replicate")
    if xcol is None or ycol is None:
        raise _missing_columns(raw, kind)
    vals = _numeric_columns(raw, [xcol, ycol])
    x, y = vals[xcol], vals[ycol]
    rep = _replicate_column(raw, rcol, replicate_default)
    groups = _groups(rep)
    _check_not_negative(raw, y, ycol, STRESS_NOISE_FRACTION * max(float(y.max(initial=0.0)), 0.0), "stress")
    _check_stress_units(raw, y, ycol, in_mpa)
    _check_fraction(raw, x, xcol, x_name)
    _check_monotonic(raw, x, groups, xcol, x_name)
    _check_point_count(raw, groups, rcol or xcol)
    y_si = y * _MPA if in_mpa else y
    return Curve(x, y_si, rep, kind, _metadata(raw), raw.path)


def _machine_curve(raw: _RawTable, diameter, height, replicate_default: str) -> Curve:
    """Form (b): a test-machine export converted with eq. 4.

    sigma_1 = P / (pi R h) with R = D / 2, and dL/D = (displacement - its first value
    in the replicate) / D, so an absolute crosshead position works as well.
    """
    dcol_mm, dcol_m = raw.col("displacement_mm"), raw.col("displacement_m")
    if dcol_mm and dcol_m:
        raise raw.error(f"both {dcol_mm!r} and {dcol_m!r} given; give one displacement column")
    dcol = dcol_mm or dcol_m
    fcol, tcol, rcol = raw.col("force_n"), raw.col("time_s"), raw.col("replicate")
    if dcol is None or fcol is None:
        raise _missing_columns(raw, "diametral")
    D = _length_from(raw, diameter, "diameter")
    h = _length_from(raw, height, "height")
    vals = _numeric_columns(raw, [c for c in (tcol, dcol, fcol) if c])
    disp = vals[dcol] * (_MM if dcol == dcol_mm else 1.0)
    force = vals[fcol]
    rep = _replicate_column(raw, rcol, replicate_default)
    groups = _groups(rep)
    _check_not_negative(raw, force, fcol, FORCE_NOISE_N, "force")
    if tcol:
        _check_monotonic(raw, vals[tcol], groups, tcol, "time")
    _check_monotonic(raw, vals[dcol], groups, dcol, "displacement")  # in the column's unit
    dl = np.empty_like(disp)
    for idx in groups.values():
        dl[idx] = disp[idx] - disp[idx[0]]
    too_far = np.flatnonzero(dl > D)
    if too_far.size:
        r = int(too_far[0])
        raise raw.error(f"displacement {float(vals[dcol][r])!r} is {dl[r]:.4g} m past the replicate's "
                        f"first row, more than the pellet diameter {D:.4g} m; check the column unit", r, dcol)
    _check_point_count(raw, groups, rcol or dcol)
    sigma_1 = force / (math.pi * (D / 2.0) * h)  # eq. 4
    meta = _metadata(raw, drop=("diameter_mm", "diameter_m", "height_mm", "height_m"))
    meta.update(diameter_m=D, height_m=h)
    return Curve(dl / D, sigma_1, rep, "diametral", meta, raw.path)


def load_curve(path, kind: str = "diametral", *, diameter: float | None = None,
               height: float | None = None, replicate: str = "1") -> Curve:
    """Read a measured curve from a CSV file and return a :class:`Curve` (SI units).

    ``kind="diametral"`` accepts two forms:

    (a) columns ``dL_D`` (-) and ``sigma_1_mpa`` or ``sigma_1_pa``;
    (b) a test-machine export with ``displacement_mm`` or ``displacement_m``,
        ``force_n`` (N) and optionally ``time_s`` (s). The pellet's ``diameter`` and
        ``height`` (metres) come from the arguments or, when those are None, from
        ``# diameter_mm=10.0, height_mm=6.4`` header comments (``_m`` keys also
        work). Converted with eq. 4: sigma_1 = P / (pi R h), R = D / 2, and
        dL/D = displacement / D with the displacement measured from the first row of
        each replicate.

    ``kind="compaction"``: columns ``dh_h0`` (-) and ``sigma_z_mpa`` or
    ``sigma_z_pa``.

    All forms take an optional ``replicate`` column (any text id); without one every
    point gets the id ``replicate``. Column names are case-insensitive; comma, tab
    and semicolon separators are recognised. ``# key=value`` comment lines become
    ``Curve.metadata`` (numbers as float).

    Raises :class:`MeasuredDataError` (a ValueError) naming file, 1-based data row and
    column for: missing columns, empty or non-numeric cells, NaN/inf, negative
    force (beyond FORCE_NOISE_N = 0.05 N), stress (beyond 0.1% of the peak),
    diameter or height, stress units inconsistent with the column name, deformations
    outside [0, 1], displacement span larger than the diameter, x (or time) decreasing
    within a replicate, fewer than 3 points in a replicate.
    """
    kind = _check_kind(kind)
    raw = _read_raw(path)
    declared = raw.meta.get("kind")
    if declared is not None and declared != kind:
        raise MeasuredDataError(raw.path, f"the header declares kind={declared} "
                                f"but kind={kind!r} was requested")
    if kind == "compaction":
        return _stress_curve(raw, kind, "dh_h0", replicate)
    if raw.col("dL_D") is not None:
        return _stress_curve(raw, kind, "dL_D", replicate)
    return _machine_curve(raw, diameter, height, replicate)


def _check_meta_item(key, value):
    if not isinstance(key, str) or not _META_ITEM.match(f"{key}=x"):
        raise ValueError(f"metadata key {key!r} must be an identifier (letters, digits, _)")
    if key in _RESERVED_META:
        raise ValueError(f"metadata key {key!r} is reserved")
    if isinstance(value, (float, np.floating)) and not math.isfinite(value):
        raise ValueError(f"metadata {key}={value!r}: only finite numbers can be saved")
    if any(ch in str(value) for ch in ",;\n\r"):
        raise ValueError(f"metadata {key}={value!r}: values cannot contain ',', ';' or line breaks")


def _meta_text(value) -> str:
    # repr of a Python float is the shortest string that reads back to the same double.
    if isinstance(value, (bool, np.bool_)):
        return str(value)
    if isinstance(value, (int, float, np.integer, np.floating)):
        return repr(float(value)) if isinstance(value, (float, np.floating)) else str(int(value))
    return str(value)


def save_curve(curve: Curve, path) -> None:
    """Write ``curve`` to CSV so that :func:`load_curve` returns an equal Curve.

    Columns ``replicate``, ``dL_D`` / ``dh_h0`` (-) and ``sigma_1_pa`` /
    ``sigma_z_pa`` (Pa), floats written with the shortest exact representation;
    ``kind`` and the metadata go to ``# key=value`` lines. Metadata must be numbers or
    text without ``,;`` (a text that looks like a number reads back as float).
    """
    for key, value in curve.metadata.items():
        _check_meta_item(key, value)
    for rid in curve.replicates:
        if rid != rid.strip() or not rid or any(ch in rid for ch in "\n\r"):
            raise ValueError(f"replicate id {rid!r} cannot be saved (empty, padded or multi-line)")
    xname, yname = _X_COLUMN[curve.kind], f"{_Y_COLUMN[curve.kind]}_pa"
    with open(path, "w", newline="", encoding="utf-8") as fh:
        fh.write("# pelletdem curve file; x dimensionless; stress in Pa\n")
        fh.write(f"# kind={curve.kind}\n")
        for key, value in curve.metadata.items():
            fh.write(f"# {key}={_meta_text(value)}\n")
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(["replicate", xname, yname])
        for rid, xv, yv in zip(curve.replicate, curve.x, curve.y, strict=True):
            writer.writerow([rid, repr(float(xv)), repr(float(yv))])


def concat_curves(curves: Iterable[Curve]) -> Curve:
    """Join single-pellet curves (e.g. one test-machine export each) into one Curve.

    All must share ``kind``; replicate ids must not repeat across curves (load each
    file with its own ``replicate=`` id). Metadata is kept only where all agree.
    """
    curves = list(curves)
    if not curves:
        raise ValueError("curves is empty")
    kinds = {c.kind for c in curves}
    if len(kinds) != 1:
        raise ValueError(f"curves must share one kind; got {sorted(kinds)}")
    seen: set[str] = set()
    for c in curves:
        clash = seen.intersection(c.replicates)
        if clash:
            raise ValueError(f"replicate ids {sorted(clash)} repeat across curves; "
                             "load each file with a distinct replicate=")
        seen.update(c.replicates)
    common = {k: v for k, v in curves[0].metadata.items() if all(c.metadata.get(k) == v for c in curves)}
    return Curve(np.concatenate([c.x for c in curves]), np.concatenate([c.y for c in curves]),
                 np.concatenate([c.replicate for c in curves]), curves[0].kind, common)
