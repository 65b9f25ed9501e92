"""The discrepancy loop's report: one Markdown file with PNG figures, written by one call.

It shows the verdict, the error before and after on fitted and held-out data (on packings the
fits never used), every step of the forward selection (the model's fitted parameters with
their uncertainty, its residual, the candidates' screening, the ones fitted in full and why
each was or was not added), what the data could have revealed of each candidate (detection
power), and figures of the measured and simulated numbers and of the residuals.
"""
from __future__ import annotations

import math
import os
from typing import Dict, List

import numpy as np

from .loop_data import QUANTITIES, Dataset
from .loop_models import ModelFit
from .loop_screen import screens_table
from .loop_selection import LoopResult

__all__ = ["write_report", "summary", "model_summary", "params_text"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(plt, fig, path: str) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _means(mf: ModelFit, data: Dataset) -> np.ndarray:
    """The model's predictions of ``data`` on the check seeds (each observation's unit)."""
    return np.array([mf.check[o.condition].mean_se(o)[0] for o in data.observations])


def _groups(data: Dataset) -> Dict[str, List[int]]:
    out: Dict[str, List[int]] = {}
    for i, o in enumerate(data.observations):
        out.setdefault(o.curve or o.quantity, []).append(i)  # scalars of a quantity share a panel
    return out


def _fig_fit(res: LoopResult, path: str) -> str:
    """Measured means (standard-error bars) and the baseline's and final model's predictions
    on fresh packings, one panel per curve or scalar, fit and held-out conditions."""
    plt = _plt()
    panels = []
    for data, tag in ((res.fit_data, "fit"), (res.heldout_data, "held out")):
        if data is None:
            continue
        pb, pa = _means(res.baseline, data), _means(res.final, data)
        for name, idx in _groups(data).items():
            panels.append((f"{name} ({tag})", data, idx, pb, pa))
    cols = min(3, len(panels))
    rows = (len(panels) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False)
    for ax, (title, data, idx, pb, pa) in zip(axes.flat, panels):
        obs = [data.observations[i] for i in idx]
        q = obs[0].quantity
        unit = QUANTITIES[q][0]
        scale = 1e-6 if unit == "Pa" else 1.0
        if obs[0].curve:
            order = np.argsort([o.x for o in obs])
            idx, obs = [idx[k] for k in order], [obs[k] for k in order]
            x, style = np.array([o.x for o in obs]), "-"
            ax.set_xlabel("dL/D" if q == "sigma_1" else "dh/h0")
        else:
            x, style = np.arange(len(obs), dtype=float), "s"
            ax.set_xticks(x, [o.condition.label for o in obs], rotation=45, ha="right", fontsize=6)
        ax.errorbar(x, [o.value * scale for o in obs], yerr=[o.standard_error * scale for o in obs], fmt="o",
                    ms=3, color="k", label="measured")
        ax.plot(x, pb[idx] * scale, style, ms=4, mfc="none", color="tab:red", label="baseline")
        if res.chosen:
            ax.plot(x, pa[idx] * scale, style.replace("s", "^"), ms=4, mfc="none", color="tab:blue",
                    label=res.final.name)
        ax.set_title(title, fontsize=8)
        ax.set_ylabel(f"{q} [{'MPa' if unit == 'Pa' else unit}]")
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    return _save(plt, fig, path)


def _fig_residual(res: LoopResult, path: str) -> str:
    """z-scores of every observation on fresh packings, baseline and final model."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 3.4))
    zb = [res.baseline.z_check_fit] + ([res.baseline.z_check_held] if res.heldout_data is not None else [])
    za = [res.final.z_check_fit] + ([res.final.z_check_held] if res.heldout_data is not None else [])
    zb, za = np.concatenate(zb), np.concatenate(za)
    k = np.arange(len(zb))
    ax.axhspan(-2, 2, color="0.9")
    ax.plot(k, zb, "o-", ms=3, color="tab:red", label="baseline")
    if res.chosen:
        ax.plot(k, za, "^-", ms=3, color="tab:blue", label=res.final.name)
    ax.axvline(len(res.fit_data) - 0.5, color="0.5", ls="--", lw=0.8)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("observation (fit data, then held out)")
    ax.set_ylabel("z on fresh packings")
    ax.legend(fontsize=8)
    return _save(plt, fig, path)


def _fig_screen(res: LoopResult, path: str) -> str:
    """First-order chi2 gain of each candidate in the first round, and the threshold."""
    plt = _plt()
    step = res.steps[0]
    sc = [s for s in step.screens if not s.skipped][::-1]
    fig, ax = plt.subplots(figsize=(6, 0.45 * max(len(sc), 2) + 1))
    ax.barh([s.effect.name for s in sc], [max(s.gain, 1e-3) for s in sc],
            color=["tab:blue" if s.effect.name in res.chosen else "0.6" for s in sc])
    if math.isfinite(step.threshold):
        ax.axvline(step.threshold, color="k", ls="--", lw=0.8, label="fit test threshold")
        ax.legend(fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("first-order chi2 gain on the baseline's residual")
    return _save(plt, fig, path)


def _paper_variants(res: LoopResult) -> Dict:
    """The paper's variant of each condition of the data, when every condition is one of the
    paper's 12 ({Condition: Variant}); {} otherwise."""
    from .paper_tables import variants

    by_key = {(v.material, float(v.mc_percent), float(v.sigma_z)): v for v in variants()}
    conds = list(res.fit_data.conditions) + (list(res.heldout_data.conditions) if res.heldout_data is not None else [])
    out = {c: by_key.get((c.material, float(c.mc), float(c.sigma_z))) for c in conds}
    return out if all(out.values()) else {}


def _fig_coordination(res: LoopResult, variants: Dict, path: str) -> str:
    """The paper's Fig. 10 for the relaxed pellets: bulk CN against BD_p / BD_w (BD_w the
    intact wood's bulk density, Table 2), the paper's (its measured BD_p with SD, its fitted
    CN of Table 5) beside the baseline's and the final model's on fresh packings."""
    from .plots import paper_coordination

    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.4, 4.2))
    conds = list(variants)
    bdw = np.array([variants[c].bd_wood for c in conds])
    paper_coordination(ax, [variants[c].bd_pellet for c in conds], [variants[c].bd_pellet_sd for c in conds], bdw,
                       [variants[c].cn for c in conds], [c.label for c in conds])
    models = [(res.baseline, "s", "tab:red")] + ([(res.final, "^", "tab:blue")] if res.chosen else [])
    for mf, marker, colour in models:
        x = np.array([mf.check[c].scalar("bulk_density") for c in conds]) / bdw
        y = [mf.check[c].scalar("coordination_number") for c in conds]
        ax.plot(x, y, marker, ms=5, mfc="none", color=colour, label=f"{mf.name}, relaxed (bulk CN)")
    ax.set_xlabel("$BD_p / BD_w$")
    ax.set_ylabel("coordination number CN")
    ax.legend(fontsize=7)
    return _save(plt, fig, path)


