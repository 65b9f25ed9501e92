"""Calibration of the paper's 12 variants against Tables 2 and 3, beside the paper's Table 5.

    python examples/03_calibration.py OUT_DIR [--preset tiny|quick|paper] [--workers N]
                                      [--max-runs N] [--variant oak 8 120 ...]

One shared loading stiffness k1 against Table 2's pellet densities, then E_b and sigma_c per
variant against Table 3's sigma_f and dL_f/D (pelletdem.calibrate.calibrate_variants). Writes
into OUT_DIR: calibration.csv (the fitted values beside Table 5 and the errors against Tables 2
and 3), fig15_measured_vs_simulated.png and fig15_curves.png (each variant's fitted
sigma_1(dL/D) with Table 3's point). Runs are cached in OUT_DIR/cache: run again to resume.

Size knob: PRESET and MAX_RUNS below. "tiny" with 4 runs per variant takes a few minutes on
two cores; the full study is --preset paper --max-runs 8 (~9 h on two cores, estimated, or give
calibrate_variants a Dask distributed.Client).
"""
import argparse
from pathlib import Path

import numpy as np

PRESET = "tiny"      # "tiny" (minutes), "quick" (~20 min), "paper" (the paper's size, ~9 h)
MAX_RUNS = 4         # parameter points per variant fit
COMPACTION_RUNS = 2  # k1 points of the shared compaction fit (0: keep Table 4's k1)
MPA = 1e6


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path, help="output directory (created)")
    ap.add_argument("--preset", default=PRESET, choices=["tiny", "quick", "paper"])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--max-runs", type=int, default=MAX_RUNS)
    ap.add_argument("--variant", nargs=3, action="append", metavar=("MATERIAL", "MC", "SIGMA_Z_MPA"),
                    help="calibrate only these variants (repeatable); default all 12")
    args = ap.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pelletdem import calibrate, measured, plots
    from pelletdem.calibrate import RunCache
    from pelletdem.presets import get_preset

    preset = get_preset(args.preset)
    variants = (measured.variants() if not args.variant
                else [measured.variant(m, int(mc), int(sz)) for m, mc, sz in args.variant])
    args.out.mkdir(parents=True, exist_ok=True)
    k1 = preset.contact.k1
    report = calibrate.calibrate_variants(
        variants, preset, compaction={"k1": (k1 / 10, k1 * 10, k1)} if COMPACTION_RUNS else None,
        compaction_max_runs=max(COMPACTION_RUNS, 1), max_runs=args.max_runs,
        cache_dir=args.out / "cache", relaxed_dir=args.out / "relaxed", max_workers=args.workers)
    print(report)
    report.table.to_csv(args.out / "calibration.csv", index=False)

    fig = plots.calibration_measured_vs_simulated(report)
    fig.savefig(args.out / "fig15_measured_vs_simulated.png", dpi=120)
    plt.close(fig)

    # Each variant's curve at its best bonds, read back from the run cache.
    cache = RunCache(args.out / "cache")
    records = [cache.get(k) for k in cache.keys()]
    mats = sorted({v.material for v in variants})
    fig, axs = plt.subplots(1, len(mats), figsize=(5 * len(mats), 4), squeeze=False)
    for ax, mat in zip(axs[0], mats):
        for k, v in enumerate(x for x in variants if x.material == mat):
            p = report.fits[v.label].params
            for rec in records:
                s = rec["spec"]
                if (rec["ok"] and s.get("kind") == "diametral" and np.isclose(s["sigma_z"], v.sigma_z)
                        and np.isclose(s["bond"]["youngs_modulus"], p["E_b"])
                        and np.isclose(s["bond"]["sigma_c"], p["sigma_c"])):
                    ax.plot(rec["curve"]["dL_D"], np.asarray(rec["curve"]["sigma_1"]) / MPA, color=f"C{k}",
                            label=f"MC {v.mc_percent} %, {v.sigma_z_mpa} MPa")
                    break
            ax.errorbar([v.dLf_D], [v.sigma_f / MPA], xerr=[v.dLf_D_sd], yerr=[v.sigma_f_sd / MPA], fmt="s",
                        color=f"C{k}", mec="k", capsize=3)
        ax.set_title(f"{mat}: DEM (lines), Table 3 (squares)")
        ax.set_xlabel("$\\Delta L/D$")
        ax.set_ylabel("$\\sigma_1$ (MPa)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out / "fig15_curves.png", dpi=120)
    plt.close(fig)
    print("wrote", ", ".join(sorted(p.name for p in args.out.iterdir() if p.is_file())))
    return 0


if __name__ == "__main__":   # calibrate_variants starts its worker processes with 'spawn'
    raise SystemExit(main())
