"""Hostile input at every public entry point: property tests with hypothesis.

Random and hostile values (NaN, inf, huge and negative numbers and counts, wrong types, wrong
dtypes and shapes, non-contiguous arrays, broken state dicts, garbage files, random command
lines) go into the Python API and the raw bindings (pelletdem._core). The only acceptable
outcomes are a normal return or a named Python error: a ValueError (pelletdem.ParameterError,
MeasuredDataError, ...), a TypeError (a value of the wrong type), or a RuntimeError
(pelletdem.SimulationError when a run goes wrong). Never a crash, a hang, a MemoryError from
a huge allocation, or a KeyError / IndexError / AttributeError from deep inside.

The examples are run in a child process (`test_hostile_inputs_in_a_child_process`), so a
segfault or an abort fails that test with the child's output instead of killing pytest, and
the child's address space is capped (outside sanitizer builds) so that a huge allocation
fails fast. Each property test draws MAX_EXAMPLES examples with a fixed seed (derandomize),
the same ones on every run; `PELLETDEM_HOSTILE_EXAMPLES` raises the count.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile

import numpy as np
import pytest

CHILD = os.environ.get("PELLETDEM_HOSTILE_CHILD") == "1"
MAX_EXAMPLES = int(os.environ.get("PELLETDEM_HOSTILE_EXAMPLES", "120"))
ALLOWED = (ValueError, TypeError, RuntimeError)


def test_hostile_inputs_in_a_child_process():
    """Run this file's property tests in a child pytest; it must pass (no crash, no hang)."""
    if CHILD:
        pytest.skip("inside the child")
    env = dict(os.environ, PELLETDEM_HOSTILE_CHILD="1", OMP_WAIT_POLICY="PASSIVE", MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-x",
                           "-k", "not child_process", __file__],
                          capture_output=True, text=True, timeout=900, env=env)
    tail = (proc.stdout + proc.stderr)[-6000:]
    assert proc.returncode == 0, f"child exited with {proc.returncode}:\n{tail}"
    assert " passed" in proc.stdout, tail


# The property tests below run only in the child; the parent collects and skips them.
child_only = pytest.mark.skipif(not CHILD, reason="runs in the child process (see the test above)")

import resource  # noqa: E402

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

import pelletdem as pd  # noqa: E402
from pelletdem import _core, checkpoint, cli, measured, pipeline  # noqa: E402
from pelletdem.result import Result  # noqa: E402

if CHILD and "asan" not in os.environ.get("LD_PRELOAD", ""):
    # A huge allocation must fail fast, not swap the machine (ASan needs its own huge map).
    _soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    _cap = 6 << 30 if _hard == resource.RLIM_INFINITY else min(6 << 30, _hard)
    resource.setrlimit(resource.RLIMIT_AS, (_cap, _hard))

SETTINGS = settings(max_examples=MAX_EXAMPLES, deadline=None, derandomize=True, database=None,
                    suppress_health_check=list(HealthCheck))

# --- strategies ------------------------------------------------------------------------------

huge_ints = st.sampled_from([-2**70, -2**63, -2**31 - 1, -1, 0, 2**31, 2**32 + 1, 2**63, 2**70, 10**13])
floats = st.floats(allow_nan=True, allow_infinity=True)
odd_floats = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 1e-320, 1e-300, 1e300, 1.7e308])
scalars = st.one_of(floats, odd_floats, st.integers(-10**6, 10**6), huge_ints, st.booleans(), st.none(),
                    st.text(max_size=4), st.just(1 + 2j), st.just(b"\x00"), st.just([1.0, 2.0]),
                    st.just(np.float32(np.nan)), st.just(np.int64(-5)))
vectors = st.one_of(st.lists(st.one_of(floats, odd_floats), min_size=0, max_size=5),
                    st.tuples(floats, floats, floats), scalars,
                    hnp.arrays(np.float64, st.integers(0, 5), elements=floats))
dtypes = st.sampled_from([np.float64, np.float32, np.int64, np.int8, np.uint8, np.complex128, np.bool_,
                          np.float16, object, "U3"])


