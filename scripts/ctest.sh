#!/usr/bin/env bash
# The engine alone, without Python: builds the C++ engine and its checks (cpp/tests) with CMake
# and runs them with ctest. Needs a C++ compiler, CMake, Eigen and OpenMP (scripts/setup.sh
# installs them). Extra arguments go to cmake's configure step (e.g. -DPELLETDEM_SANITIZE=ON).
set -euo pipefail
cd "$(dirname "$0")/.."
build=build/ctest
cmake -S . -B "$build" -DPELLETDEM_PYTHON=OFF -DPELLETDEM_CPP_TESTS=ON -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
cmake --build "$build" -j 2 --target engine_checks
ctest --test-dir "$build" --output-on-failure
