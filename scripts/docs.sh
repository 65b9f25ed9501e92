#!/usr/bin/env bash
# Builds the documentation site into site/ (open site/index.html): installs the package with
# its `docs` extra (MkDocs, mkdocstrings), then `mkdocs build --strict`, which fails on any
# warning (a broken link, a page missing from the nav, a docstring mkdocstrings cannot read).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh ".[docs]"
python3 -m mkdocs build --strict -d site "$@"
