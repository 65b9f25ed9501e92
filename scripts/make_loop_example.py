"""Make the example data set of `pelletdem loop --data example` with the engine, the way a
laboratory makes its measurements.

    python scripts/make_loop_example.py [OUT_DIR] [--workers N] [--cache DIR]

OUT_DIR defaults to python/pelletdem/data/loop_example (the shipped copy). Oak at 8 %
moisture, pressed at the pressures of ``pelletdem loop --synthetic`` (the last one held out);
five replicate pellets per pressure, each from its own packing (pelletdem.loop_synthetic's
DATA_SEEDS, which no fit or check of the loop uses); the bond law of synthetic data
(pelletdem.loop_cli.SYNTHETIC_BOND) with an effect the manifest does not declare switched on
(HIDDEN below). Each replicate carries measurement noise (NOISE, relative, one normal draw per
replicate and number):

* its diametral curve sigma_1(dL/D): sigma_1 times (1 + NOISE N) (eq. 4 divides the force by
  the pellet's measured R and h) and dL/D times (1 + NOISE N) (the measured diameter); the test
  stops at STOP_AFTER times the replicate's deformation at failure, as an operator stops it
  once the pellet has broken;
* its compaction curve sigma_z(dh/h0): sigma_z times (1 + NOISE N) (the load cell);
* its relaxed bulk density times (1 + NOISE N) (caliper and balance).

Writes the curve files (pelletdem.measured.save_curve, replicates in one file, the condition in
``# pressure_mpa=...`` headers), the manifest loop_example.toml (bulk densities as
{mean, sd, n}) and README.md. Simulations go through a run cache (--cache, default a
temporary directory), so a rerun with the same cache only writes the files again.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

PRESET = "tiny"
MATERIAL = "oak"
MOISTURE_PERCENT = 8.0
HIDDEN = "overlap_bond_radius"  # an effect of pelletdem.effects, not declared in the manifest
HIDDEN_STRENGTH = 3.0          # bonds between flattened contacts are wider: r_b (1 + g delta_0 / r*)
NOISE = 0.02               # relative measurement noise per replicate
STOP_AFTER = 2.0           # the diametral test ends at this multiple of the replicate's dL_f/D
NOISE_SEED = 0
ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "python" / "pelletdem" / "data" / "loop_example"
MPA = 1e6


def stop_test(x: np.ndarray, y: np.ndarray, x_f: float, sigma_f: float) -> int:
    """Points of a simulated diametral curve (dL/D, sigma_1 Pa) the laboratory's test records:
    up to STOP_AFTER x_f, and before any later rise above the failure stress sigma_f (a small
    pellet crushed between the plates can load up again; a machine's break detection has
    stopped the test by then)."""
    n = int(np.searchsorted(x, STOP_AFTER * x_f, side="right"))
    above = np.flatnonzero((x > x_f) & (y > sigma_f))
    return min(n, int(above[0])) if above.size else n


def replicate_curves(members, cond, rng, noise: float):
    """(diametral Curve, compaction Curve, bulk densities kg/m^3) of the replicates
    ``members`` (pelletdem.loop.Prediction, one per packing) of ``cond``, with measurement
    noise drawn from ``rng``."""
    from pelletdem.measured import Curve

    meta = {"pressure_mpa": cond.sigma_z / MPA, "moisture_percent": cond.mc, "material": cond.material}
    dx, dy, dr, cx, cy, cr, rho = [], [], [], [], [], [], []
    for k, m in enumerate(members, start=1):
        if m.scalars.get("peaked", 0.0) < 1.0:
            raise RuntimeError(f"{cond.label}, replicate {k}: the pellet did not break inside the test window")
        x, y = (np.asarray(a, float) for a in m.curve)
        n = stop_test(x, y, m.scalars["dLf_D"], m.scalars["sigma_f"])
        kx, ky, kz, kd = 1.0 + noise * rng.standard_normal(4)
        # rounded as a test machine exports them: 1e-6 of dL/D, 0.1 Pa
        dx.append(np.round(x[:n] * kx, 6))
        dy.append(np.round(y[:n] * ky, 1))
        dr += [str(k)] * n
        xc, yc = (np.asarray(a, float) for a in m.compaction)
        # the loading branch from the piston's first touch: dh/h0 from 0, never stepping back
        keep = (xc >= 0.0) & (xc >= np.maximum.accumulate(xc))
        cx.append(np.round(xc[keep], 6))
        cy.append(np.round(yc[keep] * kz, 1))
        cr += [str(k)] * int(keep.sum())
        rho.append(m.scalars["bulk_density"] * kd)
    diam = Curve(np.concatenate(dx), np.concatenate(dy), dr, "diametral", meta)
    comp = Curve(np.concatenate(cx), np.concatenate(cy), cr, "compaction", meta)
    return diam, comp, np.array(rho)


def _toml_float(v: float) -> str:
    """2e7 rather than 2e+07 (both TOML)."""
    return f"{v:g}".replace("e+0", "e").replace("e+", "e")


def manifest_text(rows, bounds, held_mpa: float) -> str:
    """The TOML manifest: ``rows`` of (pressure MPa, diametral file, compaction file,
    densities kg/m^3); ``bounds`` {name: (lo, hi)} SI."""
    from pelletdem.runs import PARAMETERS

    out = ["# The example data of `pelletdem loop --data example`, made by scripts/make_loop_example.py",
           "# (see README.md here). Each condition's pressure, moisture and material are in its curve",
           "# files' headers.",
           f'name = "{MATERIAL}, {MOISTURE_PERCENT:g} % moisture (example made with the engine)"', "",
           "[fit]".ljust(32) + "# bounds of the fitted base parameters (SI)"]
    out += [f"{k} = [{_toml_float(lo)}, {_toml_float(hi)}]".ljust(32) + "# " + PARAMETERS[k][0]
            for k, (lo, hi) in bounds.items()]
    out += ["", "[model]", f'preset = "{PRESET}"']
    for p, dfile, cfile, rho in rows:
        sd = float(np.std(rho, ddof=1))
        out += ["", "[[condition]]".ljust(32) + f"# {p:g} MPa",
                f"held_out = {'true' if p == held_mpa else 'false'}",
                f'diametral = "{dfile}"', f'compaction = "{cfile}"',
                f"bulk_density = {{ mean = {np.mean(rho):.1f}, sd = {sd:.1f}, n = {len(rho)} }}   # kg/m^3"]
    return "\n".join(out) + "\n"


def readme_text(pressures_mpa, held_mpa: float, bond: dict, seeds, wall_s: float, workers: int, command: str) -> str:
    """README.md of the data set: how it was made and what is hidden in it."""
    ps = ", ".join(f"{p:g}" for p in pressures_mpa[:-1]) + f" and {pressures_mpa[-1]:g}"
    from pelletdem.effects import EFFECTS

    n, effect = len(seeds), EFFECTS[HIDDEN]
    return f"""# Example data for `pelletdem loop --data example`

