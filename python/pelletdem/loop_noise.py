"""How one packing's luck ties a condition's observations together, and misfits that allow for it.

A pellet that happens to be strong is strong along its whole diametral curve, at its peak and
in its deformation at failure: the errors of a condition's observations share a cause (which
packing it was) and are correlated. Summing their squared z-scores as if they were independent
counts one lucky packing many times: the fit believes its parameters too well (intervals too
narrow) and a chi2 swings far more than a chi-square of n degrees of freedom does.

:class:`PackingNoise` estimates the correlation of the packings' scatter between observations
from a model's design: at every design point the same k packings were simulated, so the
deviations of each packing from its point's mean, pooled over the points near the fit (on log
values for positive numbers), sample that correlation with (points x (k - 1)) degrees of
freedom. Within a condition it is modelled by one common factor (the packing's luck) with a
loading per observation, which tens of degrees of freedom estimate well. Between conditions
the model's packings are shared too (each condition presses the same fills), and a fill that
comes out dense is dense at every pressure: the compaction curves of one fill pressed to 60
and to 120 MPa are one curve up to 60 MPa. That correlation is kept as sampled, each
coefficient shrunk towards zero by its own sampling error (1 / sqrt(dof)), and the whole
matrix made a valid correlation (:func:`_valid_correlation`). Conditions the design did
not simulate (held out) borrow the correlation of the nearest fit condition, observation by
observation (same quantity, nearest position along its curve), and are tied to no other.

:meth:`PackingNoise.covariance` combines it with the data's own standard errors into the
covariance of each difference model - data: the model's part follows the packings'
correlation within and between conditions; the data's part too, up to the model's packing
variance, within a condition and between conditions whose replicates are the same packings
(``Dataset.same_packings``: a laboratory's are other pellets), and what of the data's
variance exceeds that (measurement noise) stays independent. The fits use
the resulting correlation of the misfits only linearly, in sandwich standard errors
(:mod:`pelletdem.loop_fit`), never inverted: inverted, the noise of a correlation estimated
from tens of packings is amplified (on the engine's pellets it tripled the chi2 of the truth).
"""
from __future__ import annotations

import math
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .loop_data import Condition, Dataset, Observation

__all__ = ["PackingNoise", "observation_key"]

Key = Tuple[Condition, str, float]


def observation_key(o: Observation) -> Key:
    """(condition, quantity, x): what identifies an observation across datasets."""
    return (o.condition, o.quantity, round(float(o.x), 12) if math.isfinite(o.x) else math.nan)


