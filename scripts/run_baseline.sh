#!/usr/bin/env bash
# README main job: fly the paper's baseline controller along the figure-eight in the full aeroelastic model and
# write metrics and plots to runs/baseline. Extra arguments are passed to kite-eval
# (e.g. --duration 20 --set wind.speed_mps=6 --out runs/other).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
if [ "$#" -eq 0 ]; then
  set -- --policy baseline --duration 60 --out runs/baseline --force
fi
exec .venv/bin/kite-eval "$@"
