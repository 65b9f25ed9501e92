"""The LIGGGHTS side of the reference benchmark (liggghts_ref.py): the bed's constants, its
radius classes, the input decks that settle and time it, the bed's data and CSV files, and
the dump reader. Read liggghts_ref.py's docstring for the contact model and why."""

from __future__ import annotations

import math
import os

import numpy as np

# ----------------------------------------------------------------------------- constants
CYL_RADIUS = 0.005          # m (container diameter 10 mm)
R_MEAN = 0.2e-3             # m
R_SD = 0.02e-3              # m
R_MIN = 0.14e-3             # m
R_MAX = 0.26e-3             # m
DENSITY = 680.0e4           # kg/m3 (scaled x1e4)
GRAVITY = 9.81e-4           # m/s2 (scaled /1e4)
K_N = 4.0e5                 # N/m
K_T = 4.0e5                 # N/m
K1 = 1.0e5                  # N/m (hysteresis option: loading stiffness)
K2 = 4.0e5                  # N/m (hysteresis option: max unloading stiffness)
K_C = 600.0                 # N/m (hysteresis option: adhesion stiffness)
MU_PP = 0.5
MU_PW = 0.15
MU_ROLL = 0.01
RESTITUTION = 0.5

TIMED_BEGIN = "@@PELLETDEMTIMED_BEGIN"
TIMED_END = "@@PELLETDEMTIMED_END"


# ----------------------------------------------------------------------------- helpers
def _is_prime(n: int) -> bool:
    if n < 2:
        return False
    if n % 2 == 0:
        return n == 2
    f = 3
    while f * f <= n:
        if n % f == 0:
            return False
        f += 2
    return True


def _primes_from_seed(seed: int, count: int) -> list[int]:
    """LIGGGHTS wants prime seeds > 10000; derive `count` distinct ones from `seed`."""
    rng = np.random.default_rng(seed)
    out: list[int] = []
    while len(out) < count:
        n = int(rng.integers(10_007, 90_000_000))
        while not _is_prime(n):
            n += 1
        if n not in out:
            out.append(n)
    return out


def radius_classes(seed: int = 1, n_classes: int = 13, n_samples: int = 1_000_000):
    """Bin the truncated-normal radius distribution into discrete classes.

    Returns (radii [m], number fractions) for the non-empty classes; the fractions
    sum to exactly 1 (within float formatting) and each radius is the mean of its
    samples, so the mean radius matches the sampled distribution.
    """
    rng = np.random.default_rng(seed)
    samples = np.empty(0)
    while samples.size < n_samples:
        s = rng.normal(R_MEAN, R_SD, size=2 * n_samples)
        s = s[(s >= R_MIN) & (s <= R_MAX)]
        samples = np.concatenate([samples, s])
    samples = samples[:n_samples]
    edges = np.linspace(R_MIN, R_MAX, n_classes + 1)
    idx = np.clip(np.searchsorted(edges, samples, side="right") - 1, 0, n_classes - 1)
    counts = np.bincount(idx, minlength=n_classes)
    sums = np.bincount(idx, weights=samples, minlength=n_classes)
    keep = counts > 0
    radii = sums[keep] / counts[keep]
    fracs = counts[keep] / counts.sum()
    return radii, fracs


def _fmt_fracs(fracs: np.ndarray) -> list[str]:
    """Format fractions with 8 decimals so they sum to exactly 1.00000000."""
    q = np.round(fracs * 1e8).astype(np.int64)
    q[np.argmax(q)] += 100_000_000 - q.sum()
    return [f"{v / 1e8:.8f}" for v in q]


def _damping_rate(k: float, r_mean: float, e: float) -> float:
    """Relative damping gamma [1/s] so that a mean pair has restitution e (hooke/stiffness)."""
    m = DENSITY * 4.0 / 3.0 * math.pi * r_mean ** 3
    meff = 0.5 * m
    ln_e = math.log(e)
    zeta = -ln_e / math.sqrt(math.pi ** 2 + ln_e ** 2)
    return 2.0 * zeta * math.sqrt(k / meff)


