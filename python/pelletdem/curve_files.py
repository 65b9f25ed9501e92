"""User curve files: :func:`load_curve` reads a diametral-compression or compaction curve
from CSV, checks it and returns a :class:`~pelletdem.curves.Curve` in SI units
(dimensionless deformation, stress in Pa); :func:`save_curve` writes it back losslessly.

A malformed user file raises :class:`MeasuredDataError` naming the file, the data row
(1-based, counting data rows only, not the header or ``#`` comment lines) and the
column, so the user can go straight to the offending cell. :mod:`pelletdem.measured`
re-exports everything here.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from .curves import Curve, check_curve_kind, replicate_groups

__all__ = [
    "MeasuredDataError",
    "load_curve",
    "save_curve",
    "MIN_POINTS_PER_REPLICATE",
    "FORCE_NOISE_N",
    "STRESS_NOISE_FRACTION",
]

_MPA = 1.0e6
_MM = 1.0e-3
# Column names written by save_curve, and the x column read for each kind.
_X_COLUMN = {"diametral": "dL_D", "compaction": "dh_h0"}
_Y_COLUMN = {"diametral": "sigma_1", "compaction": "sigma_z"}


# --------------------------------------------------------------------------------------
# Errors and raw CSV reading
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


# --------------------------------------------------------------------------------------
# Checks
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
# Loading and saving
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
    groups = replicate_groups(rep)
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
    groups = replicate_groups(rep)
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
    kind = check_curve_kind(kind)
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
