"""The documentation: the parameter reference lists every parameter, and the site builds.

`bash scripts/docs.sh` builds the site with `mkdocs build --strict`; the build test here runs
the same build (into a temporary directory) when MkDocs and mkdocstrings are installed (the
`docs` extra) and is skipped otherwise.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pelletdem.engine import BondLaw, ContactLaw
from pelletdem.parameter_docs import markdown_table
from pelletdem.presets import Preset

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _documented_names(section: str) -> set[str]:
    """Field names in the first column of the tables under the `## ...` heading `section`."""
    text = (DOCS / "parameters.md").read_text()
    m = re.search(rf"^## {re.escape(section)}.*?$(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert m, f"parameters.md has no section {section!r}"
    return set(re.findall(r"^\| `(\w+)`", m.group(1), re.M))


def test_parameter_reference_lists_every_preset_field():
    fields = {f.name for f in dataclasses.fields(Preset)}
    documented = _documented_names("Run sizes and stage settings")
    assert sorted(fields - documented) == [], "Preset fields missing from docs/parameters.md"
    assert sorted(documented - fields) == [], "docs/parameters.md lists Preset fields that do not exist"


@pytest.mark.parametrize("law, marker", [(ContactLaw, "<!-- law table: contact -->"),
                                         (BondLaw, "<!-- law table: bond -->")], ids=["ContactLaw", "BondLaw"])
def test_the_laws_tables_are_made_from_their_rows(law, marker):
    """docs/parameters.md holds the marker the docs build replaces with the law's table, and the
    table has one line per row (field, unit, default) of the C++ table."""
    assert marker in (DOCS / "parameters.md").read_text()
    table = markdown_table(law)
    for r in law.rows():
        assert re.search(rf"^\| `{r.name}` \| {re.escape(r.unit)} \| ", table, re.M), r.name
    assert len(table.splitlines()) == len(law.rows()) + 2


def test_every_page_in_the_nav_exists():
    text = (ROOT / "mkdocs.yml").read_text()
    for page in re.findall(r":\s*(\S+\.md)\s*$", text, re.M):
        assert (DOCS / page).is_file(), page


def test_docs_build_strict(tmp_path):
    for mod in ("mkdocs", "mkdocstrings", "mkdocstrings_handlers.python"):
        if importlib.util.find_spec(mod.split(".")[0]) is None:
            pytest.skip(f"{mod} is not installed (pip install '.[docs]')")
    out = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-f", str(ROOT / "mkdocs.yml"),
                          "-d", str(tmp_path / "site")], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert (tmp_path / "site" / "api" / "engine" / "index.html").is_file()
    assert (tmp_path / "site" / "parameters" / "index.html").is_file()
