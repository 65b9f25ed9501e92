"""The discrepancy loop's report: one Markdown file with PNG figures, written by one call.

It shows the error before and after on fitted and held-out data, the residuals before and
after (per point along each curve, and per part of the curve), the ranking of the candidate
effects, and why the chosen effect won (or why none was added).
"""
from __future__ import annotations

import os
from typing import Dict, List

import numpy as np

from .loop_data import QUANTITIES
from .loop_selection import LoopResult

__all__ = ["write_report"]


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


def _predictions(data, z) -> np.ndarray:
    return data.values + np.asarray(z) * data.sds


def _curves(data) -> Dict[str, List[int]]:
    out: Dict[str, List[int]] = {}
    for i, o in enumerate(data.observations):
        # scalars of one quantity share a panel, one tick per condition
        key = o.curve or o.quantity
        out.setdefault(key, []).append(i)
    return out


def _fig_fit(res: LoopResult, path: str) -> str:
    """Measured points (with SD bars) and both models' predictions, one panel per curve or
    scalar group, fit and held-out conditions."""
    plt = _plt()
    panels = []
    for data, zb, za, tag in ((res.fit_data, res.baseline.z, res.final.z, "fit"),
                              (res.heldout_data, res.heldout_before, res.heldout_after, "held out")):
        pb, pa = _predictions(data, zb), _predictions(data, za)
        for name, idx in _curves(data).items():
            panels.append((f"{name} ({tag})", data, idx, pb, pa))
    n = len(panels)
    cols = min(3, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.6 * rows), squeeze=False)
    for ax, (title, data, idx, pb, pa) in zip(axes.flat, panels):
        obs = [data.observations[i] for i in idx]
        q = obs[0].quantity
        unit = QUANTITIES[q][0]
        scale = 1e-6 if unit == "Pa" else 1.0
        if obs[0].curve:
            order = np.argsort([o.x for o in obs])
            idx = [idx[k] for k in order]
            obs = [obs[k] for k in order]
            x = np.array([o.x for o in obs])
            xl = "dL/D" if q == "sigma_1" else "dh/h0"
            style = "-"
        else:
            x = np.arange(len(obs), dtype=float)
            xl = ""
            ax.set_xticks(x, [o.condition.label for o in obs], rotation=60, ha="right", fontsize=6)
            style = "s"  # one value per condition: markers, not a line between conditions
        ax.errorbar(x, [o.value * scale for o in obs], yerr=[o.effective_sd * scale for o in obs], fmt="o",
                    ms=3, color="k", label="measured")
        ax.plot(x, pb[idx] * scale, style, ms=4, mfc="none", color="tab:red", label="baseline")
        if res.chosen is not None:
            ax.plot(x, pa[idx] * scale, style.replace("s", "^"), ms=4, mfc="none", color="tab:blue",
                    label=f"+ {res.chosen}")
        ax.set_title(title, fontsize=8)
        ax.set_xlabel(xl)
        ax.set_ylabel(f"{q} [{'MPa' if unit == 'Pa' else unit}]")
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    return _save(plt, fig, path)


def _fig_residual(res: LoopResult, path: str) -> str:
    """z-scores per point along the fit data, before and after, and per part of the curve."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 3.6), gridspec_kw={"width_ratios": [2, 1]})
    k = np.arange(len(res.baseline.z))
    a1.axhspan(-2, 2, color="0.9")
    a1.plot(k, res.baseline.z, "o-", ms=3, color="tab:red", label="baseline")
    if res.chosen is not None:
        a1.plot(k, res.final.z, "o-", ms=3, color="tab:blue", label=f"+ {res.chosen}")
    a1.axhline(0, color="k", lw=0.5)
    a1.set_xlabel("fit observation (curves in order of x)")
    a1.set_ylabel("z = (sim - measured) / SD")
    a1.legend(fontsize=8)
    parts = list(res.residual_before.by_part)
    x = np.arange(len(parts))
    a2.bar(x - 0.2, [res.residual_before.by_part[p][1] for p in parts], 0.4, color="tab:red", label="baseline")
    if res.chosen is not None:
        a2.bar(x + 0.2, [res.residual_after.by_part.get(p, (0, 0.0, 0))[1] for p in parts], 0.4, color="tab:blue",
               label=f"+ {res.chosen}")
    a2.axhline(0, color="k", lw=0.5)
    a2.set_xticks(x, parts, rotation=30, fontsize=7)
    a2.set_ylabel("mean z per part")
    return _save(plt, fig, path)


def _fig_ranking(res: LoopResult, path: str) -> str:
    """Fraction of the structured residual each candidate's signature explains."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 0.45 * max(len(res.candidates), 2) + 1))
    names = [c.effect.name for c in res.candidates][::-1]
    vals = [c.explained for c in res.candidates][::-1]
    colors = ["tab:blue" if n == res.chosen else "0.6" for n in names]
    ax.barh(names, vals, color=colors)
    ax.set_xlim(0, 1)
    ax.set_xlabel("fraction of the structured residual explained (first order)")
    return _save(plt, fig, path)


