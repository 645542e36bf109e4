# Sourced by the scripts in this folder: create or reuse ./.venv and install kite_env into it (editable).
# The dependencies at the versions of constraints.txt (the pinned flights are bit-for-bit results of them).
# Re-installs only when pyproject.toml or constraints.txt changed since the last install (stamp file inside .venv).
set -euo pipefail
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv" >&2
  "$PY" -m venv .venv
fi
stamp=.venv/.kite_env_installed
want=$(cat pyproject.toml constraints.txt | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "[setup] installing kite_env and its dependencies into .venv" >&2
  .venv/bin/python -m pip install -q --upgrade pip >&2
  .venv/bin/python -m pip install -q -e ".[test]" -c constraints.txt >&2
  echo "$want" > "$stamp"
fi
