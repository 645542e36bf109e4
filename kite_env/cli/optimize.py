"""``kite-train --optimize``: hyperparameter search with Optuna on a shared study (Akiba et al., "Optuna: a
next-generation hyperparameter optimization framework", KDD 2019).

Every ``kite-train --optimize`` process is one worker: it opens (or creates) the study ``--study-name`` in the RDB
storage ``--storage`` (SQLite on one machine, ``sqlite:///runs/study.db``; PostgreSQL or MySQL across machines,
``postgresql://user:pass@host/db``, with that database's driver installed) and runs ``--n-trials`` trials of it, so
that several processes or machines add trials to one study. A trial trains the recipe's algorithm for
``--timesteps`` with hyperparameters drawn by the study's TPE sampler (:func:`sample_ppo`, :func:`sample_sac`: the
ranges of rl-baselines3-zoo's ``hyperparams_opt.py``, narrowed to what trains on the batched fast kites), evaluates it
every ``eval_freq`` steps on validation episodes (seeds ``seed + 20_000`` onwards: neither the training seeds nor the
held-out seeds of the evaluation in ``kite-eval``) and reports the mean validation return; the median pruner stops
a trial whose report falls below the median of the earlier trials at the same step. At the end the best trial so far
is written as a recipe, ``OUT/best_recipe.yaml`` (the recipe given, its env entry's hyperparameters replaced), which
``kite-train --recipe`` trains from.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import cast

import yaml

#: offset of the validation seeds from the training seed (kite-eval's evaluation seeds are chosen by the user;
#: training uses seed .. seed + n_envs, its EvalCallback seed + 10_000)
VALIDATION_SEED_OFFSET = 20_000


def sample_ppo(trial) -> dict:
    """PPO's hyperparameters for one trial."""
    n_steps = trial.suggest_categorical("n_steps", [64, 128, 256, 512])
    return {"learning_rate": trial.suggest_float("learning_rate", 1e-5, 1e-3, log=True), "n_steps": n_steps,
            "batch_size": trial.suggest_categorical("batch_size", [64, 128, 256]),
            "gamma": trial.suggest_categorical("gamma", [0.98, 0.99, 0.995, 0.999]),
            "gae_lambda": trial.suggest_categorical("gae_lambda", [0.9, 0.95, 0.98]),
            "n_epochs": trial.suggest_categorical("n_epochs", [5, 10, 20]),
            "clip_range": trial.suggest_categorical("clip_range", [0.1, 0.2, 0.3]),
            "ent_coef": trial.suggest_float("ent_coef", 1e-8, 1e-2, log=True),
            "policy_kwargs": {"log_std_init": trial.suggest_float("log_std_init", -2.0, 0.0)}}


def sample_sac(trial) -> dict:
    """SAC's hyperparameters for one trial."""
    return {"learning_rate": trial.suggest_float("learning_rate", 1e-5, 1e-3, log=True),
            "batch_size": trial.suggest_categorical("batch_size", [128, 256, 512]),
            "gamma": trial.suggest_categorical("gamma", [0.98, 0.99, 0.995, 0.999]),
            "tau": trial.suggest_categorical("tau", [0.005, 0.01, 0.02]),
            "gradient_steps": trial.suggest_categorical("gradient_steps", [1, 2, 4, 8]),
            "learning_starts": trial.suggest_categorical("learning_starts", [1000, 5000, 10000])}


SAMPLERS = {"ppo": sample_ppo, "sac": sample_sac}


