#!/usr/bin/env bash
# Debug build with AddressSanitizer and UndefinedBehaviorSanitizer, then the test suite under
# it. The extension is built into a private prefix so the release install is untouched.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh ".[test]" >/dev/null
prefix=$(mktemp -d /tmp/pelletdem-asan.XXXX)
PELLETDEM_SANITIZE=ON python3 -m pip install -q --no-deps --target "$prefix" \
  -Ccmake.build-type=Debug -Cbuild-dir=build/asan .
export PYTHONPATH="$prefix"
export LD_PRELOAD="$(g++ -print-file-name=libasan.so):$(g++ -print-file-name=libubsan.so)"
export ASAN_OPTIONS=detect_leaks=0:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
python3 -m pytest -q -p no:cacheprovider "$@"
