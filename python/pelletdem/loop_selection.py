"""Closing the loop with measured data: fit, find the residual, trace it to an effect the model
lacks, add the effect, and report the error before and after (:func:`close_loop`).

The pellet is a stochastic simulator: every prediction is a mean over packings with its
standard error, and every model is fitted on its emulator (:mod:`pelletdem.loop_models`). The
procedure is forward selection:

1. **Baseline.** The paper's model with the base parameters free is designed, emulated and
   fitted on the fit data (the conditions not held out). If most of its packings do not pass
   the peak of their diametral test (no failure inside the window: the "peak" is the end of
   the test, and a bond effect shows nothing), the simulator's window is widened (x 1.5, up
   to dL/D = :data:`MAX_WINDOW`) and the baseline fitted again; what cannot be widened is
   said in the verdict. A base parameter fitted at an end of its box is not fitted: the box is
   widened there (by half its width, :mod:`pelletdem.loop_box`, up to :data:`MAX_WIDEN`
   times) and the baseline fitted again with every point already simulated; a parameter
   still pinned is said in the verdict.
2. **Residual.** The fitted model's residual (simulated on the fit seeds) is described by
   :mod:`pelletdem.residuals` for the report: by part of the curve, by condition, trends.
3. **Screen.** Every remaining candidate of the library is probed on top of the model and
   ranked by the chi2 it could remove to first order (:func:`pelletdem.loop_screen.screen`).
4. **Fit in full** the best ``screen_top`` candidates that pass the screening threshold: each
   with its strength free, on a design of its own box, on the same packings.
5. **Accept** a candidate when it passes all of: its fit chi2 falls by more than
   ``threshold`` (chi-square with one degree of freedom at ``alpha`` divided by the number of
   candidates screened, at least ln n, so its BIC falls too); on packings used neither in the
   design nor in the fit (the *check seeds*), the chi2 of all the data (fit and held-out
   conditions) falls by at least 4 and by ``min_check_gain`` of the model's excess over the
   number of points, where that chi2 was above what noise gives (n + 2 sqrt(2 n)): a model
   already at the noise level on fresh packings has nothing there to gain; that fall exceeds
   its scatter between the check packings (a jackknife over them: a compaction effect is
   checked on pellets compacted again, whose luck does not cancel as the same pellets' does;
   where only this fails, as many packings again are simulated and the gates asked again);
   and the held-out
   conditions' chi2 does not rise by more than its noise (2 sqrt(2 n_held)), and the RRMSE
   (eq. 16) of all the data on those packings does not rise by more than twice its scatter
   between them (a jackknife over the packings; a chi2 can fall by fitting
   the most precise observations, a density, at the cost of all the others). The fresh
   packings are what a lucky packing cannot pass: an effect acting during compaction
   re-packs the pellet at every strength, and the fit may pick the strength whose packing
   happens to match; the check's packings are new at every strength alike. The best accepted
   candidate (lowest chi2 on the check seeds) is added, even if what remains is still
   structured, with the others it cannot be told from named beside it (:func:`pick`); those
   tied with it are first checked again on as many packings more, where the lower chi2
   decides. The loop goes back to 3 with the rest, up to ``max_effects``.
6. **Report** every step: residual, screening, full fits, the effect added and why the others
   were not, errors before and after on fit and held-out data, and what the data could have
   revealed of each candidate (:func:`pelletdem.loop_screen.detection_power`).
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
from scipy import stats

from .effects import EFFECTS, Effect, clash
from .loop_box import pinned, pinned_list, pinned_note, rebox, widened
from .loop_check import check_chi2, check_chi2_se, check_rrmse, held_chi2, model_errors, rrmse_rise_se
from .loop_data import Condition, Dataset
from .loop_emulator import Axis, Space
from .loop_models import ModelFit, effective_dim, fit_model, nested_points, with_more_check_packings
from .loop_screen import Power, Screen, detection_power, screen
from .loop_separation import separation, statement
from .loop_simulators import MAX_WINDOW, Simulator, next_window
from .residuals import DEFAULT_ALPHA, ResidualSummary, describe

__all__ = ["FIT_SEEDS", "CHECK_SEEDS", "MAX_WINDOW", "unfailed", "fit_window", "Trial", "Step", "LoopResult",
           "close_loop", "describe_residual", "Gates", "judge", "pick", "rrmse_rise_se", "check_chi2_se"]

#: Times the baseline's box is widened where its fit is pinned at an end (pelletdem.loop_box).
MAX_WIDEN = 2

#: Packings every model is designed and fitted on, and the fresh ones its fit is checked on.
FIT_SEEDS = (0, 1, 2, 3)
CHECK_SEEDS = (100, 101, 102, 103)
#: Two accepted candidates whose chi2 on fresh packings differ by less than this (each adds one
#: parameter, so this is their BIC difference there) are not told apart by the data: under 2 is
#: "not worth more than a bare mention" (Kass and Raftery 1995). The better one is added and
#: the other named beside it, as is one whose emulated fit was the better.
TIE_CHI2 = 2.0
#: The fall of a candidate's chi2 on fresh packings must exceed this many of its standard
#: errors between those packings (:func:`check_chi2_se`). The fit test is the significance
#: test (at alpha / K); the fresh packings guard against luck: a compaction effect checked on
#: pellets compacted again must do better than their scatter, once. Twice refused true
#: compaction effects whose fall was 1.4-1.7 of it on the toy pellet.
LUCK_SE = 1.0


@dataclass
class Trial:
    """A candidate fitted in full: its ``model``, the emulated fit's chi2 drop
    (``delta_chi2``), the chi2 of all the data on fresh packings before and after
    (``check_before``, ``check_after``), whether it was ``accepted`` and ``why``."""

    effect: Effect
    model: ModelFit
    delta_chi2: float
    check_before: float
    check_after: float
    accepted: bool
    why: str


@dataclass
class Step:
    """One round of forward selection: the ``model`` it started from, its ``residual``, the
    ``screens``, the ``trials``, the effect ``added`` (None when none was) and its ``rivals``:
    other accepted candidates within :data:`TIE_CHI2` of it on fresh packings or better in the
    emulated fit; ``powers``: what the data could reveal of each screened candidate on top of
    this round's model; ``separations``: rival -> how far these data separate it from the
    effect added (:func:`pelletdem.loop_separation.separation`); ``rival_notes``: what the
    check of the rivals on more packings found, and each rival's separation, in words."""

    model: ModelFit
    residual: ResidualSummary
    screens: List[Screen]
    trials: List[Trial]
    added: Optional[str]
    threshold: float
    note: str = ""
    rivals: List[str] = field(default_factory=list)
    powers: Dict[str, Power] = field(default_factory=dict)
    separations: Dict[str, float] = field(default_factory=dict)
    rival_notes: List[str] = field(default_factory=list)


