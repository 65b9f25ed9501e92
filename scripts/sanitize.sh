#!/usr/bin/env bash
# The test suite under AddressSanitizer and UndefinedBehaviorSanitizer:
#
#     bash scripts/sanitize.sh                      # the whole suite (what .ci/run runs)
#     bash scripts/sanitize.sh tests/test_bonds.py  # or any pytest arguments
#     PELLETDEM_SANITIZERS=address bash scripts/sanitize.sh     # one sanitizer at a time
#     PELLETDEM_SANITIZERS=undefined bash scripts/sanitize.sh
#     PELLETDEM_NOTEBOOK_KEEP=DIR bash scripts/sanitize.sh tests/test_notebooks.py -k "runs and 04"
#                          # notebook 04 alone takes hours here; with DIR kept, a rerun resumes
#                          # from its run cache
#
# Builds the extension with -fsanitize=$PELLETDEM_SANITIZERS (default address,undefined) at -O2,
# our asserts on and Eigen's off (see CMakeLists.txt), into build/san-<sanitizers>-prefix, so the
# release install is untouched, and runs pytest against it. Both together cost more than the two
# runs one after the other: a tiny pellet's life took 197 s under both, 72 s under ASan alone and
# 39 s under UBSan alone (11 s in the release build), because each instruments the other's checks.
# The build directory is kept: a rerun rebuilds only what changed. Any sanitizer report aborts
# the process, so it fails the test that triggered it (subprocesses of the suite, the
# CLI runs and notebook kernels, inherit the preload and the options).
set -euo pipefail
cd "$(dirname "$0")/.."
sanitizers=${PELLETDEM_SANITIZERS:-address,undefined}
# Checked before any work; the runtimes are located after setup.sh, which installs g++ if missing.
# (libstdc++ is preloaded with ASan alone, for its C++ exception interceptor to find __cxa_throw)
case "$sanitizers" in
  address) runtimes="libasan.so libstdc++.so" ;;
  undefined) runtimes="libubsan.so" ;;
  address,undefined|undefined,address) sanitizers=address,undefined; runtimes="libasan.so libubsan.so" ;;
  *) echo "PELLETDEM_SANITIZERS = '$sanitizers': allowed address, undefined or address,undefined" >&2
     exit 2 ;;
esac
bash scripts/setup.sh ".[test]" >/dev/null
preload=""
for lib in $runtimes; do preload="$preload:$(g++ -print-file-name=$lib)"; done
preload=${preload#:}
tag=${sanitizers/,/-}
prefix="$PWD/build/san-$tag-prefix"
# The build requirements are installed here (not in a throw-away isolated environment) so that
# the build directory stays valid and a rerun is incremental.
python3 -m pip install -q --disable-pip-version-check "scikit-build-core>=0.10" "pybind11>=2.12"
PELLETDEM_SANITIZE=ON python3 -m pip install -q --no-deps --no-build-isolation --upgrade \
  --target "$prefix" -Ccmake.build-type=Debug -Cbuild-dir="build/san-$tag" \
  -Ccmake.define.PELLETDEM_SANITIZERS="$sanitizers" .
export PYTHONPATH="$prefix"
# (made before the preload: a plain tool run under it can exit non-zero at its leak check)
reports=$(mktemp -d)
export LD_PRELOAD="$preload"
# Leaks: CPython's own allocations at exit would be reported as leaks; the engine's are checked
# by tests/test_memory.py in the normal build (it skips itself under ASan).
# Reports also go to files: a worker process of a scan that aborts on one is retried and then
# recorded as a failed point, so its test need not fail; the files make the run fail anyway.
export ASAN_OPTIONS=detect_leaks=0:abort_on_error=1:log_path=$reports/asan
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1:log_path=$reports/ubsan
# A notebook cell may take ten times its usual time here.
export PELLETDEM_NOTEBOOK_CELL_TIMEOUT=${PELLETDEM_NOTEBOOK_CELL_TIMEOUT:-9000}
python3 -c "import pelletdem._core as c; assert c.__file__.startswith('$prefix'), c.__file__"
set +e
python3 -m pytest -q -p no:cacheprovider "$@"
rc=$?
unset LD_PRELOAD ASAN_OPTIONS UBSAN_OPTIONS
if [ -n "$(ls -A "$reports")" ]; then
  echo "sanitizer reports (in $reports):"
  cat "$reports"/*
  rc=1
fi
exit $rc