@st.composite
def arrays(draw, rows=None, cols=None):
    """Arrays of a random (often wrong) dtype and shape, sometimes non-contiguous."""
    dt = draw(dtypes)
    shape = draw(st.one_of(
        st.just(()), st.tuples(st.integers(0, 6)), st.tuples(st.integers(0, 6), st.integers(0, 4)),
        st.tuples(st.integers(0, 3), st.integers(0, 3), st.integers(0, 3)),
        st.just((rows or 3, cols or 3)) if cols else st.just((rows or 3,))))
    if dt is object:
        a = np.empty(shape, dtype=object)
        a.fill(draw(scalars))
    elif dt == "U3":
        a = np.full(shape, "ab", dtype="U3")
    else:
        with np.errstate(all="ignore"):
            a = np.asarray(draw(hnp.arrays(np.float64, shape, elements=st.one_of(floats, odd_floats))))
            a = a.astype(dt) if dt != np.float64 else a
    if draw(st.booleans()) and a.ndim >= 1 and a.shape[0] > 1:
        a = a[::2]  # a strided view
    if draw(st.booleans()) and a.ndim == 2:
        a = np.asfortranarray(a)
    return a


def _ok(fn, *args, **kwargs):
    """Call fn; a normal return or an allowed error is fine, anything else fails the test."""
    try:
        return fn(*args, **kwargs)
    except ALLOWED:
        return None


