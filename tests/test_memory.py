"""Memory: repeating work in one process does not grow its resident set (VmRSS).

A calibration runs hundreds of pellets in one worker process, so a leak of one world per run
(tens of MB on the paper preset) would end it. RSS is read from /proc/self/status after a
warm-up (the allocator, numpy, h5py and the first world's arrays settle in the first runs)
and must stay within a margin over the repetitions that follow.
"""
import gc
import os

import numpy as np
import pytest

import pelletdem as pd
from pelletdem import checkpoint, pipeline

pytestmark = [
    pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="needs Linux /proc"),
    # AddressSanitizer keeps freed blocks in a quarantine (256 MB by default) and maps shadow
    # memory, so RSS grows under scripts/sanitize.sh whatever the code does.
    pytest.mark.skipif("libasan" in os.environ.get("LD_PRELOAD", ""), reason="RSS is meaningless under ASan"),
]


def rss_mb() -> float:
    """Resident set size of this process, MB (VmRSS)."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS in /proc/self/status")


def test_engine_objects_do_not_leak(tmp_path):
    """120 worlds of 400 particles built, run, viewed, cloned, saved and restored: the margin
    is 8 MB over the last 80 (one such world with its neighbour list is ~0.5 MB, so a leak of a
    world per round would show as 40 MB). Measured: 0.0 MB."""
    r = pd.truncated_normal_radii(400, seed=1)
    x, r = pd.random_pack_cylinder(r, radius=1.5e-3, z_lo=0.0, z_hi=0.012, seed=2)
    path = tmp_path / "w.h5"
    seen = []
    for k in range(120):
        w = pd.World(box=((-2e-3, -2e-3, -1e-3), (2e-3, 2e-3, 0.015)), gravity=(0, 0, -9.81e4))
        w.add_particles(x, r)
        w.add_plane("floor", (0, 0, 0), (0, 0, 1))
        w.add_cylinder("mould", (0, 0, 0), 1.5e-3)
        w.run(100, progress=lambda done: None)
        views = (w.x, w.v, w.f)
        assert np.isfinite(views[0]).all()
        c = w.clone()
        c.run(10)
        back = pd.World.from_state(w.get_state())
        if k % 10 == 0:
            checkpoint.save_world(back, path)
            checkpoint.load_world(path).run(5)
        try:
            w.add_particles(x[:1], r[:1])  # refused while views are alive: the error path too
        except pd.ParameterError:
            pass
        del w, c, back, views
        gc.collect()
        seen.append(rss_mb())
    growth = max(seen[40:]) - seen[39]
    assert growth < 8.0, f"RSS grew {growth:.1f} MB over 80 rounds: {seen[39]:.1f} -> {seen[-1]:.1f} MB"


@pytest.mark.slow
def test_fifty_pipelines_in_one_process(tmp_path):
    """50 small pellets (the tiny preset with 60 particles: every stage, bonds, the diametral
    test, a checkpoint at every stage end and the Result saved to HDF5) in one process. Measured:
    114.1 MB after 5 runs, 114.2 MB after 50. Margin: 10 MB over the 45 runs after warm-up
    (one run's Result with its snapshots is ~0.3 MB, its world ~0.1 MB)."""
    seen = []
    for k in range(50):
        ck = checkpoint.RunCheckpoint(tmp_path / "ck.h5", {"k": k}, interval=float("inf"))
        res = pipeline.run_pellet("tiny", n_particles=60, seed=k % 3, threads=1, progress=False, checkpoint=ck)
        assert res.scalar("diametral", "sigma_f") > 0
        res.save(tmp_path / "result.h5")
        os.remove(tmp_path / "ck.h5")
        del res, ck
        gc.collect()
        seen.append(rss_mb())
    growth = max(seen[5:]) - seen[4]
    assert growth < 10.0, f"RSS grew {growth:.1f} MB over 45 runs: {seen[4]:.1f} -> {seen[-1]:.1f} MB"
