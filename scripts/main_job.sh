#!/usr/bin/env bash
# The main job: set up, then one small pellet from fill to breakage with its plots.
# Output: out/quick/{result.h5, result.xdmf, summary.json, fig*.png}. Extra arguments go to
# `pelletdem run` (e.g. --preset paper --material pine --mc 20 --sigma-z 60).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh .
python3 -m pelletdem.cli run --preset quick --out out/quick "$@"
