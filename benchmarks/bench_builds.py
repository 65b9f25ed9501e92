#!/usr/bin/env python3
"""Two or more builds of pelletdem timed against each other in one run, on the engine
benchmark's settled bed (bench_engine.settled_bed: the paper's radii at rest in the 10 mm
mould, contact law of eq. 5-11).

Run:  python3 benchmarks/bench_builds.py --ref HEAD~3 --ref HEAD
      python3 benchmarks/bench_builds.py --ref old=/path/to/site --ref new=HEAD --n 10000

A ``--ref`` is a git revision, built once into benchmarks/.cache/builds/<commit> from a
clean checkout of it (``pip install --target``, Release build), or ``NAME=DIR`` for a
directory that holds an installed ``pelletdem`` package. Each round times every build in
turn, each in a fresh process (``--steps`` steps on 1 and 2 threads after the bed
benchmark's warm-up), and the best of the rounds is kept for each; the machines are shared
and drift by 10-40 % between runs, so only builds timed in the same run are compared. The
last lines give each build's particle-steps per second and its ratio to the first build.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
BUILDS = os.path.join(HERE, ".cache", "builds")


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True, text=True).stdout.strip()


def build(ref: str) -> tuple[str, str]:
    """(name, directory holding the installed package) for one --ref."""
    if "=" in ref:
        name, path = ref.split("=", 1)
        if os.path.isdir(os.path.join(path, "pelletdem")):
            return name, os.path.abspath(path)
        ref = path
    else:
        name = ref
    commit = _git("rev-parse", "--verify", ref + "^{commit}")
    target = os.path.join(BUILDS, commit)
    if not os.path.isdir(os.path.join(target, "pelletdem")):
        os.makedirs(BUILDS, exist_ok=True)
        with tempfile.TemporaryDirectory() as tmp:
            src = os.path.join(tmp, "src")
            _git("worktree", "add", "--detach", src, commit)
            try:
                print(f"# building {name} ({commit[:10]}) ...", flush=True)
                subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                                "--target", target, src], check=True)
            finally:
                _git("worktree", "remove", "--force", src)
    return name, target


def time_build(path: str, n: int, threads: int, steps: int) -> dict:
    """bench_engine.time_steps on the settled bed of n, run with the build at `path`."""
    code = ("import json, bench_engine as b; x, r = b.settled_bed(%d); "
            "print(json.dumps(b.time_steps(x, r, %d, %d)))" % (n, threads, steps))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([path, HERE]), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True,
                         cwd=HERE).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ref", action="append", required=True, help="git revision or NAME=DIR (two or more)")
    ap.add_argument("--n", type=int, default=10000, help="particles in the settled bed")
    ap.add_argument("--steps", type=int, default=1000, help="timed steps per sample")
    ap.add_argument("--rounds", type=int, default=3, help="rounds, every build timed once in each")
    ap.add_argument("--threads", default="1,2", help="thread counts, comma-separated")
    a = ap.parse_args(argv)
    if len(a.ref) < 2:
        ap.error("give at least two --ref")
    threads = [int(t) for t in a.threads.split(",")]
    builds = [build(r) for r in a.ref]
    sys.path.insert(0, HERE)
    import bench_engine

    bench_engine.settled_bed(a.n)  # built (and cached) once, by the installed pelletdem
    best: dict = {}
    for k in range(a.rounds):
        for name, path in builds:
            for t in threads:
                res = time_build(path, a.n, t, a.steps)
                key = (name, t)
                if key not in best or res["ps"] > best[key]["ps"]:
                    best[key] = res
                print(f"round {k + 1} {name:>12} {t} thread(s): {res['ps'] / 1e6:6.2f} M particle-steps/s "
                      f"(CN {res['cn_start']:.2f} -> {res['cn_end']:.2f}, {res['builds']} list builds)", flush=True)
    first = builds[0][0]
    print(f"# best of {a.rounds} rounds, {a.n} particles, {a.steps} steps:")
    for name, _ in builds:
        cells = []
        for t in threads:
            ps = best[(name, t)]["ps"]
            cells.append(f"{t} thread(s) {ps / 1e6:6.2f} M ({ps / best[(first, t)]['ps']:.3f}x {first})")
        print(f"{name:>12}: " + ", ".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
