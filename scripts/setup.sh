#!/usr/bin/env bash
# Installs what pelletdem needs on a fresh Debian machine: Eigen from apt (only if missing),
# then the package and its Python dependencies with pip. Extra pip requirements (e.g. ".[test]")
# may be given as arguments. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -f /usr/include/eigen3/Eigen/Core ] && [ ! -f /usr/local/include/eigen3/Eigen/Core ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libeigen3-dev g++ cmake >/dev/null
fi
PY=${PYTHON:-python3}
target="${1:-.}"
"$PY" -m pip install -q --disable-pip-version-check "$target"
