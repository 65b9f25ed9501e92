"""Measured data: the paper's tables and the user's own test curves, in one namespace.

This module re-exports three others, so that ``measured.variant(...)`` and
``measured.load_curve(...)`` work side by side:

* :mod:`pelletdem.paper_tables`: the paper's Tables 1-5, shipped as CSV package data
  (:func:`solid_density`, :func:`bulk_density`, :func:`bulk_density_long`,
  :func:`tensile_strength`, :func:`dem_parameters`, :func:`best_fit_dem`,
  :func:`load_table`, :func:`table_provenance`), and :func:`variant` / :func:`variants`,
  every measured scalar of one of the 12 experimental variants as a :class:`Variant` in
  SI units (Pa, kg/m3, fractions).
* :mod:`pelletdem.curves`: the :class:`Curve` type (stress in Pa against a dimensionless
  deformation, with replicates), :class:`MeanCurve`, :class:`Peak`,
  :func:`interp_curve` and :func:`concat_curves`.
* :mod:`pelletdem.curve_files`: :func:`load_curve` reads a diametral-compression or
  compaction curve from CSV, checks it and returns a :class:`Curve`; :func:`save_curve`
  writes it back losslessly. A malformed file raises :class:`MeasuredDataError` naming
  the file, the 1-based data row and the column.
"""

from __future__ import annotations

from .curve_files import (
    FORCE_NOISE_N,
    MIN_POINTS_PER_REPLICATE,
    STRESS_NOISE_FRACTION,
    MeasuredDataError,
    load_curve,
    save_curve,
)
from .curves import CURVE_KINDS, Curve, MeanCurve, Peak, concat_curves, interp_curve
from .paper_tables import (
    COMPACTION_PRESSURES_MPA,
    MATERIALS,
    MOISTURE_CONTENTS_PERCENT,
    Variant,
    best_fit_dem,
    bulk_density,
    bulk_density_long,
    dem_parameters,
    load_table,
    solid_density,
    table_provenance,
    tensile_strength,
    variant,
    variants,
)

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
    "MIN_POINTS_PER_REPLICATE",
    "FORCE_NOISE_N",
    "STRESS_NOISE_FRACTION",
]
