"""Benchmark of the whole flight model on one core (real-time factor); prints a table, writes DIR/bench_flight.json.

    python scripts/bench_flight.py --out runs/bench                 # 3 s of the baseline at dt = 5 and 10 ms
"""

from __future__ import annotations

import os

# one core: set before numpy is imported
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder for bench_flight.json")
    p.add_argument("--duration", type=float, default=3.0, help="simulated seconds per time step (default 3)")
    p.add_argument("--dt-ms", default="5,10", help="comma-separated time steps [ms] (default 5,10)")
    args = p.parse_args(argv)
    try:
        dts = [float(v) * 1e-3 for v in args.dt_ms.split(",")]
    except ValueError:
        print(f"bench_flight: error: --dt-ms must look like 5,10, got {args.dt_ms!r}", file=sys.stderr)
        return 2
    if not (args.duration > 0 and all(d > 0 for d in dts)):
        print("bench_flight: error: --duration and --dt-ms must be positive", file=sys.stderr)
        return 2
    from kite_env.benchmark import (
        PAPER_REAL_TIME_FACTOR,
        bench_flight,
        format_flight_table,
        pin_to_one_core,
        write_json,
    )

    pin_to_one_core()

    rows = bench_flight(duration_s=args.duration, dt_values=dts)
    result = {"flight": rows, "paper_real_time_factor": PAPER_REAL_TIME_FACTOR,
              "machine": {"python": platform.python_version(), "cpu": platform.processor() or platform.machine()}}
    write_json(args.out, "bench_flight.json", result)
    print(format_flight_table(rows))
    print(f"paper (Matlab, RK45 mean step 5.3 ms): {PAPER_REAL_TIME_FACTOR} s wall per simulated second; target 1.0")
    return 0


if __name__ == "__main__":
    sys.exit(main())
