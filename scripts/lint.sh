#!/usr/bin/env bash
# Lint: ruff on the Python (rules in pyproject.toml), clang-format on the C++ (.clang-format).
# Both come with the test extra (pip install '.[test]'). CI runs this before the tests.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m ruff check python tests benchmarks scripts examples
git ls-files 'cpp/*.cpp' 'cpp/*.hpp' | xargs clang-format --dry-run -Werror
echo "lint: clean"
