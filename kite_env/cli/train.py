"""``kite-train``: train a PPO or SAC agent (Stable-Baselines3) on ``KiteFigureEight-v0``.

    kite-train --algo ppo|sac --timesteps N --out runs/ppo [--config configs/agents/ppo.yaml] [--n-envs K]
               [--seed S] [--resume] [--env-config FILE] [--set section.key=value ...]

Hyperparameters come from a YAML file keyed by environment id, with a ``default`` entry (``configs/agents/``);
the environment and physics from the project config (``--env-config``, ``--set``). The run folder gets
``config.yml`` (the complete environment config), ``args.yml``, ``command.txt``, TensorBoard logs in ``tb/``,
periodic checkpoints with the VecNormalize statistics in ``checkpoints/``, evaluations in ``eval/`` and the final
``model.zip`` (+ ``vecnormalize.pkl``). Ctrl-C saves a checkpoint; ``--resume`` continues from the newest one.
"""

from __future__ import annotations

import argparse
import re
import shlex
import sys
from pathlib import Path

import yaml

from kite_env.config import FIDELITIES, ConfigError, load_config

ALGOS = ("ppo", "sac")
ENV_ID = "KiteFigureEight-v0"
FAST_ENV_ID = "KiteFigureEightFast-v0"  # the same env with sim.fidelity = surrogate (hyperparameters keyed by it)
#: hyperparameter keys that are not constructor arguments of the algorithm
_META_KEYS = {"policy", "normalize", "checkpoint_freq", "eval_freq", "eval_episodes", "n_envs"}
_DEFAULT_HP = {
    "ppo": {"policy": "MlpPolicy", "normalize": True, "learning_rate": 3.0e-4, "n_steps": 512, "batch_size": 64,
            "gamma": 0.99, "gae_lambda": 0.95, "n_epochs": 10, "ent_coef": 0.0, "clip_range": 0.2,
            "checkpoint_freq": 5000, "eval_freq": 5000, "eval_episodes": 2},
    "sac": {"policy": "MlpPolicy", "normalize": True, "learning_rate": 3.0e-4, "buffer_size": 200000,
            "learning_starts": 1000, "batch_size": 256, "gamma": 0.99, "tau": 0.005, "train_freq": 1,
            "gradient_steps": 1, "checkpoint_freq": 5000, "eval_freq": 5000, "eval_episodes": 2},
}


class UsageError(Exception):
    pass


