"""``kite-bench --out DIR``: environment steps per second and real-time factor on one core, per fidelity.

Prints a table and writes ``DIR/bench.json`` as ``{"fe": {"env_steps_per_s": ..., "real_time_factor": ...}}``
(real-time factor = wall seconds per simulated second, as ``kite-eval``; below 1 is faster than real time). The env
is reset (timed separately) and then stepped with the paper's controller, so that the flight is the one users see;
an episode that ends early is reset and the count goes on.
"""

from __future__ import annotations

import argparse
import sys
import time

from kite_env.config import ConfigError


def bench_env(n_steps: int = 100, overrides=(), seed: int = 0) -> dict:
    """Time ``n_steps`` env steps of KiteFigureEight-v0 (full fidelity) driven by the baseline agent."""
    from agents.baseline import BaselineAgent
    from kite_env.envs.figure_eight import KiteFigureEightEnv

    env = KiteFigureEightEnv(overrides=overrides)
    agent = BaselineAgent(env.cfg)
    t0 = time.perf_counter()
    obs, _ = env.reset(seed=seed)
    t_reset = time.perf_counter() - t0
    start, wall, steps, resets = True, 0.0, 0, 0
    while steps < n_steps:
        a, _ = agent.predict(obs, episode_start=start)
        start = False
        t0 = time.perf_counter()
        obs, _, term, trunc, _ = env.step(a)
        wall += time.perf_counter() - t0
        steps += 1
        if term or trunc:
            obs, _ = env.reset(seed=seed + resets + 1)
            resets += 1
            start = True
    sim = steps * env.control_dt
    return {"env_steps_per_s": steps / wall, "real_time_factor": wall / sim, "steps": steps,
            "control_dt_s": env.control_dt, "reset_s": t_reset, "resets_during_run": resets}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="kite-bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="folder for bench.json")
    p.add_argument("--steps", type=int, default=150, help="env steps per fidelity (default 150 = 3 s of flight)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    if args.steps <= 0:
        print(f"kite-bench: error: --steps must be positive, got {args.steps}", file=sys.stderr)
        return 2
    from kite_env.benchmark import pin_to_one_core, write_json

    pin_to_one_core()
    try:
        result = {"fe": bench_env(args.steps, args.set)}
    except ConfigError as exc:
        print(f"kite-bench: error: {exc}", file=sys.stderr)
        return 2
    print(f"{'fidelity':<10} {'env steps/s':>12} {'real-time factor':>17} {'reset [s]':>10}")
    for name, r in result.items():
        print(f"{name:<10} {r['env_steps_per_s']:>12.1f} {r['real_time_factor']:>17.2f} {r['reset_s']:>10.2f}")
    write_json(args.out, "bench.json", result)
    print(f"kite-bench: wrote {args.out}/bench.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