@dataclass
class LoopResult:
    """Everything :func:`close_loop` found. ``chosen``: the effects added, in order;
    ``verdict``: the sentence that sums it up; ``steps``; ``baseline`` and ``final`` models;
    ``errors``: model name -> {fit / held-out chi2 per point and RRMSE}; ``power``: effect ->
    what these data could reveal; ``n_simulations``; ``wall_time_s``; ``log``."""

    fit_data: Dataset
    heldout_data: Optional[Dataset]
    baseline: ModelFit
    final: ModelFit
    steps: List[Step]
    chosen: List[str]
    verdict: str
    errors: Dict[str, Dict[str, float]]
    power: Dict[str, Power]
    n_simulations: int
    wall_time_s: float
    log: List[str] = field(default_factory=list)

    def table(self) -> str:
        """The before/after errors as a Markdown table."""
        rows = ["| model | fit: chi2/n | fit: RRMSE | held-out: chi2/n | held-out: RRMSE |", "|---|---|---|---|---|"]
        for name, e in self.errors.items():
            rows.append(f"| {name} | {e['fit_chi2_per_point']:.2f} | {e['fit_rrmse']:.3f} | "
                        f"{e['heldout_chi2_per_point']:.2f} | {e['heldout_rrmse']:.3f} |")
        return "\n".join(rows)


#: Data with dL_f/D but no curve: the test runs to this many times the largest dL_f/D.
SCALAR_REACH = 2.0
#: ... and ends once the plate force has fallen to this fraction of its peak (after the
#: failure, a 10 % fall, :data:`pelletdem.worker.FAILURE_DROP`).
SCALAR_BREAK_DROP = 0.5


