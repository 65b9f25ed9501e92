"""The discrepancy loop, in one namespace: fit, find the residual, trace it to an effect the
model lacks, add the effect, and report the error before and after.

:func:`close_loop` runs the whole procedure (described in :mod:`pelletdem.loop_selection`).
This module re-exports the public names of the modules the loop is made of:

* :mod:`pelletdem.loop_data`: :class:`Condition`, :class:`Observation`, :class:`Dataset`
  (from the paper's tables, from measured curves, from a data manifest).
* :mod:`pelletdem.loop_synthetic`: :func:`synthetic_dataset` (data made by a simulator the
  way a laboratory makes them, with a hidden effect).
* :mod:`pelletdem.loop_simulators`: :class:`Simulator`, :class:`Prediction`,
  :class:`Ensemble` (one condition on several packings), :class:`EngineSimulator` (the C++
  pellet) and :class:`FunctionSimulator` (any Python function).
* :mod:`pelletdem.loop_emulator`: :class:`Axis`, :class:`Space`, :class:`Emulator` (the
  Gaussian-process surrogate every fit runs on).
* :mod:`pelletdem.loop_models`: :func:`fit_model` and the :class:`ModelFit` it returns.
* :mod:`pelletdem.loop_screen`: the candidates' :class:`Screen` and :class:`Power`.
* :mod:`pelletdem.loop_selection`: :func:`close_loop` and what it found (:class:`LoopResult`,
  its :class:`Step` s and :class:`Trial` s).

The report is :func:`pelletdem.loop_report.write_report` (and ``pelletdem loop``).
"""
from __future__ import annotations

from .loop_data import COMPACTION_SPLIT, DIAMETRAL_GRID, DIAMETRAL_PARTS, QUANTITIES, Condition, Dataset, Observation
from .loop_emulator import Axis, Emulator, Space
from .loop_models import ModelFit, fit_model
from .loop_screen import Power, Screen
from .loop_selection import CHECK_SEEDS, FIT_SEEDS, LoopResult, Step, Trial, close_loop
from .loop_simulators import EngineSimulator, Ensemble, FunctionSimulator, Prediction, Simulator
from .loop_synthetic import DATA_SEEDS, synthetic_dataset

__all__ = [
    "Condition", "Observation", "Dataset", "Prediction", "Ensemble", "Simulator", "FunctionSimulator",
    "EngineSimulator", "Axis", "Space", "Emulator", "ModelFit", "fit_model", "Screen", "Power", "Trial", "Step",
    "LoopResult", "close_loop", "synthetic_dataset", "FIT_SEEDS", "CHECK_SEEDS", "DATA_SEEDS", "QUANTITIES",
    "DIAMETRAL_PARTS", "DIAMETRAL_GRID", "COMPACTION_SPLIT",
]
