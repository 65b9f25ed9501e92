"""The parameter studies of section 3.2 of the paper, as PNG files.

    python examples/02_parameter_studies.py OUT_DIR [--preset tiny|quick|paper] [--workers N]

Writes into OUT_DIR:

- fig10_coordination.png: coordination number against BD_p/BD_w during compaction to 48, 60
  and 120 MPa, with the relaxed pellets and the paper's values;
- fig11_coordination_effect.png: sigma_1(dL/D) and the tensile strength against the relaxed CN;
- fig12_bond_radius.png: r_b = 10-40 um at fixed E_b, sigma_c (a), and with E_b r_b^2 and
  sigma_c r_b^2 fixed (b);
- fig13_bond_area.png: sigma_f and dL_f/D against the bond area, with oak's Table 3 ranges;
- fig14_rrmse_map.png: RRMSE (eq. 16) over (E_b, sigma_c) against a synthetic measured curve
  made with another packing (the paper's measured curves are not published).

Every bond-parameter run branches off one relaxed pellet per pressure; runs are cached in
OUT_DIR/cache, so running again reads them back. Size knob: PRESET and GRID below. "tiny" takes
about three minutes on two cores; "paper" (40,000 particles) about a day.
"""
import argparse
import math
from pathlib import Path

import numpy as np

