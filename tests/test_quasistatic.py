"""Quasi-static check: the tensile strength does not depend on the loading speed.

The loading in the simulation is ~1000 times faster than the laboratory's (see NOTES and the
docs/model.md, "Quasi-static control"); the usual check is that halving the speeds changes the
result by little. Here every speed of the default 'quick' preset (2500 particles, 5 mm mould)
is halved -- piston down and up, mould opening and plates -- and sigma_f must move by less
than 5 %. The bonds are the paper's Table 5 oak ones (MC 8 %, 120 MPa: E_b = 120 MPa,
sigma_c = tau_c = 36 MPa), with which the quick pellet peaks near dL/D = 0.1; the test runs
on to dL/D = 0.15 so the peak is inside it.

One pellet's peak also moves by several per cent with nothing but the packing changed (the
breakage is chaotic: see the reproducibility figures in docs/reliability.md), so the test compares the mean
sigma_f over two packing seeds at each speed.

Slow (four quick pellets on one thread, two at half speed: ~8 min): `pytest -m slow`.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from pelletdem import pipeline
from pelletdem.presets import get_preset

SPEEDS = ("piston_speed", "unload_speed", "demould_rate", "plate_speed")
MAX_DLD = 0.15


SEEDS = (0, 1)


def _sigma_f(preset, seed):
    t0 = time.perf_counter()
    law = pipeline.bond_law_for("oak", 8, 120)
    res = pipeline.run_pellet(preset, material="oak", mc=8, sigma_z_mpa=120, seed=seed, threads=1,
                              bond_law=law, progress=False)
    s = res.stages["diametral"].series
    k = int(np.argmax(s["sigma_1"]))
    # The peak must be a peak: inside the test and followed by a fall.
    assert res.scalar("diametral", "dLf_D") < 0.9 * MAX_DLD
    assert s["sigma_1"][k:].min() < 0.9 * s["sigma_1"][k]
    return res, time.perf_counter() - t0


@pytest.mark.slow
def test_sigma_f_does_not_depend_on_the_loading_speed():
    base = get_preset("quick").with_(max_dLD=MAX_DLD)
    half = base.with_(**{name: 0.5 * getattr(base, name) for name in SPEEDS})
    f1, f2 = [], []
    for seed in SEEDS:
        r1, t1 = _sigma_f(base, seed)
        r2, t2 = _sigma_f(half, seed)
        f1.append(r1.scalar("diametral", "sigma_f"))
        f2.append(r2.scalar("diametral", "sigma_f"))
        print(f"\nseed {seed}: sigma_f {f1[-1] / 1e6:.4f} MPa at the preset's speeds ({t1:.0f} s), "
              f"{f2[-1] / 1e6:.4f} MPa at half ({t2:.0f} s); relaxed bulk density "
              f"{r1.scalar('relax', 'bulk_density'):.1f} / {r2.scalar('relax', 'bulk_density'):.1f} kg/m^3")
    change = abs(np.mean(f2) - np.mean(f1)) / np.mean(f1)
    print(f"mean sigma_f {np.mean(f1) / 1e6:.4f} -> {np.mean(f2) / 1e6:.4f} MPa: change {100 * change:.1f} %")
    assert change < 0.05
