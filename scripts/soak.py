"""Soak an environment with random actions and print the table (:mod:`kite_env.soak`).

    python scripts/soak.py --fidelity surrogate --episodes 10000 --jobs 2 --out runs/soak_fast
    python scripts/soak.py --fidelity fe --episodes 100 --jobs 2 --out runs/soak_fe
    python scripts/soak.py --fidelity batched --episodes 10000 --out runs/soak_batched
    python scripts/soak.py --merge runs/soak_fe_0 runs/soak_fe_50 --out runs/soak_fe   # parts flown apart

Exit status 0 when no step was non-finite and nothing raised, 1 otherwise, 2 for bad input.
"""

from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fidelity", choices=("surrogate", "fe", "batched"),
                   help="surrogate / fe: the single env of that wing; batched: the fast fidelity's vector env")
    p.add_argument("--episodes", type=int)
    p.add_argument("--merge", nargs="+", metavar="DIR", help="merge these soaks (disjoint seeds) into one table")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--out", required=True)
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    if args.merge:
        return _merge(args.merge, args.out)
    if args.fidelity is None or args.episodes is None:
        p.error("--fidelity and --episodes are required (or --merge DIR ...)")
    if args.episodes < 1 or args.jobs < 1 or args.duration <= 0:
        p.error("--episodes and --jobs must be >= 1 and --duration > 0")
    from kite_env.config import ConfigError, load_config
    from kite_env.soak import soak, soak_table, write

    try:
        load_config(None, args.set)
    except ConfigError as exc:
        print(f"soak: error: {exc}", file=sys.stderr)
        return 2
    result = soak(args.fidelity, args.episodes, args.seed, args.duration, args.jobs, args.set)
    write(result, args.out)
    print(soak_table(result), end="")
    for row in result["exceptions"][:5]:
        print(f"seed {row['seed']}: {row['exception']}", file=sys.stderr)
    return 0 if not result["exceptions"] and not result["non_finite_steps"] else 1


def _merge(dirs, out) -> int:
    import json
    from pathlib import Path

    from kite_env.soak import merge, soak_table, write

    parts = []
    for d in dirs:
        f = Path(d) / "soak.json"
        if not f.is_file():
            print(f"soak: error: {f} does not exist (not a soak folder)", file=sys.stderr)
            return 2
        parts.append(json.loads(f.read_text()))
    try:
        result = merge(parts)
    except ValueError as exc:
        print(f"soak: error: {exc}", file=sys.stderr)
        return 2
    write(result, out)
    print(soak_table(result), end="")
    return 0 if not result["exceptions"] and not result["non_finite_steps"] else 1


if __name__ == "__main__":
    sys.exit(main())
