"""Early ends of randomised episodes by where on the figure-eight they start: in a turn or on the straighter parts.

    python scripts/start_transients.py [--policy baseline] [--fidelity fe|surrogate] [--seed 7000] [--episodes 60]
        [--duration 1.0] [--early 0.5] [--curvature 1.0] [--recipe configs/agents/ppo.yaml] [--set KEY=VALUE ...]
        [--out FILE.json]

Flies ``--episodes`` episodes (``reset(seed=seed + i)``) of ``--duration`` seconds in the training recipe's
randomised conditions (wind, turbulence, start speed; the start point drawn over the whole figure-eight,
``env.start_curvature_max=inf``, unless ``--set`` says otherwise) with the policy ``--policy`` (a name or a model,
as ``kite-eval --policy``) and splits them by the magnitude of the path's geodesic curvature at the start point:
above ``--curvature`` [1/rad] ("turn") or not ("straight"). Prints, per group, how many episodes end within
``--early`` seconds, their termination reasons and the median time at which they end; ``--out`` writes every
episode (start parameter, curvature, draws, end time, reason) as JSON.

The reset starts the kite with neutral steering and no turn rate (``FlightSimulator.reset``); this measures what
that costs where the path turns (README, "Trained agents").
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def fly(env, agent, seeds, curvature: float) -> list[dict]:
    """One row per seed: the episode's draws, the start's geodesic curvature, its group, end time and reason."""
    from kite_env.flight import run_episode

    rows = []
    for s in seeds:
        _, info = run_episode(env, agent, seed=int(s), record=False)
        k = float(env.path.geodesic_curvature(info["start_s"]))
        rows.append({"seed": int(s), "start_s": info["start_s"], "curvature_per_rad": k,
                     "group": "turn" if abs(k) > curvature else "straight",
                     "wind_speed_mps": info["wind_speed_mps"], "turbulence_intensity": info["turbulence_intensity"],
                     "initial_speed_mps": info["initial_speed_mps"],
                     "end_s": info["episode_steps"] * env.control_dt, "termination_reason": info["termination_reason"]})
    return rows


def summary(rows: list[dict], early: float) -> list[dict]:
    """Per group: episodes, those that end (not at the time limit) within ``early`` seconds, their reasons and median
    end time."""
    out = []
    for group in ("turn", "straight"):
        g = [r for r in rows if r["group"] == group]
        e = [r for r in g if r["end_s"] < early and r["termination_reason"] != "time limit"]
        out.append({"group": group, "episodes": len(g), "early": len(e),
                    "reasons": dict(collections.Counter(r["termination_reason"] for r in e)),
                    "median_end_s": float(np.median([r["end_s"] for r in e])) if e else None})
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--policy", default="baseline", help="policy name or model path, as kite-eval --policy")
    p.add_argument("--fidelity", choices=("fe", "surrogate"), default="fe")
    p.add_argument("--seed", type=int, default=7000, help="first episode seed (default 7000)")
    p.add_argument("--episodes", type=int, default=60)
    p.add_argument("--duration", type=float, default=1.0, help="episode length [s] (default 1.0)")
    p.add_argument("--early", type=float, default=0.5, help="an end before this time [s] is early (default 0.5)")
    p.add_argument("--curvature", type=float, default=1.0,
                   help="|geodesic curvature| [1/rad] above which a start is in a turn (default 1.0)")
    p.add_argument("--recipe", type=Path, default=ROOT / "configs" / "agents" / "ppo.yaml",
                   help="training recipe whose randomised conditions are flown (default configs/agents/ppo.yaml)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")
    p.add_argument("--out", type=Path, default=None, help="write every episode as JSON")
    args = p.parse_args(argv)
    if args.episodes < 1:
        p.error("--episodes must be at least 1")
    for name in ("duration", "early", "curvature"):
        v = getattr(args, name)
        if not (math.isfinite(v) and v > 0):
            p.error(f"--{name} must be a positive number, got {v}")
    if not args.recipe.is_file():
        p.error(f"recipe '{args.recipe}' does not exist")

    from agents.policies import make_agent
    from kite_env.cli.train import FAST_ENV_ID, UsageError, load_hyperparameters, recipe_overrides
    from kite_env.config import load_config
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.flight import evaluation_config

    try:
        # only the recipe's env overrides are used; they do not depend on the algorithm
        cond = recipe_overrides(load_hyperparameters(args.recipe, "ppo", FAST_ENV_ID))
        cfg = load_config(None, [*cond, "env.start_curvature_max=inf", f"sim.fidelity={args.fidelity}",
                                 *args.overrides])
        env = KiteFigureEightEnv(config=evaluation_config(cfg, args.duration, randomize=True))
        agent = make_agent(args.policy, env)
    except (ValueError, UsageError) as exc:  # ConfigError and PolicyError included
        p.error(str(exc))
    rows = fly(env, agent, range(args.seed, args.seed + args.episodes), args.curvature)
    print(f"{args.policy}, {args.fidelity}, seeds {args.seed}-{args.seed + args.episodes - 1}, {args.duration:g} s "
          f"episodes; early: an end within {args.early:g} s; turn: |kappa_g| > {args.curvature:g}/rad at the start")
    print(f"{'start':<9} {'episodes':>8} {'early':>6} {'share':>6} {'median end [s]':>15}  reasons")
    table = summary(rows, args.early)
    for t in table:
        share = t["early"] / t["episodes"] if t["episodes"] else float("nan")
        med = f"{t['median_end_s']:.2f}" if t["median_end_s"] is not None else "-"
        print(f"{t['group']:<9} {t['episodes']:>8} {t['early']:>6} {share:>6.0%} {med:>15}  {t['reasons']}")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.out.with_name(args.out.name + ".tmp")
        tmp.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "summary": table,
                                   "episodes": rows}, indent=2) + "\n")
        tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
