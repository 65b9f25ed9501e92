#!/usr/bin/env python3
"""Bit fingerprints of a few whole pellet lives, to show that a change of structure changed
no result: run it with the build before and the build after and compare the lines.

    python3 scripts/fingerprint.py                   # the installed pelletdem
    PYTHONPATH=benchmarks/.cache/builds/<commit> python3 scripts/fingerprint.py

Each line is one life of the `tiny` preset (seed 0, one thread; and 2,500 particles on two
threads, to the end of compaction) with the paper's law, or with one optional effect of the
laws switched on, and the SHA-256 of every series, scalar and snapshot it produced (the
wall times left out).
"""
from __future__ import annotations

import hashlib
import json
import sys

import numpy as np

# (name, contact law fields, bond law fields): the paper's law and each optional effect.
CASES = [
    ("paper", {}, {}),
    ("hardening", {"hardening": 5.0, "hardening_exponent": 2.0}, {}),
    ("unloading_growth", {"unloading_growth": 10.0}, {}),
    ("plate_crushing", {"plate_yield_stress": 3e5}, {}),
    ("weibull_strength", {}, {"weibull_modulus": 2.5, "strength_seed": 7.0}),
    ("bond_softening", {}, {"softening": 1.5}),
    ("overlap_bond_radius", {}, {"overlap_radius_gain": 3.0}),
    ("moisture_bonds", {"moisture_content": 20.0}, {"moisture_coefficient": 0.03}),
    ("moisture_yield", {"moisture_yield": 0.03, "moisture_content": 20.0}, {}),
    ("densified_yield", {"densified_yield": 3.0}, {}),
    ("interlocking_friction", {"interlocking_friction": 2.0}, {}),
]


def digest(result) -> str:
    h = hashlib.sha256()
    for name, st in result.stages.items():
        h.update(name.encode())
        h.update(json.dumps(st.scalars, sort_keys=True).encode())
        h.update(str(st.steps).encode())
        for key in sorted(st.series):
            h.update(key.encode())
            h.update(np.ascontiguousarray(st.series[key]).tobytes())
    for name in sorted(result.snapshots):
        for key in sorted(result.snapshots[name]):
            h.update(np.ascontiguousarray(result.snapshots[name][key]).tobytes())
    return h.hexdigest()[:16]


def main() -> int:
    import pelletdem as pd
    from pelletdem import pipeline, stages
    from pelletdem.presets import get_preset

    bond = dict(radius=2e-5, youngs_modulus=30e6, sigma_c=9e6, tau_c=9e6)
    for name, contact, bonds in CASES:
        preset = get_preset("tiny").with_(max_dLD=0.15)
        if contact:
            preset = preset.with_(contact=pd.ContactLaw(**contact))
        res = pipeline.run_pellet(preset, seed=0, threads=1, bond_law=pd.BondLaw(**bond, **bonds), progress=False)
        print(f"{name:<22} {digest(res)}", flush=True)
    pellet, fill = stages.fill(get_preset("quick"), seed=1, threads=2, progress=False)
    comp = stages.compact(pellet, 120e6, progress=False)
    h = hashlib.sha256()
    for st in (fill, comp):
        for key in sorted(st.series):
            h.update(np.ascontiguousarray(st.series[key]).tobytes())
    h.update(np.ascontiguousarray(pellet.world.x).tobytes())
    print(f"{'quick compaction 2 thr':<22} {h.hexdigest()[:16]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
