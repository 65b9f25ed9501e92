"""The paper's figures from a Result (matplotlib, Agg backend when there is no display).

Fig. 5: compaction-unloading sigma_z(dh) and diametral sigma_1(dL/D). Fig. 9: sigma_z(dh/h0).
Fig. 10: coordination number against BD/BD_w. Fig. 11: sigma_1(dL/D) for several runs and
sigma_f against CN. Fig. 15: simulated against measured (Table 3 point with SD bars).
Fig. 16: crack maps (see pelletdem.cracks). Every function returns the matplotlib Figure.
"""
from __future__ import annotations

import os
from typing import Iterable, Optional, Sequence

import numpy as np


def _plt():
    import matplotlib

    if not os.environ.get("DISPLAY") and matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def fig5_stress_deformation(result, ax=None):
    """Fig. 5: (a) piston stress sigma_z (MPa) against piston displacement dh (mm), loading and
    unloading; (b) sigma_1 (MPa) against dL/D in the diametral test."""
    plt = _plt()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4)) if ax is None else (ax[0].figure, ax)
    h0 = result.scalar("fill", "h0")
    for name, style in (("compact", "-"), ("unload", "--")):
        if name in result.stages:
            s = result.stages[name].series
            a.plot((h0 - s["h"]) * 1e3, s["sigma_z"] / 1e6, style, label=name)
    a.set_xlabel("piston displacement $\\Delta h$ (mm)")
    a.set_ylabel("$\\sigma_z$ (MPa)")
    a.legend()
    a.set_title("(a) compaction and unloading")
    if "diametral" in result.stages:
        s = result.stages["diametral"].series
        b.plot(s["dL_D"], s["sigma_1"] / 1e6)
    b.set_xlabel("$\\Delta L/D$")
    b.set_ylabel("$\\sigma_1$ (MPa)")
    b.set_title("(b) diametral compression")
    fig.tight_layout()
    return fig


def fig9_compaction(result, measured: Optional[Sequence] = None, ax=None):
    """Fig. 9: sigma_z (MPa) against dh/h0 for compaction and unloading; `measured` is an
    optional list of (label, dh_h0 array, sigma_z Pa array) curves to draw with it."""
    plt = _plt()
    fig, ax = (plt.subplots(figsize=(5, 4)) if ax is None else (ax.figure, ax))
    for name, style in (("compact", "-"), ("unload", "--")):
        if name in result.stages:
            s = result.stages[name].series
            ax.plot(s["dh_h0"], s["sigma_z"] / 1e6, style, label=f"DEM {name}")
    for label, x, y in measured or []:
        ax.plot(x, np.asarray(y) / 1e6, "o", ms=3, label=label)
    ax.set_xlabel("$\\Delta h / h_0$")
    ax.set_ylabel("$\\sigma_z$ (MPa)")
    ax.legend()
    fig.tight_layout()
    return fig


def fig10_coordination(result, bd_wood: float = 675.0, ax=None):
    """Fig. 10: coordination number against BD_p/BD_w during compaction (every particle in
    the mould), with the relaxed pellet as points: its bulk CN (away from the free surfaces,
    the one compared with the paper's 12.9 / 12.2 / 10.5) and its CN over every particle, at
    its caliper density; bd_wood is the intact wood's bulk density, kg/m^3 (oak: 675)."""
    plt = _plt()
    fig, ax = (plt.subplots(figsize=(5, 4)) if ax is None else (ax.figure, ax))
    s = result.stages["compact"].series
    n = min(len(s["bulk_density"]), len(s["coordination_number"]))
    ax.plot(s["bulk_density"][:n] / bd_wood, s["coordination_number"][:n], label="compaction")
    if "relax" in result.stages:
        r = result.stages["relax"].scalars
        x = r["bulk_density"] / bd_wood
        if "coordination_number_bulk" in r:
            ax.plot([x], [r["coordination_number_bulk"]], "s", label="relaxed pellet, bulk CN")
        ax.plot([x], [r["coordination_number"]], "o", mfc="none", label="relaxed pellet, every particle")
    ax.set_xlabel("$BD_p / BD_w$")
    ax.set_ylabel("coordination number CN")
    ax.legend()
    fig.tight_layout()
    return fig


