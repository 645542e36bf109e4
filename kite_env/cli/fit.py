"""``kite-fit``: make the fast fidelity's reduced-order wing for a model.

    kite-fit sample --out DIR [--episodes N] [--seed S] [--jobs J] [--config FILE] [--set SECTION.KEY=VALUE ...]

``sample`` flies the episodes of the sampling plan (:func:`kite_env.surrogate.trajectories.sampling_plan`) in the full
model and keeps every physics step of each (``DIR/ep_XXXX.npz``); a run that was stopped goes on where it stopped.

Exit status: 0 done, 2 bad input (one line, nothing written), 130 interrupted.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
from pathlib import Path


def _sample_worker(args):
    out, n, seed, overrides, start, step = args
    from kite_env.surrogate.trajectories import sample_flights

    sample_flights(out, n, seed, overrides, start=start, step=step, log=lambda s: print(s, flush=True))
    return 0


def _overrides(args) -> list[str]:
    """The model's overrides: the config file's values as ``section.key=value`` plus ``--set``."""
    from kite_env.config import load_config

    cfg = load_config(args.config, args.set)  # validates
    base = load_config(None)
    d, d0 = cfg.to_dict(), base.to_dict()
    return [f"{s}.{k}={v}" for s in d for k, v in d[s].items() if v != d0[s][k] and s not in ("env",)]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="kite-fit", description="Make the reduced-order wing of a model.")
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("sample", help="fly the sampling plan in the full model, one tape per episode")
    s.add_argument("--out", required=True, type=Path)
    s.add_argument("--episodes", type=int, default=120)
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--jobs", type=int, default=1)
    s.add_argument("--config", default=None, help="physics config (YAML); default: the flying model")
    s.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    from kite_env.config import ConfigError

    try:
        over = _overrides(args)
    except ConfigError as exc:
        print(f"kite-fit: error: {exc}", file=sys.stderr)
        return 2
    if args.episodes < 1 or args.jobs < 1:
        print("kite-fit: error: --episodes and --jobs must be at least 1", file=sys.stderr)
        return 2
    try:
        if args.jobs == 1:
            _sample_worker((args.out, args.episodes, args.seed, over, 0, 1))
        else:
            with mp.get_context("spawn").Pool(args.jobs) as pool:
                pool.map(_sample_worker, [(args.out, args.episodes, args.seed, over, j, args.jobs)
                                          for j in range(args.jobs)])
    except KeyboardInterrupt:
        print("kite-fit: interrupted; run the same command again to go on", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
