"""MkDocs hooks: one API reference page per public module of pelletdem, generated at build time.

Every python/pelletdem/*.py whose name does not start with an underscore gets a page
``api/<module>.md`` holding ``::: pelletdem.<module>`` (mkdocstrings renders its docstrings),
and the compiled engine gets one from its type stub. A module added later (the discrepancy loop,
say) is documented by the next build without touching mkdocs.yml. The laws' parameter tables
in docs/parameters.md are made from the C++ rows (pelletdem.parameter_docs.markdown_table).
"""
from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "pelletdem"

# Order of the API section: the user's path first, the rest alphabetically after it.
FIRST = ["engine", "presets", "stages", "pipeline", "result", "measured", "metrics", "calibrate",
         "plots", "cracks", "checkpoint"]
TITLES = {"engine": "engine (World, ContactLaw, BondLaw)", "_core": "_core (compiled engine)"}


def _modules() -> list[str]:
    found = sorted(p.stem for p in PACKAGE.glob("*.py") if not p.stem.startswith("_"))
    return [m for m in FIRST if m in found] + [m for m in found if m not in FIRST] + ["_core"]


def _page(module: str) -> str:
    intro = ""
    if module == "_core":
        intro = ("The C++ engine as Python sees it, documented from its type stub "
                 "(`python/pelletdem/_core.pyi`). Use the Python layer (`pelletdem.World`, "
                 "`ContactLaw`, `BondLaw`) rather than this module directly.\n\n")
    return f"# pelletdem.{module}\n\n{intro}::: pelletdem.{module}\n"


def on_config(config, **kwargs):
    nav = config["nav"]
    api = [{TITLES.get(m, m): f"api/{m}.md"} for m in _modules()]
    nav[:] = [item for item in nav if not (isinstance(item, dict) and "API reference" in item)]
    nav.append({"API reference": api})
    return config


# docs/parameters.md holds these markers where the laws' tables go: made from the C++ rows.
LAW_TABLES = {"<!-- law table: contact -->": "ContactLaw", "<!-- law table: bond -->": "BondLaw"}


def on_page_markdown(markdown, page, config, files, **kwargs):
    if any(marker in markdown for marker in LAW_TABLES):
        import pelletdem
        from pelletdem.parameter_docs import markdown_table

        for marker, law in LAW_TABLES.items():
            markdown = markdown.replace(marker, markdown_table(getattr(pelletdem, law)))
    return markdown


def on_files(files, config, **kwargs):
    for m in _modules():
        files.append(File.generated(config, f"api/{m}.md", content=_page(m)))
    return files