def _by_quantity(res: LoopResult) -> str:
    """chi2/n and RRMSE (eq. 16) of each quantity on fresh packings, fit and held-out data, the
    baseline's beside the final model's, as a Markdown table."""
    models = [res.baseline] + ([res.final] if res.chosen else [])
    head = "| quantity | data | n | " + " | ".join(f"{m.name}: chi2/n | {m.name}: RRMSE" for m in models) + " |"
    rows = [head, "|---|---|---|" + "---|---|" * len(models)]
    for data, tag, z_of in ((res.fit_data, "fit", lambda m: m.z_check_fit),
                            (res.heldout_data, "held out", lambda m: m.z_check_held)):
        if data is None:
            continue
        quantity = np.array([o.quantity for o in data.observations])
        values = np.array([o.value for o in data.observations])
        rel = {m.name: (_means(m, data) - values) / values for m in models}
        for q in dict.fromkeys(quantity):
            idx = np.flatnonzero(quantity == q)
            cells = []
            for m in models:
                z = np.asarray(z_of(m), float)[idx]
                cells.append(f"{np.mean(z ** 2):.2f} | {math.sqrt(np.mean(rel[m.name][idx] ** 2)):.3f}")
            rows.append(f"| {q} | {tag} | {len(idx)} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def _num(v: float, fmt: str) -> str:
    return format(v, fmt) if math.isfinite(v) else "-"  # a simulator that does not report it


def _relaxed(res: LoopResult) -> str:
    """Each condition's relaxed pellet on fresh packings (bulk density, kg/m^3, and bulk
    coordination number, the means over the check packings), measured density beside it, as
    a Markdown table."""
    models = [res.baseline] + ([res.final] if res.chosen else [])
    measured = {}
    for data in (res.fit_data, res.heldout_data):
        for o in (data.observations if data is not None else ()):
            if o.quantity == "bulk_density":
                measured[o.condition] = o
    conds = list(res.baseline.check)
    head = " | ".join(f"{m.name}: density | {m.name}: CN" for m in models)
    rows = [f"| condition | measured density | {head} |", "|---|---|" + "---|---|" * len(models)]
    for c in conds:
        o = measured.get(c)
        cells = [f"{o.value:.0f} +- {o.sd:.0f}" if o is not None else "-"]
        cells += [f"{_num(m.check[c].scalar('bulk_density'), '.0f')} | "
                  f"{_num(m.check[c].scalar('coordination_number'), '.2f')}" for m in models]
        rows.append(f"| {c.label} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def params_text(mf: ModelFit) -> str:
    """The fitted parameters as the report writes them: value, standard error, 2-sigma
    interval where profiled, and a warning when the fit had not settled."""
    out = []
    for name in mf.space.names:
        v, se = mf.fit.params[name], mf.fit.se.get(name, math.nan)
        rel = mf.fit.relative.get(name, True)
        unc = f" (+-{100 * se:.0f} %)" if rel and math.isfinite(se) else (f" +- {se:.3g}" if math.isfinite(se) else "")
        lo, hi = mf.fit.interval(name, 2.0)
        band = f", 2-sigma {lo:.3g}..{hi:.3g}" if name in mf.fit.profiles else ""
        out.append(f"{name} = {v:.4g}{unc}{band}")
    moving = ("" if mf.settled else f" (not settled: the fit still moved {mf.last_move:.3f} of the box in its last "
              "refinement, so these errors read an emulator that has not simulated its optimum)")
    return ", ".join(out) + moving


def model_summary(mf: ModelFit) -> dict:
    """One fitted model as plain data: parameters (SI) with standard errors (relative for
    log axes), 2-sigma intervals, the fit packings' share of the errors, the emulated chi2,
    the design's size and whether the refinement settled."""
    return {"name": mf.name, "params": {k: mf.fit.params[k] for k in mf.space.names},
            "se": {k: mf.fit.se.get(k) for k in mf.space.names},
            "interval_2sigma": {k: list(mf.fit.interval(k, 2.0)) for k in mf.space.names},
            "fit_packings_se": ({a.name: math.sqrt(max(float(mf.fit.jackknife[i, i]), 0.0)) * a.relative_scale()
                                 for i, a in enumerate(mf.space.axes)} if mf.fit.jackknife is not None else None),
            "emulated_chi2": mf.fit.chi2,
            "design_points": int(len(mf.emulator.U)),
            "last_move": None if math.isnan(mf.last_move) else mf.last_move, "settled": mf.settled}


def summary(res: LoopResult) -> dict:
    """The loop's outcome as plain data (for loop.json): verdict, chosen effects, errors,
    fitted parameters with standard errors, the steps' screening and trials, the power."""
    return {"verdict": res.verdict, "chosen": list(res.chosen), "errors": res.errors,
            "baseline": model_summary(res.baseline), "final": model_summary(res.final),
            "steps": [{"model": st.model.name, "structured": st.residual.structured, "threshold": st.threshold,
                       "screens": [{"effect": s.effect.name, "gain": s.gain, "strength": s.strength,
                                    "skipped": s.skipped} for s in st.screens],
                       "trials": [{"effect": t.effect.name, "accepted": t.accepted, "why": t.why,
                                   "delta_chi2": t.delta_chi2, "check_before": t.check_before,
                                   "check_after": t.check_after, "model": model_summary(t.model)} for t in st.trials],
                       "added": st.added, "rivals": list(st.rivals),
                       "separations": dict(st.separations)} for st in res.steps],
            "power": {k: {"detectable": p.detectable, "replicates": p.replicates, "packings": p.packings,
                          "statement": p.statement} for k, p in res.power.items()},
            "n_simulations": res.n_simulations, "wall_time_s": res.wall_time_s}


def write_report(res: LoopResult, out_dir: str, title: str = "Discrepancy loop") -> str:
    """Write ``report.md`` and its PNG figures into ``out_dir`` (created); returns the
    report's path."""
    os.makedirs(out_dir, exist_ok=True)
    figs = {"fit": _fig_fit(res, os.path.join(out_dir, "loop_fit.png")),
            "residual": _fig_residual(res, os.path.join(out_dir, "loop_residual.png"))}
    if res.steps and res.steps[0].screens:
        figs["screen"] = _fig_screen(res, os.path.join(out_dir, "loop_screen.png"))
    paper = _paper_variants(res)
    if paper and any(o.quantity == "bulk_density" for o in res.fit_data.observations):
        figs["coordination"] = _fig_coordination(res, paper, os.path.join(out_dir, "loop_coordination.png"))
    held = res.heldout_data
    L = [f"# {title}", "", f"**Verdict: {res.verdict}.**", "",
         f"Fit data: {len(res.fit_data)} numbers of {', '.join(c.label for c in res.fit_data.conditions)}; "
         + (f"held out: {len(held)} numbers of {', '.join(c.label for c in held.conditions)}. " if held is not None
            else "nothing held out. ")
         + f"{res.n_simulations} simulations, {res.wall_time_s:.0f} s.", "",
         "## Error before and after", "", res.table(), "",
         "On packings no fit or design used. chi2/n: mean squared z-score, z the normal score of the "
         "difference between the model's mean over its packings and the measured mean, over both standard "
         "errors; about 1 when the model is right. RRMSE: eq. 16.", "", "By quantity:", "", _by_quantity(res), "",
         "Relaxed pellets (means over the fresh packings; CN away from the free surfaces):", "", _relaxed(res), ""]
    for k, st in enumerate(res.steps):
        widen = st.model.fit.widen
        shared = (" The errors allow for the misfits of one condition's observations being correlated (they share "
                  "their pellets' packings) and for the fit packings' own luck (the fit repeated leaving each out): "
                  "variances x" + ", x".join(f"{widen[a]:.2f}" for a in st.model.space.names)
                  + ".") if widen and max(widen.values()) > 1.0 else ""
        L += [f"## Step {k + 1}: {st.model.name}", "", f"Fitted (emulated chi2 {st.model.fit.chi2:.1f} on "
              f"{st.model.fit.n} numbers, {len(st.model.emulator.U)} design points): {params_text(st.model)}.{shared}",
              "", "Residual:", ""]
        L += ["    " + s for s in st.residual.lines()]
        if st.screens:
            L += ["", f"Screening (fit test threshold {st.threshold:.1f}):", "",
                  screens_table(st.screens, st.powers or res.power)]
        for t in st.trials:
            L += ["", f"- **{t.effect.name}** {'added' if t.accepted else 'not added'}: {t.why}. Fitted: "
                  f"{params_text(t.model)}."]
        if st.rivals:
            L += ["", f"- {st.added} and {' and '.join(st.rivals)} fit as well (on fresh packings their chi2 within 2 "
                  "of each other, their BIC difference, or within twice the scatter of that difference between the "
                  "packings, or the emulated fit preferring the other): these data do not "
                  f"tell them apart; {st.added} was added for the lower chi2 on fresh packings."]
        L += [f"  {note}." if st.rivals else f"\n- {note}." for note in st.rival_notes]
        L.append("")
    if "screen" in figs:
        L += [f"![screening]({os.path.basename(figs['screen'])})", ""]
    L += ["## What these data could reveal", ""]
    L += [f"- {p.statement}" for p in res.power.values()] or ["- (no candidate was screened)"]
    L += ["", "## Measured and simulated", "", f"![fit]({os.path.basename(figs['fit'])})", "",
          f"![residuals]({os.path.basename(figs['residual'])})", ""]
    if "coordination" in figs:
        L += ["Relaxed pellets against the paper's Fig. 10 (its measured densities, the coordination numbers "
              "of its fits):", "", f"![coordination]({os.path.basename(figs['coordination'])})", ""]
    L += ["## Log", "", "```"]
    L += res.log + ["```", ""]
    path = os.path.join(out_dir, "report.md")
    with open(path, "w") as fh:
        fh.write("\n".join(L))
    return path