def fig11_coordination_effect(results: Iterable, ax=None):
    """Fig. 11: (a) sigma_1(dL/D) of several runs labelled by their relaxed bulk CN; (b)
    sigma_f (MPa) against that CN."""
    plt = _plt()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4)) if ax is None else (ax[0].figure, ax)
    cn, sf = [], []
    for res in results:
        rs = res.stages["relax"].scalars
        c = rs.get("coordination_number_bulk", rs["coordination_number"])
        s = res.stages["diametral"].series
        a.plot(s["dL_D"], s["sigma_1"] / 1e6, label=f"CN = {c:.1f}")
        cn.append(c)
        sf.append(res.scalar("diametral", "sigma_f") / 1e6)
    a.set_xlabel("$\\Delta L/D$")
    a.set_ylabel("$\\sigma_1$ (MPa)")
    a.legend()
    b.plot(cn, sf, "o-")
    b.set_xlabel("CN")
    b.set_ylabel("$\\sigma_f$ (MPa)")
    fig.tight_layout()
    return fig


def fig15_fit(result, variant=None, measured_curve=None, ax=None):
    """Fig. 15: simulated sigma_1(dL/D) (MPa) with the measured tensile strength and
    deformation at failure (Table 3, mean +- SD bars) of `variant` (a measured.Variant), and
    an optional measured curve (measured.Curve)."""
    plt = _plt()
    fig, ax = (plt.subplots(figsize=(5, 4)) if ax is None else (ax.figure, ax))
    s = result.stages["diametral"].series
    ax.plot(s["dL_D"], s["sigma_1"] / 1e6, label="DEM")
    if measured_curve is not None:
        ax.plot(measured_curve.x, measured_curve.y / 1e6, ".", ms=2, label="measured")
    if variant is not None:
        ax.errorbar([variant.dLf_D], [variant.sigma_f / 1e6], xerr=[variant.dLf_D_sd],
                    yerr=[variant.sigma_f_sd / 1e6], fmt="ks", capsize=3, label=f"{variant.label} (Table 3)")
    ax.set_xlabel("$\\Delta L/D$")
    ax.set_ylabel("$\\sigma_1$ (MPa)")
    ax.legend()
    fig.tight_layout()
    return fig


def save_all(result, directory: str, variant=None) -> list:
    """Write every figure the run covers as PNG files into `directory`; returns the paths."""
    plt = _plt()
    os.makedirs(directory, exist_ok=True)
    out = []

    def save(fig, name):
        path = os.path.join(directory, name)
        fig.savefig(path, dpi=120)
        plt.close(fig)
        out.append(path)

    if "compact" in result.stages:
        save(fig5_stress_deformation(result), "fig5_stress_deformation.png")
        save(fig9_compaction(result), "fig9_compaction.png")
        bd_w = variant.bd_wood if variant is not None else 675.0
        save(fig10_coordination(result, bd_wood=bd_w), "fig10_coordination.png")
    if "diametral" in result.stages:
        save(fig15_fit(result, variant), "fig15_fit.png")
        try:
            from .cracks import plot_crack_maps
        except ImportError:
            plot_crack_maps = None
        if plot_crack_maps is not None:
            d = result.stages["diametral"]
            snap = result.snapshots.get("diametral") or result.snapshots.get("bond")
            broken = {"position": d.series["broken_position"], "mode": d.series["broken_mode"],
                      "time": d.series["broken_time"], "load_marker": d.series["broken_dL_D"]}
            path = os.path.join(directory, "fig16_crack_map.png")
            plot_crack_maps({"broken": broken, "positions": snap["position"], "radii": snap["radius"],
                             "height": d.scalars["height"]}, path)
            out.append(path)
    return out


# --- calibration (pelletdem.calibrate) -----------------------------------------------------

def calibration_measured_vs_simulated(report, ax=None):
    """Measured (Table 3, mean +- SD bars) against simulated values for the variants of a
    calibration: (a) tensile strength sigma_f (MPa), (b) deformation at failure dL_f/D (-),
    with the 1:1 line. `report` is a calibrate.CalibrationReport or its `table` (columns
    sigma_f_mpa_exp/_sd/_sim, dLf_D_exp/_sd/_sim, material, mc_percent, sigma_z_mpa)."""
    plt = _plt()
    table = getattr(report, "table", report)
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.5)) if ax is None else (ax[0].figure, ax)
    markers = {"birch": "o", "oak": "s", "pine": "^"}
    for panel, col, label in ((a, "sigma_f_mpa", "$\\sigma_f$ (MPa)"), (b, "dLf_D", "$\\Delta L_f/D$")):
        exp, sd, sim = (np.asarray(table[f"{col}_{k}"], float) for k in ("exp", "sd", "sim"))
        for i, row in enumerate(table.itertuples()):
            m = markers.get(getattr(row, "material", ""), "o")
            filled = getattr(row, "mc_percent", 8) == 8
            panel.errorbar([exp[i]], [sim[i]], xerr=[sd[i]], fmt=m, capsize=3,
                           mfc=None if filled else "none", color=f"C{i % 10}",
                           label=f"{row.material} {row.mc_percent}% {row.sigma_z_mpa} MPa")
        finite = np.concatenate([exp[np.isfinite(exp)], sim[np.isfinite(sim)]])
        if finite.size:
            lo, hi = float(finite.min()), float(finite.max())
            lo, hi = (0.0 if lo < 0.3 * hi else 0.8 * lo), 1.1 * hi
            panel.plot([lo, hi], [lo, hi], "k--", lw=0.8)
            panel.set_xlim(lo, hi)
            panel.set_ylim(lo, hi)
        panel.set_xlabel(f"measured {label} (Table 3, mean $\\pm$ SD)")
        panel.set_ylabel(f"simulated {label}")
    a.set_title("(a) tensile strength")
    b.set_title("(b) deformation at failure")
    b.legend(fontsize=6, ncol=2, loc="lower right")
    fig.tight_layout()
    return fig