def _small_world(**kw):
    w = pd.World(dt=2e-6, box=((-2e-3, -2e-3, -1e-3), (2e-3, 2e-3, 5e-3)), gravity=(0, 0, -9.81e4), **kw)
    r = np.full(20, 2e-4)
    x = np.stack([np.zeros(20) + (np.arange(20) % 4) * 5e-4 - 7.5e-4, np.zeros(20),
                  (np.arange(20) // 4) * 5e-4 + 2e-4], axis=1)
    w.add_particles(x, r)
    w.add_plane("floor", (0, 0, 0), (0, 0, 1))
    w.add_cylinder("mould", (0, 0, 0), 1.5e-3)
    return w


def _raw_params():
    p = _core.WorldParams()
    p.box_lo, p.box_hi = [-1e-2] * 3, [1e-2] * 3
    return p


def _raw_world():
    return _core.World(_raw_params())


# --- World construction -------------------------------------------------------------------------

WORLD_KW = ["dt", "box", "density", "density_scale", "gravity", "skin", "threads", "max_overlap_ratio",
            "sample_interval", "contact"]


@child_only
@SETTINGS
@given(st.dictionaries(st.sampled_from(WORLD_KW), st.one_of(scalars, vectors,
                                                            st.tuples(vectors, vectors))))
def test_world_construction(kw):
    w = _ok(pd.World, **kw)
    if w is not None:
        _ok(w.run, 5)


CONTACT_FIELDS = list(pd.ContactLaw.__dataclass_fields__)


@child_only
@SETTINGS
@given(st.dictionaries(st.sampled_from(CONTACT_FIELDS), scalars, max_size=4))
def test_contact_law(fields):
    law = _ok(pd.ContactLaw, **fields)
    if law is not None:
        _ok(pd.World, contact=law)
        _ok(law.to_core)


@child_only
@SETTINGS
@given(st.sampled_from(["dt", "threads", "density", "density_scale", "skin", "max_overlap_ratio",
                        "sample_interval"] + [f"contact.{f}" for f in CONTACT_FIELDS]), scalars)
def test_raw_world_params(name, value):
    p = _raw_params()
    target = p
    if name.startswith("contact."):
        target, name = p.contact, name.split(".", 1)[1]
    _ok(setattr, target, name, value)
    if target is not p:
        _ok(setattr, p, "contact", target)
    w = _ok(_core.World, p)
    if w is not None:
        _ok(w.add_particles, np.zeros((1, 3)) + 1e-3, np.array([2e-4]))
        _ok(w.run_until, [], 5)


# --- particles, walls, runs ---------------------------------------------------------------------

@child_only
@SETTINGS
@given(arrays(cols=3), arrays())
def test_add_particles(x, r):
    w = pd.World(box=((-1e-2,) * 3, (1e-2,) * 3))
    n0 = w.n
    if _ok(w.add_particles, x, r) is None and w.n != n0:
        _ok(w.run, 3)
    _ok(_raw_world().add_particles, x, r)


@child_only
@SETTINGS
@given(arrays(cols=3), arrays(cols=3))
def test_set_velocities_and_positions(v, omega):
    w = _small_world()
    _ok(w.set_velocities, v, omega)
    _ok(w.set_positions, v)
    _ok(w.run, 3)


@child_only
@SETTINGS
@given(st.sampled_from(["add_plane", "add_cylinder", "set_wall_velocity", "set_wall_point",
                        "set_wall_radius", "set_wall_radius_rate", "set_wall_servo", "set_wall_active",
                        "set_load_walls", "wall_state", "wall_samples", "set_sample_interval",
                        "set_max_overlap_ratio", "set_adhesion_ramp", "gravity", "dt", "threads"]),
       st.lists(st.one_of(scalars, vectors), min_size=0, max_size=4))
def test_wall_and_world_setters(method, args):
    w = _small_world()
    if method in ("gravity", "dt", "threads"):
        _ok(setattr, w, method, args[0] if args else None)
    else:
        _ok(getattr(w, method), *args)
    _ok(w.run, 5)


CONDITIONS = ["time", "steps", "kinetic_energy_below", "internal_kinetic_energy_below", "wall_force_above",
              "wall_force_below", "wall_travel_above", "load_marker_above", "load_drop_below", "bogus"]


@child_only
@SETTINGS
@given(st.dictionaries(st.sampled_from(CONDITIONS), st.one_of(scalars, st.tuples(scalars, scalars)), max_size=3),
       st.one_of(st.integers(0, 300), huge_ints, scalars), st.one_of(st.integers(1, 50), scalars))
def test_run_conditions(conds, max_steps, check_interval):
    w = _small_world()
    conds["steps"] = 200  # whatever max_steps says, a valid call ends within 200 steps
    _ok(w.run_until, max_steps=max_steps, check_interval=check_interval, **conds)
    kinds = list(_core.StopKind.__members__.values())
    raw = [_ok(_core.StopCondition, k, v, wl, ci) for k, v, wl, ci in
           [(kinds[0], 1e-4, -1, 1)] + [(kinds[i % len(kinds)], _num(v), _int(v), _int(v)) for i, v in
                                         enumerate(conds.values())]]
    raw = [c for c in raw if c is not None] + [_core.StopCondition(_core.StopKind.Steps, 100)]
    _ok(w._core.run_until, raw, _int(max_steps) if _int(max_steps) is not None else 100)


def _num(v):
    try:
        return float(v)
    except Exception:  # noqa: BLE001
        return math.nan


def _int(v):
    try:
        return int(v)
    except Exception:  # noqa: BLE001
        return None


# --- bonds ---------------------------------------------------------------------------------------

BOND_FIELDS = list(pd.BondLaw.__dataclass_fields__)


@child_only
@SETTINGS
@given(st.dictionaries(st.sampled_from(BOND_FIELDS), scalars, max_size=4),
       st.sampled_from(["radius", "kn", "kt", "sigma_c", "tau_c", "bogus"]), arrays())
def test_bond_laws(fields, prop, values):
    w = _small_world()
    w.run(50)
    law = _ok(pd.BondLaw, **fields)
    if law is not None and _ok(w.create_bonds, law) is not None:
        _ok(w.set_bond_property, prop, values)
        _ok(w.run, 5)


# --- states and checkpoints ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def good_state():
    w = _small_world()
    w.run(100)
    w.create_bonds(pd.BondLaw(gap_tolerance=1e-5))
    w.run(10)
    return w.get_state()


def _mutate(draw, state):
    """One random damage to a state dict: a key deleted, replaced by a hostile value, an array
    cut short or cast to another (negated) dtype, or a wall entry spoilt."""
    d = dict(state)
    key = draw(st.sampled_from(sorted(d)))
    action = draw(st.sampled_from(["delete", "replace", "truncate", "wrongtype", "wall"]))
    value = d[key]
    if action == "delete":
        del d[key]
    elif action == "replace":
        d[key] = draw(st.one_of(scalars, arrays()))
    elif action == "truncate" and isinstance(value, np.ndarray) and value.ndim and len(value):
        d[key] = value[: draw(st.integers(0, len(value) - 1))]
    elif action == "wrongtype" and isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        with np.errstate(all="ignore"):
            d[key] = (-value).astype(draw(dtypes)) if value.dtype.kind != "u" else value.astype(draw(dtypes))
    elif action == "wall" and isinstance(d.get("walls"), list) and d["walls"] and \
            all(isinstance(x, dict) for x in d["walls"]):
        walls = [dict(x) for x in d["walls"]]
        k = draw(st.sampled_from(sorted(walls[0])))
        walls[0][k] = draw(st.one_of(scalars, arrays()))
        d["walls"] = draw(st.sampled_from([walls, tuple(walls), [1, 2], "walls"]))
    return d


@child_only
@SETTINGS
@given(st.data())
def test_set_state_with_broken_dicts(good_state, data):
    d = good_state
    for _ in range(data.draw(st.integers(1, 3))):
        d = _mutate(data.draw, d)
    w = _small_world()
    _ok(w._core.set_state, d)
    _ok(w.run, 3)
    back = _ok(pd.World.from_state, d)
    if back is not None:
        _ok(back.run, 3)
    _ok(_raw_world().set_state, data.draw(scalars))


@child_only
@SETTINGS
@given(st.binary(max_size=2000), st.integers(0, 3))
def test_garbage_files(data, kind):
    """Random bytes, or a real file cut short, as a checkpoint, a run checkpoint or a result."""
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "f.h5")
        if kind == 0:
            blob = data
        else:
            src = os.path.join(d, "good.h5")
            if kind == 1:
                checkpoint.save_world(_small_world(), src)
            else:
                Result(params={"a": 1}, seed=0, version="x").save(src, xdmf=False)
            blob = open(src, "rb").read()
            cut = int.from_bytes(data[:4].ljust(4, b"\0"), "little") % max(len(blob), 1)
            blob = blob[:cut] + data[4:]
        with open(path, "wb") as fh:
            fh.write(blob)
        for load in (checkpoint.load_world, Result.load,
                     lambda p: checkpoint.RunCheckpoint(p, {"x": 1}).resume()):
            try:
                load(path)
            except (checkpoint.CheckpointError, pd.engine.ParameterError, ValueError):
                pass


# --- generation -----------------------------------------------------------------------------------

@child_only
@SETTINGS
@given(st.one_of(st.integers(-5, 2000), huge_ints, scalars), scalars, scalars, scalars, scalars,
       st.one_of(st.integers(0, 2**64), huge_ints, scalars))
def test_truncated_normal_radii(n, mean, sd, r_min, r_max, seed):
    kw = {k: v for k, v in dict(mean=mean, sd=sd, r_min=r_min, r_max=r_max).items() if v is not None}
    _ok(pd.truncated_normal_radii, n, seed=seed if isinstance(seed, int) else 0, **kw)
    _ok(_core.truncated_normal_radii, n, mean, sd, r_min, r_max, seed)


@child_only
@SETTINGS
@given(arrays(), scalars, scalars, scalars, st.tuples(scalars, scalars), st.one_of(st.integers(-3, 2000), scalars))
def test_random_pack_cylinder(radii, radius, z_lo, z_hi, center, attempts):
    _ok(pd.random_pack_cylinder, radii, radius=radius, z_lo=z_lo, z_hi=z_hi, center=center,
        max_attempts=attempts if isinstance(attempts, int) and attempts <= 2000 else 1000)
    _ok(_core.random_pack_cylinder, radii, _num(center[0]), _num(center[1]), _num(radius), _num(z_lo),
        _num(z_hi), 0, 1000)


# --- measured data files ----------------------------------------------------------------------------

cells = st.one_of(st.sampled_from(["", "nan", "inf", "-inf", "1e400", "-1", "0", "1", "0.5", "abc", "1,5",
                                   "\x00", "\"", "1e-320", "  3 ", "NaN"]),
                  floats.map(repr), st.text(max_size=6))
columns = st.sampled_from(["dL_D", "sigma_1_mpa", "sigma_1_pa", "displacement_mm", "displacement_m", "force_n",
                           "time_s", "dh_h0", "sigma_z_mpa", "sigma_z_pa", "replicate", "x", "DL_D", ""])


@st.composite
def csv_texts(draw):
    cols = draw(st.lists(columns, min_size=0, max_size=4))
    sep = draw(st.sampled_from([",", ";", "\t"]))
    lines = [draw(st.sampled_from(["", "# diameter_mm=10, height_mm=6", "# kind=compaction",
                                   "# diameter_mm=nan", "# height_m=-1", "# diameter_mm=abc"]))]
    lines.append(sep.join(cols))
    for _ in range(draw(st.integers(0, 6))):
        lines.append(sep.join(draw(cells) for _ in range(draw(st.sampled_from([len(cols), len(cols) + 1])))))
    return "\n".join(lines)


@child_only
@SETTINGS
@given(st.one_of(csv_texts(), st.binary(max_size=300).map(lambda b: b.decode("latin-1"))),
       st.sampled_from(["diametral", "compaction", "tension", 3, None]), st.one_of(st.none(), scalars),
       st.one_of(st.none(), scalars), st.booleans())
def test_measured_curve_files(text, kind, diameter, height, as_bytes):
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "curve.csv")
        with open(path, "wb") as fh:
            fh.write(text.encode("latin-1", "replace") if as_bytes else text.encode("utf-8", "surrogatepass"))
        try:
            measured.load_curve(path, kind=kind, diameter=diameter, height=height)
        except measured.MeasuredDataError:
            pass
        except (ValueError, TypeError) as e:
            # Only for the arguments themselves (kind, diameter, height), never for the file.
            assert not isinstance(e, UnicodeError), e


@child_only
@SETTINGS
@given(scalars, scalars, scalars, scalars)
def test_measured_tables_and_variants(n, material, mc, sigma_z):
    _ok(measured.load_table, n)
    _ok(measured.variant, material, mc, sigma_z)
    _ok(pipeline.bond_law_for, material, mc, sigma_z)


# --- the command line -------------------------------------------------------------------------------

ARG_WORDS = ["run", "loop", "calibrate", "--preset", "tiny", "quick", "paper", "huge", "--out", "o", "--material",
             "oak", "teak", "--mc", "8", "20", "--sigma-z", "60", "120", "--seed", "-1", "0", "1.5",
             "99999999999999999999", "--threads", "0", "1", "2", "1e9", "--particles", "5", "-5", "0", "--quiet",
             "--restart", "--checkpoint-interval", "nan", "inf", "-1", "1e400", "--help-me", "", "--", "-",
             # calibrate's own options
             "--variant", "--max-runs", "--compaction-runs", "--workers", "--from", ".", "--dask", "tcp://x:1",
             "--set", "contact.mu=0.4", "contact.mu=-1", "bond.sigma_c=9e6", "bond.softening=nan", "k1=1"]


class _NoRun(Exception):
    pass


@child_only
@SETTINGS
@given(st.lists(st.one_of(st.sampled_from(ARG_WORDS), st.text(max_size=6)), max_size=10))
def test_cli_argv(argv):
    def no_run(*a, **k):
        raise _NoRun

    import distributed

    from pelletdem import calibration_dir, loop_cli

    saved, saved_loop, cwd = pipeline.run_pellet, loop_cli.run, os.getcwd()
    saved_calibrate, saved_client = calibration_dir.calibrate_into, distributed.Client
    with tempfile.TemporaryDirectory() as d:
        os.chdir(d)
        # parsing and checks only: no simulation, no calibration, no Dask scheduler
        pipeline.run_pellet = loop_cli.run = calibration_dir.calibrate_into = distributed.Client = no_run
        try:
            code = cli.main(argv)
            assert isinstance(code, int)
        except SystemExit:
            pass  # argparse's way out: a usage error (2) or --help / -h / --h... (0)
        except _NoRun:
            pass
        finally:
            pipeline.run_pellet, loop_cli.run = saved, saved_loop
            calibration_dir.calibrate_into, distributed.Client = saved_calibrate, saved_client
            os.chdir(cwd)
