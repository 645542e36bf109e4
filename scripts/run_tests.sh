#!/usr/bin/env bash
# The README's test command: sets up .venv if needed, then lints the tree (ruff), type-checks the public API (mypy,
# the modules listed in pyproject.toml [tool.mypy]) while it compiles the kernels into numba's cache, and runs the
# whole test suite (extra args go to pytest). A lint or type error fails the script before pytest. The suite runs on
# two workers.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
# one BLAS thread per process: the two workers fill the two cores, and OpenBLAS's own threads would spin against the
# other worker (a cold wing solve with dense factorisations took minutes instead of 10 s)
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}" OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}" \
  MKL_NUM_THREADS="${MKL_NUM_THREADS:-1}"
echo "[lint] ruff check ." >&2
.venv/bin/python -m ruff check .
# numba's cache built once per run: one short flight per fidelity compiles the kernels while mypy runs, so that the
# workers load them instead of each compiling them (about 60 s per cold process)
warm_logs=$(mktemp -d)
.venv/bin/kite-bench warm --fidelity fe >"$warm_logs/fe" 2>&1 & warm_fe=$!
.venv/bin/kite-bench warm --fidelity surrogate --fidelity batched >"$warm_logs/fast" 2>&1 & warm_fast=$!
trap 'kill $warm_fe $warm_fast 2>/dev/null || true; rm -rf "$warm_logs"' EXIT
echo "[types] mypy" >&2
.venv/bin/python -m mypy
for job in fe:$warm_fe fast:$warm_fast; do
  log="$warm_logs/${job%%:*}"
  if wait "${job#*:}"; then grep "^kite-bench warm" "$log" >&2 || true
  else echo "[warm] the ${job%%:*} warm-up failed (the tests below will say why):" >&2; tail -5 "$log" >&2; fi
done
# two workers (pytest-xdist), each test file on one worker so that its module fixtures are built once;
# KITE_TEST_WORKERS=0 runs the suite in this process
.venv/bin/python -m pytest -n "${KITE_TEST_WORKERS:-2}" --dist loadfile "$@"
