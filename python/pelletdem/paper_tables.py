"""The paper's Tables 1-5, shipped as CSV package data (``pelletdem/data``).

The loaders return tidy :class:`pandas.DataFrame` objects with the units of the CSV
(named in the column names: ``_mpa``, ``_percent``; densities in kg/m3), and
:func:`variant` collects every measured scalar of one of the 12 experimental variants
into a :class:`Variant` in SI units (Pa, kg/m3, fractions). :mod:`pelletdem.measured`
re-exports everything here.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from io import StringIO
from typing import Sequence

import numpy as np
import pandas as pd

__all__ = [
    "MATERIALS",
    "MOISTURE_CONTENTS_PERCENT",
    "COMPACTION_PRESSURES_MPA",
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
]

# `__package__` is empty when this file is imported by path (tests, scripts).
_PACKAGE = __package__ or "pelletdem"
_MPA = 1.0e6

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

