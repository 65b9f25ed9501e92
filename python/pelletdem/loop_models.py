"""One model of the discrepancy loop: the baseline, or the baseline with effects switched on.

:func:`fit_model` simulates the model on a space-filling design of its box (every point on
the same packings, the loop's *fit seeds*), builds its emulator, fits the data on it, and then
simulates the fitted parameters twice more: on the fit seeds (the residual a person looks at,
and the pairing for the candidates' probes) and on the *check seeds*, packings used neither in
the design nor in the fit, on every condition (the held-out test, which a lucky packing
cannot pass). All simulations go through the simulator's cache, so a design shared by several
loops (the same box, conditions and seeds) is simulated once.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .loop_data import Condition, Dataset, split_material
from .loop_emulator import Emulator, Space, design
from .loop_fit import EmulatedFit, fit_emulated, profile, welch_z
from .loop_jackknife import packing_jackknife, with_packing_luck
from .loop_noise import PackingNoise
from .loop_simulators import Ensemble, Simulator

__all__ = ["ModelFit", "REFINE_ROUNDS", "SETTLED", "design_size", "relaxing_axes", "share_relaxations",
           "active_axes", "effective_dim", "tied_design", "simulate_design", "local_design", "fit_model",
           "nested_points", "ensemble_z", "emulator_correlation", "chi2_of", "with_more_check_packings"]


#: Rounds of refinement of each model's emulator around its fit (at most). Three left 8 of 15
#: models that reached the third still moving (by up to 0.27 of the box, on spring-back
#: laws), and such a fit was judged where its emulator had seen no simulation.
REFINE_ROUNDS = 5
#: A fit that moves less than this fraction of the unit box in a refinement round has settled.
SETTLED = 0.02

#: A candidate's fit whose strength profile finds chi2 this much lower elsewhere (other
#: parameters re-optimised) was a local minimum of its emulator, and is fitted and refined
#: again from the profile's best point (once). The optimiser agrees with itself to far less;
#: 1 is a one-sigma improvement in one parameter.
ESCAPE_CHI2 = 1.0

#: Design points within about this distance of the fit (unit box) inform the packings'
#: correlation (:mod:`pelletdem.loop_noise`): Gaussian weights of this width.
NOISE_RADIUS = 0.1


def design_size(dim: int) -> int:
    """Design points for a box of ``dim`` parameters: 6 per dimension, at least 12."""
    return max(12, 6 * dim)


def active_axes(space: Space, data: Dataset) -> List[Tuple[int, ...]]:
    """Per observation of ``data``, the axes of ``space`` its prediction moves with: the shared
    ones and its condition's material's own (``E_b[oak]`` moves no pine pellet)."""
    return [tuple(i for i, a in enumerate(space.axes) if split_material(a.name)[1] in ("", o.condition.material))
            for o in data.observations]


def effective_dim(space: Space) -> int:
    """The most axes one condition's predictions move with: the shared ones and one material's."""
    mats = {split_material(a.name)[1] for a in space.axes} - {""}
    return max(sum(split_material(a.name)[1] in ("", m) for a in space.axes) for m in (mats or {""}))


def tied_design(space: Space, n: int, seed: int = 0) -> np.ndarray:
    """A Sobol design of ``n`` points (unit box) on which every material's copy of a parameter
    (``E_b[oak]``, ``E_b[pine]``) takes the same value: each material's axes, with the shared
    ones, are covered as one material's box alone would be, at the cost of its dimension, not
    of all materials' (each output's emulator sees only its own axes, :func:`active_axes`)."""
    keys = [split_material(a.name)[0] for a in space.axes]
    roots = list(dict.fromkeys(keys))
    return design(len(roots), n, seed)[:, [roots.index(k) for k in keys]]


def relaxing_axes(sim: Simulator, space: Space, conditions: Sequence[Condition]) -> Tuple[int, ...]:
    """The axes of ``space`` along which the simulator's relaxed pellets change (a compaction
    effect's strength, k1), from the simulator's own :meth:`Simulator.same_relaxation` at the
    two ends of each axis (the others at the box's centre)."""
    mid = space.params(np.full(space.dim, 0.5))
    out = []
    for k, a in enumerate(space.axes):
        try:
            same = sim.same_relaxation(dict(mid, **{a.name: a.lo}), dict(mid, **{a.name: a.hi}), conditions)
        except ValueError:  # a parameter the simulator checks only when it runs: as if it relaxed
            same = False
        if not same:
            out.append(k)
    return tuple(out)


def share_relaxations(U: np.ndarray, axes: Sequence[int]) -> np.ndarray:
    """``U`` with its second half taking the first half's coordinates on ``axes`` (row i + h
    those of row i, h = ceil(n / 2)): along a compaction parameter every new value compacts
    new pellets (most of a run's cost), and this way each relaxed pellet serves two design
    points, which differ on the other axes. Unchanged when every axis (or none) relaxes."""
    U = np.array(U, dtype=float, copy=True)
    if not axes or len(axes) >= U.shape[1] or len(U) < 2:
        return U
    h = (len(U) + 1) // 2
    idx = list(axes)
    U[h:, idx] = U[:len(U) - h, idx]
    return U


@dataclass
class ModelFit:
    """A fitted model: ``effects`` switched on (names), its box (``space``), ``emulator`` and
    emulated ``fit``; the fitted parameters simulated on the fit seeds (``direct``) and on the
    check seeds (``check``), every condition; the misfit z-scores of the fit data on the fit
    seeds (``z_direct``) and on the check seeds (``z_check_fit``) and of the held-out data on
    the check seeds (``z_check_held``, None without held-out data); ``noise``: the packings'
    correlation between observations (:mod:`pelletdem.loop_noise`) its errors allow for;
    ``members``: each packing's prediction at the emulator's design points (points, packings,
    observations), from which its errors measure what the fit owes to the fit packings
    (:mod:`pelletdem.loop_jackknife`); ``last_move``: how far the fit moved in its last
    refinement (fraction of the unit box; nan when none ran), at least :data:`SETTLED` when
    the rounds ran out before it settled."""

    effects: Tuple[str, ...]
    space: Space
    emulator: Emulator
    fit: EmulatedFit
    direct: Dict[Condition, Ensemble]
    check: Dict[Condition, Ensemble]
    z_direct: np.ndarray
    z_check_fit: np.ndarray
    z_check_held: Optional[np.ndarray]
    noise: PackingNoise
    members: Optional[np.ndarray] = None
    last_move: float = math.nan

    @property
    def settled(self) -> bool:
        """False when the refinement rounds ran out with the fit still moving: its errors and
        the gates then read an emulator that has not simulated the optimum."""
        return not self.last_move >= SETTLED

    @property
    def name(self) -> str:
        """'baseline', or 'baseline + a + b'."""
        return " + ".join(("baseline",) + self.effects)

    @property
    def n_params(self) -> int:
        """Fitted parameters."""
        return self.space.dim

    def bic(self, n: int) -> float:
        """chi2 + p ln(n) of the emulated fit on n observations."""
        return self.fit.chi2 + self.n_params * math.log(max(n, 2))


def ensemble_z(ensembles: Dict[Condition, Ensemble], data: Dataset) -> np.ndarray:
    """Misfit z-scores (-) of ``data`` under directly simulated ensembles: the Welch score
    (:func:`pelletdem.loop_fit.welch_z`) of ensemble mean - measured mean, with the data's SE
    (n - 1 degrees of freedom) and the ensemble's (k - 1 for k packings); NaN where a
    prediction failed."""
    mse = np.array([ensembles[o.condition].mean_se(o) for o in data.observations]).reshape(len(data), 2)
    k = np.array([len(ensembles[o.condition].seeds) for o in data.observations], float)
    z = welch_z(mse[:, 0] - data.values, data.standard_errors, data.dofs, mse[:, 1], k - 1)
    return np.where(np.isfinite(mse[:, 0]), z, np.nan)


def emulator_correlation(noise: PackingNoise, emu: Emulator, data: Dataset, k: int) -> np.ndarray:
    """The correlation (-) of the emulated misfits of ``data``: the emulator's ensemble means
    carry its noise as standard error, from ``k`` packings."""
    se = emu.noise()
    return noise.misfit_correlation(data, se, se * math.sqrt(k))


def chi2_of(z: np.ndarray) -> float:
    """sum z^2 over the finite z (inf when any is not finite)."""
    z = np.asarray(z, float)
    return float(np.sum(z ** 2)) if np.all(np.isfinite(z)) else math.inf


def simulate_design(sim: Simulator, space: Space, data: Dataset, seeds: Sequence[int],
                    n: Optional[int] = None, U: Optional[np.ndarray] = None,
                    relaxing: Sequence[int] = (), errors: Optional[List[str]] = None
                    ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(U, Y, SE, V): the design positions of ``space`` (default its Sobol design of ``n``
    points, its points paired on the ``relaxing`` axes, :func:`share_relaxations`), the
    ensemble means and standard errors of every observation of ``data`` there, simulated on
    ``seeds``, and each packing's own prediction, V[point, packing, observation]; the default
    design gives every material the same bonds (:func:`tied_design`). ``errors``:
    a list that gets, per point whose simulation failed, its parameters and the engine's
    message."""
    if U is None:
        U = share_relaxations(tied_design(space, n or design_size(effective_dim(space))), relaxing)
    conds = data.conditions
    preds = sim.predict_many([space.params(u) for u in U], conds, tuple(seeds))
    Y = np.empty((len(U), len(data)))
    SE = np.empty_like(Y)
    V = np.empty((len(U), len(seeds), len(data)))
    for k, p in enumerate(preds):
        bad = next((e.error for e in p.values() if not e.ok), "")
        if bad and errors is not None:
            errors.append(", ".join(f"{a} = {v:.4g}" for a, v in space.params(U[k]).items()) + f": {bad}")
        for i, o in enumerate(data.observations):
            Y[k, i], SE[k, i] = p[o.condition].mean_se(o)
            V[k, :, i] = p[o.condition].values(o)
    return U, Y, SE, V


def local_design(space: Space, u: np.ndarray, half_width: float, n: int, seed: int,
                 relaxing: Sequence[int] = ()) -> np.ndarray:
    """``u`` and ``n`` Sobol points of the box of ``half_width`` (unit coordinates) around it,
    clipped to the model's box, paired on the ``relaxing`` axes (:func:`share_relaxations`):
    where a refinement of the emulator simulates."""
    pts = np.clip(u + (design(space.dim, max(n, 2), seed) - 0.5) * 2.0 * half_width, 0.0, 1.0)
    return np.vstack([u[None, :], share_relaxations(pts[:n], relaxing)])


def _emulate(space: Space, U, Y, SE, name: str, data: Dataset, warm: Optional[Emulator] = None,
             errors: Sequence[str] = ()) -> Emulator:
    ok = np.all(np.isfinite(Y), axis=1)
    if not ok.any():
        raise RuntimeError(f"{name}: every design point's simulation failed"
                           + (f" (the first: {errors[0]})" if errors else ""))
    return Emulator(space, U[ok], Y[ok], SE[ok], warm, active=active_axes(space, data))


def fit_model(sim: Simulator, space: Space, effects: Sequence[str], fit_data: Dataset,
              heldout: Optional[Dataset], fit_seeds: Sequence[int], check_seeds: Sequence[int],
              start: Optional[Dict[str, float]] = None, n_design: Optional[int] = None,
              log: Callable[[str], None] = lambda s: None, refine: int = REFINE_ROUNDS,
              shared: Optional[Tuple[np.ndarray, ...]] = None,
              noise: Optional[PackingNoise] = None) -> ModelFit:
    """Design, emulate, fit and check one model (see the module docstring). ``start``: a
    starting point (SI) for the fit; the design's best points are tried too. ``refine``: at
    most this many rounds of refinement, each simulating the fitted point and 2 d + 2 points
    around it (in a box of half-width 0.15, 0.075, ... of the unit box) and fitting again on
    the richer emulator, until the fit moves less than :data:`SETTLED` of the box. ``shared``: (U, Y, SE)
    already simulated in this box on the same packings (the nested model's design, its new
    axis at the strength that switches the effect off, :func:`nested_points`), which join
    the emulator without being simulated again (and the packings' own predictions there, as a
    fourth array, for the jackknife of :mod:`pelletdem.loop_jackknife`). ``noise``: the packings' correlation between
    the observations (:mod:`pelletdem.loop_noise`); None estimates it from this model's
    design (after the refinement, near the fit); a candidate takes its baseline's, so the
    two models' errors allow for the same correlation."""
    name = " + ".join(("baseline",) + tuple(effects))
    n_new = design_size(effective_dim(space)) if n_design is None else n_design
    log(f"{name}: simulating {n_new} design points on {len(fit_seeds)} packings x "
        f"{len(fit_data.conditions)} conditions")
    relaxing = relaxing_axes(sim, space, fit_data.conditions)
    errors: List[str] = []
    U, Y, SE, V = simulate_design(sim, space, fit_data, fit_seeds, n_design, relaxing=relaxing, errors=errors)
    UV, VV = [U], [V]  # the points simulated here, with each packing's prediction
    k = len(fit_seeds)
    estimate = noise is None
    noise = PackingNoise.independent() if noise is None else noise
    rows = [V]  # every emulator row's packings, in the emulator's order (None: not known)
    if shared is not None:
        U, Y, SE = np.vstack([U, shared[0]]), np.vstack([Y, shared[1]]), np.vstack([SE, shared[2]])
        rows.append(shared[3] if len(shared) > 3 and shared[3] is not None else None)
    emu = _emulate(space, U, Y, SE, name, fit_data, errors=errors)
    fit = fit_emulated(emu, fit_data, space.unit(start) if start else None,
                       corr=emulator_correlation(noise, emu, fit_data, k))
    for attempt in range(2):
        moved = math.nan
        for r in range(refine):
            Ul = local_design(space, fit.u, 0.15 / 2 ** r, 2 * effective_dim(space) + 2, seed=attempt * refine + r + 1,
                              relaxing=relaxing)
            _, Yl, SEl, Vl = simulate_design(sim, space, fit_data, fit_seeds, U=Ul, errors=errors)
            UV.append(Ul)
            VV.append(Vl)
            rows.append(Vl)
            U, Y, SE = np.vstack([U, Ul]), np.vstack([Y, Yl]), np.vstack([SE, SEl])
            emu = _emulate(space, U, Y, SE, name, fit_data, emu, errors)
            new = fit_emulated(emu, fit_data, fit.u, corr=emulator_correlation(noise, emu, fit_data, k))
            moved = float(np.max(np.abs(new.u - fit.u)))
            log(f"{name}: refinement {r + 1} ({len(U)} points), the fit moved {moved:.3f} of the box")
            fit = new
            if moved < SETTLED:
                break
            if r == refine - 1:
                log(f"{name}: the fit had not settled after {refine} refinements (it moved {moved:.3f} of the "
                    "box in the last): its errors and the gates read an emulator that has not simulated its optimum")
        if estimate:
            # the packings' correlation where the model was fitted, and the fit's errors with it
            Ua = np.vstack(UV)
            w = np.exp(-0.5 * (np.linalg.norm(Ua - fit.u[None, :], axis=1) / NOISE_RADIUS) ** 2)
            noise = PackingNoise.estimate(fit_data, np.concatenate(VV), w)
            fit = fit_emulated(emu, fit_data, fit.u, corr=emulator_correlation(noise, emu, fit_data, k))
            log(f"{name}: the packings' correlation between observations near the fit, from {noise.dof:.0f} "
                f"degrees of freedom (median |r| within a condition {_median_within(noise):.2f}): the parameters' "
                "variances widen by " + ", ".join(f"{fit.widen[a]:.2f}" for a in space.names))
        failed = ~np.all(np.isfinite(Y), axis=1)
        members = np.concatenate(rows)[~failed] if all(r is not None for r in rows) else None
        if members is not None:
            jack = packing_jackknife(emu, members, fit_data, fit.u)
            before = np.diag(fit.cov).copy()
            fit = with_packing_luck(fit, emu, fit_data, noise, k, jack)
            if jack is not None:
                log(f"{name}: fitted again leaving out each fit packing in turn: jackknife variance "
                    + ", ".join(f"{jack[i, i] / max(before[i], 1e-300):.2f}" for i in range(space.dim))
                    + " of the sandwich's; reported variances x "
                    + ", ".join(f"{c / max(b, 1e-300):.2f}" for c, b in zip(np.diag(fit.cov), before)))
        if not effects:
            break
        # the candidate's strength, added last
        strength = space.names[-1]
        profile(emu, fit_data, fit, strength)
        drop = fit.below_fit(strength)
        if drop <= ESCAPE_CHI2 or attempt:
            break
        # the fit is a local minimum of its emulator: start again where the profile found better
        far = space.params(fit.profile_best[strength])
        log(f"{name}: {strength}'s profile lies {drop:.1f} below the fit at " + ", ".join(
            f"{a} = {far[a]:.4g}" for a in space.names) + ": the fit was a local minimum; fitted again from there")
        fit = fit_emulated(emu, fit_data, fit.profile_best[strength],
                           corr=emulator_correlation(noise, emu, fit_data, k))
    conds = fit_data.conditions + (heldout.conditions if heldout is not None else [])
    direct = sim.predict(fit.params, conds, tuple(fit_seeds))
    check = sim.predict(fit.params, conds, tuple(check_seeds))
    z_held = ensemble_z(check, heldout) if heldout is not None else None
    mf = ModelFit(tuple(effects), space, emu, fit, direct, check, ensemble_z(direct, fit_data),
                  ensemble_z(check, fit_data), z_held, noise, members, moved)
    log(f"{name}: {len(U)} design points ({int(failed.sum())} failed), emulated chi2/n "
        f"{fit.chi2_per_point:.2f} at " + ", ".join(f"{k} = {fit.params[k]:.4g}" for k in space.names)
        + f"; fresh packings: chi2/n {chi2_of(mf.z_check_fit) / len(fit_data):.2f} fit"
        + (f", {chi2_of(z_held) / len(heldout):.2f} held out" if heldout is not None else ""))
    if errors:
        log(f"{name}: the first failed design point: {errors[0]}")
    return mf


def with_more_check_packings(sim: Simulator, mf: ModelFit, seeds: Sequence[int], fit_data: Dataset,
                             heldout: Optional[Dataset]) -> ModelFit:
    """``mf`` checked on its check packings and ``seeds`` (more packings no fit used): its
    fitted parameters simulated there, the check ensembles and their z-scores extended."""
    conds = list(mf.check)
    more = sim.predict(mf.fit.params, conds, tuple(seeds))
    check = {c: Ensemble(tuple(mf.check[c].seeds) + tuple(more[c].seeds),
                         tuple(mf.check[c].members) + tuple(more[c].members)) for c in conds}
    return dataclasses.replace(mf, check=check, z_check_fit=ensemble_z(check, fit_data),
                               z_check_held=ensemble_z(check, heldout) if heldout is not None else None)


def _median_within(noise: PackingNoise) -> float:
    conds = [k[0] for k in noise.keys]
    n = len(conds)
    pairs = [abs(noise.corr[i, j]) for i in range(n) for j in range(i + 1, n) if conds[i] == conds[j]]
    return float(np.median(pairs)) if pairs else 0.0


def nested_points(mf: ModelFit, off_unit: float) -> Tuple[np.ndarray, ...]:
    """The design of ``mf`` (U, Y, SE, and each packing's predictions or None) as points of a
    box with one more axis, at unit position ``off_unit`` on it: the model with a candidate
    effect switched off is ``mf`` itself."""
    e = mf.emulator
    return np.column_stack([e.U, np.full(len(e.U), float(off_unit))]), e.Y, e.SE, mf.members


def unit_jacobian(mf: ModelFit, fit_data: Dataset, h: float = 1e-3) -> np.ndarray:
    """d(emulated mean)/du at the fitted position, one column per axis (outputs' units per unit
    of the box), by central differences on the emulator."""
    u0 = mf.fit.u
    cols: List[np.ndarray] = []
    for k in range(len(u0)):
        up, dn = u0.copy(), u0.copy()
        up[k] = min(1.0, u0[k] + h)
        dn[k] = max(0.0, u0[k] - h)
        mp, _ = mf.emulator.predict(up[None, :])
        md, _ = mf.emulator.predict(dn[None, :])
        cols.append((mp[0] - md[0]) / max(up[k] - dn[k], 1e-12))
    return np.array(cols).T


__all__ += ["unit_jacobian"]