def write_report(res: LoopResult, out_dir: str, title: str = "Discrepancy loop") -> str:
    """Write ``report.md`` and its PNG figures into ``out_dir`` (created); returns the
    report's path."""
    os.makedirs(out_dir, exist_ok=True)
    figs = {"fit": _fig_fit(res, os.path.join(out_dir, "loop_fit.png")),
            "residual": _fig_residual(res, os.path.join(out_dir, "loop_residual.png"))}
    if res.candidates:
        figs["ranking"] = _fig_ranking(res, os.path.join(out_dir, "loop_ranking.png"))
    L = [f"# {title}", "", f"**Verdict: {res.verdict}.**", "",
         f"Fit data: {len(res.fit_data)} points of {len(res.fit_data.conditions)} conditions "
         f"({', '.join(c.label for c in res.fit_data.conditions)}); held out: {len(res.heldout_data)} points of "
         f"{', '.join(c.label for c in res.heldout_data.conditions)}. {res.n_simulations} simulations, "
         f"{res.wall_time_s:.0f} s.", "", "## Error before and after", "", res.table(), "",
         "chi2/n: mean squared z-score (z = (sim - measured) / replicate SD); RRMSE: eq. 16 over all points.",
         "", "## Baseline fit", "",
         ", ".join(f"{k} = {v:.4g}" for k, v in res.baseline.params.items()), "", "## Residual of the baseline", ""]
    L += ["    " + s for s in res.residual_before.lines()]
    L += ["", f"![residuals]({os.path.basename(figs['residual'])})", "", "## Candidate effects", ""]
    if res.candidates:
        L += ["| effect | law parameter | explained | refit held-out chi2/n | BIC | outcome |",
              "|---|---|---|---|---|---|"]
        nh = len(res.heldout_data)
        for c in res.candidates:
            held = f"{c.heldout_chi2 / nh:.2f}" if np.isfinite(c.heldout_chi2) else "-"
            bic = f"{c.bic:.1f}" if np.isfinite(c.bic) else "-"
            out = "**chosen**" if c.effect.name == res.chosen else (c.why or "not refitted")
            L.append(f"| {c.effect.name} | `{c.effect.param}` | {c.explained:.2f} | {held} | {bic} | {out} |")
        L += ["", f"![ranking]({os.path.basename(figs['ranking'])})", "", "Signatures (what each effect does to "
              "the residual when the model lacks it):", ""]
        L += [f"- **{c.effect.name}**: {c.effect.description}. {c.effect.signature}." for c in res.candidates]
    else:
        L.append("None traced: the residual is consistent with the replicate scatter.")
    if res.chosen is not None:
        L += ["", "## Residual after adding the effect", ""]
        L += ["    " + s for s in res.residual_after.lines()]
        L += ["", "Fitted: " + ", ".join(f"{k} = {v:.4g}" for k, v in res.final.params.items())]
    L += ["", "## Measured and simulated", "", f"![fit]({os.path.basename(figs['fit'])})", "", "## Log", "", "```"]
    L += res.log + ["```", ""]
    path = os.path.join(out_dir, "report.md")
    with open(path, "w") as fh:
        fh.write("\n".join(L))
    return path