def fit_window(sim: Simulator, data: Dataset, say: Callable[[str], None]) -> str:
    """Fit the simulator's diametral window (``max_dLD``, ``widen``) to the data's reach (their
    last curve point and dL_f/D, plus 10 %) before any fit: wider when the data go further,
    narrower when they stop short (a test's cost grows with its length; a model that then
    fails outside is caught by :func:`unfailed`). Data with dL_f/D and no curve (the paper's
    Table 3) say where the pellet fails, not how far the test went: a model's packings fail
    either side of it, so the test runs to :data:`SCALAR_REACH` times the largest and, where
    the simulator can (``end_at_break``), stops once the pellet has broken. Returns the
    sentence to add to the verdict when it cannot widen ('' when nothing is wrong)."""
    curve = [o.x for o in data.observations if o.quantity == "sigma_1"]
    failures = [o.value for o in data.observations if o.quantity == "dLf_D"]
    xs = curve + failures
    end = getattr(sim, "max_dLD", None)
    if not xs or end is None:
        return ""
    reach = 1.1 * max(xs)
    if not curve:
        reach = SCALAR_REACH * max(failures)
        if getattr(sim, "end_at_break", None) is not None:
            sim.end_at_break(SCALAR_BREAK_DROP)
            say(f"the data give dL_f/D, no curve: each test ends once its force has fallen to "
                f"{SCALAR_BREAK_DROP:.0%} of its peak")
    if reach <= end:
        if getattr(sim, "widen", None) is not None and reach < 0.9 * end:
            say(f"the data reach dL/D = {max(xs):.3g}: the tests run to dL/D = {reach:.3g} instead of {end:.3g}")
            sim.widen(reach)
        return ""
    if getattr(sim, "widen", None) is None or reach > MAX_WINDOW:
        note = (f"the data reach dL/D = {max(xs):.3g}, beyond the simulated test window (dL/D up to {end:.3g}), "
                "which cannot be widened so far")
        say(note)
        return note
    say(f"the data reach dL/D = {max(xs):.3g}: the tests run to dL/D = {reach:.3g} instead of {end:.3g}")
    sim.widen(reach)
    return ""


def unfailed(mf: ModelFit, data: Dataset) -> List[str]:
    """Labels of the conditions with diametral data where most of the fitted model's packings
    (fit seeds) did not pass the peak of their diametral test (scalar ``peaked`` below 1)."""
    out = []
    for c in data.conditions:
        if not any(o.condition == c and o.quantity in ("sigma_1", "sigma_f", "dLf_D") for o in data.observations):
            continue
        peaked = [m.scalars.get("peaked", 1.0) for m in mf.direct[c].members if m.ok]
        if peaked and np.mean(peaked) < 0.5:
            out.append(c.label)
    return out


def off_unit(e: Effect, axis: Axis) -> float:
    """Where on the candidate's axis the effect is off: its ``off`` value when inside the
    bounds, else the bound nearest to it (a strength there is as good as off: a plate yield
    stress of 50 MPa, a Weibull modulus of 30, a softening of 0.05)."""
    if axis.lo < e.off < axis.hi:
        return axis.to_unit(e.off)
    return 1.0 if e.stronger == "lower" or e.off >= axis.hi else 0.0


def describe_residual(data: Dataset, z: np.ndarray, n_params: int, alpha: float = DEFAULT_ALPHA) -> ResidualSummary:
    """:func:`pelletdem.residuals.describe` of the misfits ``z`` of ``data``."""
    curves: Dict[str, List[int]] = {}
    for i, o in enumerate(data.observations):
        if o.curve:
            curves.setdefault(o.curve, []).append(i)
    curves = {k: sorted(v, key=lambda i: data.observations[i].x) for k, v in curves.items()}
    labels = [o.condition.label for o in data.observations]
    levels = {"sigma_z [MPa]": {c.label: c.sigma_z / 1e6 for c in data.conditions},
              "mc [%]": {c.label: c.mc for c in data.conditions}}
    groups = {"material": {c.label: c.material for c in data.conditions if c.material}}
    zz = np.where(np.isfinite(z), z, 0.0)
    return describe(zz, parts=[o.part for o in data.observations], conditions=labels, curves=curves,
                    levels=levels, groups=groups, n_params=n_params, alpha=alpha)


