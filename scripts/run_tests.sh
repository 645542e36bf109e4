#!/usr/bin/env bash
# The README's test command: sets up .venv if needed, then lints the tree (ruff)
# and runs the whole test suite (extra args go to pytest). A lint error fails the script before pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
echo "[lint] ruff check ." >&2
.venv/bin/python -m ruff check .
exec .venv/bin/python -m pytest "$@"
