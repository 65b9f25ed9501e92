"""The scripts in examples/ compile, say what they do, and the fastest one runs.

Every example has a docstring, a size knob at the top (PRESET = "tiny" by default) and takes
its output directory on the command line. 01_pellet_life.py (one tiny pellet's life, ~15 s)
runs end to end here; the longer ones (02, 03: minutes) are compiled and their command lines
checked. Budget: under a minute in all.
"""
from __future__ import annotations

import ast
import json
import py_compile
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))


def test_the_three_examples_exist():
    names = {p.name for p in EXAMPLES}
    assert {"01_pellet_life.py", "02_parameter_studies.py", "03_calibration.py"} <= names


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_compiles(path, tmp_path):
    py_compile.compile(str(path), cfile=str(tmp_path / (path.stem + ".pyc")), doraise=True)


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_has_docstring_and_size_knob(path):
    tree = ast.parse(path.read_text())
    doc = ast.get_docstring(tree)
    assert doc and "OUT_DIR" in doc, f"{path.name}: the docstring must say how to call it"
    knobs = re.findall(r'^PRESET\s*=\s*"(\w+)"', path.read_text(), re.M)
    assert knobs == ["tiny"], f"{path.name}: PRESET = \"tiny\" must be set at the top"
    # The work runs under `if __name__ == "__main__":` (process pools start with 'spawn').
    assert any(isinstance(n, ast.If) and "__main__" in ast.unparse(n.test) for n in tree.body)


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_help(path):
    out = subprocess.run([sys.executable, str(path), "--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "out" in out.stdout


def test_pellet_life_example_runs(tmp_path):
    out = tmp_path / "ex01"
    run = subprocess.run([sys.executable, str(ROOT / "examples" / "01_pellet_life.py"), str(out)],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    for name in ("result.h5", "result.xdmf", "summary.json", "fig5_stress_deformation.png",
                 "fig16_crack_map.png", "particles_relaxed.png", "particles_broken.png"):
        assert (out / name).is_file(), name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_particles"] == 400
    assert summary["sigma_f_mpa"] > 0


def test_calibration_example_checks_its_arguments_as_the_command_line_does(tmp_path):
    """03_calibration.py is `pelletdem calibrate` with the file's size knobs as defaults: a bad
    argument is refused, naming it, before any work."""
    out = tmp_path / "ex03"
    run = subprocess.run([sys.executable, str(ROOT / "examples" / "03_calibration.py"), str(out), "--max-runs", "0"],
                         capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert run.returncode == 2
    assert "--max-runs = 0 is out of range: allowed 1..100" in run.stderr
    assert not out.exists()