@dataclass(frozen=True)
class Gates:
    """What a candidate must pass: the fit test's ``threshold`` (chi2 drop), the number of
    points checked on fresh packings (``n_check``, of which ``n_held`` held out) and the
    fraction of the model's excess chi2 there it must remove (``min_check_gain``)."""

    threshold: float
    n_check: int
    n_held: int
    min_check_gain: float


def judge(g: Gates, drop: float, before: Tuple[float, float, float],
          after: Tuple[float, float, float], rrmse_se: float = 0.0, chi2_se: float = 0.0) -> Tuple[bool, str]:
    """Whether a candidate is accepted, and why.

    ``drop``: the fall of its fit chi2; ``before`` / ``after``: (chi2 of all data, chi2 of the
    held-out data, RRMSE of all data) on the check packings, for the model without and with the
    candidate; ``rrmse_se``: the standard error of the RRMSE's rise (:func:`rrmse_rise_se`);
    ``chi2_se``: that of the fresh packings' chi2 (:func:`check_chi2_se`).
    The gates, in order: the fit test; a real fall of chi2 on fresh packings (a lucky packing
    cannot pass it), by a quarter of the model's excess there and by more than its scatter
    between packings (:data:`LUCK_SE`; new pellets cannot pass it by luck); no rise of the held-out
    chi2 beyond its own scatter; no rise of the RRMSE (eq. 16) beyond twice its scatter
    between packings, which a candidate fitting the most precise observations at the others'
    cost would show.
    """
    (base_before, held_before, rrmse_before), (base_after, held_after, rrmse_after) = before, after
    need = max(4.0, g.min_check_gain * (base_before - g.n_check))
    if drop < g.threshold:
        return False, f"fit chi2 fell by {drop:.1f}, below the threshold {g.threshold:.1f}"
    if base_before - base_after < need:
        return False, f"chi2 on fresh packings {base_before:.1f} -> {base_after:.1f}: it needed to fall by {need:.1f}"
    if base_before - base_after <= LUCK_SE * chi2_se:
        return False, (f"chi2 on fresh packings {base_before:.1f} -> {base_after:.1f}, a fall within its scatter "
                       f"between packings ({chi2_se:.1f}): other pellets, not the effect, may have made it")
    if g.n_held and held_after - held_before > 2.0 * math.sqrt(2.0 * g.n_held):
        return False, (f"the held-out chi2 rose {held_before:.1f} -> {held_after:.1f} on fresh packings: "
                       "it does not carry over to the held-out conditions")
    if rrmse_after - rrmse_before > 2.0 * rrmse_se:
        return False, (f"the RRMSE on fresh packings rose {rrmse_before:.3f} -> {rrmse_after:.3f}, more than twice "
                       f"its scatter between packings ({rrmse_se:.3f}): its chi2 fell by fitting the most precise "
                       "observations at the others' cost")
    return True, (f"fit chi2 -{drop:.1f} (threshold {g.threshold:.1f}); chi2 on fresh packings "
                  f"{base_before:.1f} -> {base_after:.1f} (its fall's scatter {chi2_se:.1f})"
                  + (f" (held out {held_before:.1f} -> {held_after:.1f})" if g.n_held else "")
                  + f"; RRMSE {rrmse_before:.3f} -> {rrmse_after:.3f} (its rise's scatter {rrmse_se:.3f})")


def _check_numbers(mf: ModelFit, fit_data: Dataset, heldout: Optional[Dataset]) -> Tuple[float, float, float]:
    """(chi2 of all the data, chi2 of the held-out data, RRMSE of all the data) on the check
    packings."""
    return check_chi2(mf), held_chi2(mf), check_rrmse(mf, fit_data, heldout)


def _judge_on(g: Gates, drop: float, before: ModelFit, after: ModelFit, fit_data: Dataset,
              heldout: Optional[Dataset]) -> Tuple[bool, str]:
    """:func:`judge` of ``after`` against ``before``, both checked on the same packings."""
    return judge(g, drop, _check_numbers(before, fit_data, heldout), _check_numbers(after, fit_data, heldout),
                 rrmse_rise_se(before, after, fit_data, heldout), check_chi2_se(before, after, fit_data, heldout))


