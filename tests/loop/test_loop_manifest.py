"""A loop data manifest (pelletdem.loop_manifest): the shipped example loads, and every problem
of a user's manifest is refused naming the file, the line and the field. No simulations."""
from __future__ import annotations

import argparse
import math
import textwrap
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from pelletdem import loop_cli
from pelletdem.loop import DIAMETRAL_GRID, Condition, Dataset
from pelletdem.loop_manifest import ManifestError, example_manifest, load_manifest
from pelletdem.measured import Curve, load_curve, save_curve

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
COMPACTION_POINTS = 8  # Dataset.from_curves' default, what `pelletdem loop --data` uses


def _keys(observations):
    """Observations as comparable tuples (a scalar's x is NaN, which equals nothing)."""
    return [(o.condition, o.quantity, None if math.isnan(o.x) else o.x, o.value, o.sd, o.n, o.part)
            for o in observations]


# --------------------------------------------------------------------------------------
# The shipped example
# --------------------------------------------------------------------------------------


def test_the_example_loads_with_its_conditions_and_held_out_pressure():
    m = load_manifest(example_manifest())
    conds = m.dataset.conditions
    assert sorted(c.sigma_z for c in conds) == [60e6, 90e6, 120e6]
    assert {(c.mc, c.material) for c in conds} == {(8.0, "oak")}
    assert m.held_out == (Condition(90e6, 8.0, "oak"),)
    assert m.bounds == loop_cli.SYNTHETIC_BOUNDS and m.preset == "tiny" and m.settings == {}
    counts = Counter((o.condition, o.quantity) for o in m.dataset.observations)
    for c in conds:
        assert 2 <= counts[(c, "sigma_1")] <= len(DIAMETRAL_GRID)
        assert counts[(c, "sigma_z")] == COMPACTION_POINTS
        assert counts[(c, "sigma_f")] == counts[(c, "dLf_D")] == counts[(c, "bulk_density")] == 1
    assert {o.n for o in m.dataset.observations} == {5}  # five replicate pellets everywhere
    fit, held = m.dataset.split(lambda c: c in m.held_out)
    assert len(fit) + len(held) == len(m.dataset) and held.conditions == [Condition(90e6, 8.0, "oak")]


def test_the_examples_curve_headers_give_its_conditions():
    """The manifest names no pressure: each comes from its curve files' headers, and the
    observations are those of load_curve -> Dataset.from_curves on the same files."""
    path = Path(example_manifest())
    doc = tomllib.loads(path.read_text())
    m = load_manifest(path)
    for entry, cond in zip(doc["condition"], m.dataset.conditions):
        assert not {"pressure_mpa", "moisture_percent", "material"} & set(entry)
        curves = {kind: load_curve(path.parent / entry[kind], kind) for kind in ("diametral", "compaction")}
        for cv in curves.values():
            assert cv.metadata["pressure_mpa"] * 1e6 == cond.sigma_z
            assert (cv.metadata["moisture_percent"], cv.metadata["material"]) == (cond.mc, cond.material)
            assert len(cv.replicates) == 5
        mine = [o for o in m.dataset.observations if o.condition == cond and o.quantity != "bulk_density"]
        direct = [o for kind in ("diametral", "compaction")
                  for o in Dataset.from_curves({cond: curves[kind]}).observations]
        assert _keys(mine) == _keys(direct)