class PackingNoise:
    """The correlation (-) of the packings' scatter between the observations ``keys`` (see the
    module docstring): ``corr``, an (m, m) matrix within conditions (zero between them), and
    ``shared``, the (m, m) correlation within and between conditions where every condition
    presses the same packings (default ``corr``), estimated with ``dof`` degrees of freedom
    (0 for the independent model)."""

    def __init__(self, keys: Sequence[Key], corr: np.ndarray, dof: float = 0.0,
                 shared: Optional[np.ndarray] = None):
        self.keys = tuple(keys)
        m = len(self.keys)
        self.corr = np.asarray(corr, float).reshape(m, m)
        self.shared = self.corr.copy() if shared is None else np.asarray(shared, float).reshape(m, m)
        self.dof = float(dof)
        self._index = {k: i for i, k in enumerate(self.keys)}

    @classmethod
    def independent(cls) -> "PackingNoise":
        """No correlation between any observations."""
        return cls((), np.zeros((0, 0)))

    @classmethod
    def estimate(cls, data: Dataset, members: np.ndarray, weights: Optional[np.ndarray] = None) -> "PackingNoise":
        """The correlation from ``members`` (points, k, m): each design point's k packings'
        predictions of ``data``'s m observations (their units; NaN where a simulation failed,
        which drops that point), each point's deviations weighted by ``weights`` (points,
        default equal). Weight the points near the fitted parameters: a curve point at a fixed
        dL/D lies before the peak at one parameter set and after it at another, and its
        scatter and correlations change with that."""
        V = np.asarray(members, float)
        if V.ndim != 3 or V.shape[2] != len(data):
            raise ValueError(f"members of shape {V.shape} do not match {len(data)} observations")
        w = np.ones(len(V)) if weights is None else np.asarray(weights, float).reshape(len(V))
        ok = np.all(np.isfinite(V), axis=(1, 2)) & np.isfinite(w) & (w > 0)
        V, w = V[ok], w[ok]
        g, k, m = V.shape
        if g == 0 or k < 2:
            return cls.independent()
        w = w / w.sum()
        positive = np.all(V > 0, axis=(0, 1))
        V = np.where(positive[None, None, :], np.log(np.where(V > 0, V, 1.0)), V)
        dev = (V - V.mean(axis=1, keepdims=True)) * math.sqrt(k / (k - 1.0))
        # rows scaled so that their plain mean square is the weighted one
        dev = (dev * np.sqrt(w * g)[:, None, None]).reshape(g * k, m)
        sd = np.sqrt(np.mean(dev * dev, axis=0))
        varying = sd > 1e-12 * np.maximum(1.0, np.abs(V).mean(axis=(0, 1)))
        E = np.zeros_like(dev)
        E[:, varying] = dev[:, varying] / sd[varying]
        sample = E.T @ E / len(E)
        dof = (k - 1.0) / float(np.sum(w * w))  # effective points x (k - 1)
        corr = np.eye(m)
        conds = [o.condition for o in data.observations]
        for c in dict.fromkeys(conds):
            idx = np.array([i for i in range(m) if conds[i] == c and varying[i]], int)
            if len(idx) >= 2:
                corr[np.ix_(idx, idx)] = _one_factor(sample[np.ix_(idx, idx)])
        cid = {c: k for k, c in enumerate(dict.fromkeys(conds))}
        c_arr = np.array([cid[c] for c in conds])
        between = (c_arr[:, None] != c_arr[None, :]) & varying[:, None] & varying[None, :]
        shrunk = sample * np.clip(1.0 - (1.0 / dof) / np.maximum(sample * sample, 1e-300), 0.0, 1.0)
        shared = _valid_correlation(np.where(between, shrunk, corr))
        return cls([observation_key(o) for o in data.observations], corr, dof, shared)

    def _mapping(self, data: Dataset) -> List[Optional[int]]:
        """Each observation of ``data`` as an index into :attr:`keys` (None: no counterpart)."""
        out: List[Optional[int]] = []
        by_cond: Dict[Condition, List[int]] = {}
        for i, (c, _, _) in enumerate(self.keys):
            by_cond.setdefault(c, []).append(i)
        reach: Dict[Tuple[Condition, str], float] = {}
        for dataset_keys in (self.keys, [observation_key(o) for o in data.observations]):
            for c, q, x in dataset_keys:
                if math.isfinite(x):
                    reach[(c, q)] = max(reach.get((c, q), 0.0), abs(x))
        for o in data.observations:
            key = observation_key(o)
            if key in self._index:
                out.append(self._index[key])
                continue
            c = o.condition
            near = sorted((cc for cc in by_cond if cc.material == c.material),
                          key=lambda cc: (abs(cc.mc - c.mc), abs(math.log(cc.sigma_z / c.sigma_z))))
            pick = None
            for cc in near:
                same = [i for i in by_cond[cc] if self.keys[i][1] == o.quantity]
                if not same:
                    continue
                if not math.isfinite(o.x):
                    pick = same[0]
                else:
                    pos = o.x / max(reach.get((c, o.quantity), 0.0), 1e-300)
                    pick = min(same, key=lambda i: abs(self.keys[i][2] / max(reach[(cc, o.quantity)], 1e-300)
                                                       - pos) if math.isfinite(self.keys[i][2]) else math.inf)
                break
            out.append(pick)
        return out

    def correlation(self, data: Dataset,
                    shared: Optional[Callable[[Condition, Condition], bool]] = None) -> np.ndarray:
        """The packings' correlation between ``data``'s observations (-). Observations of
        conditions the estimate never saw take their counterparts' correlation and are tied
        to no other condition. Conditions the estimate saw that ``shared(a, b)`` links (as
        groups: linked to a linked one is linked) take the sampled correlation within and
        between them (:attr:`shared`); between any others nothing is relied on (R = 0).
        Default: no two conditions share packings."""
        n = len(data)
        idx = self._mapping(data)
        conds = [o.condition for o in data.observations]
        own = [a is not None and self.keys[a][0] == c for a, c in zip(idx, conds)]
        group = {c: k for k, c in enumerate(dict.fromkeys(conds))}
        if shared is not None:
            seen = [c for c, ok in zip(conds, own) if ok]
            for a in dict.fromkeys(seen):
                for b in dict.fromkeys(seen):
                    if group[a] != group[b] and shared(a, b):
                        old = group[b]
                        group = {c: (group[a] if g == old else g) for c, g in group.items()}
        members = {}
        for c, ok in zip(conds, own):
            if ok:
                members.setdefault(group[c], set()).add(c)
        R = np.eye(n)
        for i in range(n):
            for j in range(i + 1, n):
                a, b = idx[i], idx[j]
                if a is None or b is None or a == b:
                    continue
                # a whole group takes its principal block of the valid matrix `shared`
                if own[i] and own[j] and group[conds[i]] == group[conds[j]] and len(members[group[conds[i]]]) > 1:
                    R[i, j] = R[j, i] = self.shared[a, b]
                elif conds[i] == conds[j] and self.keys[a][0] == self.keys[b][0]:
                    R[i, j] = R[j, i] = self.corr[a, b]
        return R

    def covariance(self, data: Dataset, model_se: np.ndarray, model_sd: Optional[np.ndarray] = None) -> np.ndarray:
        """Covariance (units of ``data``, squared) of the differences model - data for
        ``data``'s observations, against a model whose means carry the standard errors
        ``model_se`` (per observation), one pellet's packing scatter being ``model_sd``
        (default: the data's replicate SD). The data's replicate variance up to the model's
        packing variance is correlated within a condition, and between conditions whose
        replicates are the same packings (``data.same_packings``); the rest of it (measurement
        noise) is independent. The model's packings are the same in every condition."""
        c_data, c_model = self.covariance_parts(data, model_se, model_sd)
        return c_data + c_model

    def covariance_parts(self, data: Dataset, model_se: np.ndarray,
                         model_sd: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
        """(data's, model's) parts of :meth:`covariance` (same arguments and units): what the
        measured means' scatter contributes, and what the model's own packings do."""
        R = self.correlation(data, data.packings_shared)
        R_model = self.correlation(data, lambda a, b: True)
        m = np.nan_to_num(np.asarray(model_se, float))
        sd, n = data.sds, np.array([o.n for o in data.observations], float)
        pack = sd if model_sd is None else np.minimum(np.nan_to_num(np.asarray(model_sd, float)), sd)
        c = pack / np.sqrt(n)                                   # the data's packing part of its SE
        e2 = np.maximum(data.standard_errors ** 2 - c * c, 0.0)  # and the independent rest
        return np.outer(c, c) * R + np.diag(e2), np.outer(m, m) * R_model

    def misfit_correlation(self, data: Dataset, model_se: np.ndarray,
                           model_sd: Optional[np.ndarray] = None) -> np.ndarray:
        """The correlation (-) of ``data``'s misfit z-scores against a model (arguments as in
        :meth:`covariance`)."""
        C = self.covariance(data, model_se, model_sd)
        d = np.sqrt(np.maximum(np.diag(C), 1e-300))
        return C / np.outer(d, d)


#: The largest loading of one observation on its pellet's common factor: no observation is
#: taken as all luck of the packing.
MAX_LOADING = 0.95


def _one_factor(sample: np.ndarray) -> np.ndarray:
    """A one-factor correlation lambda lambda^T (unit diagonal) from a sample correlation, the
    loadings lambda clipped to |lambda| <= MAX_LOADING. One
    factor, a pellet's luck (how strong its packing came out), carries most of the shared
    scatter, and its loadings are estimated well from tens of degrees of freedom where a full
    correlation matrix is not: the rest of a sample correlation from so few is noise that a
    whitening would amplify."""
    # principal-axis factoring: the leading eigenpair of the correlation with the shared
    # variances (communalities) on its diagonal, iterated; the plain leading eigenvector would
    # count each observation's own scatter as shared and overstate the loadings
    S = np.array(sample, float)
    off = np.abs(S - np.diag(np.diag(S)))
    h = off.max(axis=1) if len(S) > 1 else np.zeros(len(S))
    lam = np.zeros(len(S))
    for _ in range(50):
        np.fill_diagonal(S, h)
        w, Q = np.linalg.eigh(S)
        lam = np.clip(math.sqrt(max(float(w[-1]), 0.0)) * Q[:, -1], -MAX_LOADING, MAX_LOADING)
        if np.max(np.abs(lam * lam - h)) < 1e-6:
            break
        h = lam * lam
    R = np.outer(lam, lam)
    np.fill_diagonal(R, 1.0)
    return R


def _valid_correlation(R: np.ndarray) -> np.ndarray:
    """The symmetric matrix ``R`` (unit diagonal) made a valid correlation: its negative
    eigenvalues (which blocks estimated apart, or coefficients shrunk apart, can leave) set
    to zero and the diagonal brought back to one."""
    R = 0.5 * (R + R.T)
    w, Q = np.linalg.eigh(R)
    P = (Q * np.maximum(w, 0.0)) @ Q.T
    d = np.sqrt(np.maximum(np.diag(P), 1e-300))
    P = P / np.outer(d, d)
    np.fill_diagonal(P, 1.0)
    return P