def load_hyperparameters(path: str | Path | None, algo: str, env_id: str = ENV_ID) -> dict:
    """Hyperparameters for ``algo``: built-in defaults, then the file's ``default`` entry, then its ``env_id`` entry."""
    hp = dict(_DEFAULT_HP[algo])
    if path is None:
        return hp
    p = Path(path)
    if not p.is_file():
        raise UsageError(f"hyperparameter file '{p}' does not exist")
    try:
        data = yaml.safe_load(p.read_text()) or {}
    except yaml.YAMLError as exc:
        raise UsageError(f"hyperparameter file '{p}' is not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise UsageError(f"hyperparameter file '{p}' must map env ids (and 'default') to settings")
    for key in ("default", env_id):
        entry = data.get(key) or {}
        if not isinstance(entry, dict):
            raise UsageError(f"hyperparameter file '{p}': entry '{key}' must be a mapping")
        hp.update(entry)
    return hp


def _make_env(cfg, seed: int, rank: int):
    def thunk():
        from stable_baselines3.common.monitor import Monitor

        from kite_env.envs.figure_eight import KiteFigureEightEnv

        env = Monitor(KiteFigureEightEnv(config=cfg))
        env.reset(seed=seed + rank)
        return env

    return thunk


def _vec_env(cfg, n_envs: int, seed: int, normalize: bool, gamma: float, training: bool = True):
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

    fns = [_make_env(cfg, seed, i) for i in range(n_envs)]
    venv = SubprocVecEnv(fns) if n_envs > 1 else DummyVecEnv(fns)
    venv.seed(seed)
    if normalize:
        venv = VecNormalize(venv, gamma=gamma, training=training, norm_reward=training)
    return venv


def _latest_checkpoint(ckpt_dir: Path):
    best = None
    for f in ckpt_dir.glob("model_*_steps.zip"):
        m = re.fullmatch(r"model_(\d+)_steps\.zip", f.name)
        if m and (best is None or int(m.group(1)) > best[0]):
            best = (int(m.group(1)), f)
    return best


def _algo_class(algo: str):
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[algo]


def train(args) -> Path:
    import torch
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback, EvalCallback

    out = Path(args.out)
    cfg = load_config(args.env_config, [*args.set, *([f"sim.fidelity={args.fidelity}"] if args.fidelity else [])])
    env_id = FAST_ENV_ID if cfg.sim.fidelity == "surrogate" else ENV_ID
    hp = load_hyperparameters(args.config, args.algo, env_id)
    n_envs = int(args.n_envs or hp.get("n_envs", 1))
    if n_envs < 1:
        raise UsageError(f"--n-envs must be >= 1, got {n_envs}")
    ckpt_dir = out / "checkpoints"
    latest = _latest_checkpoint(ckpt_dir) if args.resume else None
    if args.resume and latest is None:
        raise UsageError(f"--resume: no checkpoint in '{ckpt_dir}'")
    if not args.resume and out.exists() and any(out.iterdir()) and not args.force:
        raise UsageError(f"output folder '{out}' is not empty (use --resume to continue it or --force to overwrite)")
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    if not args.resume:
        (out / "config.yml").write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))
        (out / "args.yml").write_text(yaml.safe_dump({**vars(args), "hyperparameters": hp}, sort_keys=False))
        (out / "command.txt").write_text(" ".join(shlex.quote(a) for a in ["kite-train", *sys.argv[1:]]) + "\n")
    gamma = float(hp.get("gamma", 0.99))
    venv = _vec_env(cfg, n_envs, args.seed, bool(hp["normalize"]), gamma)
    eval_env = _vec_env(cfg, 1, args.seed + 10_000, bool(hp["normalize"]), gamma, training=False)
    kwargs = {k: v for k, v in hp.items() if k not in _META_KEYS}
    Algo = _algo_class(args.algo)
    if latest is not None:
        steps, path = latest
        model = Algo.load(path, env=venv, device="cpu", tensorboard_log=str(out / "tb"))
        vn = ckpt_dir / f"model_vecnormalize_{steps}_steps.pkl"
        if hp["normalize"] and vn.is_file():
            from stable_baselines3.common.vec_env import VecNormalize

            stats = VecNormalize.load(str(vn), venv.venv)
            venv.obs_rms, venv.ret_rms = stats.obs_rms, stats.ret_rms
        rb = ckpt_dir / f"model_replay_buffer_{steps}_steps.pkl"
        if args.algo == "sac" and rb.is_file():
            model.load_replay_buffer(rb)
        print(f"kite-train: resuming from {path.name} ({steps} steps)", file=sys.stderr)
    else:
        model = Algo(hp["policy"], venv, seed=args.seed, device="cpu", verbose=0,
                     tensorboard_log=str(out / "tb"), **kwargs)
    remaining = max(0, int(args.timesteps) - int(model.num_timesteps))
    freq = max(1, int(hp["checkpoint_freq"]) // n_envs)
    callbacks = [
        CheckpointCallback(save_freq=freq, save_path=str(ckpt_dir), name_prefix="model",
                           save_vecnormalize=bool(hp["normalize"]), save_replay_buffer=args.algo == "sac"),
        EvalCallback(eval_env, n_eval_episodes=int(hp["eval_episodes"]), eval_freq=max(1, int(hp["eval_freq"]) // n_envs),
                     log_path=str(out / "eval"), best_model_save_path=str(out / "eval"), deterministic=True),
    ]
    if hp["normalize"]:
        from stable_baselines3.common.callbacks import BaseCallback

        class SyncNorm(BaseCallback):  # the evaluation env uses the training statistics
            def _on_step(self) -> bool:
                eval_env.obs_rms = venv.obs_rms
                return True

        callbacks.insert(0, SyncNorm())

    def save_checkpoint(tag: str) -> None:
        ckpt_dir.mkdir(parents=True, exist_ok=True)
        n = int(model.num_timesteps)
        model.save(ckpt_dir / f"model_{n}_steps.zip")
        if hp["normalize"]:
            venv.save(str(ckpt_dir / f"model_vecnormalize_{n}_steps.pkl"))
        if args.algo == "sac":
            model.save_replay_buffer(ckpt_dir / f"model_replay_buffer_{n}_steps.pkl")
        print(f"kite-train: {tag}: checkpoint at {n} steps in {ckpt_dir}", file=sys.stderr)

    try:
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=CallbackList(callbacks), reset_num_timesteps=False,
                        progress_bar=_has_rich(), tb_log_name=args.algo)
    except KeyboardInterrupt:
        save_checkpoint("interrupted")
        raise
    finally:
        venv.close()
        eval_env.close()
    model.save(out / "model.zip")
    if hp["normalize"]:
        venv.save(str(out / "vecnormalize.pkl"))
    save_checkpoint("done")
    return out / "model.zip"


def _has_rich() -> bool:
    try:
        import rich  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return sys.stderr.isatty()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="kite-train", description=__doc__.split("\n\n")[0])
    p.add_argument("--algo", required=True, choices=ALGOS)
    p.add_argument("--timesteps", type=int, required=True, help="total environment steps")
    p.add_argument("--out", required=True, help="run folder")
    p.add_argument("--config", default=None, help="hyperparameter YAML (keyed by env id, with 'default')")
    p.add_argument("--env-config", default=None, help="project config YAML for the environment and physics")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override any project config value (repeatable)")
    p.add_argument("--n-envs", type=int, default=None, help="parallel environments (SubprocVecEnv when > 1)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--fidelity", choices=FIDELITIES, default=None,
                   help="wing model of the training env: fe (the aeroelastic FE wing) or surrogate (reduced-order "
                        "wing, KiteFigureEightFast-v0); default: sim.fidelity of the config")
    p.add_argument("--resume", action="store_true", help="continue from the newest checkpoint in OUT/checkpoints")
    p.add_argument("--force", action="store_true", help="train into a non-empty OUT")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if args.timesteps <= 0:
        print(f"kite-train: error: --timesteps must be positive, got {args.timesteps}", file=sys.stderr)
        return 2
    try:
        path = train(args)
    except (UsageError, ConfigError) as exc:
        print(f"kite-train: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("kite-train: interrupted; continue with --resume", file=sys.stderr)
        return 130
    print(f"kite-train: wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