Measurements of a laboratory that does not exist: {MATERIAL} pellets at {MOISTURE_PERCENT:g} %
moisture pressed at {ps} MPa, {n} replicate pellets each. They were made with the
engine, not typed in, by

    {command}

in {wall_s:.0f} s with {workers} worker{'s' if workers > 1 else ''} (the generator's docstring says every choice).

- `loop_example.toml`: the manifest (its format: `docs/loop.md`, "Your own data");
  {held_mpa:g} MPa is held out of the fit.
- `{MATERIAL}_<P>mpa_diametral.csv`: sigma_1 (Pa) against dL/D, {n} replicates in one file;
  the `# pressure_mpa=`, `# moisture_percent=` and `# material=` headers give the condition.
- `{MATERIAL}_<P>mpa_compaction.csv`: sigma_z (Pa) against dh/h0, {n} replicates.
- The bulk densities of the relaxed pellets are in the manifest (mean, SD and count).

How: the `{PRESET}` pellet; one replicate per packing, seeds {", ".join(map(str, seeds))}
(`pelletdem.loop_synthetic.DATA_SEEDS`, which no fit or check of the loop uses); the bond law
of synthetic data (`pelletdem.loop_cli.SYNTHETIC_BOND`: E_b = {bond['youngs_modulus']:g} Pa,
sigma_c = tau_c = {bond['sigma_c']:g} Pa); {100 * NOISE:g} % measurement noise per replicate on
sigma_1 and dL/D, on sigma_z and on the density; each diametral test stopped at
{STOP_AFTER:g} times the replicate's deformation at failure.

**The truth, which the manifest does not say:** `{HIDDEN}` is switched on, `{effect.param}` =
{HIDDEN_STRENGTH:g}: {effect.description}.
The loop is not told; finding it is its job.
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", nargs="?", type=Path, default=DEFAULT_OUT, help="output directory (created)")
    ap.add_argument("--workers", type=int, default=1, help="simulation processes")
    ap.add_argument("--cache", type=Path, default=None, help="run cache directory (default: a temporary one)")
    args = ap.parse_args(argv)
    if args.workers < 1:
        ap.error("--workers must be >= 1")

    from pelletdem import loop
    from pelletdem.effects import EFFECTS
    from pelletdem.engine import BondLaw
    from pelletdem.loop_cli import SYNTHETIC_BOND, SYNTHETIC_BOUNDS, SYNTHETIC_PRESSURES, WINDOW
    from pelletdem.measured import save_curve

    t0 = time.perf_counter()
    conds = [loop.Condition(p, MOISTURE_PERCENT, MATERIAL) for p in SYNTHETIC_PRESSURES]
    held_mpa = SYNTHETIC_PRESSURES[-1] / MPA  # as `pelletdem loop --synthetic` holds it out
    truth = {"E_b": SYNTHETIC_BOND["youngs_modulus"], "sigma_c": SYNTHETIC_BOND["sigma_c"],
             **EFFECTS[HIDDEN].settings(HIDDEN_STRENGTH)}
    rng = np.random.default_rng(NOISE_SEED)
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        cache = str(args.cache) if args.cache else tmp
        with loop.EngineSimulator(PRESET, bond=BondLaw(**SYNTHETIC_BOND), max_dLD=WINDOW,
                                  executor="serial" if args.workers == 1 else None, max_workers=args.workers,
                                  cache_dir=cache, relaxed_dir=os.path.join(cache, "relaxed")) as sim:
            ensembles = sim.predict(truth, conds, loop.DATA_SEEDS)
    rows = []
    for c in sorted(conds, key=lambda c: c.sigma_z):
        ens = ensembles[c]
        if not ens.ok:
            raise RuntimeError(f"{c.label}: {ens.error}")
        diam, comp, rho = replicate_curves(ens.members, c, rng, NOISE)
        p = c.sigma_z / MPA
        names = (f"{MATERIAL}_{p:g}mpa_diametral.csv", f"{MATERIAL}_{p:g}mpa_compaction.csv")
        save_curve(diam, args.out / names[0])
        save_curve(comp, args.out / names[1])
        rows.append((p, *names, rho))
    (args.out / "loop_example.toml").write_text(manifest_text(rows, SYNTHETIC_BOUNDS, held_mpa))
    wall = time.perf_counter() - t0
    command = "python scripts/make_loop_example.py" + ("" if args.out == DEFAULT_OUT else f" {args.out}")
    pressures = sorted(c.sigma_z / MPA for c in conds)
    (args.out / "README.md").write_text(readme_text(pressures, held_mpa, SYNTHETIC_BOND, loop.DATA_SEEDS,
                                                    wall, args.workers, command))
    print(f"wrote {args.out} in {wall:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
