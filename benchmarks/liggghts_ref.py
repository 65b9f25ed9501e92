#!/usr/bin/env python3
"""Reference benchmark: a dense, settled bed of pellet-sawdust spheres in LIGGGHTS.

It builds, settles and times the same bed that pelletdem's own benchmark uses:
``n_particles`` polydisperse spheres in a 10 mm cylinder with a floor.  It then times
exactly ``n_steps`` steps of the settled bed with (scaled) gravity on, using the
Debian package ``liggghts`` (LIGGGHTS-PUBLIC 3.8.0).

Contact model used in LIGGGHTS and why
--------------------------------------
pelletdem's model:
    linear hysteretic normal spring (Walton-Braun type) with loading k1 = 1e5 N/m,
    unloading k2 = 4e5 N/m, adhesion k_c, so e = sqrt(k1/k2) = 0.5 with no dashpot;
    incremental tangential spring k_t with Coulomb limit mu = 0.5; rolling
    friction coefficient 0.01; dt = 2e-6 s (density x1e4, gravity /1e4).

LIGGGHTS settings (default ``contact="hooke/stiffness"``):
    pair_style gran model hooke/stiffness tangential history rolling_friction cdt
    * normal:  linear spring with a FIXED stiffness k_n = 4e5 N/m (= k2, the stiffness
      of the settled, unloading/reloading contacts in our model), plus a linear
      dashpot.  Damping is "relative" (LIGGGHTS' default for hooke/stiffness):
      F_d = -gamma_n * m_eff * v_n.  gamma_n is set so that a pair of mean-size
      spheres (r = 0.2 mm) rebounds with e = 0.5:
      gamma_n = 2*zeta*sqrt(k_n/m_eff), zeta = -ln e / sqrt(pi^2 + ln^2 e).
      Smaller pairs get a somewhat larger e, larger pairs a smaller e; our model
      gives e = 0.5 for every size.
    * tangential: ``tangential history``.  This is an incremental (history)
      tangential spring k_t = 4e5 N/m with a Coulomb cap mu = 0.5 particle-particle,
      the same structure as ours.  gamma_t = gamma_n (LIGGGHTS' usual choice; the
      tangential dashpot is switched on by default).
    * rolling: ``rolling_friction cdt`` (constant directional torque,
      M_r = mu_r * |F_n| * r_eff * w_rel/|w_rel|), mu_r = 0.01.  This is the
      cheapest of LIGGGHTS' rolling models and corresponds to a constant rolling
      friction coefficient 0.01.  Pass ``rolling="epsd2"`` for the spring-type model,
      or ``rolling=None`` to switch it off.
    * walls: mesh-free primitive walls (``fix wall/gran ... primitive type 2
      zcylinder`` with radius 5 mm, and a ``zplane`` floor at z = 0) with the same
      contact model.  They use atom type 2, so particle-wall friction is
      mu_pw = 0.15 (the paper's value); all other wall values are the same as
      particle-particle.
    * no adhesion (our k_c term; LIGGGHTS' cohesion models are JKR/capillary
      types, not a linear adhesion branch).

Why not ``hooke/hysteresis``?  LIGGGHTS 3.8 does have ``model hooke/hysteresis``,
a Luding-type linear hysteretic model with adhesion.  Its per-type-pair properties
are coefficientMaxElasticStiffness (k2Max/kn), coefficientAdhesionStiffness (kc/kn)
and coefficientPlasticityDepth (phiF).  It is closer in kind, but in this version
its loading stiffness is not a fixed constant: it is worked out for each pair from
Young's modulus, the particle sizes and a "characteristicVelocity"
(k_n ~ r_eff^0.4 * m_eff^0.2 * Y^0.8).  Its unloading stiffness also grows with
the largest overlap, up to k2Max, and it still needs a dashpot for e.  So it
cannot reproduce fixed k1/k2 N/m values.  You can select it with
``contact="hooke/hysteresis"``.  Young's modulus is then chosen so that a pair of
mean-size spheres gets k_n = k1 = 1e5 N/m (Y = 8.96e9 Pa with v_char = 0.1 m/s;
``hard_particles yes`` is needed because Y > 1e9 Pa), with k2Max/kn = 4,
kc/kn = 0.006 and phiF = 0.05.  Use it only as a rough second reference.  The
default is the fixed-stiffness Hooke model, as the benchmark brief asks.

Radii: a truncated normal distribution (mean 0.2 mm, SD 0.02 mm, cut at
[0.14, 0.26] mm).  It is sampled with numpy (seeded, 1e6 samples) and binned into
``n_classes`` (13) equal-width radius classes.  Each class gets the mean radius of
its samples and its number fraction.  The classes go to LIGGGHTS through
``fix particletemplate/sphere`` + ``fix particledistribution/discrete/numberbased``,
so the fractions are NUMBER fractions.  (The plain ``/discrete`` is mass-based.)
The binned distribution has mean 0.2000 mm and SD 0.0195 mm; truncation at +-3 SD
makes the SD slightly smaller than 0.02 mm.
Density 680e4 kg/m3 (x1e4 scaling).  dt = 2e-6 s.

Settling protocol (documented choice)
-------------------------------------
Deck 1, ``in.settle`` (one LIGGGHTS process):

1. ``fix insert/pack`` puts all N spheres at random, without overlap, into a
   cylinder region.  Its radius is R - 1.05 r_max, and its height is chosen so the
   solid fraction is ``phi_insert`` (0.28).  Random sequential insertion jams at
   ~0.30, so the bed starts about 2.2x as tall as it ends.  The spheres start with
   v_z = -0.5 m/s.
2. Settling uses UNSCALED gravity 9.81 m/s2 (1e4 x the production value) and a
   larger time step dt_settle = 2.5*dt = 5e-6 s.  That is still ~1/10 of the
   mean-pair contact time, ~5.3e-5 s.  First comes a free collapse, in chunks of
   1000 steps, until v_rms < 0.05 m/s.  Then a quench with ``fix viscous`` (rate
   500 1/s) runs until v_rms < ``settle_vtol`` (5e-3 m/s).  Under 9.81 m/s2 the
   static overlap at the bottom of a 40k bed is ~0.2 % of r, and impacts
   (< ~1 m/s) give transient overlaps < ~8 % r.
3. Unloading: gravity is ramped down exponentially from 9.81 to the
   timed-run gravity (9.81e-4) over 1000 steps, then held for 250 steps, with
   ``fix viscous`` (rate 2000 1/s) on.  The bed is then written with
   ``write_data``.

Deck 2, ``in.timed`` (a second LIGGGHTS process):

4. ``read_data`` of the bed AT REST: zero translational AND angular velocities.
   LIGGGHTS 3.8's ``set`` cannot zero omega; that is one reason for using two
   processes.  Contact history starts empty.  The same bed is saved as
   ``bed.csv`` (x,y,z,r in m), so pelletdem can start from exactly the same
   state.  Gravity is ``timed_gravity`` (default 9.81e-4), dt = 2e-6 s, and
   ``n_relax`` untimed steps (default 0) come first.
5. The TIMED run: exactly ``n_steps`` steps (``run n_steps``).  Thermo output is
   only at the first and last step.  The time is LIGGGHTS' own "Loop time of X on
   P procs for N steps with M atoms" line for that run.  So it is the wall time of
   the integration loop only.  Setup, the neighbour build at run start and the
   diagnostics (contact/atom coordination numbers before and after, final dump)
   are not counted.

``settle_time_s`` is the sum of LIGGGHTS' loop times for steps 1-3 (plus
``n_relax``).  ``total_wall_s`` is the wall time of both LIGGGHTS processes.

CAVEAT, contact count: with gravity at 9.81e-4 m/s2 and no adhesion, a settled
bed is held together only by ~1e-11 m overlaps.  Any leftover motion opens
contacts.  The mean number of particle-particle contacts (``cn_timed_start`` /
``cn_timed_end``, particle-particle contacts only) therefore depends on bed size
and history.  With seed 1 we measured 4.1 -> 3.0 over 2000 steps for 40k
particles, but only 0.33 -> 0.09 for 10k.  The cost per step depends strongly on
it: ~1.7e7 particle-steps/s at CN ~0.3 against ~3-4e6 at CN ~4 (10k, 1 core).
For a well-defined, contact-rich reference, use ``timed_gravity=9.81`` (CLI
``--gravity 9.81``): the bed stays loaded as it was settled, with CN 3.4-4.3,
constant over the run.  bench_engine.py does so (since 2026-12-04; before, it
timed at 9.81e-4 a bed settled at 9.81, which sprang apart: CN 4.4 -> 0.06 here,
~2 in pelletdem), and lets LIGGGHTS settle pelletdem's bed again first (once, read
back with ``liggghts_deck.read_dump_bed``): its linear spring has no plastic part, so it springs
back from overlaps that pelletdem's hysteretic contacts hold at rest (10,000 bed:
CN 4.5 -> 0.3 in 2,000 steps with k_n = k2, -> 1.0 with k_n = k1; at rest again,
CN 4.5, after 30,000 steps with k_n = k_t = k1, the springs the benchmark uses).
For like-for-like figures, time pelletdem and LIGGGHTS on the SAME bed.  Either load
``bed.csv`` (``liggghts_deck.load_bed_csv``) into pelletdem, or pass pelletdem's bed to
``run_liggghts_bed(..., bed=(x, r))``; this skips settling.  Report the CN with the figures.
``time_settled_bed(workdir)`` re-times an already settled bed, for repeats or other thread counts.

Timing noise: loop times are wall times.  On a shared machine, check
``cpu_share_timed_process``; values well below 1 mean other processes took CPU
time and the loop time is inflated.

MPI: threads > 1 runs ``mpirun -np threads liggghts`` for both decks.  As root,
Open MPI needs ``--allow-run-as-root``, and ``--oversubscribe`` is added too.  It
uses ``processors * * 1`` so the tall domain is never cut along z; otherwise, in
the settled bed, one rank would hold almost every particle.

Usage: python benchmarks/liggghts_ref.py --n 10000 --steps 2000 --threads 1
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import tempfile
import time

from liggghts_deck import (
    GRAVITY,
    K_N,
    K_T,
    TIMED_BEGIN,
    TIMED_END,
    bed_stats,
    build_settle_deck,
    build_timed_deck,
    convert_data,
    write_bed_files,
)

_LOOP_RE = re.compile(
    r"Loop time of\s+([0-9.eE+-]+)\s+on\s+(\d+)\s+procs.*?for\s+(\d+)\s+steps\s+with\s+(\d+)\s+atoms")
_VERSION_RE = re.compile(r"LIGGGHTS \(Version ([^,)]+)")


# ----------------------------------------------------------------------------- helpers
def _liggghts_exe() -> str | None:
    return shutil.which("liggghts")


def liggghts_available() -> bool:
    """True if a working ``liggghts`` executable is on PATH."""
    exe = _liggghts_exe()
    if exe is None:
        return False
    try:
        with tempfile.TemporaryDirectory(prefix="liggghts_probe_") as d:
            p = subprocess.run([exe, "-log", "none", "-nocite", "-h"], cwd=d,
                               capture_output=True, text=True, timeout=60)
        return "LIGGGHTS" in (p.stdout + p.stderr)
    except (OSError, subprocess.SubprocessError):
        return False


def _liggghts_version(exe: str) -> str:
    try:
        with tempfile.TemporaryDirectory(prefix="liggghts_probe_") as d:
            p = subprocess.run([exe, "-log", "none", "-nocite", "-h"], cwd=d,
                               capture_output=True, text=True, timeout=60)
        m = _VERSION_RE.search(p.stdout + p.stderr)
        return m.group(1).strip() if m else "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _tail(text: str, n: int = 40) -> str:
    return "\n".join(text.splitlines()[-n:])


# ----------------------------------------------------------------------------- main API
def _mpi_prefix(threads: int) -> tuple[list[str] | None, str | None]:
    """Return (command prefix, error) for running with `threads` MPI ranks."""
    if threads <= 1:
        return [], None
    mpirun = shutil.which("mpirun") or shutil.which("mpiexec")
    if mpirun is None:
        return None, "mpirun/mpiexec not found"
    base = [mpirun]
    extra = ["--oversubscribe"]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        extra = ["--allow-run-as-root"] + extra
    try:
        p = subprocess.run(base + extra + ["-np", str(threads), "true"],
                           capture_output=True, text=True, timeout=60)
        if p.returncode != 0:
            # not Open MPI? try without the Open-MPI-only flags
            p2 = subprocess.run(base + ["-np", str(threads), "true"],
                                capture_output=True, text=True, timeout=60)
            if p2.returncode != 0:
                return None, "mpirun does not work: " + _tail(p.stdout + p.stderr, 10)
            extra = []
    except (OSError, subprocess.SubprocessError) as exc:
        return None, f"mpirun does not work: {exc}"
    return base + extra + ["-np", str(threads)], None


def _run_deck(cmd_prefix: list[str], exe: str, deck: str, log: str, workdir: str,
              timeout_s: float | None, must_contain: str) -> tuple[str, float, float]:
    """Run one deck; return (output, wall seconds, CPU seconds of the process tree)."""
    cmd = cmd_prefix + [exe, "-in", deck, "-log", log, "-nocite", "-echo", "none"]
    env = dict(os.environ)
    env.setdefault("OMP_NUM_THREADS", "1")
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, cwd=workdir, capture_output=True, text=True,
                           timeout=timeout_s, env=env)
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout or b""
        out = out.decode(errors="replace") if isinstance(out, bytes) else out
        raise RuntimeError(f"LIGGGHTS timed out after {timeout_s} s (deck {deck}); last output:\n"
                           f"{_tail(out)}") from None
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    out = p.stdout + ("\n" + p.stderr if p.stderr else "")
    if p.returncode != 0 or re.search(r"^ERROR", out, re.M) or must_contain not in out:
        raise RuntimeError(f"LIGGGHTS failed (rc={p.returncode}, deck {deck}, log {log}); "
                           f"last output:\n{_tail(out)}")
    return out, wall, cpu


def _grab(pattern: str, text: str, conv=float):
    m = re.search(pattern + r"\s+([0-9.eE+-]+)", text)
    return conv(m.group(1)) if m else None


def run_liggghts_bed(n_particles: int, n_steps: int = 2000, threads: int = 1, seed: int = 1,
                     workdir: str | None = None, dt: float = 2e-6, *,
                     timed_gravity: float = GRAVITY, n_relax: int = 0,
                     contact: str = "hooke/stiffness", rolling: str | None = "cdt",
                     skin: float = 4.0e-5, timeout_s: float | None = None,
                     bed: tuple | None = None, kn: float = K_N, kt: float = K_T,
                     **settle_kw) -> dict:
    """Build, settle and time a dense bed of `n_particles` spheres in LIGGGHTS.

    Two LIGGGHTS processes: deck 1 (``in.settle``) inserts, settles, unloads gravity
    and writes the bed; deck 2 (``in.timed``) reads the bed at rest and runs exactly
    `n_steps` steps, which are timed.  Returns a dict with n_particles (actual count
    in the timed run), n_steps, loop_time_s (LIGGGHTS loop time of the timed run only),
    particle_steps_per_s, threads (MPI ranks), settle_time_s (LIGGGHTS loop time of
    deck 1), total_wall_s, liggghts_version, deck (timed deck path), settle_deck,
    bed_file (x,y,z,r CSV of the starting bed), coordination numbers and bed
    diagnostics.  If MPI is requested but unusable, returns a dict with an ``error``
    field instead of raising.  Raises RuntimeError (with the last lines of the
    LIGGGHTS output) if LIGGGHTS fails.  Extra keyword arguments go to
    :func:`build_settle_deck`.

    ``bed=(x, r)`` (positions [N,3] and radii [N] in m, e.g. pelletdem's own settled
    bed) skips deck 1 and times that bed instead (from rest, density 6.8e6 kg/m3);
    n_particles must then equal N, and settle_time_s is 0. ``kn``, ``kt`` (N/m): the
    hooke/stiffness springs of that timed run (K_N, K_T by default; a bed settled by
    pelletdem is in equilibrium with kn = kt = K1, its loading stiffness).
    """
    exe = _liggghts_exe()
    if exe is None:
        raise RuntimeError("liggghts executable not found on PATH")
    threads = max(1, int(threads))
    prefix, err = _mpi_prefix(threads)
    if prefix is None:
        return dict(n_particles=0, n_steps=n_steps, threads=threads, loop_time_s=float("nan"),
                    particle_steps_per_s=float("nan"), settle_time_s=float("nan"),
                    liggghts_version=_liggghts_version(exe), deck=None,
                    error=f"MPI not usable for threads={threads}: {err}")
    if n_steps < 1:
        raise ValueError("n_steps must be >= 1")

    if workdir is None:
        workdir = tempfile.mkdtemp(prefix="liggghts_ref_")
    os.makedirs(workdir, exist_ok=True)
    workdir = os.path.abspath(workdir)
    for stale in ("final.dump", "settled.data", "bed_start.data", "bed.csv",
                  "log.settle", "log.timed"):
        try:
            os.remove(os.path.join(workdir, stale))
        except FileNotFoundError:
            pass

    bed_data = os.path.join(workdir, "bed_start.data")
    bed_csv = os.path.join(workdir, "bed.csv")
    if bed is not None:
        bx, br = bed
        if len(br) != n_particles:
            raise ValueError(f"bed has {len(br)} spheres but n_particles={n_particles}")
        write_bed_files(bx, br, bed_data, bed_csv, note="(given bed)")
        res = _timed_run(prefix, exe, workdir, n_steps, dt, contact=contact, rolling=rolling,
                         timed_gravity=timed_gravity, n_relax=n_relax, skin=skin, nprocs=threads,
                         timeout_s=timeout_s, kn=kn, kt=kt)
        relax_time = res.pop("_relax_time_s")
        res["total_wall_s"] = res.pop("_wall_s")
        res.update(kn=kn, kt=kt)
        res.update(n_requested=n_particles, settle_time_s=relax_time, settle_steps=0,
                   settle_deck=None, bed_source="given", contact=contact, rolling=rolling,
                   skin_m=skin)
        return res

    # ---- deck 1: insert + settle (+ unload)
    settle_text, meta = build_settle_deck(n_particles, seed, dt, contact=contact, rolling=rolling,
                                          skin=skin, timed_gravity=timed_gravity, nprocs=threads,
                                          data_out="settled.data", kn=kn, kt=kt, **settle_kw)
    settle_deck = os.path.join(workdir, "in.settle")
    with open(settle_deck, "w") as fh:
        fh.write(settle_text)
    out1, wall1, _cpu1 = _run_deck(prefix, exe, settle_deck, os.path.join(workdir, "log.settle"),
                            workdir, timeout_s, "@@PELLETDEM_SETTLE_DONE")
    settle_time = sum(float(x.group(1)) for x in _LOOP_RE.finditer(out1))
    settle_steps = sum(int(x.group(3)) for x in _LOOP_RE.finditer(out1))

    convert_data(os.path.join(workdir, "settled.data"), bed_data, bed_csv)

    # ---- deck 2: timed run from rest
    res = _timed_run(prefix, exe, workdir, n_steps, dt, contact=contact, rolling=rolling,
                     timed_gravity=timed_gravity, n_relax=n_relax, skin=skin, nprocs=threads,
                     timeout_s=timeout_s, kn=kn, kt=kt)
    relax_time = res.pop("_relax_time_s")
    wall2 = res.pop("_wall_s")
    res.update(
        n_requested=n_particles,
        settle_time_s=settle_time + relax_time,
        settle_steps=settle_steps,
        total_wall_s=wall1 + wall2,
        settle_deck=settle_deck,
        n_inserted=_grab("@@PELLETDEM_INSERTED", out1, int),
        settle_vrms_m_s=_grab("@@PELLETDEM_SETTLE_VRMS", out1),
        cn_settled=_grab("@@PELLETDEM_CN_SETTLED", out1),
        cn_unloaded=_grab("@@PELLETDEM_CN_UNLOADED", out1),
        **{k: v for k, v in meta.items() if k not in ("radii_m", "fractions")},
        n_radius_classes=len(meta["radii_m"]),
        bed_source="liggghts",
    )
    if res["n_particles"] != n_particles:
        w = f"only {res['n_particles']} of {n_particles} particles in the timed run"
        res["warning"] = (res["warning"] + "; " + w) if "warning" in res else w
    return res


def _timed_run(prefix: list[str], exe: str, workdir: str, n_steps: int, dt: float, *,
               contact: str, rolling: str | None, timed_gravity: float, n_relax: int,
               skin: float, nprocs: int, timeout_s: float | None, kn: float = K_N,
               kt: float = K_T) -> dict:
    """Write and run deck 2 (in.timed) on workdir/bed_start.data; parse the timed loop."""
    timed_text = build_timed_deck("bed_start.data", n_steps, dt, contact=contact, rolling=rolling,
                                  timed_gravity=timed_gravity, n_relax=n_relax, skin=skin,
                                  nprocs=nprocs, kn=kn, kt=kt)
    deck = os.path.join(workdir, "in.timed")
    with open(deck, "w") as fh:
        fh.write(timed_text)
    log = os.path.join(workdir, "log.timed")
    try:
        os.remove(os.path.join(workdir, "final.dump"))
    except FileNotFoundError:
        pass
    out2, wall2, cpu2 = _run_deck(prefix, exe, deck, log, workdir, timeout_s, TIMED_END)

    pre, _, rest = out2.partition(TIMED_BEGIN)
    timed_part = rest.partition(TIMED_END)[0]
    m = _LOOP_RE.search(timed_part)
    if m is None:
        raise RuntimeError(f"could not parse the timed 'Loop time' line (deck {deck}); last output:\n"
                           f"{_tail(out2)}")
    loop_time = float(m.group(1))
    nprocs_run = int(m.group(2))
    steps_run = int(m.group(3))
    natoms = int(m.group(4))
    mnb = re.search(r"Neighbor list builds\s*=\s*(\d+)", timed_part)
    mnn = re.search(r"Ave neighs/atom\s*=\s*([0-9.eE+-]+)", timed_part)
    mver = _VERSION_RE.search(out2)
    res = dict(
        n_particles=natoms,
        n_steps=steps_run,
        loop_time_s=loop_time,
        particle_steps_per_s=natoms * steps_run / loop_time if loop_time > 0 else float("inf"),
        threads=nprocs_run,
        liggghts_version=mver.group(1).strip() if mver else _liggghts_version(exe),
        deck=deck,
        log=log,
        bed_file=os.path.join(workdir, "bed.csv"),
        workdir=workdir,
        cn_timed_start=_grab("@@PELLETDEM_CN_START", out2),
        cn_after_relax=_grab("@@PELLETDEM_CN_AFTER_RELAX", out2),
        cn_timed_end=_grab("@@PELLETDEM_CN_END", out2),
        neighbor_builds_timed=int(mnb.group(1)) if mnb else None,
        neighs_per_atom=float(mnn.group(1)) if mnn else None,
        dt=dt,
        timed_gravity=timed_gravity,
        n_relax=n_relax,
        # share of the timed process's wall time x ranks that it got on a CPU: well below 1
        # means other work shared the cores and loop_time_s is inflated
        cpu_share_timed_process=cpu2 / (wall2 * nprocs_run) if wall2 > 0 else float("nan"),
        _relax_time_s=sum(float(x.group(1)) for x in _LOOP_RE.finditer(pre)),
        _wall_s=wall2,
    )
    if steps_run != n_steps:
        res["warning"] = f"timed run reported {steps_run} steps, expected {n_steps}"
    dump = os.path.join(workdir, "final.dump")
    if os.path.exists(dump):
        try:
            res.update(bed_stats(dump))
        except Exception as exc:  # diagnostics only
            res["bed_stats_error"] = repr(exc)
    return res


def time_settled_bed(workdir: str, n_steps: int = 2000, threads: int = 1, dt: float = 2e-6, *,
                     timed_gravity: float = GRAVITY, n_relax: int = 0,
                     contact: str = "hooke/stiffness", rolling: str | None = "cdt",
                     skin: float = 4.0e-5, timeout_s: float | None = None) -> dict:
    """Re-time a bed that :func:`run_liggghts_bed` already settled in `workdir`.

    Only deck 2 runs (same bed_start.data, at rest), e.g. for repeats or other
    thread counts.  Returns the same timing fields as run_liggghts_bed (no settle data).
    """
    exe = _liggghts_exe()
    if exe is None:
        raise RuntimeError("liggghts executable not found on PATH")
    workdir = os.path.abspath(workdir)
    if not os.path.exists(os.path.join(workdir, "bed_start.data")):
        raise RuntimeError(f"no bed_start.data in {workdir}; run run_liggghts_bed first")
    threads = max(1, int(threads))
    prefix, err = _mpi_prefix(threads)
    if prefix is None:
        return dict(n_particles=0, n_steps=n_steps, threads=threads, loop_time_s=float("nan"),
                    particle_steps_per_s=float("nan"), liggghts_version=_liggghts_version(exe),
                    deck=None, error=f"MPI not usable for threads={threads}: {err}")
    res = _timed_run(prefix, exe, workdir, n_steps, dt, contact=contact, rolling=rolling,
                     timed_gravity=timed_gravity, n_relax=n_relax, skin=skin, nprocs=threads,
                     timeout_s=timeout_s)
    res["relax_time_s"] = res.pop("_relax_time_s")
    res["total_wall_s"] = res.pop("_wall_s")
    return res


# ----------------------------------------------------------------------------- CLI
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="LIGGGHTS reference benchmark: settled pellet-sawdust bed")
    ap.add_argument("--n", type=int, default=10000, help="number of particles")
    ap.add_argument("--steps", type=int, default=2000, help="timed steps")
    ap.add_argument("--threads", type=int, default=1, help="MPI processes")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--dt", type=float, default=2e-6)
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--contact", default="hooke/stiffness",
                    choices=["hooke/stiffness", "hooke/hysteresis"])
    ap.add_argument("--rolling", default="cdt", help="cdt, epsd2 or none")
    ap.add_argument("--gravity", type=float, default=GRAVITY,
                    help="gravity during the timed run (default 9.81e-4 m/s2)")
    ap.add_argument("--relax", type=int, default=0, help="untimed steps before the timed run")
    ap.add_argument("--skin", type=float, default=4.0e-5, help="neighbour skin, m")
    ap.add_argument("--json", action="store_true", help="also print the result dict as JSON")
    a = ap.parse_args(argv)
    if not liggghts_available():
        print("LIGGGHTS not available")
        return 2
    rolling = None if a.rolling.lower() in ("none", "off", "") else a.rolling
    res = run_liggghts_bed(a.n, a.steps, a.threads, a.seed, a.workdir, a.dt,
                           contact=a.contact, rolling=rolling, timed_gravity=a.gravity,
                           n_relax=a.relax, skin=a.skin)
    if a.json:
        print(json.dumps(res, indent=1, default=str))
    if "error" in res:
        print(f"error: {res['error']}")
        return 1
    print(f"liggghts_version     {res['liggghts_version']}")
    print(f"deck                 {res['deck']}")
    if "solid_fraction_core" in res:
        print(f"bed_height_mm        {res['bed_height_m'] * 1e3:.2f}")
        print(f"solid_fraction_core  {res['solid_fraction_core']:.3f}")
    print(f"coordination_start   {res['cn_timed_start']}")
    print(f"coordination_end     {res['cn_timed_end']}")
    print(f"bed_file             {res['bed_file']}")
    print(f"cpu_share_timed      {res['cpu_share_timed_process']:.2f}")
    print(f"n_particles          {res['n_particles']}")
    print(f"n_steps              {res['n_steps']}")
    print(f"threads              {res['threads']}")
    print(f"settle_time_s        {res['settle_time_s']:.2f}")
    print(f"total_wall_s         {res['total_wall_s']:.2f}")
    print(f"loop_time_s          {res['loop_time_s']:.3f}")
    print(f"particle_steps_per_s {res['particle_steps_per_s']:.4g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