def paper_coordination(ax, bd_p, bd_p_sd, bd_w, cn, labels) -> None:
    """The paper's points of Fig. 10 on ``ax``: Table 2's measured BD_p (kg/m^3, SD bar) over
    its intact wood's BD_w against Table 5's coordination number, each point labelled."""
    bd_w = np.asarray(bd_w, float)
    x, y = np.asarray(bd_p, float) / bd_w, np.asarray(cn, float)
    ax.errorbar(x, y, xerr=np.asarray(bd_p_sd, float) / bd_w, fmt="o", ms=4, color="k",
                label="paper: measured $BD_p$, Table 5 CN")
    for k, (text, xv, yv) in enumerate(zip(labels, x, y)):
        # alternate above and below: variants of one CN in Table 5 sit on top of each other
        ax.annotate(text, (xv, yv), fontsize=5, xytext=(3, 4 if k % 2 == 0 else -8), textcoords="offset points")


def calibration_coordination(report, ax=None):
    """The paper's Fig. 10 for a calibration's relaxed pellets: bulk coordination number against
    BD_p / BD_w (-), the paper's (Table 2's measured BD_p with its SD bar, Table 5's CN) beside
    the simulated (the relaxed pellet's bulk CN and density, BD_w of Table 2). `report` is a
    calibrate.CalibrationReport or its `table` (columns bd_exp, bd_sd, bd_sim, bd_wood, cn_paper,
    cn_sim, material, mc_percent, sigma_z_mpa)."""
    plt = _plt()
    table = getattr(report, "table", report)
    fig, ax = (plt.subplots(figsize=(5.4, 4.2)) if ax is None else (ax.figure, ax))
    bdw = np.asarray(table["bd_wood"], float)
    paper_coordination(ax, table["bd_exp"], table["bd_sd"], bdw, table["cn_paper"],
                       [f"{r.material} {r.mc_percent}% {r.sigma_z_mpa}" for r in table.itertuples()])
    xs, ys = np.asarray(table["bd_sim"], float) / bdw, np.asarray(table["cn_sim"], float)
    ax.plot(xs, ys, "^", ms=5, mfc="none", color="tab:blue", label="simulated, relaxed (bulk CN)")
    # variants that share a relaxed pellet (one pressure, no moisture effect) share a point
    shared = {}
    for x, y, row in zip(xs, ys, table.itertuples()):
        if np.isfinite(x) and np.isfinite(y):
            shared.setdefault((round(float(x), 3), round(float(y), 2)), []).append(row)
    for (x, y), rows in shared.items():
        text = f"{rows[0].sigma_z_mpa} MPa" + (f" ({len(rows)} variants)" if len(rows) > 1 else
                                              f", {rows[0].material} {rows[0].mc_percent}%")
        ax.annotate(text, (x, y), fontsize=6, color="tab:blue", xytext=(4, -9), textcoords="offset points")
    ax.set_xlabel("$BD_p / BD_w$")
    ax.set_ylabel("coordination number CN")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def calibration_parameter_map(points, x: str = "E_b", y: str = "sigma_c", value: str = "loss",
                              ax=None, log: bool = True, best: bool = True):
    """Fig. 14-style map of a fit error over two parameters: `points` is a scan's `points`
    table (or a fit's `history`), x and y parameter columns (Pa, shown in MPa), `value` the
    error column (rms z-score or RRMSE, -). A full grid is drawn as coloured cells, scattered
    points (a fit's path) as coloured dots joined in run order; the lowest error is marked."""
    plt = _plt()
    fig, ax = (plt.subplots(figsize=(5.5, 4.5)) if ax is None else (ax.figure, ax))
    xs = np.asarray(points[x], float) / 1e6
    ys = np.asarray(points[y], float) / 1e6
    vs = np.asarray(points[value], float)
    vplot = np.where(np.isfinite(vs), vs, np.nan)
    ux, uy = np.unique(xs), np.unique(ys)
    if len(ux) * len(uy) == len(xs) and len(ux) > 1 and len(uy) > 1:
        grid = np.full((len(uy), len(ux)), np.nan)
        for xi, yi, vi in zip(xs, ys, vplot):
            grid[np.searchsorted(uy, yi), np.searchsorted(ux, xi)] = vi
        im = ax.pcolormesh(ux, uy, grid, shading="nearest", cmap="viridis_r")
    else:
        ax.plot(xs, ys, "-", color="0.6", lw=0.8, zorder=1)
        im = ax.scatter(xs, ys, c=vplot, cmap="viridis_r", zorder=2)
        for k, (xi, yi) in enumerate(zip(xs, ys)):
            ax.annotate(str(k), (xi, yi), fontsize=7, xytext=(3, 3), textcoords="offset points")
    fig.colorbar(im, ax=ax, label=value)
    if best and np.isfinite(vplot).any():
        k = int(np.nanargmin(vplot))
        ax.plot([xs[k]], [ys[k]], "r*", ms=14, label=f"best: {value} = {vs[k]:.3g}")
        ax.legend(fontsize=8)
    if log:
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.set_xlabel(f"{x} (MPa)")
    ax.set_ylabel(f"{y} (MPa)")
    fig.tight_layout()
    return fig


