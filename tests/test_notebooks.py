"""Every notebook in notebooks/ runs from top to bottom at its small default size.

Executed with nbclient in a fresh kernel, in a temporary directory (the notebooks write their
results under PELLETDEM_NOTEBOOK_OUT when it is set); any error in any cell fails the test.
Parametrised over notebooks/*.ipynb, so a new notebook is picked up without a change here.
The notebooks are kept with their outputs stripped (checked below); strip one with
`jupyter nbconvert --clear-output --inplace notebooks/NAME.ipynb`. Run with `-s` to see each
notebook's wall time. nbclient, nbformat and ipykernel are in
the `test` extra of pyproject.toml.
"""
from __future__ import annotations

import os
import re
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_there_are_notebooks():
    assert any(p.name == "01_pellet_life.ipynb" for p in NOTEBOOKS)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_is_stored_without_outputs(path):
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [], f"{path.name}: a cell has stored outputs"
            assert cell.execution_count is None, f"{path.name}: a cell has an execution count"
        # nbclient's timings and widget state are outputs too
        assert "execution" not in cell.metadata, f"{path.name}: a cell has stored execution metadata"
    assert "widgets" not in nb.metadata, f"{path.name}: the notebook has stored widget state"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_defaults_to_the_small_size(path):
    """The size knob sits at the top and defaults to the small preset."""
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(path, as_version=4)
    code = [c.source for c in nb.cells if c.cell_type == "code"]
    knobs = [m for src in code[:2] for m in re.findall(r'^PRESET\s*=\s*"(\w+)"', src, re.M)]
    if knobs:
        assert knobs == ["tiny"], knobs


# Notebook 04 at its default size (the loop with the engine on the shipped example data, ~250
# simulations: 30 minutes with one worker on 2 shared cores) is a slow test; the fast suite
# runs it with the knobs below instead: the analytic pellet of tests/loop/toy_pellet.py, at
# the example's scale, stands in for the engine.
LOOP_NOTEBOOK = "04_discrepancy_loop.ipynb"
LOOP_SMALL_KNOBS = {"SIMULATOR": '"toy_pellet:example_toy"', "PACKINGS": "2", "N_DESIGN": "8", "SCREEN_TOP": "1",
                    "MAX_EFFECTS": "1", "WORKERS": "1"}
LOOP_TOY = ROOT / "tests" / "loop"


def _marked(path):
    return pytest.param(path, marks=pytest.mark.slow) if path.name == LOOP_NOTEBOOK else path


@pytest.mark.parametrize("path", [_marked(p) for p in NOTEBOOKS], ids=lambda p: p.name)
def test_notebook_runs(path, tmp_path, monkeypatch):
    _run_notebook(path, tmp_path, monkeypatch)


def test_loop_notebook_runs_with_small_knobs(tmp_path, monkeypatch):
    """Every cell of notebook 04 on the shipped example data, with the analytic pellet in place
    of the engine: the user's path (curve file, observations, manifest, loop, report), not the
    quality of the verdict."""
    path = ROOT / "notebooks" / LOOP_NOTEBOOK
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(LOOP_TOY), os.environ.get("PYTHONPATH")])))
    _run_notebook(path, tmp_path, monkeypatch, knobs=LOOP_SMALL_KNOBS)


def _run_notebook(path, tmp_path, monkeypatch, knobs=None):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    nb = nbformat.read(path, as_version=4)
    for name, value in (knobs or {}).items():
        cell = next(c for c in nb.cells if c.cell_type == "code")  # the knobs sit in the first one
        cell.source, n = re.subn(rf"^{name}\s*=\s*[^#\n]*?(\s*#|$)", rf"{name} = {value}\1", cell.source,
                                 flags=re.M)
        assert n == 1, f"{path.name}: no knob {name} in the first code cell"
    # PELLETDEM_NOTEBOOK_KEEP (a directory) keeps each notebook's output, its run cache with it,
    # so that a run which outlasts its shell (notebook 04 under the sanitizers takes hours)
    # resumes where it stopped when started again.
    keep = os.environ.get("PELLETDEM_NOTEBOOK_KEEP")
    if keep:
        tmp_path = Path(keep) / path.stem
        tmp_path.mkdir(parents=True, exist_ok=True)
    monkeypatch.setenv("PELLETDEM_NOTEBOOK_OUT", str(tmp_path / "out"))
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")
    # A cell's time limit; the sanitizer build (scripts/sanitize.sh) runs ~10x slower and raises it.
    timeout = int(os.environ.get("PELLETDEM_NOTEBOOK_CELL_TIMEOUT", "900"))
    client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    t0 = time.perf_counter()
    client.execute()  # raises CellExecutionError on the first failing cell
    print(f"{path.name}: {time.perf_counter() - t0:.0f} s")
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors
    images = sum("image/png" in o.get("data", {}) for c in nb.cells if c.cell_type == "code"
                 for o in c.outputs)
    assert images >= 1, f"{path.name} drew no figure"
    out = tmp_path / "out"
    if path.name == "01_pellet_life.ipynb":
        assert (out / "result.h5").is_file() and (out / "result.xdmf").is_file()
        assert (out / "fig16_crack_map.png").is_file()
        assert images >= 10  # every stage drew its plots
    elif path.name == "02_parameter_studies.ipynb":
        assert images >= 6  # Figs. 10, 11, 12, 13 and the two Fig. 14 views
        assert any((out / "cache").rglob("*.json"))  # the runs went through the calibration cache
    elif path.name == "03_calibration.ipynb":
        assert images >= 4  # measured vs simulated, densities, Fig. 15 curves, a fit's path
        assert any((out / "relaxed").glob("*.h5"))  # relaxed pellets kept for the workers
    elif path.name == LOOP_NOTEBOOK:
        assert (out / "report" / "report.md").is_file()
        text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs)
        assert "verdict:" in text, text[-3000:]