def _youngs_for_kn(kn_target: float, r_mean: float, char_vel: float, nu: float) -> float:
    """Young's modulus giving kn(hooke/hysteresis) == kn_target for a mean-size pair.

    LIGGGHTS: kn = 16/15 sqrt(reff) Yeff (15 meff V^2 / (16 sqrt(reff) Yeff))^0.2,
    Yeff = Y / (2 (1 - nu^2)) for identical materials  ->  kn ~ Yeff^0.8.
    """
    reff = 0.5 * r_mean
    meff = 0.5 * DENSITY * 4.0 / 3.0 * math.pi * r_mean ** 3
    sq = math.sqrt(reff)
    # kn = 16/15 sq * Yeff^0.8 * (15 meff V^2 / (16 sq))^0.2
    c = 16.0 / 15.0 * sq * (15.0 * meff * char_vel ** 2 / (16.0 * sq)) ** 0.2
    yeff = (kn_target / c) ** (1.0 / 0.8)
    return yeff * 2.0 * (1.0 - nu ** 2)


# ----------------------------------------------------------------------------- deck
def _deck_header(L: list[str], nprocs: int) -> None:
    a = L.append
    a("atom_style granular")
    a("atom_modify map array")
    a("boundary f f f")
    a("newton off")
    a("communicate single vel yes")
    a("units si")
    if nprocs > 1:
        a("processors * * 1")


def _deck_contact(L: list[str], contact: str, rolling: str | None, skin: float,
                  kn: float = K_N, kt: float = K_T) -> None:
    """Neighbour settings, material properties, pair style and primitive walls; kn, kt: the
    hooke/stiffness springs, N/m."""
    a = L.append
    model = f"model {contact} tangential history"
    if rolling:
        model += f" rolling_friction {rolling}"
    a(f"neighbor {skin:.6g} bin")
    a("neigh_modify delay 0")
    a("# ---- material / contact properties (type 1 particles, type 2 walls)")
    if contact == "hooke/stiffness":
        g = _damping_rate(kn, R_MEAN, RESTITUTION)
        a(f"fix m_kn all property/global kn peratomtypepair 2 {kn:g} {kn:g} {kn:g} {kn:g}")
        a(f"fix m_kt all property/global kt peratomtypepair 2 {kt:g} {kt:g} {kt:g} {kt:g}")
        a(f"fix m_gn all property/global gamman peratomtypepair 2 {g:.6g} {g:.6g} {g:.6g} {g:.6g}")
        a(f"fix m_gt all property/global gammat peratomtypepair 2 {g:.6g} {g:.6g} {g:.6g} {g:.6g}")
    elif contact == "hooke/hysteresis":
        nu = 0.35
        vchar = 0.1
        y = _youngs_for_kn(K1, R_MEAN, vchar, nu)
        a("hard_particles yes")   # Y > 1e9 Pa needs this switch in SI units
        a(f"fix m_E all property/global youngsModulus peratomtype {y:.6g} {y:.6g}")
        a(f"fix m_nu all property/global poissonsRatio peratomtype {nu} {nu}")
        a(f"fix m_e all property/global coefficientRestitution peratomtypepair 2 "
          f"{RESTITUTION} {RESTITUTION} {RESTITUTION} {RESTITUTION}")
        a(f"fix m_vc all property/global characteristicVelocity scalar {vchar}")
        kr = K2 / K1
        kc = K_C / K1
        a(f"fix m_k2 all property/global coefficientMaxElasticStiffness peratomtypepair 2 {kr:g} {kr:g} {kr:g} {kr:g}")
        a(f"fix m_kc all property/global coefficientAdhesionStiffness peratomtypepair 2 {kc:g} {kc:g} {kc:g} {kc:g}")
        a("fix m_phi all property/global coefficientPlasticityDepth peratomtypepair 2 0.05 0.05 0.05 0.05")
    else:
        raise ValueError(f"unsupported contact model {contact!r}")
    a(f"fix m_mu all property/global coefficientFriction peratomtypepair 2 "
      f"{MU_PP} {MU_PW} {MU_PW} {MU_PW}")
    if rolling:
        a(f"fix m_mur all property/global coefficientRollingFriction peratomtypepair 2 "
          f"{MU_ROLL} {MU_ROLL} {MU_ROLL} {MU_ROLL}")
        if rolling.startswith("epsd"):
            a("fix m_rv all property/global coefficientRollingViscousDamping peratomtypepair 2 "
              "0.1 0.1 0.1 0.1")
    a(f"pair_style gran {model}")
    a("pair_coeff * *")
    a("# ---- walls: mesh-free primitives (cylinder R = 5 mm, floor z = 0), wall atom type 2")
    a(f"fix wall_cyl all wall/gran {model} primitive type 2 zcylinder {CYL_RADIUS:g} 0.0 0.0")
    a(f"fix wall_floor all wall/gran {model} primitive type 2 zplane 0.0")


