"""The discrepancy loop, in one namespace: fit, find the residual, trace it to an effect the
model lacks, add the effect, and report the error before and after.

:func:`close_loop` runs the whole procedure (described in :mod:`pelletdem.loop_selection`).
This module re-exports the public names of the modules the loop is made of:

* :mod:`pelletdem.loop_data`: :class:`Condition`, :class:`Observation`, :class:`Dataset`
  (from the paper's tables, from measured curves) and :func:`synthetic_dataset` (data made by
  a simulator with a hidden effect); :data:`QUANTITIES`, :data:`DIAMETRAL_PARTS`,
  :data:`COMPACTION_SPLIT`.
* :mod:`pelletdem.loop_simulators`: :class:`Simulator`, :class:`Prediction`,
  :class:`EngineSimulator` (the C++ pellet through the calibration's run cache and
  executors) and :class:`FunctionSimulator` (any Python function).
* :mod:`pelletdem.loop_fit`: :func:`fit_model` (Levenberg-Marquardt on z-scores, on the
  least-squares pieces of :mod:`pelletdem.optimize`) and its :class:`FitState`.
* :mod:`pelletdem.loop_selection`: :func:`close_loop`, the candidates it ranks
  (:class:`Candidate`) and what it found (:class:`LoopResult`).

The report is :func:`pelletdem.loop_report.write_report` (and ``pelletdem loop``).
"""
from __future__ import annotations

from .loop_data import COMPACTION_SPLIT, DIAMETRAL_PARTS, QUANTITIES, Condition, Dataset, Observation
from .loop_fit import FitState, fit_model
from .loop_selection import Candidate, LoopResult, close_loop
from .loop_simulators import EngineSimulator, FunctionSimulator, Prediction, Simulator, synthetic_dataset

__all__ = [
    "Condition", "Observation", "Dataset", "Prediction", "Simulator", "FunctionSimulator",
    "EngineSimulator", "FitState", "Candidate", "LoopResult", "fit_model", "close_loop",
    "synthetic_dataset", "QUANTITIES", "DIAMETRAL_PARTS", "COMPACTION_SPLIT",
]
