"""Calibration of the DEM micro-parameters against the paper's measurements, in one namespace.

What the paper did (sections 3.1.4, 3.1.5, 3.2): one particle yield strength p_y (hence k1,
eq. 7) for all materials from the compaction curves, then, per variant, the bond modulus E_b
and strength sigma_c = tau_c (r_b = 20 um fixed) from the diametral stress-deformation curve
by minimising RRMSE (eq. 16): 8-10 runs per variant in two or three one-parameter sweeps
(Fig. 14), 80 runs for the 12 variants. The calibration does the same with less hand work.
This module re-exports its public names, so that ``from pelletdem import calibrate as C;
C.fit(...)`` reaches all of it; each part lives in a module of its own:

* :mod:`pelletdem.runs`: a run as a :class:`RunSpec` (:func:`make_spec` from the named
  :data:`PARAMETERS`), its cache key (:func:`cache_key`, :func:`engine_fingerprint`,
  :data:`CACHE_FORMAT`) and the relax key its relaxed pellet is shared by.
* :mod:`pelletdem.run_cache`: :class:`RunCache`, one JSON record per run on disk, so a
  scan or fit resumes where it stopped.
* :mod:`pelletdem.worker`: :func:`run_point` (one run, in a worker process), the relaxed
  pellets it branches from (:func:`clone_pellet`, :func:`clear_memo`,
  :data:`RELAX_MEMO_SIZE`) and the failure point of a diametral curve
  (:func:`failure_point`, :data:`FAILURE_DROP`).
* :mod:`pelletdem.execution`: the executors runs go to (process pool, serial, Dask) and the
  driver-side evaluator that serves cached runs and retries failed ones.
* :mod:`pelletdem.objectives`: :class:`Targets` and the errors a pellet is scored by
  (:func:`diametral_error`, :func:`curve_error`, :func:`density_error`, :func:`score`,
  :func:`compaction_targets`, :data:`CENSORED_DLF_FACTOR`).
* :mod:`pelletdem.search`: :func:`scan` (a grid, :class:`ScanResult`) and :func:`fit`
  (:class:`FitResult`; a search started from the paper's scaling laws,
  :data:`SCALING_EXPONENTS`, or Nelder-Mead), on the least-squares pieces of
  :mod:`pelletdem.optimize`.
* :mod:`pelletdem.variants`: :func:`calibrate_variants`, the paper's procedure for its 12
  variants, and its :class:`CalibrationReport`.

Units: SI everywhere (Pa, m, N/m, kg/m^3); tables shown to people carry the unit in the column
name (``_mpa``).
"""
from __future__ import annotations

from .objectives import (
    CENSORED_DLF_FACTOR,
    Targets,
    compaction_targets,
    curve_error,
    density_error,
    diametral_error,
    score,
)
from .run_cache import RunCache
from .runs import CACHE_FORMAT, PARAMETERS, RunSpec, cache_key, engine_fingerprint, make_spec
from .search import SCALING_EXPONENTS, FitResult, ScanResult, fit, scan
from .variants import CalibrationReport, calibrate_variants
from .worker import FAILURE_DROP, RELAX_MEMO_SIZE, clear_memo, clone_pellet, failure_point, run_point

__all__ = [
    "PARAMETERS", "SCALING_EXPONENTS", "CACHE_FORMAT", "RELAX_MEMO_SIZE",
    "RunSpec", "make_spec", "cache_key", "engine_fingerprint", "RunCache", "run_point", "clone_pellet",
    "clear_memo", "failure_point", "FAILURE_DROP", "CENSORED_DLF_FACTOR",
    "Targets", "diametral_error", "curve_error", "density_error", "score",
    "compaction_targets", "ScanResult", "scan", "FitResult", "fit",
    "CalibrationReport", "calibrate_variants",
]
