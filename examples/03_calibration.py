"""Calibration of the paper's 12 variants against Tables 2 and 3, beside the paper's Table 5.

    python examples/03_calibration.py OUT_DIR [--preset tiny|quick|paper] [--workers N]
                                      [--max-runs N] [--compaction-runs N] [--from DIR]
                                      [--variant oak 8 120 ...] [--set contact.mu=0.4 ...]
                                      [--dask ADDRESS]

The same as `pelletdem calibrate OUT_DIR` (pelletdem.calibrate_cli), with this file's size
knobs as defaults. One shared loading stiffness k1 against Table 2's pellet densities, then
E_b and sigma_c per variant against Table 3's sigma_f and dL_f/D
(pelletdem.calibrate.calibrate_variants). Writes into OUT_DIR: calibration.csv (the fitted
values beside Table 5 and the errors against Tables 2 and 3), calibration.json (the contact
law, the bond fits, runs, wall time and the agreement with the paper),
fig15_measured_vs_simulated.png, fig15_curves.png (each variant's fitted sigma_1(dL/D) with
Table 3's point) and fig10_relaxed.png (CN against BD_p / BD_w). Runs are cached in OUT_DIR/cache:
run again to resume; calibration.json's ``sittings`` and ``wall_time_total_s`` then add up the
wall time of every sitting, killed ones included (up to their last finished run, a lower
bound). From Python: pelletdem.calibration_dir.calibrate_into(OUT_DIR, preset=..., ...).

``--from DIR`` takes the contact law (k1) and the bond fits of an earlier calibration written
to DIR, on a smaller preset, in place of the compaction fit and Table 5's starting values:
the paper-size calibration then relaxes one pellet per pressure instead of one per k1 tried.

Size knob: PRESET and MAX_RUNS below. "tiny" with 4 runs per variant takes a few minutes on
two cores; the full study is --preset quick --compaction-runs 6 --max-runs 8 (~20 min), then
--preset paper --max-runs 8 --from the quick run's OUT_DIR (hours on two cores, or --dask with
a Dask scheduler's address).
"""
import argparse

PRESET = "tiny"      # "tiny" (minutes), "quick" (~20 min), "paper" (the paper's size, ~9 h)
MAX_RUNS = 4         # parameter points per variant fit
COMPACTION_RUNS = 2  # k1 points of the shared compaction fit (0: keep Table 4's k1)


def main(argv=None):
    from pelletdem import calibrate_cli

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    calibrate_cli.add_arguments(ap, preset=PRESET, max_runs=MAX_RUNS, compaction_runs=COMPACTION_RUNS, workers=2)
    args = ap.parse_args(argv)
    try:
        return calibrate_cli.run(args)
    except (ValueError, OSError) as e:  # a bad argument (before any work), an unwritable OUT_DIR
        ap.error(str(e))


if __name__ == "__main__":   # calibrate_variants starts its worker processes with 'spawn'
    raise SystemExit(main())