def calibration_curves(report, variants, records, ax=None):
    """Fig. 15 for a calibration: each variant's simulated sigma_1(dL/D) (MPa) at its fitted
    bonds (lines) with Table 3's sigma_f and dL_f/D (squares, mean +- SD), one panel per
    material. `report` is a calibrate.CalibrationReport, `variants` its variants (measured
    Variants), `records` the run cache's records (the curves are read from them)."""
    plt = _plt()
    mats = sorted({v.material for v in variants})
    if ax is None:
        fig, axs = plt.subplots(1, len(mats), figsize=(5 * len(mats), 4), squeeze=False)
        axs = axs[0]
    else:
        axs = np.atleast_1d(ax)
        fig = axs[0].figure
    diametral = [r for r in records if r and r["ok"] and r["spec"].get("kind") == "diametral"]
    for panel, mat in zip(axs, mats):
        for k, v in enumerate(x for x in variants if x.material == mat):
            p = report.fits[v.label].params
            for rec in diametral:
                s = rec["spec"]
                if (np.isclose(s["sigma_z"], v.sigma_z) and np.isclose(s["bond"]["youngs_modulus"], p["E_b"])
                        and np.isclose(s["bond"]["sigma_c"], p["sigma_c"])):
                    panel.plot(rec["curve"]["dL_D"], np.asarray(rec["curve"]["sigma_1"]) / 1e6, color=f"C{k}",
                               label=f"MC {v.mc_percent} %, {v.sigma_z_mpa} MPa")
                    break
            panel.errorbar([v.dLf_D], [v.sigma_f / 1e6], xerr=[v.dLf_D_sd], yerr=[v.sigma_f_sd / 1e6], fmt="s",
                           color=f"C{k}", mec="k", capsize=3)
        panel.set_title(f"{mat}: DEM (lines), Table 3 (squares)")
        panel.set_xlabel("$\\Delta L/D$")
        panel.set_ylabel("$\\sigma_1$ (MPa)")
        panel.legend(fontsize=7)
    fig.tight_layout()
    return fig


def save_calibration(report, variants, records, directory: str) -> list:
    """Write a calibration's figures as PNG files into `directory` (Fig. 15 as measured against
    simulated, :func:`calibration_measured_vs_simulated`, and as curves,
    :func:`calibration_curves`; Fig. 10 for its relaxed pellets, :func:`calibration_coordination`);
    returns the paths."""
    plt = _plt()
    out = []
    for name, fig in (("fig15_measured_vs_simulated.png", calibration_measured_vs_simulated(report)),
                      ("fig15_curves.png", calibration_curves(report, variants, records)),
                      ("fig10_relaxed.png", calibration_coordination(report))):
        path = os.path.join(directory, name)
        fig.savefig(path, dpi=120)
        plt.close(fig)
        out.append(path)
    return out