def build_settle_deck(n_particles: int, seed: int, dt: float, *,
                      contact: str = "hooke/stiffness", rolling: str | None = "cdt",
                      n_classes: int = 13, phi_insert: float = 0.28, v_insert: float = 0.5,
                      dt_settle_factor: float = 2.5, g_settle: float = 9.81,
                      settle_chunk: int = 1000, max_settle_steps: int = 60_000,
                      settle_vtol: float = 5e-3, v_collapse: float = 0.05,
                      settle_damping_rate: float = 500.0, timed_gravity: float = GRAVITY,
                      unload_steps: int = 1000, unload_hold: int = 250,
                      unload_damping_rate: float = 2000.0, skin: float = 4.0e-5,
                      nprocs: int = 1, data_out: str = "settled.data", kn: float = K_N,
                      kt: float = K_T) -> tuple[str, dict]:
    """Deck 1: insert, settle under g_settle, unload gravity to timed_gravity, write_data."""
    if n_particles < 1:
        raise ValueError("n_particles must be >= 1")
    radii, fracs = radius_classes(seed, n_classes)
    ffracs = _fmt_fracs(fracs)
    v_mean = float(np.sum(fracs * 4.0 / 3.0 * np.pi * radii ** 3))
    m_mean = DENSITY * v_mean
    r_max = float(radii.max())
    r_ins = CYL_RADIUS - 1.05 * r_max
    z_lo = 1.05 * r_max
    h_ins = n_particles * v_mean / (phi_insert * math.pi * r_ins ** 2)
    z_hi = z_lo + h_ins
    z_top = z_hi + 2.0e-3
    half = CYL_RADIUS + 0.5e-3
    primes = _primes_from_seed(seed, len(radii) + 2)
    dt_settle = dt * dt_settle_factor
    max_chunks = max(1, int(math.ceil(max_settle_steps / settle_chunk)))
    do_unload = unload_steps > 0 and timed_gravity < g_settle

    L: list[str] = []
    a = L.append
    a("# pelletdem reference bed, deck 1/2 (insert + settle) -- generated by benchmarks/liggghts_ref.py")
    a(f"# n_particles={n_particles} seed={seed} contact={contact} rolling={rolling}")
    _deck_header(L, nprocs)
    a(f"region domain block {-half:.6g} {half:.6g} {-half:.6g} {half:.6g} -0.0005 {z_top:.6g} units box")
    a("create_box 2 domain")   # type 1 = particles, type 2 = walls
    _deck_contact(L, contact, rolling, skin, kn, kt)
    a("")
    a(f"# ---- radius classes: truncated normal ({R_MEAN} +- {R_SD} m in [{R_MIN}, {R_MAX}]),"
      f" {len(radii)} classes, number fractions")
    names = []
    for i, r in enumerate(radii):
        nm = f"pts{i + 1}"
        names.append(nm)
        a(f"fix {nm} all particletemplate/sphere {primes[i]} atom_type 1 "
          f"density constant {DENSITY:g} radius constant {r:.8g}")
    pdd = " ".join(f"{nm} {f}" for nm, f in zip(names, ffracs))
    a(f"fix pdd all particledistribution/discrete/numberbased {primes[-2]} {len(radii)} {pdd}")
    a("")
    a("# ---- phase 1: insertion (random sequential, no overlaps), initial v_z < 0")
    a(f"timestep {dt_settle:.6g}")
    a(f"fix gravi all gravity {g_settle:g} vector 0.0 0.0 -1.0")
    a(f"region ins cylinder z 0.0 0.0 {r_ins:.8g} {z_lo:.8g} {z_hi:.8g} units box")
    a(f"fix ins all insert/pack seed {primes[-1]} distributiontemplate pdd verbose no "
      f"maxattempt 200 insert_every once overlapcheck yes all_in yes "
      f"vel constant 0.0 0.0 {-abs(v_insert):g} "
      f"particles_in_region {n_particles} region ins ntry_mc 20000")
    a("fix integr all nve/sphere")
    a("compute rke all erotate/sphere")
    a("compute zmax all reduce max z")
    a("compute cn all contact/atom")
    a("compute cnave all reduce ave c_cn")
    a("variable vrms equal sqrt(2.0*ke/(mass(all)+1e-300))")
    a("variable cnv equal c_cnave")
    a("thermo_style custom step atoms ke c_rke v_vrms c_zmax")
    a(f"thermo {settle_chunk}")
    a("thermo_modify lost ignore norm no")
    a("run 1")
    a("unfix ins")
    a("variable nins equal atoms")
    a('print "@@PELLETDEM_INSERTED ${nins}"')
    a("")
    a(f"# ---- phase 2a: free collapse under g = {g_settle:g} until v_rms < {v_collapse:g} m/s")
    a(f"variable ichunk loop {max_chunks}")
    a("label collapse_loop")
    a(f"run {settle_chunk}")
    a(f'if "${{vrms}} < {v_collapse:.8f}" then "jump SELF collapse_done"')
    a("next ichunk")
    a("jump SELF collapse_loop")
    a("label collapse_done")
    a(f"# ---- phase 2b: quench with viscous damping (rate {settle_damping_rate:g} 1/s) "
      f"until v_rms < {settle_vtol:g} m/s")
    if settle_damping_rate > 0:
        a(f"fix visc all viscous {settle_damping_rate * m_mean:.6g}")
    a(f"variable jchunk loop {max_chunks}")
    a("label settle_loop")
    a(f'if "${{vrms}} < {settle_vtol:.8f}" then "jump SELF settle_done"')
    a(f"run {settle_chunk}")
    a("next jchunk")
    a("jump SELF settle_loop")
    a("label settle_done")
    if settle_damping_rate > 0:
        a("unfix visc")
    a('print "@@PELLETDEM_SETTLE_VRMS ${vrms}"')
    a("thermo_style custom step atoms ke c_rke v_vrms c_zmax c_cnave")
    a("run 0")
    a('print "@@PELLETDEM_CN_SETTLED ${cnv}"')
    if do_unload:
        a("")
        a(f"# ---- phase 3: unload gravity {g_settle:g} -> {timed_gravity:g} (exponential ramp over "
          f"{unload_steps} steps) with viscous damping, then hold {unload_hold} steps")
        a(f"fix visc all viscous {unload_damping_rate * m_mean:.6g}")
        a("unfix gravi")
        ln = math.log(timed_gravity / g_settle)
        a(f"variable gramp equal {g_settle:g}*exp({ln:.10g}*elapsed/{unload_steps})")
        a("fix gravi all gravity v_gramp vector 0.0 0.0 -1.0")
        a(f"thermo {unload_steps}")
        a(f"run {unload_steps}")
        a("unfix gravi")
        a(f"fix gravi all gravity {timed_gravity:g} vector 0.0 0.0 -1.0")
        if unload_hold > 0:
            a(f"run {unload_hold}")
        a("unfix visc")
        a("run 0")
        a('print "@@PELLETDEM_CN_UNLOADED ${cnv}"')
    a(f"write_data {data_out}")
    a('print "@@PELLETDEM_SETTLE_DONE"')
    a("")
    meta = dict(radii_m=[float(r) for r in radii], fractions=[float(f) for f in fracs],
                insert_region_height_m=h_ins, dt_settle_s=dt_settle, g_settle=g_settle,
                phi_insert=phi_insert, settle_vtol=settle_vtol, unloaded=do_unload,
                unload_steps=unload_steps if do_unload else 0,
                unload_hold=unload_hold if do_unload else 0, skin_m=skin, contact=contact,
                rolling=rolling)
    return "\n".join(L), meta