def _generator():
    """scripts/make_loop_example.py as a module."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_loop_example", ROOT / "scripts" / "make_loop_example.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    return gen


def test_the_example_says_how_it_was_made_and_the_manifest_hides_the_effect():
    folder = Path(example_manifest()).parent
    readme = (folder / "README.md").read_text()
    gen = _generator()
    assert "scripts/make_loop_example.py" in readme and f"`{gen.HIDDEN}`" in readme
    assert gen.HIDDEN not in (folder / "loop_example.toml").read_text()


def test_the_example_folder_holds_what_its_manifest_names():
    path = Path(example_manifest())
    doc = tomllib.loads(path.read_text())
    named = {e[k] for e in doc["condition"] for k in ("diametral", "compaction") if k in e}
    assert {p.name for p in path.parent.iterdir()} == named | {path.name, "README.md"}


def test_the_generator_writes_curves_the_manifest_reader_takes(tmp_path):
    """scripts/make_loop_example.py's replicate curves, here of the analytic pellet: stopped
    after the failure, noisy, saved and read back by load_curve, sampled by from_curves."""
    from toy_pellet import TRUTH, toy

    gen = _generator()
    cond = Condition(120e6, 8.0, "oak")
    members = [toy(TRUTH, cond, s) for s in range(5)]
    diam, comp, rho = gen.replicate_curves(members, cond, np.random.default_rng(0), 0.02)
    for m, (_, x, y) in zip(members, diam.per_replicate()):
        assert x[-1] <= gen.STOP_AFTER * m.scalars["dLf_D"] * 1.1 and np.argmax(y) < len(y) - 1
    save_curve(diam, tmp_path / "d.csv")
    back = load_curve(tmp_path / "d.csv")
    assert back.metadata == {"pressure_mpa": 120.0, "moisture_percent": 8.0, "material": "oak"}
    assert len(back.replicates) == 5 and len(rho) == 5
    obs = Dataset.from_curves({cond: back, Condition(90e6): comp}).observations
    assert {o.quantity for o in obs} == {"sigma_1", "sigma_f", "dLf_D", "sigma_z"}


def test_loop_data_example_is_the_shipped_manifest():
    sub = argparse.ArgumentParser().add_subparsers()
    loop_cli.add_parser(sub)
    args = sub.choices["loop"].parse_args(["--data", "example", "--out", "unused"])
    data, held, bounds, _, _, _, preset, title, density = loop_cli._problem(args)
    m = load_manifest(example_manifest())
    assert _keys(data.observations) == _keys(m.dataset.observations) and held == m.held_out
    assert bounds == m.bounds and preset == "tiny" and m.name in title


# --------------------------------------------------------------------------------------
# A user's manifest, and what is refused
# --------------------------------------------------------------------------------------


def _diametral(path: Path, peak: bool = True, **meta) -> str:
    """Three replicates of an analytic diametral curve (failing at dL/D ~0.06 when ``peak``,
    rising to the end of the test otherwise), header ``meta`` (None leaves a key out)."""
    x = np.linspace(0.0, 0.15, 61)
    xs, ys, reps = [], [], []
    for k, s in enumerate((0.95, 1.0, 1.05), start=1):
        t = x / (0.06 * s)
        xs.append(x)
        ys.append(8e4 * s * (t * np.exp(1.0 - t) if peak else t))
        reps += [str(k)] * len(x)
    header = {k: v for k, v in {"pressure_mpa": 120.0, "material": "oak", **meta}.items() if v is not None}
    save_curve(Curve(np.concatenate(xs), np.concatenate(ys), reps, "diametral", header), path)
    return path.name


def _compaction(path: Path, **meta) -> str:
    x = np.linspace(0.0, 0.5, 26)
    header = {k: v for k, v in {"pressure_mpa": 120.0, "material": "oak", **meta}.items() if v is not None}
    save_curve(Curve(np.concatenate([x, x]), np.concatenate([120e6 * (x / 0.5) ** 3, 118e6 * (x / 0.5) ** 3]),
                     ["1"] * len(x) + ["2"] * len(x), "compaction", header), path)
    return path.name


def _manifest(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "data.toml"
    path.write_text(textwrap.dedent(text).lstrip())
    return path


def _line(path: Path, needle: str, nth: int = 1) -> int:
    """The 1-based line of the ``nth`` line of ``path`` holding ``needle``."""
    hits = [k + 1 for k, ln in enumerate(path.read_text().splitlines()) if needle in ln]
    return hits[nth - 1]


def _refused(path: Path, line: int, fld: str, match: str) -> ManifestError:
    with pytest.raises(ManifestError, match=match) as info:
        load_manifest(path)
    e = info.value
    assert (e.path, e.line, e.field) == (str(path), line, fld), str(e)
    assert str(e).startswith(f"{path}, line {line}, field {fld!r}: ")
    return e


def test_a_manifest_of_curves_and_scalars_loads(tmp_path):
    d = _diametral(tmp_path / "d120.csv")
    c = _compaction(tmp_path / "c120.csv")
    path = _manifest(tmp_path, f"""
        name = "mine"
        [fit]
        "E_b[oak]" = [1e7, 1e9]
        sigma_c = [1e6, 1e8]
        [model]
        preset = "quick"
        set = {{ "contact.mu" = 0.4 }}
        particle_density = {{ oak = 675.0 }}
        [[condition]]
        diametral = "{d}"
        compaction = "{c}"
        bulk_density = {{ mean = 1100.0, sd = 10.0, n = 5 }}
        [[condition]]
        pressure_mpa = 60
        moisture_percent = 10
        material = "oak"
        held_out = true
        sigma_f = {{ mean = 5e5, sd = 5e4 }}
        """)
    m = load_manifest(path)
    assert m.name == "mine" and m.preset == "quick" and m.settings == {"contact.mu": 0.4}
    assert m.particle_density == {"oak": 675.0}
    assert m.bounds == {"E_b[oak]": (1e7, 1e9), "sigma_c": (1e6, 1e8)}
    assert m.dataset.conditions == [Condition(120e6, 8.0, "oak"), Condition(60e6, 10.0, "oak")]
    assert m.held_out == (Condition(60e6, 10.0, "oak"),)
    sf = [o for o in m.dataset.observations if o.condition.sigma_z == 60e6]
    assert [(o.quantity, o.value, o.sd, o.n) for o in sf] == [("sigma_f", 5e5, 5e4, 1)]  # n defaults to 1


@pytest.mark.parametrize("table,match", [
    ("{ oak = -5.0 }", "must be a number in"),
    ("{ oak = true }", "must be a number in"),
    ("{ pine = 510.0 }", "no condition is of material 'pine'"),
])
def test_a_bad_particle_density_names_its_line(tmp_path, table, match):
    path = _manifest(tmp_path, f"""
        [model]
        particle_density = {table}
        [[condition]]
        pressure_mpa = 120
        material = "oak"
        bulk_density = {{ mean = 1000.0, sd = 10.0, n = 5 }}
        """)
    field = "model.particle_density." + table.split()[1]
    _refused(path, _line(path, "particle_density"), field, match)


def test_missing_pressure(tmp_path):
    d = _diametral(tmp_path / "d.csv", pressure_mpa=None)
    path = _manifest(tmp_path, f"""
        [[condition]]
        diametral = "{d}"
        """)
    _refused(path, _line(path, "[[condition]]"), "pressure_mpa", "neither here nor in its curve files' headers")


def test_pressure_in_the_manifest_disagreeing_with_the_curve_header(tmp_path):
    d = _diametral(tmp_path / "d.csv", pressure_mpa=120.0)
    path = _manifest(tmp_path, f"""
        [[condition]]
        pressure_mpa = 90
        diametral = "{d}"
        """)
    _refused(path, _line(path, "pressure_mpa"), "pressure_mpa", "90 here but 120.0 in a curve file's header")


def test_the_curve_headers_disagreeing(tmp_path):
    d = _diametral(tmp_path / "d.csv", pressure_mpa=120.0)
    c = _compaction(tmp_path / "c.csv", pressure_mpa=60.0)
    path = _manifest(tmp_path, f"""
        [[condition]]
        diametral = "{d}"
        compaction = "{c}"
        """)
    _refused(path, _line(path, "compaction"), "compaction", "headers disagree on pressure_mpa")


def test_a_header_pressure_that_is_not_a_number(tmp_path):
    d = _diametral(tmp_path / "d.csv", pressure_mpa="high")
    path = _manifest(tmp_path, f"""
        [[condition]]
        diametral = "{d}"
        """)
    _refused(path, _line(path, "diametral"), "diametral", "pressure_mpa=high: it must be a number")


def test_unknown_field(tmp_path):
    path = _manifest(tmp_path, """
        [[condition]]
        pressure_mpa = 120
        pressur = 120
        """)
    _refused(path, _line(path, "pressur ="), "pressur", "unknown field")


def test_bad_held_out_type(tmp_path):
    path = _manifest(tmp_path, """
        [[condition]]
        pressure_mpa = 120
        held_out = "yes"
        sigma_f = { mean = 1e6, sd = 1e5, n = 5 }
        """)
    _refused(path, _line(path, "held_out"), "held_out", "must be true or false")


def test_scalar_missing_sd(tmp_path):
    path = _manifest(tmp_path, """
        [[condition]]
        pressure_mpa = 120
        bulk_density = { mean = 1100.0, n = 5 }
        """)
    _refused(path, _line(path, "bulk_density"), "bulk_density", "the replicates' SD")


def test_a_scalar_the_diametral_curve_gives_too(tmp_path):
    d = _diametral(tmp_path / "d.csv")
    path = _manifest(tmp_path, f"""
        [[condition]]
        diametral = "{d}"
        sigma_f = {{ mean = 1e6, sd = 1e5, n = 5 }}
        """)
    _refused(path, _line(path, "sigma_f"), "sigma_f", "give it one way")


def test_every_condition_held_out(tmp_path):
    path = _manifest(tmp_path, """
        [[condition]]
        pressure_mpa = 60
        held_out = true
        sigma_f = { mean = 1e6, sd = 1e5, n = 5 }
        [[condition]]
        pressure_mpa = 120
        held_out = true
        sigma_f = { mean = 2e6, sd = 1e5, n = 5 }
        """)
    _refused(path, _line(path, "held_out", 2), "held_out", "every condition is held out")


def test_a_missing_curve_file(tmp_path):
    path = _manifest(tmp_path, """
        [[condition]]
        pressure_mpa = 120
        compaction = "nowhere.csv"
        """)
    e = _refused(path, _line(path, "compaction"), "compaction", "no such file")
    assert str(tmp_path / "nowhere.csv") in str(e)  # relative to the manifest


def test_a_malformed_curve_file_names_its_own_row_and_column(tmp_path):
    (tmp_path / "d.csv").write_text("# pressure_mpa=120\ndL_D,sigma_1_pa\n0.0,1e4\n0.01,abc\n0.02,3e4\n")
    path = _manifest(tmp_path, """
        [[condition]]
        diametral = "d.csv"
        """)
    e = _refused(path, _line(path, "diametral"), "diametral", "non-numeric value")
    assert "data row 2" in str(e) and "column 'sigma_1_pa'" in str(e)


def test_a_curve_that_never_peaks(tmp_path):
    d = _diametral(tmp_path / "d.csv", peak=False)
    path = _manifest(tmp_path, f"""
        [[condition]]
        diametral = "{d}"
        """)
    e = _refused(path, _line(path, "diametral"), "diametral", "reach their maximum at the end of the test")
    assert "no peak" in str(e) and str(tmp_path / "d.csv") in str(e)


def test_duplicate_condition(tmp_path):
    path = _manifest(tmp_path, """
        [[condition]]
        pressure_mpa = 120
        sigma_f = { mean = 1e6, sd = 1e5, n = 5 }
        [[condition]]
        pressure_mpa = 120.0
        moisture_percent = 8
        dLf_D = { mean = 0.05, sd = 0.01, n = 5 }
        """)
    e = _refused(path, _line(path, "[[condition]]", 2), "condition", "listed twice")
    assert f"first at line {_line(path, '[[condition]]')}" in str(e)


@pytest.mark.parametrize("text, needle, fld", [
    ("[[condition]]\npressure_mpa = 12 0\n", "pressure_mpa", "pressure_mpa"),
    ("[fit\nE_b = [1e7, 1e8]\n", "[fit", "fit"),
    ("[[condition]]\nsigma_f = { mean = 1e6, sd = }\n", "sigma_f", "sigma_f"),
], ids=["value", "table", "inline-table"])
def test_malformed_toml(tmp_path, text, needle, fld):
    path = _manifest(tmp_path, text)
    _refused(path, _line(path, needle), fld, "not valid TOML")


@pytest.mark.parametrize("text, needle, fld, match", [
    ("[units]\nstress = 'MPa'\n", "[units]", "units", "unknown top-level key"),
    ("model = 3\n", "model", "model", "must be a table"),
    ("[model]\nset = { 'contact.nonsense' = 1.0 }\n", "set", "model.set.contact.nonsense", "no such contact law"),
    ("[model]\npreset = 'huge'\n", "preset", "model.preset", "allowed presets"),
    ("[fit]\nE_b = [1e8, 1e7]\n", "E_b", "fit.E_b", "0 < lo < hi"),
    ("[fit]\nstiffness = [1e7, 1e8]\n", "stiffness", "fit.stiffness", "unknown base parameter"),
    ("condition = [1, 2]\n", "condition", "condition", "must be a \\[\\[condition\\]\\] table"),
    ("name = 'nothing'\n[[condition]]\nmaterial = 'oak'\npressure_mpa = 120\n", "[[condition]]", "condition",
     "no measurement"),
    ("[[condition]]\npressure_mpa = 5000\nsigma_f = { mean = 1e6, sd = 1e5 }\n", "pressure_mpa", "pressure_mpa",
     "must be a number in"),
], ids=["top-level-table", "model-not-table", "unknown-law-parameter", "preset", "bounds", "fit-parameter",
        "condition-not-table", "no-measurement", "pressure-range"])
def test_other_problems_name_the_line_and_field(tmp_path, text, needle, fld, match):
    path = _manifest(tmp_path, text)
    _refused(path, _line(path, needle), fld, match)
