"""Calibration of the paper's 12 variants against Tables 2 and 3, beside the paper's Table 5.

    python examples/03_calibration.py OUT_DIR [--preset tiny|quick|paper] [--workers N]
                                      [--max-runs N] [--compaction-runs N] [--from DIR]
                                      [--variant oak 8 120 ...]

One shared loading stiffness k1 against Table 2's pellet densities, then E_b and sigma_c per
variant against Table 3's sigma_f and dL_f/D (pelletdem.calibrate.calibrate_variants). Writes
into OUT_DIR: calibration.csv (the fitted values beside Table 5 and the errors against Tables 2
and 3), calibration.json (the contact law, the bond fits, runs and wall time),
fig15_measured_vs_simulated.png and fig15_curves.png (each variant's fitted sigma_1(dL/D) with
Table 3's point). Runs are cached in OUT_DIR/cache: run again to resume; calibration.json's
``sittings`` and ``wall_time_total_s`` then add up the wall time of every sitting, killed ones
included (up to their last finished run, a lower bound).

``--from DIR`` takes the contact law (k1) and the bond fits of an earlier calibration written
to DIR, on a smaller preset, in place of the compaction fit and Table 5's starting values:
the paper-size calibration then relaxes one pellet per pressure instead of one per k1 tried.

Size knob: PRESET and MAX_RUNS below. "tiny" with 4 runs per variant takes a few minutes on
two cores; the full study is --preset quick --compaction-runs 6 --max-runs 8 (~20 min), then
--preset paper --max-runs 8 --from the quick run's OUT_DIR (hours on two cores, or give
calibrate_variants a Dask distributed.Client).
"""
import argparse
import json
import time
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
    ap.add_argument("--compaction-runs", type=int, default=COMPACTION_RUNS,
                    help="k1 points of the shared compaction fit (0: keep Table 4's k1)")
    ap.add_argument("--from", dest="source", type=Path, default=None,
                    help="OUT_DIR of an earlier calibration: its k1 and bond fits are the start here")
    ap.add_argument("--variant", nargs=3, action="append", metavar=("MATERIAL", "MC", "SIGMA_Z_MPA"),
                    help="calibrate only these variants (repeatable); default all 12")
    args = ap.parse_args(argv)
    if args.compaction_runs < 0 or args.max_runs < 1 or args.workers < 1:
        ap.error("--compaction-runs must be >= 0, --max-runs and --workers >= 1")
    source = None
    if args.source is not None:
        path = args.source / "calibration.json"
        if not path.is_file():
            ap.error(f"--from {args.source}: no calibration.json there (write one with this script)")
        source = json.loads(path.read_text())

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
    if source is not None:
        setup = dict(compaction=None, contact=source["contact"], start=source["bond_start"])
    elif args.compaction_runs:
        setup = dict(compaction={"k1": (k1 / 10, k1 * 10, k1)}, compaction_max_runs=args.compaction_runs)
    else:
        setup = dict(compaction=None)
    segments = _segments_log(args.out)
    segments.start()
    report = calibrate.calibrate_variants(
        variants, preset, max_runs=args.max_runs, cache_dir=args.out / "cache",
        relaxed_dir=args.out / "relaxed", max_workers=args.workers, **setup)
    print(report)
    report.table.to_csv(args.out / "calibration.csv", index=False)
    (args.out / "calibration.json").write_text(json.dumps({
        "preset": args.preset, "contact": report.contact, "bond_start": report.bond_start(),
        "from": str(args.source) if args.source else None, "n_simulations": report.n_simulations,
        "n_cached": report.n_cached, "n_relaxations": report.n_relaxations,
        "wall_time_s": report.wall_time_s, **segments.finish(report)}, indent=1))

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


class _segments_log:
    """Wall time of a calibration that ran in several sittings: OUT_DIR/segments.jsonl holds a
    line at each start and end. A sitting that was killed has no end line; its end is taken as
    the last cache record written before the next start (a lower bound: the runs in flight
    when it was killed are not counted)."""

    def __init__(self, out: Path):
        self.path, self.cache = out / "segments.jsonl", out / "cache"

    def _append(self, **row):
        with open(self.path, "a") as fh:
            fh.write(json.dumps({"time": time.time(), **row}) + "\n")

    def start(self):
        """Marks the start of a sitting (wall clock, s since the epoch)."""
        self._append(event="start")

    def finish(self, report) -> dict:
        """Marks the end; returns calibration.json's fields on every sitting and their sum (s)."""
        self._append(event="end", n_simulations=report.n_simulations, n_cached=report.n_cached)
        rows = [json.loads(line) for line in self.path.read_text().splitlines() if line.strip()]
        mtimes = sorted(f.stat().st_mtime for f in self.cache.rglob("*.json"))
        sittings = []
        for k, row in enumerate(rows):
            if row["event"] != "start":
                continue
            nxt = rows[k + 1] if k + 1 < len(rows) else None
            if nxt is not None and nxt["event"] == "end":
                sittings.append({"start": row["time"], "wall_time_s": nxt["time"] - row["time"],
                                 "killed": False, "n_simulations": nxt["n_simulations"]})
            else:  # killed: it ran until its last record, at least
                stop = nxt["time"] if nxt is not None else float("inf")
                done = [t for t in mtimes if row["time"] <= t < stop]
                sittings.append({"start": row["time"], "wall_time_s": (max(done) - row["time"]) if done else 0.0,
                                 "killed": True, "n_simulations": len(done)})
        return {"sittings": sittings, "wall_time_total_s": sum(s["wall_time_s"] for s in sittings)}


if __name__ == "__main__":   # calibrate_variants starts its worker processes with 'spawn'
    raise SystemExit(main())
