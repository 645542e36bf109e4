"""Sample the full aeroelastic wing along flights for the reduced-order wing (:mod:`kite_env.surrogate.samples`).

    python scripts/sample_wing.py --out runs/surrogate/samples.npz [--policies baseline,random,constant:0.5,...]
           [--winds 4,5,6,8,10] [--episodes 2] [--duration 6] [--every 2] [--perturb 0] [--perturb-every 1]
           [--seed 0] [--set k=v ...]

For every policy, wind speed and episode: one episode of ``KiteFigureEight-v0`` (random start point on the
figure-eight, initial speed 18-26 m/s, turbulence intensity up to 0.1, all drawn from the seed), the wing solution
of every ``--every``-th physics step stored as a sample, plus ``--perturb`` static solves around every
``--perturb-every``-th stored state (one static solve costs about as much as 6 physics steps). Writes the samples
with their provenance (git commit, config, mesh, counts per policy and wind) and prints a table per setting.
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
    p.add_argument("--winds", default="4,5,6,8,10", help="wind speeds [m/s], comma-separated")
    p.add_argument("--episodes", type=int, default=2, help="episodes per policy and wind speed")
    p.add_argument("--duration", type=float, default=6.0, help="longest episode [s]")
    p.add_argument("--every", type=int, default=2, help="store every N-th physics step")
    p.add_argument("--perturb", type=int, default=0, help="static solves around each perturbed stored state")
    p.add_argument("--perturb-every", type=int, default=1, help="perturb every N-th stored state of an episode")
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
    counts: dict = {}
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
                sampler = _sampler_class(StateSampler)(args.every, args.perturb,
                                                       np.random.default_rng(rng.integers(2**31)), group,
                                                       perturb_every=args.perturb_every)
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
                c = counts.setdefault(pol, {}).setdefault(f"{w:g}", {"episodes": 0, "visited": 0, "perturbed": 0,
                                                                        "failed": 0, "flown_s": 0.0})
                c["episodes"] += 1
                c["visited"] += int(np.sum(part.origin == 0))
                c["perturbed"] += int(np.sum(part.origin == 1))
                c["failed"] += sampler.failed
                c["flown_s"] += float(info["t"])
                print(f"{pol:<14} {w:5.1f} {group:3d} {info['t']:9.2f} {len(part.inputs):8d} {sampler.failed:6d}  "
                      f"{info['termination_reason']}", flush=True)
                group += 1
            env.close()
    cfg = env.cfg
    meta = {"git_commit": git_commit(), "kite": cfg.kite.name, "n_sections": int(len(env.sim.wing.mesh.sections)),
            "n_dof": int(env.sim.wing.n_dof), "config": cfg.to_dict(), "policies": policies, "winds_mps": winds,
            "episodes": group, "every": args.every, "perturb": args.perturb, "perturb_every": args.perturb_every,
            "duration_s": args.duration, "seed": args.seed, "overrides": args.set, "counts": counts,
            "wall_time_s": time.perf_counter() - t0}
    samples = WingSamples.concatenate(parts, meta)
    samples.meta["n_samples"] = int(len(samples.inputs))
    samples.save(out)
    print(f"\n{'policy':<14} {'wind':>5} {'episodes':>8} {'flown [s]':>9} {'visited':>8} {'perturbed':>9}")
    for pol, per_wind in counts.items():
        for w, c in per_wind.items():
            print(f"{pol:<14} {w:>5} {c['episodes']:8d} {c['flown_s']:9.1f} {c['visited']:8d} {c['perturbed']:9d}")
    print(f"sample_wing: {len(samples.inputs)} samples from {group} episodes in {meta['wall_time_s']:.0f} s -> {out}")
    print(json.dumps({k: v for k, v in meta.items() if k not in ("config", "counts")}))
    return 0


def _sampler_class(base):
    """``base`` (:class:`~kite_env.surrogate.samples.StateSampler`) with its perturbations restricted to every
    ``perturb_every``-th stored state of the episode (the first one included)."""

    class Sampler(base):
        def __init__(self, *args, perturb_every: int = 1, **kwargs):
            super().__init__(*args, **kwargs)
            self.perturb_every = max(1, int(perturb_every))
            self._n_base = self.n_perturb
            self._n_stored = 0

        def _sample(self, rec) -> None:
            self.n_perturb = self._n_base if self._n_stored % self.perturb_every == 0 else 0
            self._n_stored += 1
            super()._sample(rec)

    return Sampler


if __name__ == "__main__":
    sys.exit(main())
