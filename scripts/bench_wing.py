"""Benchmark of the static aeroelastic wing on one core; prints a table and writes DIR/bench_wing.json.

    python scripts/bench_wing.py --out runs/bench            # default kite rhino16, three resolutions
"""

from __future__ import annotations

import os

# one core: set before numpy is imported
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder for bench_wing.json")
    p.add_argument("--kite", default="rhino16")
    p.add_argument("--steps", type=int, default=100, help="warm steps per resolution (default 100)")
    p.add_argument("--resolutions", default="21x4,37x6,51x8",
                   help="comma-separated SECTIONSxCHORD list; must include the default 37x6")
    args = p.parse_args(argv)
    try:
        res = [tuple(int(v) for v in r.split("x")) for r in args.resolutions.split(",")]
    except ValueError:
        print(f"bench_wing: error: --resolutions must look like 21x4,37x6,51x8, got {args.resolutions!r}",
              file=sys.stderr)
        return 2
    if args.steps < 1:
        print("bench_wing: error: --steps must be >= 1", file=sys.stderr)
        return 2
    from kite_env.benchmark import PAPER_WALL_PER_STEP_MS, bench_resolution, format_table, pin_to_one_core, write_json

    pin_to_one_core()

    rows = []
    for ns, nc in res:
        print(f"bench_wing: {args.kite} {ns}x{nc} ...", flush=True)
        rows.append(bench_resolution(args.kite, ns, nc, n_steps=args.steps))
    default = next((r for r in rows if (r["n_sections"], r["n_chord"]) == (37, 6)), rows[0])
    result = {k: v for k, v in default.items()}
    result["resolutions"] = rows
    result["paper_wall_per_step_ms"] = PAPER_WALL_PER_STEP_MS
    result["machine"] = {"python": platform.python_version(), "cpu": platform.processor() or platform.machine()}
    write_json(args.out, "bench_wing.json", result)
    print(format_table(rows))
    print(f"paper (Matlab, RK45 mean step 5.3 ms): {PAPER_WALL_PER_STEP_MS:.0f} ms wall per step; "
          f"target: warm step < 5 ms at 37x6")
    print(f"wrote {Path(args.out) / 'bench_wing.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