PRESET = "tiny"   # "tiny" (minutes), "quick" (~10x longer), "paper" (the paper's size, a day)
GRID = 3          # points per axis of the Fig. 14 map
MPA, UM = 1e6, 1e-6
E_B, SIGMA_C, R_B = 120 * MPA, 36 * MPA, 20 * UM   # the paper's reference bonds (Figs. 11-13)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path, help="output directory (created)")
    ap.add_argument("--preset", default=PRESET, choices=["tiny", "quick", "paper"])
    ap.add_argument("--workers", type=int, default=1, help="processes for the Fig. 14 scan (1: this one)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pelletdem import calibrate, measured, plots
    from pelletdem.calibrate import RunCache, Targets, make_spec, run_point
    from pelletdem.engine import BondLaw
    from pelletdem.presets import get_preset

    preset = get_preset(args.preset)
    max_dld = 0.2 if args.preset != "paper" else preset.max_dLD   # small pellets fail late
    args.out.mkdir(parents=True, exist_ok=True)
    cache = RunCache(args.out / "cache")
    bond = BondLaw(radius=R_B, youngs_modulus=E_B, sigma_c=SIGMA_C, tau_c=SIGMA_C)

    def run(sigma_z_mpa=120, seed=args.seed, **params):
        spec = make_spec(params, preset=preset, sigma_z=sigma_z_mpa * MPA, seed=seed, bond=bond, max_dLD=max_dld)
        rec = cache.get(spec.key)
        if rec is None:
            rec = run_point(spec)
            cache.put(rec)
        if not rec["ok"]:
            raise RuntimeError(rec["error"])
        return rec

    def save(fig, name):
        fig.tight_layout()
        fig.savefig(args.out / name, dpi=120)
        plt.close(fig)
        print("wrote", args.out / name, flush=True)

    # Figs. 10, 11: coordination number
    bd_wood = float(np.mean([v.bd_wood for v in measured.variants()]))
    paper = {120: (1.62, 12.9), 60: (1.32, 12.2), 48: (1.13, 10.5)}
    by_p = {sz: run(sz) for sz in (48, 60, 120)}
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for k, (sz, rec) in enumerate(by_p.items()):
        c, o = rec["compaction_curve"], rec["outputs"]
        ax.plot(np.asarray(c["bulk_density"]) / bd_wood, c["coordination_number"], color=f"C{k}", lw=5 - 1.5 * k,
                label=f"compaction to {sz} MPa")
        ax.plot([o["bulk_density_relaxed"] / bd_wood], [o["coordination_number_relaxed"]], "s", color=f"C{k}", ms=8)
        ax.plot([paper[sz][0]], [paper[sz][1]], "*", color=f"C{k}", ms=12, mec="k")
    ax.set_xlabel("$BD_p / BD_w$")
    ax.set_ylabel("coordination number CN")
    ax.set_title("Fig. 10 (squares: relaxed; stars: the paper's)")
    ax.legend(fontsize=8)
    save(fig, "fig10_coordination.png")

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    pts = sorted((rec["outputs"]["coordination_number_relaxed"], rec["outputs"]["sigma_f"] / MPA)
                 for rec in by_p.values())
    for sz, rec in by_p.items():
        a.plot(rec["curve"]["dL_D"], np.asarray(rec["curve"]["sigma_1"]) / MPA,
               label=f"{sz} MPa, CN = {rec['outputs']['coordination_number_relaxed']:.2f}")
    a.set_xlabel("$\\Delta L/D$")
    a.set_ylabel("$\\sigma_1$ (MPa)")
    a.legend(fontsize=8)
    b.plot(*zip(*pts), "o-")
    b.set_xlabel("CN")
    b.set_ylabel("$\\sigma_f$ (MPa)")
    save(fig, "fig11_coordination_effect.png")

    # Figs. 12, 13: bond radius, plain and compensated (E_b r_b^2, sigma_c r_b^2 constant)
    radii = (10, 20, 30, 40)
    plain = {r: run(r_b=r * UM) for r in radii}
    comp = {r: run(r_b=r * UM, E_b=E_B * (20 / r) ** 2, sigma_c=SIGMA_C * (20 / r) ** 2) for r in radii}
    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    panels = ((axs[0], plain, "(a) $E_b$, $\\sigma_c$ fixed"),
              (axs[1], comp, "(b) $E_b r_b^2$, $\\sigma_c r_b^2$ fixed"))
    for ax, runs, title in panels:
        for r, rec in runs.items():
            ax.plot(rec["curve"]["dL_D"], np.asarray(rec["curve"]["sigma_1"]) / MPA, label=f"$r_b$ = {r} µm")
        ax.set_xlabel("$\\Delta L/D$")
        ax.set_ylabel("$\\sigma_1$ (MPa)")
        ax.set_title(f"Fig. 12{title}")
        ax.legend(fontsize=8)
    save(fig, "fig12_bond_radius.png")

    area = [math.pi * (r * UM) ** 2 * 1e12 for r in radii]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    for ax, key, scale, label in ((a, "sigma_f", MPA, "$\\sigma_f$ (MPa)"), (b, "dLf_D", 1.0, "$\\Delta L_f/D$")):
        ax.plot(area, [plain[r]["outputs"][key] / scale for r in radii], "o-", label="DEM")
        for k, v in enumerate(x for x in measured.variants() if x.material == "oak"):
            m, sd = getattr(v, key) / scale, getattr(v, key + "_sd") / scale
            ax.axhspan(m - sd, m + sd, color=f"C{k + 1}", alpha=0.2, label=v.label)
        ax.set_xlabel("bond area A (µm²)")
        ax.set_ylabel(label)
        ax.legend(fontsize=7)
    save(fig, "fig13_bond_area.png")

    # Fig. 14: RRMSE over (E_b, sigma_c) against a synthetic curve from another packing
    ref = run(seed=args.seed + 1)
    target = Targets(sigma_z=120 * MPA, curve=(np.asarray(ref["curve"]["dL_D"]), np.asarray(ref["curve"]["sigma_1"])),
                     label="synthetic")
    f = np.sqrt(2.0) ** (np.arange(GRID) - GRID // 2)
    sc = calibrate.scan({"E_b": list(E_B * f), "sigma_c": list(SIGMA_C * f)}, target, preset=preset,
                        seeds=(args.seed,), bond=bond, max_dLD=max_dld, cache_dir=args.out / "cache",
                        executor="serial" if args.workers == 1 else None, max_workers=args.workers)
    fig = plots.calibration_parameter_map(sc.points, value="rrmse")
    fig.axes[0].plot([E_B / MPA], [SIGMA_C / MPA], "wx", ms=10, mew=2)
    fig.axes[0].set_title("Fig. 14: RRMSE against a synthetic curve (x: its bonds)", fontsize=9)
    save(fig, "fig14_rrmse_map.png")
    print(f"scan: {sc.n_simulations} runs, {sc.n_cached} cached; lowest RRMSE at "
          f"E_b = {sc.best['E_b'] / MPA:.1f} MPa, sigma_c = {sc.best['sigma_c'] / MPA:.1f} MPa")
    return 0


if __name__ == "__main__":   # the scan's process pool starts workers with 'spawn'
    raise SystemExit(main())
