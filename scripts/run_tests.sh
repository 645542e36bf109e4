#!/usr/bin/env bash
# The README's test command: sets up .venv if needed, then lints the tree (ruff), type-checks the public API (mypy,
# the modules listed in pyproject.toml [tool.mypy]) and runs the whole test suite (extra args go to pytest). A lint
# or type error fails the script before pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
echo "[lint] ruff check ." >&2
.venv/bin/python -m ruff check .
echo "[types] mypy" >&2
.venv/bin/python -m mypy
exec .venv/bin/python -m pytest "$@"