def build_timed_deck(data_file: str, n_steps: int, dt: float, *,
                     contact: str = "hooke/stiffness", rolling: str | None = "cdt",
                     timed_gravity: float = GRAVITY, n_relax: int = 0, skin: float = 4.0e-5,
                     nprocs: int = 1, dump_final: bool = True, kn: float = K_N,
                     kt: float = K_T) -> str:
    """Deck 2: read the settled bed (at rest) and time exactly n_steps steps."""
    if n_steps < 1:
        raise ValueError("n_steps must be >= 1")
    L: list[str] = []
    a = L.append
    a("# pelletdem reference bed, deck 2/2 (timed run) -- generated by benchmarks/liggghts_ref.py")
    _deck_header(L, nprocs)
    a(f"read_data {data_file}")
    _deck_contact(L, contact, rolling, skin, kn, kt)
    a(f"timestep {dt:.6g}")
    a(f"fix gravi all gravity {timed_gravity:g} vector 0.0 0.0 -1.0")
    a("fix integr all nve/sphere")
    a("compute cn all contact/atom")
    a("compute cnave all reduce ave c_cn")
    a("variable cnv equal c_cnave")
    a("thermo_modify lost ignore norm no")
    a("thermo_style custom step atoms ke c_cnave")
    a("run 0")
    a('print "@@PELLETDEM_CN_START ${cnv}"')
    if n_relax > 0:
        a(f"thermo {n_relax}")
        a(f"run {n_relax}")
        a("run 0")
        a('print "@@PELLETDEM_CN_AFTER_RELAX ${cnv}"')
    a("# ---- TIMED run: thermo only at first/last step, no computes beyond KE")
    a("thermo_style custom step atoms ke")
    a(f"thermo {n_steps}")
    a(f'print "{TIMED_BEGIN}"')
    a(f"run {n_steps}")
    a(f'print "{TIMED_END}"')
    a("thermo_style custom step atoms ke c_cnave")
    a("run 0")
    a('print "@@PELLETDEM_CN_END ${cnv}"')
    if dump_final:
        a("write_dump all custom final.dump id radius x y z")
    a("")
    return "\n".join(L)