def _more_check_seeds(fit_seeds: Sequence[int], check_seeds: Sequence[int]) -> Tuple[int, ...]:
    """As many packings again as ``check_seeds``, after them, none a fit or check packing."""
    taken, out, s = set(fit_seeds) | set(check_seeds), [], max(check_seeds)
    while len(out) < len(check_seeds):
        s += 1
        if s not in taken:
            out.append(s)
    return tuple(out)


def _inconclusive(g: Gates, drop: float, before: ModelFit, after: ModelFit, fit_data: Dataset,
                  heldout: Optional[Dataset]) -> bool:
    """True when a candidate failed only the fresh packings' scatter: it would pass every gate
    were that scatter 0. More packings can then decide."""
    return judge(g, drop, _check_numbers(before, fit_data, heldout), _check_numbers(after, fit_data, heldout),
                 rrmse_rise_se(before, after, fit_data, heldout), 0.0)[0]


def _separation(a: ModelFit, b: ModelFit, fit_data: Dataset, heldout: Optional[Dataset]) -> float:
    """D of :func:`pelletdem.loop_separation.separation` over the fit and held-out data, on
    the two models' fresh packings."""
    return separation(a.check, b.check, fit_data) + (separation(a.check, b.check, heldout) if heldout else 0.0)


def _rivals_on_more_packings(sim: Simulator, contenders: Sequence[Trial], more: Sequence[int], fit_data: Dataset,
                             heldout: Optional[Dataset], say: Callable[[str], None]
                             ) -> Tuple[Trial, List[str], Dict[str, float], List[str]]:
    """Candidates that fit as well (the one picked first) checked again on ``more`` packings
    besides their check packings, and picked again there: the trial to add (as fitted and
    checked before, so that the next round compares like with like), its rivals on all those
    packings, how far the data separate each (:func:`_separation`), and what was found, in
    words. The packings' luck that tied them shrinks; the data's separation, if any, decides."""
    ext = [dataclasses.replace(t, model=with_more_check_packings(sim, t.model, more, fit_data, heldout))
           for t in contenders]
    ext = [dataclasses.replace(t, check_after=check_chi2(t.model)) for t in ext]
    k = len(next(iter(ext[0].model.check.values())).seeds)
    best, rivals = pick(ext, lambda a, b: check_chi2_se(a, b, fit_data, heldout))
    notes = [f"{' and '.join(t.effect.name for t in contenders)} fit as well on the check packings; checked again "
             f"on {k} packings (chi2 " + ", ".join(f"{t.effect.name} {t.check_after:.1f}" for t in ext)
             + f"), {best.effect.name} is the lower"]
    seps = {}
    for t in ext:
        if t.effect.name in rivals:
            seps[t.effect.name] = _separation(best.model, t.model, fit_data, heldout)
            notes.append(statement(best.effect.name, t.effect.name, seps[t.effect.name], k,
                                   t.check_after - best.check_after, check_chi2_se(best.model, t.model, fit_data,
                                                                                   heldout)))
    for line in notes:
        say(line)
    return next(t for t in contenders if t.effect is best.effect), rivals, seps, notes


def pick(accepted: Sequence[Trial], scatter: Optional[Callable[[ModelFit, ModelFit], float]] = None
         ) -> Tuple[Optional[Trial], List[str]]:
    """The accepted candidate to add and the names of its rivals.

    The one with the lowest chi2 on fresh packings is added: those are real simulations the
    fit never saw, where the emulated fit chi2 is in-sample and can favour a surface that bent
    to the fit packings' scatter. A rival is another accepted candidate within
    :data:`TIE_CHI2` of it there, or within twice the scatter of the two models' difference
    between the check packings (``scatter(a, b)``, e.g. :func:`check_chi2_se`: two compaction
    effects are checked on different pellets), or one the emulated fit preferred: the two
    measures then disagree, and the data do not tell the two apart.
    """
    if not accepted:
        return None, []
    added = min(accepted, key=lambda t: t.check_after)

    def tie(t: Trial) -> float:
        return max(TIE_CHI2, 2.0 * scatter(added.model, t.model)) if scatter is not None else TIE_CHI2

    return added, [t.effect.name for t in accepted if t is not added
                   and (t.check_after - added.check_after < tie(t) or t.delta_chi2 > added.delta_chi2)]


