#!/usr/bin/env bash
# Aeroelastic polar of the rhino16 kite at 25 m/s (the wing on its own).
# Extra arguments are passed to kite-polar (e.g. --kite v3 --out runs/polar_v3).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
if [ "$#" -eq 0 ]; then
  set -- --kite rhino16 --airspeed 25 --alpha-deg 14:22:1 --out runs/polar_rhino16
fi
exec .venv/bin/kite-polar "$@"
