"""Pick the checkpoint of a kite-train run to ship: the best mean return on validation seeds.

    python scripts/select_checkpoint.py RUN_DIR [--episodes 16] [--seed 30000] [--every 1] [--min-steps 0]
        [--duration S] [--ship agents/models/NAME] [--force]

Every checkpoint ``RUN_DIR/checkpoints/model_<N>_steps.zip`` (with its ``model_vecnormalize_<N>_steps.pkl``) flies
``--episodes`` episodes with deterministic actions in the run's own environment (``RUN_DIR/config.yml``: the
training recipe's randomised wind, turbulence and start; ``--duration`` shortens its episodes), episode ``i`` from
``reset(seed=seed + i)``; the paper's controller flies the same episodes for reference. The seeds of the project's
evaluations are disjoint, so that each stays an honest test of the checkpoint chosen here:

=============  ==================================================================
0 - 9,999      kite-train's training episodes (``--seed`` and its env seeds)
10,000 +       kite-train's periodic evaluations (``EvalCallback``)
20,000 +       ``kite-train --optimize``'s validation of each trial
30,000 +       this selection (default)
50,000 +       the held-out evaluation in the full model (README, "Agents")
70,000 +       the policy benchmark of the tests (tests/agents/test_policy_benchmark.py)
=============  ==================================================================

Prints one row per checkpoint (mean/std return, mean flight time, crashes) and writes ``RUN_DIR/selection.json``.
``--ship DIR`` copies the best checkpoint into ``DIR`` as ``model.zip`` + ``vecnormalize.pkl`` with the run's
``model.json`` (the model it was trained on), ``config.yml``, ``args.yml``, ``command.txt`` and ``selection.json``
(what ``kite-eval --policy NAME`` loads).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def checkpoints(run: Path) -> list[tuple[int, Path, Path]]:
    """(steps, model zip, vecnormalize pkl) of every checkpoint of ``run`` saved with its normalisation, by steps."""
    from kite_env.training import checkpoint_vecnormalize, checkpoints as saved

    found = [(n, p, checkpoint_vecnormalize(p.parent, n)) for n, p in saved(run / "checkpoints")]
    return [c for c in found if c[2].is_file()]


def validate(env, agent, seeds) -> dict:
    """Mean/std return, mean flight time and crashes of ``agent`` over one episode per seed."""
    from kite_env.flight import is_crash, run_episode

    rets, times, crashes = [], [], 0
    for s in seeds:
        _, info = run_episode(env, agent, seed=int(s), record=False)
        rets.append(info["episode_return"])
        times.append(info["episode_steps"] * env.control_dt)
        crashes += is_crash(info["termination_reason"])
    return {"mean_return": float(np.mean(rets)), "std_return": float(np.std(rets)),
            "flight_time_mean_s": float(np.mean(times)), "crashes": int(crashes), "episodes": len(seeds)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run", type=Path, help="kite-train output folder (checkpoints/, config.yml)")
    p.add_argument("--episodes", type=int, default=16)
    p.add_argument("--seed", type=int, default=30000, help="first validation seed (default 30000)")
    p.add_argument("--duration", type=float, default=None, help="episode length [s] (default: the run's)")
    p.add_argument("--every", type=int, default=1, help="validate every k-th checkpoint (default all)")
    p.add_argument("--min-steps", type=int, default=0, help="skip checkpoints before this many training steps")
    p.add_argument("--ship", type=Path, default=None, help="copy the best checkpoint into this folder")
    p.add_argument("--force", action="store_true", help="replace an existing --ship folder")
    args = p.parse_args(argv)
    if args.episodes < 1 or args.every < 1:
        p.error("--episodes and --every must be at least 1")
    cfg_path = args.run / "config.yml"
    if not cfg_path.is_file():
        p.error(f"'{args.run}' is not a kite-train run folder ({cfg_path} missing)")
    ckpts = [c for c in checkpoints(args.run) if c[0] >= args.min_steps][::-1][::args.every][::-1]
    if not ckpts:
        p.error(f"no checkpoints with their normalisation in '{args.run / 'checkpoints'}'")
    if args.ship is not None and args.ship.exists() and not args.force:
        p.error(f"'{args.ship}' exists (use --force to replace it)")

    from kite_env.config import load_config
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.policies import load_model_agent, make_agent
    from kite_env.training import checkpoint_vecnormalize

    cfg = load_config(cfg_path)
    # the run's environment as it trained: its randomised draws, its start rule, its episode length
    env_cfg = dataclasses.replace(cfg.env, randomize=True)
    if args.duration is not None:
        env_cfg = dataclasses.replace(env_cfg, max_episode_s=args.duration)
    cfg = dataclasses.replace(cfg, env=env_cfg)
    env = KiteFigureEightEnv(config=cfg)
    seeds = range(args.seed, args.seed + args.episodes)
    rows = [{"checkpoint": "baseline", "steps": None, **validate(env, make_agent("baseline", env), seeds)}]
    print(f"{'checkpoint':<12} {'mean return':>12} {'std':>8} {'flight [s]':>11} {'crashes':>8}")

    def show(r):
        print(f"{r['checkpoint']:<12} {r['mean_return']:>12.1f} {r['std_return']:>8.1f} "
              f"{r['flight_time_mean_s']:>11.2f} {r['crashes']:>5}/{r['episodes']}", flush=True)

    show(rows[0])
    for n, zp, vn in ckpts:
        agent = load_model_agent(zp, env, vecnormalize=vn)
        rows.append({"checkpoint": str(n), "steps": n, "model": f"checkpoints/{zp.name}",
                     **validate(env, agent, seeds)})
        show(rows[-1])
    best = max(rows[1:], key=lambda r: r["mean_return"])
    result = {"run": args.run.name, "validation_seeds": [args.seed, args.seed + args.episodes - 1],
              "best_steps": best["steps"], "rows": rows}
    (args.run / "selection.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"best: {best['steps']} steps, mean return {best['mean_return']:.1f} "
          f"(baseline {rows[0]['mean_return']:.1f}) -> {args.run / 'selection.json'}")
    if args.ship is not None:
        tmp = args.ship.with_name(args.ship.name + ".tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        ckpt = args.run / best["model"]
        shutil.copy(ckpt, tmp / "model.zip")
        shutil.copy(checkpoint_vecnormalize(ckpt.parent, best["steps"]), tmp / "vecnormalize.pkl")
        for name in ("model.json", "config.yml", "args.yml", "command.txt", "selection.json"):
            if (args.run / name).is_file():
                shutil.copy(args.run / name, tmp / name)
        shutil.rmtree(args.ship, ignore_errors=True)
        tmp.rename(args.ship)
        print(f"shipped -> {args.ship}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
