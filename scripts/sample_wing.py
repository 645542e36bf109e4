"""Sample the full aeroelastic wing along flights for the reduced-order wing (:mod:`kite_env.surrogate.samples`).

    python scripts/sample_wing.py --out runs/surrogate/samples.npz [--policies baseline,random,constant:0.5,...]
           [--winds 4,5,6,8] [--episodes 2] [--duration 6] [--every 2] [--perturb 0] [--seed 0] [--set k=v ...]

For every policy, wind speed and episode: one episode of ``KiteFigureEight-v0`` (random start point on the
figure-eight, initial speed 18-26 m/s, turbulence intensity up to 0.1, all drawn from the seed), the wing solution
of every ``--every``-th physics step stored as a sample, plus ``--perturb`` static solves around each. Writes the
samples with their provenance (git commit, config, mesh, counts) and prints a table per setting.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output .npz file")
    p.add_argument("--policies", default="baseline,random,constant:0,constant:0.5,constant:-0.5")
    p.add_argument("--winds", default="4,5,6,8", help="wind speeds [m/s], comma-separated")
    p.add_argument("--episodes", type=int, default=2, help="episodes per policy and wind speed")
    p.add_argument("--duration", type=float, default=6.0, help="longest episode [s]")
    p.add_argument("--every", type=int, default=2, help="store every N-th physics step")
    p.add_argument("--perturb", type=int, default=0, help="static solves around each stored state")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    from agents.policies import PolicyError, make_agent
    from kite_env.config import ConfigError
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.surrogate.samples import StateSampler, WingSamples, git_commit

    try:
        winds = [float(w) for w in args.winds.split(",")]
        policies = [s for s in args.policies.split(",") if s]
    except ValueError:
        print(f"sample_wing: error: --winds must be numbers, got {args.winds!r}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    parts, group, t0 = [], 0, time.perf_counter()
    print(f"{'policy':<14} {'wind':>5} {'ep':>3} {'flown [s]':>9} {'samples':>8} {'failed':>6}  end")
    for pol in policies:
        for w in winds:
            over = [f"env.wind_speed_min_mps={w}", f"env.wind_speed_max_mps={w}", "env.random_start=true",
                    "env.initial_speed_min_mps=18", "env.initial_speed_max_mps=26",
                    "env.turbulence_intensity_max=0.1", f"env.max_episode_s={args.duration}", *args.set]
            try:
                env = KiteFigureEightEnv(overrides=over)
                agent = make_agent(pol, env, seed=int(rng.integers(2**31)))
            except (ConfigError, PolicyError, ValueError) as exc:
                print(f"sample_wing: error: {exc}", file=sys.stderr)
                return 2
            for _ in range(args.episodes):
                sampler = StateSampler(args.every, args.perturb, np.random.default_rng(rng.integers(2**31)), group)
                env.recorder = sampler
                try:
                    obs, _ = env.reset(seed=int(rng.integers(2**31)))
                except RuntimeError as exc:  # no converged start at the drawn state
                    print(f"{pol:<14} {w:5.1f} {group:3d}  reset failed: {exc}")
                    group += 1
                    continue
                done, start, info = False, True, {}
                while not done:
                    a, _ = agent.predict(obs, episode_start=np.array([start]), deterministic=True)
                    start = False
                    obs, _, term, trunc, info = env.step(a)
                    done = term or trunc
                part = sampler.samples()
                parts.append(part)
                print(f"{pol:<14} {w:5.1f} {group:3d} {info['t']:9.2f} {len(part.inputs):8d} {sampler.failed:6d}  "
                      f"{info['termination_reason']}", flush=True)
                group += 1
            env.close()
    cfg = env.cfg
    meta = {"git_commit": git_commit(), "kite": cfg.kite.name, "n_sections": int(len(env.sim.wing.mesh.sections)),
            "n_dof": int(env.sim.wing.n_dof), "config": cfg.to_dict(), "policies": policies, "winds_mps": winds,
            "episodes": group, "every": args.every, "perturb": args.perturb, "seed": args.seed,
            "wall_time_s": time.perf_counter() - t0}
    samples = WingSamples.concatenate(parts, meta)
    samples.meta["n_samples"] = int(len(samples.inputs))
    samples.save(out)
    print(f"sample_wing: {len(samples.inputs)} samples from {group} episodes in {meta['wall_time_s']:.0f} s -> {out}")
    print(json.dumps({k: v for k, v in meta.items() if k != "config"}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
