"""How much a fit owes to its own packings: a jackknife over the fit seeds.

Every design point of a model is simulated on the same k packings (the fit seeds), so the
emulator's mean is the population's mean plus those k packings' luck, one smooth offset shared
by the whole box. That offset does not average out over design points, and the fitted
parameters carry it: measured on the engine's `tiny` pellets, four fit packings that came out
about one standard error looser and stiffer in late compaction than sixteen others moved every
fit of a hardening strength the same way. The sandwich errors of :mod:`pelletdem.loop_fit`
allow for it through the packings' correlation (:mod:`pelletdem.loop_noise`), but that
correlation is a model (one factor within a condition, shrunk coefficients between them)
fitted to deviations that are, at nearby design points, the same k packings again: it has
nearer k - 1 degrees of freedom than its nominal count and can understate the luck.

:func:`packing_jackknife` measures the luck's effect on the estimate directly: the model is
fitted again on emulators of the means over k - 1 packings, leaving each one out in turn, and
the spread of those fits gives the jackknife covariance (k - 1) / k sum (u_j - u_mean)^2 of the
fitted position. For an estimate linear in the data this is the sandwich with the packings'
raw sample covariance, whatever its structure. :func:`with_packing_luck` then takes, per
parameter, the variance from the data's scatter plus the larger of the two estimates of the
fit packings' part (the correlation model's and the jackknife's): from k packings the
jackknife is itself uncertain, and the larger of two estimates errs on the side of an
interval that covers.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Optional

import numpy as np

from .loop_data import Dataset
from .loop_emulator import Emulator
from .loop_fit import EmulatedFit, fit_emulated
from .loop_noise import PackingNoise

__all__ = ["packing_jackknife", "with_packing_luck"]


def packing_jackknife(emulator: Emulator, members: np.ndarray, data: Dataset, u: np.ndarray) -> Optional[np.ndarray]:
    """Jackknife covariance (unit box squared, (d, d)) of the position fitted to ``data``
    over ``emulator``'s box, from ``members`` (points, k, m): each design point's prediction
    per packing (the emulator's rows, in order). Each packing left out in turn, the means and
    standard errors of the other k - 1 are emulated (starting from ``emulator``'s
    hyperparameters) and fitted from ``u`` (the full fit). None with fewer than 3 packings or
    members that do not match the emulator."""
    V = np.asarray(members, float)
    if V.ndim != 3 or V.shape[0] != len(emulator.U) or V.shape[2] != emulator.n_outputs or V.shape[1] < 3:
        return None
    k = V.shape[1]
    us = []
    for j in range(k):
        rest = np.delete(V, j, axis=1)
        Y = np.mean(rest, axis=1)
        SE = np.std(rest, axis=1, ddof=1) / math.sqrt(k - 1)
        try:
            emu = Emulator(emulator.space, emulator.U, Y, SE, warm=emulator, active=emulator.active)
        except ValueError:
            return None
        us.append(fit_emulated(emu, data, u, starts=0).u)
    us = np.array(us)
    dev = us - us.mean(axis=0, keepdims=True)
    return (k - 1.0) / k * dev.T @ dev


def with_packing_luck(fit: EmulatedFit, emulator: Emulator, data: Dataset, noise: PackingNoise, k: int,
                      jackknife: Optional[np.ndarray]) -> EmulatedFit:
    """``fit`` with each parameter's variance the data's part of its sandwich variance plus
    the larger of the fit packings' part (the correlation's, :mod:`pelletdem.loop_noise`) and
    the ``jackknife``'s (unit box squared, :func:`packing_jackknife`), where that is larger
    than the sandwich; its standard errors and :attr:`EmulatedFit.widen` (so its profile
    intervals too) follow. The model's ensemble means are over ``k`` packings. Unchanged
    without a jackknife or a Jacobian."""
    if jackknife is None or fit.jac is None:
        return fit
    J = np.asarray(fit.jac, float)
    se_model = emulator.noise()
    c_data, c_model = noise.covariance_parts(data, se_model, se_model * math.sqrt(k))
    d = np.sqrt(np.maximum(np.diag(c_data + c_model), 1e-300))
    dd = np.outer(d, d)
    plain = np.linalg.pinv(J.T @ J)
    v_data = np.diag(plain @ (J.T @ (c_data / dd) @ J) @ plain)
    v_model = np.diag(plain @ (J.T @ (c_model / dd) @ J) @ plain)
    cov = np.array(fit.cov, float, copy=True)
    se, widen = dict(fit.se), dict(fit.widen)
    for i, a in enumerate(emulator.space.axes):
        v = v_data[i] + max(v_model[i], float(jackknife[i, i]))
        if not (math.isfinite(v) and v > cov[i, i]):
            continue
        cov[i, i] = v
        se[a.name] = math.sqrt(v) * a.relative_scale()
        if plain[i, i] > 0:
            widen[a.name] = max(widen.get(a.name, 1.0), v / plain[i, i])
    return dataclasses.replace(fit, cov=cov, se=se, widen=widen, jackknife=np.asarray(jackknife, float))