def write_bed_files(x: np.ndarray, r: np.ndarray, data_path: str, csv_path: str | None = None,
                    density: float = DENSITY, z_margin: float = 2.0e-3, note: str = "") -> dict:
    """Write a bed (positions x[N,3] and radii r[N], m) as a LIGGGHTS rest-state data file
    (atom_style granular, no Velocities section, box trimmed to the bed) and, optionally, a
    plain x,y,z,r CSV that other codes can load."""
    x = np.asarray(x, dtype=float).reshape(-1, 3)
    r = np.asarray(r, dtype=float).reshape(-1)
    if len(r) != len(x) or len(r) == 0:
        raise ValueError("bed: x must be (N,3) and r (N,) with N >= 1")
    half = CYL_RADIUS + 0.5e-3
    ztop = float(np.max(x[:, 2] + r)) + z_margin
    zlo = min(-0.0005, float(np.min(x[:, 2] - r)) - 1e-4)
    out = [f"pelletdem settled bed ({len(r)} spheres) {note}".strip(), "",
           f"{len(r)} atoms", "2 atom types", "",
           f"{-half:.17g} {half:.17g} xlo xhi", f"{-half:.17g} {half:.17g} ylo yhi",
           f"{zlo:.17g} {ztop:.17g} zlo zhi", "", "Atoms", ""]
    for k in range(len(r)):
        out.append(f"{k + 1} 1 {2.0 * r[k]:.17g} {density:.17g} "
                   f"{x[k, 0]:.17g} {x[k, 1]:.17g} {x[k, 2]:.17g}")
    with open(data_path, "w") as fh:
        fh.write("\n".join(out) + "\n")
    if csv_path:
        with open(csv_path, "w") as fh:
            fh.write("# settled bed: x,y,z,r in m; density %.6g kg/m3; cylinder R=%g m, floor z=0\n"
                     % (density, CYL_RADIUS))
            fh.write("x,y,z,r\n")
            for k in range(len(r)):
                fh.write(f"{x[k, 0]:.17g},{x[k, 1]:.17g},{x[k, 2]:.17g},{r[k]:.17g}\n")
    return dict(n=len(r), z_top=ztop)


