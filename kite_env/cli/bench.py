"""``kite-bench --out DIR``: environment steps per second and real-time factor on one core, per fidelity.

Prints a table and writes ``DIR/bench.json`` as ``{"fe": {"env_steps_per_s": ..., "real_time_factor": ...},
"surrogate": {...}, "batched": {"n_kites": 64, "kite_steps_per_s": ...}}`` (``fe``: the aeroelastic FE wing;
``surrogate``: the reduced-order wing, ``KiteFigureEightFast-v1``; ``batched``: the vector env of the surrogate
fidelity, all kites in one process)
(real-time factor = wall seconds per simulated second, as ``kite-eval``; below 1 is faster than real time). The env
is reset (timed separately) and then stepped with the paper's controller, so that the flight is the one users see;
an episode that ends early is reset and the count goes on.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from kite_env.config import ConfigError


def bench_env(n_steps: int = 100, overrides=(), seed: int = 0, fidelity: str = "fe", config=None) -> dict:
    """Time ``n_steps`` env steps of KiteFigureEight-v1 in ``fidelity`` driven by the baseline agent (``config``: a
    YAML path or None for the defaults, then ``overrides``)."""
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.policies.baseline import BaselineAgent

    env = KiteFigureEightEnv(config=config, overrides=overrides, fidelity=fidelity)
    agent = BaselineAgent(env.cfg)
    t0 = time.perf_counter()
    obs, _ = env.reset(seed=seed)
    t_reset = time.perf_counter() - t0
    start, wall, steps, resets = True, 0.0, 0, 0
    newton = []
    while steps < n_steps:
        a, _ = agent.predict(obs, episode_start=start)
        start = False
        t0 = time.perf_counter()
        obs, _, term, trunc, info = env.step(a)
        wall += time.perf_counter() - t0
        newton += info.get("newton_iters", [])
        steps += 1
        if term or trunc:
            obs, _ = env.reset(seed=seed + resets + 1)
            resets += 1
            start = True
    sim = steps * env.control_dt
    out = {"env_steps_per_s": steps / wall, "real_time_factor": wall / sim, "steps": steps,
           "control_dt_s": env.control_dt, "reset_s": t_reset, "resets_during_run": resets}
    if newton:  # the full model's wing: Newton iterations per physics step
        out.update(newton_iters_mean=float(np.mean(newton)), newton_iters_p99=float(np.percentile(newton, 99)),
                   newton_iters_max=int(np.max(newton)))
    return out


def bench_batched(n_kites: int = 64, n_steps: int = 1000, overrides=(), seed: int = 0, config=None) -> dict:
    """Time ``n_steps`` steps of the batched env (``n_kites`` kites in the surrogate fidelity, one process) with
    random actions; kite-steps per second = ``n_kites * n_steps / wall``."""
    import gymnasium as gym
    import numpy as np

    import kite_env  # noqa: F401  (registers the envs)

    env = gym.make_vec("KiteFigureEightFast-v1", num_envs=n_kites, vectorization_mode="vector_entry_point",
                       config=config, overrides=list(overrides))
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    wall = 0.0
    for _ in range(n_steps):
        a = rng.uniform(-0.3, 0.3, (n_kites, 1)).astype(np.float32)
        t0 = time.perf_counter()
        env.step(a)
        wall += time.perf_counter() - t0
    control_dt = env.unwrapped.control_dt if hasattr(env.unwrapped, "control_dt") else 0.02
    env.close()
    return {"n_kites": n_kites, "kite_steps_per_s": n_kites * n_steps / wall, "steps": n_steps,
            "real_time_factor": wall / (n_kites * n_steps * control_dt)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="kite-bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="folder for bench.json")
    p.add_argument("--steps", type=int, default=150, help="env steps of the fe fidelity (default 150 = 3 s of flight)")
    p.add_argument("--fast-steps", type=int, default=3000,
                   help="env steps of the surrogate fidelity, single and batched (default 3000)")
    p.add_argument("--n-kites", type=int, default=64, help="kites of the batched env (default 64)")
    p.add_argument("--fidelity", action="append", choices=("fe", "surrogate", "batched"), default=None,
                   help="benchmark only these (repeatable; default all)")
    p.add_argument("--config", default=None, help="physics and task config YAML (default: the flying model; the fast "
                   "fidelity needs a reduced-order wing fitted to it); --set overrides apply on top")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    if args.steps <= 0:
        print(f"kite-bench: error: --steps must be positive, got {args.steps}", file=sys.stderr)
        return 2
    from kite_env.benchmark import pin_to_one_core, write_json

    pin_to_one_core()
    which = args.fidelity or ["fe", "surrogate", "batched"]
    result = {}
    try:
        if "fe" in which:
            result["fe"] = bench_env(args.steps, args.set, config=args.config)
        if "surrogate" in which:
            result["surrogate"] = bench_env(args.fast_steps, args.set, fidelity="surrogate", config=args.config)
        if "batched" in which:
            result["batched"] = bench_batched(args.n_kites, args.fast_steps, args.set, config=args.config)
    except (ConfigError, FileNotFoundError, ValueError) as exc:
        print(f"kite-bench: error: {exc}", file=sys.stderr)
        return 2
    print(f"{'fidelity':<10} {'env steps/s':>12} {'real-time factor':>17} {'reset [s]':>10}")
    for name, r in result.items():
        if name == "batched":
            print(f"{name:<10} {r['kite_steps_per_s']:>12.1f} {r['real_time_factor']:>17.4f} {'-':>10}"
                  f"  ({r['n_kites']} kites: kite-steps/s, wall per simulated second of all kites)")
        else:
            newton = (f"  Newton iterations per step {r['newton_iters_mean']:.2f} (p99 {r['newton_iters_p99']:.0f}, "
                      f"max {r['newton_iters_max']})" if "newton_iters_mean" in r else "")
            print(f"{name:<10} {r['env_steps_per_s']:>12.1f} {r['real_time_factor']:>17.4f} {r['reset_s']:>10.2f}"
                  + newton)
    write_json(args.out, "bench.json", result)
    print(f"kite-bench: wrote {args.out}/bench.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
