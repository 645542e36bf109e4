"""Where along the figure-eight two policies' traction differs: the first episodes of two ``kite-eval`` runs (their
``timeseries.npz``) binned by the path parameter ``s`` of the nearest point of the figure, with per bin the mean
tether force of each, its difference, the mean elevation of each and the mean distance from the figure.

    .venv/bin/python analyses/traction_by_phase.py RUN_A RUN_B [--bins 12] [--skip-s 5]

Used for docs/training.md, "Traction against tracking": the paper's controller dips below the figure's lowest parts
and pulls more there; an agent that tracks the figure closely does not.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np


def by_phase(run: Path, bins: int, skip_s: float) -> list[dict]:
    """Per bin of the path parameter: share of time, mean tether force [N], elevation [deg], distance [deg]."""
    d = np.load(Path(run) / "timeseries.npz")
    keep = d["t"] > skip_s
    s = np.mod(d["path_s"][keep], 2.0 * math.pi)
    b = np.minimum((s / (2.0 * math.pi) * bins).astype(int), bins - 1)
    force, elev, dist = d["tether_force"][keep], np.degrees(d["elevation"][keep]), d["path_distance"][keep]
    dist = np.degrees(dist) if np.nanmax(np.abs(dist)) < 1.0 else dist  # stored in rad (or deg)
    return [{"share": float(np.mean(b == k)), "force": float(force[b == k].mean()),
             "elevation": float(elev[b == k].mean()), "distance": float(dist[b == k].mean())} for k in range(bins)]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run_a")
    p.add_argument("run_b")
    p.add_argument("--bins", type=int, default=12)
    p.add_argument("--skip-s", type=float, default=5.0, help="leave out the first seconds (the start)")
    args = p.parse_args()
    a, b = by_phase(Path(args.run_a), args.bins, args.skip_s), by_phase(Path(args.run_b), args.bins, args.skip_s)
    print(f"{'bin':>3} {'share A/B':>11} {'force A [kN]':>12} {'force B [kN]':>12} {'B-A [%]':>8} "
          f"{'elev A/B [deg]':>15} {'dist A/B [deg]':>15}")
    for k, (x, y) in enumerate(zip(a, b)):
        print(f"{k:>3} {x['share']:>5.3f}/{y['share']:<5.3f} {x['force'] / 1e3:>12.2f} {y['force'] / 1e3:>12.2f} "
              f"{100.0 * (y['force'] / x['force'] - 1.0):>+8.1f} {x['elevation']:>7.1f}/{y['elevation']:<7.1f} "
              f"{x['distance']:>7.2f}/{y['distance']:<7.2f}")


if __name__ == "__main__":
    main()
