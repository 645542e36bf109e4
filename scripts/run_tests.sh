#!/usr/bin/env bash
# The README's test command: sets up .venv if needed, then lints the tree (ruff), type-checks the public API (mypy,
# the modules listed in pyproject.toml [tool.mypy]) and runs the whole test suite (extra args go to pytest). A lint
# or type error fails the script before pytest. The suite runs on two workers.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
echo "[lint] ruff check ." >&2
.venv/bin/python -m ruff check .
echo "[types] mypy" >&2
.venv/bin/python -m mypy
# two workers (pytest-xdist), each test file on one worker so that its module fixtures are built once;
# KITE_TEST_WORKERS=0 runs the suite in this process
exec .venv/bin/python -m pytest -n "${KITE_TEST_WORKERS:-2}" --dist loadfile "$@"