def close_loop(sim: Simulator, data: Dataset, base_bounds: Mapping[str, Sequence[float]],
               start: Optional[Mapping[str, float]] = None, *,
               held_out: Optional[Callable[[Condition], bool]] = None,
               library: Optional[Mapping[str, Effect]] = None, fit_seeds: Sequence[int] = FIT_SEEDS,
               check_seeds: Sequence[int] = CHECK_SEEDS, alpha: float = 0.01, screen_top: int = 2,
               screen_threshold: Optional[float] = None, max_effects: int = 2, min_check_gain: float = 0.25,
               n_design: Optional[int] = None, log: Optional[Callable[[str], None]] = None) -> LoopResult:
    """Forward selection of candidate effects (see the module docstring).

    ``base_bounds``: {parameter: (lo, hi)} (SI) of the base parameters fitted in every model
    (e.g. E_b and sigma_c, or per material ``E_b[oak]``); ``start`` (SI): a start for the
    baseline's fit. ``held_out(condition)``: True for conditions kept out of every fit (None:
    none; the check then uses the fit conditions' fresh packings). ``library``: candidates
    (default :data:`pelletdem.effects.EFFECTS`). ``fit_seeds`` / ``check_seeds``: the
    packings of the designs and fits, and of the checks (disjoint). ``alpha``: family-wise
    level of the fit test. ``screen_top``: candidates fitted in full per round;
    ``screen_threshold``: the first-order gain a candidate needs to be fitted in full (default
    half the fit test's threshold, at least 3.84: a candidate that cannot come near the test to
    first order is not worth a design of its own).
    ``max_effects``: rounds of forward selection. ``min_check_gain``: the fraction of the
    model's excess chi2 on the check seeds a candidate must remove. ``n_design``: design points per model
    (default :func:`pelletdem.loop_models.design_size`).
    """
    t0 = time.perf_counter()
    lines: List[str] = []

    def say(msg: str) -> None:
        lines.append(msg)
        if log is not None:
            log(msg)

    if set(fit_seeds) & set(check_seeds):
        raise ValueError("fit_seeds and check_seeds must be disjoint packings")
    if not 0 < alpha < 1:
        raise ValueError(f"alpha = {alpha!r} is out of range: allowed 0 < alpha < 1")
    if not 0 <= min_check_gain < 1:
        raise ValueError(f"min_check_gain = {min_check_gain!r} is out of range: allowed 0 <= gain < 1")
    if not (isinstance(max_effects, int) and 0 <= max_effects <= 10):
        raise ValueError(f"max_effects = {max_effects!r} is out of range: allowed 0..10")
    if screen_threshold is not None and not (isinstance(screen_threshold, (int, float)) and screen_threshold >= 0):
        raise ValueError(f"screen_threshold = {screen_threshold!r} is out of range: allowed >= 0 (or None)")
    if not (isinstance(screen_top, int) and 1 <= screen_top <= 20):
        raise ValueError(f"screen_top = {screen_top!r} is out of range: allowed 1..20")
    if not base_bounds:
        raise ValueError("base_bounds: at least one base parameter must be fitted")
    axes = tuple(Axis(k, float(b[0]), float(b[1]), float(b[0]) > 0) for k, b in base_bounds.items())
    for k, v in (start or {}).items():
        if k not in base_bounds:
            raise ValueError(f"start: {k!r} is not among the fitted parameters {sorted(base_bounds)}")
        lo, hi = base_bounds[k][0], base_bounds[k][1]
        if not (isinstance(v, (int, float)) and lo <= v <= hi):
            raise ValueError(f"start: {k} = {v!r} is outside its bounds [{lo:g}, {hi:g}]")
    fit_data, heldout = data.split(held_out or (lambda c: False))
    library = dict(EFFECTS if library is None else library)
    n = len(fit_data)
    say(f"data: {n} fit observations of {len(fit_data.conditions)} conditions"
        + (f", {len(heldout)} held out ({', '.join(c.label for c in heldout.conditions)})" if heldout else
           ", none held out (the checks use fresh packings of the fit conditions)"))

    def fit(space: Space, effects, start_params=None, shared=None, noise=None) -> ModelFit:
        # a candidate's box shares the baseline's points (its off face): fewer new ones serve
        n = n_design if n_design is not None or shared is None else max(8, 2 * effective_dim(space) + 2)
        return fit_model(sim, space, effects, fit_data, heldout, fit_seeds, check_seeds, start_params, n, say,
                         shared=shared, noise=noise)

    window_note = fit_window(sim, fit_data, say)
    model = fit(Space(axes), (), dict(start) if start else None)
    # a fitted model that does not fail inside the test window shows the bond effects nothing
    # (its "peak" is the end of the test): widen the window where the simulator can
    for _ in range(2):
        late = unfailed(model, fit_data)
        if not late:
            break
        end, new_end = getattr(sim, "max_dLD", math.nan), next_window(sim)
        if new_end is None:
            window_note = (f"the fitted model does not fail within the test window (dL/D up to {end:.3g}) at "
                           f"{', '.join(late)}: its sigma_f and dL_f/D there are the end of the test, not a failure")
            say(window_note)
            break
        say(f"the fitted model does not fail within the test window (dL/D up to {end:.3g}) at {', '.join(late)}: "
            f"the tests now run to dL/D = {new_end:.3g} and the model is fitted again")
        sim.widen(new_end)
        model = fit(Space(axes), (), dict(model.fit.params))
    # a base parameter fitted at an end of its box is not fitted: widen the box there
    base_names = [a.name for a in axes]
    for _ in range(MAX_WIDEN):
        ends = pinned(model, base_names)
        if not ends:
            break
        space = widened(model.space, ends)
        if space == model.space:
            break
        say("the baseline's " + pinned_list(ends, model) + ": the box now runs "
            + ", ".join(f"{a.name} {a.lo:.4g} to {a.hi:.4g}" for a in space.axes) + " and the model is fitted again")
        try:
            model = fit(space, (), dict(model.fit.params), rebox(model, space))
        except ValueError as err:  # the simulator refuses the wider box's parameters
            say(f"the box cannot be widened there: {err}")
            break
    baseline = model
    errors = {model.name: model_errors(model, fit_data, heldout)}
    steps: List[Step] = []
    chosen: List[str] = []
    powers: Dict[str, Power] = {}
    n_rep = int(np.median([o.n for o in fit_data.observations]))
    set_rows = sim.base_rows()
    while True:
        residual = describe_residual(fit_data, model.z_direct, model.n_params)
        remaining = []
        for name, e in library.items():
            if name in chosen:
                continue
            why = clash([library[c] for c in chosen] + [e]) if chosen else ""
            if why:
                say(f"{name} is not tried with {', '.join(chosen)}: {why}")
                continue
            # an effect the base model sets is in it already; one its laws refuse beside the
            # model would stop the loop at its first simulation
            if e.param in set_rows and set_rows[e.param] != e.off:
                say(f"{name} is not tried: the model sets {e.param} itself")
                continue
            why = sim.refusal(dict(model.fit.params, **e.settings(e.probe)), fit_data.conditions)
            if why:
                say(f"{name} is not tried with the model: {why}")
                continue
            remaining.append(e)
        if not remaining or len(chosen) >= max_effects:
            # none tried: say so, rather than that no candidate explains the residual
            capped = not chosen and remaining and not max_effects
            steps.append(Step(model, residual, [], [], None, math.nan,
                              note="no candidate was tried (max_effects = 0)" if capped else ""))
            break
        screens = screen(sim, model, remaining, fit_data, fit_seeds)
        k = max(1, sum(1 for s in screens if not s.skipped))
        threshold = max(float(stats.chi2.isf(alpha / k, 1)), math.log(n))
        round_powers = {s.effect.name: detection_power(s, model, fit_data, threshold, n_rep, len(fit_seeds))
                        for s in screens}
        powers.update(round_powers)
        say("screened: " + ", ".join(f"{s.effect.name} {s.gain:.1f}" if not s.skipped else f"{s.effect.name} (-)"
                                     for s in screens) + f"; fit test threshold {threshold:.1f}")
        trials: List[Trial] = []
        base_before = check_chi2(model)
        n_held = len(heldout) if heldout is not None else 0
        n_check = n + n_held
        gates = Gates(threshold, n_check, n_held, min_check_gain)
        noise_level = n_check + 2.0 * math.sqrt(2.0 * n_check)
        if base_before <= noise_level:
            # the check on fresh packings is the test every candidate must pass; at the noise
            # level there is nothing for it to confirm, so no candidate is fitted in full
            note = (f"on fresh packings the model's chi2 ({base_before:.1f} on {n_check} points) is within the "
                    f"noise level ({noise_level:.1f}): no candidate could be confirmed there, none was fitted")
            say(note)
            steps.append(Step(model, residual, screens, [], None, threshold, note, powers=round_powers))
            break
        gate = max(3.84, 0.5 * threshold) if screen_threshold is None else screen_threshold
        for s in [s for s in screens if not s.skipped and s.gain >= gate][:screen_top]:
            e = s.effect
            axis = Axis(e.param, e.lo, e.hi, e.log)
            space = model.space.with_axis(axis, e.fixed)
            cand = fit(space, model.effects + (e.name,), dict(model.fit.params, **e.settings(s.strength)),
                       nested_points(model, off_unit(e, axis)), model.noise)
            drop = model.fit.chi2 - cand.fit.chi2
            after = check_chi2(cand)
            ok, why = _judge_on(gates, drop, model, cand, fit_data, heldout)
            if not ok and _inconclusive(gates, drop, model, cand, fit_data, heldout):
                # within the packings' luck: look at as many packings again before refusing
                more = _more_check_seeds(fit_seeds, check_seeds)
                say(f"{e.name}: its fall on fresh packings is within its scatter; checking on "
                    f"{len(more)} more packings")
                ok, why = _judge_on(gates, drop, with_more_check_packings(sim, model, more, fit_data, heldout),
                                    with_more_check_packings(sim, cand, more, fit_data, heldout), fit_data, heldout)
                why += f" (on {len(check_seeds) + len(more)} fresh packings)"
            trials.append(Trial(e, cand, drop, base_before, after, ok, why))
            errors[cand.name] = model_errors(cand, fit_data, heldout)
            say(f"{e.name}: {'accepted' if ok else 'not accepted'}: {why}")
        accepted = [t for t in trials if t.accepted]
        added, rivals = pick(accepted, lambda a, b: check_chi2_se(a, b, fit_data, heldout))
        seps: Dict[str, float] = {}
        notes: List[str] = []
        if rivals:
            added, rivals, seps, notes = _rivals_on_more_packings(
                sim, [added] + [t for t in accepted if t.effect.name in rivals],
                _more_check_seeds(fit_seeds, check_seeds), fit_data, heldout, say)
        steps.append(Step(model, residual, screens, trials, added.effect.name if added else None, threshold,
                          rivals=rivals, powers=round_powers, separations=seps, rival_notes=notes))
        if added is None:
            break
        chosen.append(added.effect.name)
        model = added.model
    verdict = _verdict(chosen, steps, baseline)
    if window_note:
        verdict += f" ({window_note})"
    box_note = pinned_note(pinned(model, base_names), model)
    if box_note:
        say(box_note)
        verdict += f" ({box_note})"
    say(verdict)
    return LoopResult(fit_data, heldout, baseline, model, steps, chosen, verdict, errors, powers,
                      sim.n_simulations, time.perf_counter() - t0, lines)


def _verdict(chosen: Sequence[str], steps: Sequence[Step], baseline: ModelFit) -> str:
    if chosen:
        def named(st: Step) -> str:
            if not st.rivals:
                return str(st.added)
            return f"{st.added} ({' or '.join(st.rivals)} fits as well: these data do not tell them apart)"
        return "added " + ", then ".join(named(st) for st in steps if st.added)
    first = steps[0]
    if first.note:
        return "nothing added: " + first.note
    if not first.trials:
        if first.residual.structured:
            return "no candidate explains this residual"
        return "nothing to explain: the residual is consistent with the data's and the model's scatter"
    return "no candidate explains this residual"