def _objective(args, cfg, env_id, hp, kind, n_envs):
    import optuna
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.evaluation import evaluate_policy

    from kite_env.training import _META_KEYS, _algo_class, _vec_env, schedules

    def objective(trial) -> float:
        import os
        import socket

        trial.set_user_attr("worker", f"{socket.gethostname()}:{os.getpid()}")
        params = SAMPLERS[args.algo](trial)
        if args.algo == "ppo" and (params["n_steps"] * n_envs) % params["batch_size"]:
            params["batch_size"] = params["n_steps"] * n_envs  # (PPO needs whole minibatches)
        kwargs = schedules({**{k: v for k, v in hp.items() if k not in _META_KEYS}, **params})
        gamma = float(kwargs.get("gamma", 0.99))
        seed = args.seed + trial.number
        hold = int(hp.get("action_hold", 1))
        venv = _vec_env(cfg, n_envs, seed, bool(hp["normalize"]), gamma, kind, action_hold=hold)
        eval_env = _vec_env(cfg, 1, args.seed + VALIDATION_SEED_OFFSET, bool(hp["normalize"]), gamma,
                            "batched" if kind == "batched" else "dummy", training=False, action_hold=hold)
        model = _algo_class(args.algo)(hp["policy"], venv, seed=seed, device="cpu", verbose=0, **kwargs)
        every = max(1, int(hp["eval_freq"]) // n_envs)
        episodes = int(hp["eval_episodes"])

        class Report(BaseCallback):
            def __init__(self):
                super().__init__()
                self.last = -math.inf
                self.pruned = False

            def _on_step(self) -> bool:
                if self.n_calls % every:
                    return True
                if hp["normalize"]:
                    eval_env.obs_rms = venv.obs_rms
                eval_env.seed(args.seed + VALIDATION_SEED_OFFSET)  # the same validation episodes every time
                mean, _ = evaluate_policy(model, eval_env, n_eval_episodes=episodes, deterministic=True)
                self.last = float(cast(float, mean))  # a float without return_episode_rewards
                trial.report(self.last, int(self.model.num_timesteps))
                if trial.should_prune():
                    self.pruned = True
                    return False
                return True

        cb = Report()
        try:
            model.learn(total_timesteps=int(args.timesteps), callback=cb)
            if cb.last == -math.inf:  # no evaluation yet: evaluate the final policy
                cb.n_calls = 0
                cb._on_step()
        finally:
            venv.close()
            eval_env.close()
        print(f"kite-train: trial {trial.number}: validation return {cb.last:.2f}"
              + (" (pruned)" if cb.pruned else "") + f"  {json.dumps(params, default=str)}", flush=True)
        if cb.pruned:
            raise optuna.TrialPruned()
        return cb.last

    return objective


def best_recipe(study, algo: str, env_id: str, recipe_path: Path) -> dict:
    """The recipe of ``recipe_path`` with its ``env_id`` entry's hyperparameters replaced by the best trial's."""
    data = yaml.safe_load(Path(recipe_path).read_text()) or {}
    entry = dict(data.get(env_id) or {})
    params = dict(study.best_trial.params)
    log_std = params.pop("log_std_init", None)
    entry.update(params)
    if log_std is not None:
        entry["policy_kwargs"] = {**(entry.get("policy_kwargs") or {}), "log_std_init": log_std}
    data[env_id] = entry
    return data


def _open_study(optuna, url: str, name: str, seed: int, attempts: int = 20):
    """The study ``name`` in the RDB storage ``url``, created by the first worker. Workers that start together race
    to create its tables and the study (SQLite: "database is locked", a duplicate study): such a worker waits a
    random moment and tries again; SQLite connections wait up to 60 s for a lock."""
    import random
    import time

    from kite_env.training import UsageError

    kwargs = {"connect_args": {"timeout": 60}} if url.startswith("sqlite") else {}
    last = None
    for _ in range(attempts):
        try:
            storage = optuna.storages.RDBStorage(url, engine_kwargs=kwargs)
            return optuna.create_study(storage=storage, study_name=name, direction="maximize", load_if_exists=True,
                                       sampler=optuna.samplers.TPESampler(seed=seed),
                                       pruner=optuna.pruners.MedianPruner(n_startup_trials=3, n_warmup_steps=0))
        except (ValueError, ModuleNotFoundError, ImportError) as exc:  # a malformed URL or a missing driver
            raise UsageError(f"--storage {url!r}: {exc}") from None
        except Exception as exc:  # noqa: BLE001 - a concurrent creation (lock, duplicate): wait and retry
            last = exc
            time.sleep(random.uniform(0.2, 1.5))
    raise UsageError(f"--storage {url!r}: the study could not be opened: {last}")


def optimize(args) -> Path:
    """Run this worker's trials of the study and write the best recipe so far (module docstring)."""
    try:
        import optuna
    except ImportError:  # pragma: no cover (a declared dependency)
        raise SystemExit("kite-train: error: --optimize needs optuna (pip install optuna)") from None
    from kite_env.training import _vec_env_kind, default_recipe, training_config

    cfg, env_id, hp = training_config(args)
    n_envs = int(args.n_envs or hp.get("n_envs", 1))
    kind = _vec_env_kind(args.vec_env or hp.get("vec_env"), cfg.sim.fidelity, n_envs, hp.get("action_hold", 1))
    if cfg.sim.fidelity == "surrogate":
        from kite_env.surrogate import surrogate_for

        surrogate_for(cfg)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    storage = args.storage or f"sqlite:///{(out / 'study.db').resolve()}"
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = _open_study(optuna, storage, args.study_name, args.seed)
    import torch

    torch.set_num_threads(1)
    study.optimize(_objective(args, cfg, env_id, hp, kind, n_envs), n_trials=int(args.n_trials),
                   catch=())
    done = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    if not done:
        print("kite-train: no trial of the study has completed yet", file=sys.stderr)
        return out
    recipe = best_recipe(study, args.algo, env_id, Path(args.recipe) if args.recipe else default_recipe(args.algo))
    path = out / "best_recipe.yaml"
    path.write_text(f"# best of {len(done)} completed trials of study '{args.study_name}' ({storage}): trial "
                    f"{study.best_trial.number}, validation return {study.best_value:.3f}\n"
                    + yaml.safe_dump(recipe, sort_keys=False))
    print(f"kite-train: study '{args.study_name}': {len(study.trials)} trials ({len(done)} complete); best "
          f"{study.best_value:.3f} (trial {study.best_trial.number}) -> {path}", flush=True)
    return path


__all__ = ["SAMPLERS", "VALIDATION_SEED_OFFSET", "best_recipe", "optimize", "sample_ppo", "sample_sac"]