def load_bed_csv(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Read bed.csv back as (x[N,3], r[N]) in m."""
    d = np.loadtxt(path, delimiter=",", comments="#", skiprows=2, ndmin=2)
    return d[:, :3].copy(), d[:, 3].copy()


def convert_data(src: str, dst: str, csv_out: str) -> dict:
    """Turn LIGGGHTS' write_data output into the rest-state data file + CSV (sorted by id)."""
    with open(src) as fh:
        lines = fh.read().splitlines()
    i_atoms = next(k for k, ln in enumerate(lines) if ln.strip() == "Atoms")
    rows = []
    for ln in lines[i_atoms + 1:]:
        t = ln.split()
        if not t:
            if rows:
                break
            continue
        if not t[0].lstrip("-").isdigit():
            break
        rows.append(t)
    arr = np.array([[float(v) for v in t[:7]] for t in rows])
    arr = arr[np.argsort(arr[:, 0].astype(np.int64))]
    dens = float(arr[:, 3].mean())
    return write_bed_files(arr[:, 4:7], 0.5 * arr[:, 2], dst, csv_out, density=dens,
                           note=f"from {os.path.basename(src)}")


# ----------------------------------------------------------------------------- analysis
def read_dump(dump_path: str) -> tuple[list[str], np.ndarray]:
    """The column names and rows of a final dump's ATOMS section."""
    with open(dump_path) as fh:
        lines = fh.readlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("ITEM: ATOMS"))
    return lines[i].split()[2:], np.loadtxt(lines[i + 1:], ndmin=2)


def bed_stats(dump_path: str) -> dict:
    """Solid fraction in a core sample of the bed and bed height from a final dump."""
    cols, data = read_dump(dump_path)
    r = data[:, cols.index("radius")]
    x, y, z = (data[:, cols.index(c)] for c in ("x", "y", "z"))
    # bed height: mean of the top 1 % of sphere tops (robust to a few rattlers)
    tops = np.sort(z + r)
    h = float(tops[-max(1, len(tops) // 100):].mean())
    d = 2 * R_MEAN
    rs = CYL_RADIUS - 2.5 * d
    z0, z1 = 2.5 * d, h - 2.5 * d
    phi = float("nan")
    if z1 > z0 and rs > 0:
        sel = (np.hypot(x, y) < rs) & (z > z0) & (z < z1)
        phi = float(np.sum(4.0 / 3.0 * np.pi * r[sel] ** 3) / (np.pi * rs ** 2 * (z1 - z0)))
    phi_global = float(np.sum(4.0 / 3.0 * np.pi * r ** 3) / (np.pi * CYL_RADIUS ** 2 * h))
    return dict(bed_height_m=h, solid_fraction_core=phi, solid_fraction_global=phi_global,
                mean_radius_m=float(r.mean()), std_radius_m=float(r.std()))


def read_dump_bed(dump_path: str) -> tuple[np.ndarray, np.ndarray]:
    """(x[N,3], r[N]) in m from a final dump (``id radius x y z``), in id order: the order of
    the bed file the run started from."""
    cols, data = read_dump(dump_path)
    data = data[np.argsort(data[:, cols.index("id")])]
    x = np.stack([data[:, cols.index(c)] for c in ("x", "y", "z")], axis=1)
    return x, data[:, cols.index("radius")].copy()
