"""``kite-train``: train a PPO or SAC agent (Stable-Baselines3) on ``KiteFigureEightFast-v1`` (or the full model).

    kite-train --algo ppo|sac --timesteps N --out runs/ppo [--recipe FILE] [--config FILE] [--set section.key=value ...]
               [--fidelity surrogate|fe] [--n-envs K] [--vec-env batched|subproc|dummy] [--seed S] [--resume]
    kite-train select RUN_DIR [--episodes 16] [--seed 30000] [--every 1] [--min-steps 0] [--duration S]
               [--ship agents/models/NAME] [--force]
    kite-train curves RUN_DIR [RUN_DIR ...] --out DIR

``--config`` is the physics and task config (YAML, as in ``kite-eval`` and ``kite-bench``; default: the flying
model), ``--set`` overrides any of its keys, ``--recipe`` the training recipe (default: the one shipped for the
algorithm, ``agents/recipes/<algo>.yaml``). The fidelity defaults to the fast one (``surrogate``). A recipe is keyed
by env id with a ``default`` entry (rl-zoo style); an entry holds the algorithm's arguments and may hold

* ``env``: a mapping ``section.key: value`` of config keys, applied on top of ``--config`` and below ``--set`` (the
  command line wins; a randomised quantity that ``--set`` gives is flown at that value, its range dropped),
* ``n_envs``: parallel environments (``--n-envs`` wins),
* ``vec_env``: ``batched`` (all kites in one :class:`kite_env.envs.vector.SB3VecEnv`, surrogate fidelity only),
  ``subproc`` (one process per env) or ``dummy`` (all in this process, one after the other); ``--vec-env`` wins.
  Default: ``batched`` for the surrogate fidelity with more than one env, else ``subproc`` for several envs and
  ``dummy`` for one.

A recipe key that is neither an argument of the algorithm nor one of the keys above, an env id that is not
registered, or a physics config given as the recipe exits with status 2 and one line, before anything is written.

The training env is wrapped in ``VecMonitor`` (episode returns and lengths in ``OUT/monitor.csv``) and, with
``normalize``, ``VecNormalize``; the evaluation env (``EvalCallback``) draws the same randomised conditions with
the held-out seed ``seed + 10_000``. Progress (steps, steps/s, mean episode return, time left) is printed every
``--progress-s`` seconds on any output. The run folder gets ``config.yml`` (the complete config flown),
``model.json`` (the model it was trained on: preset and fingerprint, :func:`kite_env.config.fingerprint`; an agent
loads only into that model), ``args.yml``, ``command.txt``, TensorBoard logs in ``tb/``, periodic checkpoints with the
VecNormalize statistics in ``checkpoints/``, evaluations in ``eval/`` and the final ``model.zip`` (+
``vecnormalize.pkl``). Ctrl-C saves a checkpoint; ``--resume`` continues from the newest one. A numerical failure of
the wing with inertia (:class:`~kite_env.dynamics.simulator.NumericalFailure`, a bug of the simulator) in an env of
this process (``dummy``) or in a ``subproc`` worker (which writes it into ``OUT/.worker_failures`` before it ends:
the worker prints its traceback, this process reads the failure back) saves a checkpoint too and exits with status 3
and the failure's message.

``kite-train select`` picks the checkpoint of a run to ship: every checkpoint (with its normalisation) flies
validation episodes in the run's own randomised environment (seeds 30000 and up), the paper's controller the same
ones for reference; it prints one row per checkpoint, writes ``RUN_DIR/selection.json`` and, with ``--ship DIR``,
copies the best checkpoint with the run's model, config and command into ``DIR`` (what ``kite-eval --policy NAME``
loads from ``agents/models/NAME``): :func:`kite_env.training.select_checkpoint` (the project's seed ranges) and
:func:`kite_env.training.ship`.

``kite-train curves`` plots the learning curves of runs into ``DIR/learning_curves.png``: evaluation returns against
training steps (``RUN_DIR/eval/evaluations.npz``), training episode returns (``RUN_DIR/monitor.csv``) and the
checkpoints' validation returns of ``kite-train select`` (``RUN_DIR/selection.json``)
(:func:`kite_env.training.plot_learning_curves`).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import yaml

from kite_env.cli import parse_or_status
from kite_env.config import FIDELITIES, ConfigError, fingerprint
from kite_env.envs import ENV_ID, FAST_ENV_ID
from kite_env.training import (
    _META_KEYS,
    ALGOS,
    EVAL_SEED_OFFSET,
    SELECTION_SEED,
    VEC_ENVS,
    WORKER_FAILURES,
    UsageError,
    _algo_class,
    _close,
    _latest_checkpoint,
    _vec_env,
    _vec_env_kind,
    _worker_failure,
    best_row,
    checkpoint_vecnormalize,
    checkpoints,
    default_recipe,
    load_hyperparameters,
    recipe_overrides,
    schedules,
    select_checkpoint,
    ship,
    training_config,
)


def train(args) -> Path:
    import torch
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback, EvalCallback

    from kite_env.config import check_model
    from kite_env.dynamics.simulator import NumericalFailure

    out = Path(args.out)
    cfg, env_id, hp = training_config(args)
    n_envs = int(args.n_envs or hp.get("n_envs", 1))
    if n_envs < 1:
        raise UsageError(f"--n-envs must be >= 1, got {n_envs}")
    kind = _vec_env_kind(args.vec_env or hp.get("vec_env"), cfg.sim.fidelity, n_envs, hp.get("action_hold", 1))
    ckpt_dir = out / "checkpoints"
    latest = _latest_checkpoint(ckpt_dir) if args.resume else None
    if args.resume and latest is None:
        raise UsageError(f"--resume: no checkpoint in '{ckpt_dir}'")
    if not args.resume and out.exists() and any(out.iterdir()) and not args.force:
        raise UsageError(f"output folder '{out}' is not empty (use --resume to continue it or --force to overwrite)")
    if args.resume:  # the run goes on in the model it was trained on
        check_model(_read_json(out / "model.json"), cfg, f"run '{out}'")
    init = _init_model(args, cfg) if getattr(args, "init", None) else None
    # the reduced-order wing must be this model's (one clear error, nothing written)
    if cfg.sim.fidelity == "surrogate":
        from kite_env.surrogate import surrogate_for

        surrogate_for(cfg)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    if not args.resume:
        (out / "config.yml").write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))
        (out / "model.json").write_text(json.dumps(fingerprint(cfg), indent=1, default=repr))
        (out / "args.yml").write_text(yaml.safe_dump({**vars(args), "env_id": env_id, "n_envs": n_envs,
                                                      "vec_env": kind, "hyperparameters": hp}, sort_keys=False))
        (out / "command.txt").write_text(" ".join(shlex.quote(a) for a in ["kite-train", *sys.argv[1:]]) + "\n")
    gamma = float(hp.get("gamma", 0.99))
    report_dir = out / WORKER_FAILURES
    _worker_failure(report_dir)  # (a report left by an earlier run that was killed: dropped)
    hold = int(hp.get("action_hold", 1))
    venv = _vec_env(cfg, n_envs, args.seed, bool(hp["normalize"]), gamma, kind, monitor_file=out / "monitor.csv",
                    append=latest is not None, report_dir=report_dir, action_hold=hold)
    # held-out episodes in the same randomised conditions (one env; batched stays batched, one kite)
    eval_env = _vec_env(cfg, 1, args.seed + EVAL_SEED_OFFSET, bool(hp["normalize"]), gamma,
                        "batched" if kind == "batched" else "dummy", training=False, action_hold=hold)
    kwargs = schedules({k: v for k, v in hp.items() if k not in _META_KEYS})
    Algo = _algo_class(args.algo)
    if latest is not None:
        steps, path = latest
        model = Algo.load(path, env=venv, device="cpu", tensorboard_log=str(out / "tb"))
        vn = checkpoint_vecnormalize(ckpt_dir, steps)
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
        if init is not None:  # fine-tuning: the policy, value function and optimiser of a trained agent
            zip_path, vn = init
            try:
                model.set_parameters(str(zip_path), exact_match=True, device="cpu")
            except (RuntimeError, ValueError) as exc:
                raise UsageError(f"--init: '{zip_path}' does not fit this recipe's network: "
                                 f"{str(exc).splitlines()[0]}") from None
            if hp["normalize"] and vn.is_file():  # its observation statistics (the reward's adapt to the new task)
                from stable_baselines3.common.vec_env import VecNormalize

                venv.obs_rms = VecNormalize.load(str(vn), venv.venv).obs_rms
            print(f"kite-train: starting from the weights of {zip_path}", file=sys.stderr)
    remaining = max(0, int(args.timesteps) - int(model.num_timesteps))
    freq = max(1, int(hp["checkpoint_freq"]) // n_envs)
    callbacks = [
        _progress_callback(int(args.timesteps), float(args.progress_s)),
        CheckpointCallback(save_freq=freq, save_path=str(ckpt_dir), name_prefix="model",
                           save_vecnormalize=bool(hp["normalize"]), save_replay_buffer=args.algo == "sac"),
        EvalCallback(eval_env, n_eval_episodes=int(hp["eval_episodes"]),
                     eval_freq=max(1, int(hp["eval_freq"]) // n_envs), log_path=str(out / "eval"),
                     best_model_save_path=str(out / "eval"), deterministic=True),
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
            venv.save(str(checkpoint_vecnormalize(ckpt_dir, n)))
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
    except NumericalFailure:  # a bug of the simulator (the wing with inertia): keep what was learnt, then report
        save_checkpoint("numerical failure")
        raise
    except (EOFError, ConnectionError) as exc:  # a subproc worker ended: with a NumericalFailure it reported, as above
        failure = _worker_failure(report_dir)
        if failure is None:
            raise
        save_checkpoint("numerical failure")
        raise failure from exc
    finally:
        _close(venv)
        eval_env.close()
    model.save(out / "model.zip")
    if hp["normalize"]:
        venv.save(str(out / "vecnormalize.pkl"))
    save_checkpoint("done")
    return out / "model.zip"


def _init_model(args, cfg) -> tuple[Path, Path]:
    """``--init``: the model zip (a shipped name, a run folder or a zip) and its ``vecnormalize.pkl``, checked to be
    an agent of ``--algo`` trained on this model (one clear error otherwise, before anything is written)."""
    from kite_env.config import check_model
    from kite_env.policies import PolicyError, model_algorithm, model_path, model_record

    spec = str(args.init)
    path = Path(spec) / "model.zip" if Path(spec).is_dir() else model_path(spec)
    if path is None or not path.is_file():
        raise UsageError(f"--init: no model '{spec}' (a shipped name, a kite-train run folder or a model.zip)")
    try:
        algo = model_algorithm(path)
    except PolicyError as exc:
        raise UsageError(f"--init: {exc}") from None
    if algo != args.algo:
        raise UsageError(f"--init: '{path}' is a {algo.upper()} model, not {args.algo.upper()}")
    check_model(model_record(path), cfg, f"--init model '{path}'")
    return path, path.with_name("vecnormalize.pkl")


def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None


def _progress_callback(total: int, every_s: float):
    """A callback printing, every ``every_s`` seconds of wall time and at the end, the steps done, the steps per
    second, the mean return of the last 100 episodes and the time left (on any output, not only a terminal)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Progress(BaseCallback):
        def _on_training_start(self) -> None:
            self.t0 = self.last = time.perf_counter()
            self.n0 = int(self.model.num_timesteps)

        def _line(self) -> str:
            n = int(self.model.num_timesteps)
            dt = max(time.perf_counter() - self.t0, 1e-9)
            rate = (n - self.n0) / dt
            eps = list(self.model.ep_info_buffer or [])
            ret = (f"episode return {sum(e['r'] for e in eps) / len(eps):.1f} (last {len(eps)} episodes)" if eps
                   else "no episode ended yet")
            left = (total - n) / rate if rate > 0 else float("inf")
            return (f"kite-train: {n:,} / {total:,} steps  {rate:,.0f} steps/s  {ret}  "
                    f"{_duration(left)} left")

        def _on_step(self) -> bool:
            if time.perf_counter() - self.last >= every_s:
                self.last = time.perf_counter()
                print(self._line(), flush=True)
            return True

        def _on_training_end(self) -> None:
            print(self._line(), flush=True)

    return Progress()


def _duration(s: float) -> str:
    if s == float("inf"):
        return "?"
    s = int(round(s))
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


def _has_rich() -> bool:
    try:
        import rich  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return sys.stderr.isatty()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="kite-train", description=__doc__.split("\n\n")[0],
                                epilog="subcommands: 'kite-train select --help' (choose and ship a checkpoint), "
                                "'kite-train curves --help' (learning curves of runs)")
    p.add_argument("--algo", required=True, choices=ALGOS)
    p.add_argument("--timesteps", type=int, required=True, help="total environment steps")
    p.add_argument("--out", required=True, help="run folder")
    p.add_argument("--recipe", default=None, help="training recipe YAML (keyed by env id, with 'default'); default: "
                   "the shipped agents/recipes/<algo>.yaml")
    p.add_argument("--config", default=None, help="physics and task config YAML (default: the flying model)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override any config value (repeatable); wins over the recipe")
    p.add_argument("--progress-s", type=float, default=30.0, help="seconds between progress lines (default 30)")
    p.add_argument("--n-envs", type=int, default=None, help="parallel environments (default: the recipe's n_envs, "
                   "else 1)")
    p.add_argument("--vec-env", choices=VEC_ENVS, default=None,
                   help="how the envs run: batched (one SB3VecEnv over all kites; surrogate fidelity), subproc or "
                        "dummy; default: the recipe's vec_env, else batched for surrogate with n_envs > 1, subproc "
                        "for n_envs > 1, dummy for 1")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--fidelity", choices=FIDELITIES, default=None,
                   help="wing model of the training env: surrogate (the reduced-order wing, KiteFigureEightFast-v1; "
                        "the default) or fe (the aeroelastic FE wing, KiteFigureEight-v1, about 100x slower)")
    p.add_argument("--resume", action="store_true", help="continue from the newest checkpoint in OUT/checkpoints")
    p.add_argument("--init", default=None, metavar="MODEL", help="start a new run from the weights (and observation "
                   "statistics) of a trained agent of the same algorithm and model: a shipped name (ppo), a run "
                   "folder or a model.zip; e.g. to fine-tune it on another reward")
    p.add_argument("--optimize", action="store_true", help="hyperparameter search: run --n-trials trials of the "
                   "Optuna study --study-name in --storage, each of --timesteps (kite_env.cli.optimize)")
    p.add_argument("--storage", default=None, help="--optimize: the study's RDB URL (default sqlite:///OUT/study.db; "
                   "postgresql://... or mysql://... to share it across machines)")
    p.add_argument("--study-name", default=None, help="--optimize: the study (default kite-<algo>)")
    p.add_argument("--n-trials", type=int, default=10, help="--optimize: trials this process runs (default 10)")
    p.add_argument("--force", action="store_true", help="train into a non-empty OUT")
    return p


def build_select_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="kite-train select", description="Pick the checkpoint of a kite-train run to "
                                "ship: the best mean return on validation seeds (kite_env.training.select_checkpoint).")
    p.add_argument("run", type=Path, help="kite-train output folder (checkpoints/, config.yml)")
    p.add_argument("--episodes", type=int, default=16)
    p.add_argument("--seed", type=int, default=SELECTION_SEED,
                   help=f"first validation seed (default {SELECTION_SEED})")
    p.add_argument("--duration", type=float, default=None, help="episode length [s] (default: the run's)")
    p.add_argument("--every", type=int, default=1, help="validate every k-th checkpoint (default all)")
    p.add_argument("--min-steps", type=int, default=0, help="skip checkpoints before this many training steps")
    p.add_argument("--ship", type=Path, default=None, help="copy the best checkpoint into this folder")
    p.add_argument("--force", action="store_true", help="replace an existing --ship folder")
    return p


def select(argv) -> int:
    """``kite-train select``: exit status 0, or 2 for bad input (nothing flown or written)."""
    args = parse_or_status(build_select_parser(), argv)
    if isinstance(args, int):
        return args
    if args.ship is not None and args.ship.exists() and not args.force:
        print(f"kite-train select: error: '{args.ship}' exists (use --force to replace it)", file=sys.stderr)
        return 2

    def show(r: dict) -> None:  # one row as each is done, under the header (printed with the first)
        if r["checkpoint"] == "baseline":
            print(f"{'checkpoint':<12} {'mean return':>12} {'std':>8} {'flight [s]':>11} {'crashes':>8}")
        print(f"{r['checkpoint']:<12} {r['mean_return']:>12.1f} {r['std_return']:>8.1f} "
              f"{r['flight_time_mean_s']:>11.2f} {r['crashes']:>5}/{r['episodes']}", flush=True)

    try:
        result = select_checkpoint(args.run, args.episodes, args.seed, args.every, args.min_steps, args.duration,
                                   on_row=show)
    except (UsageError, ConfigError) as exc:
        print(f"kite-train select: error: {exc}", file=sys.stderr)
        return 2
    best, base = best_row(result), result["rows"][0]
    print(f"best: {best['steps']} steps, mean return {best['mean_return']:.1f} "
          f"(baseline {base['mean_return']:.1f}) -> {args.run / 'selection.json'}")
    if args.ship is not None:
        ship(args.run, args.ship, force=True)  # (an existing folder without --force was refused above)
        print(f"shipped -> {args.ship}")
    return 0


def curves(argv) -> int:
    """``kite-train curves``: the learning curves of runs (module docstring); exit status 0, 2 for bad input."""
    p = argparse.ArgumentParser(prog="kite-train curves", description="Plot the learning curves of kite-train runs "
                                "into DIR/learning_curves.png: evaluation returns, training episode returns and the "
                                "checkpoints' validation returns (kite-train select).")
    p.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR", help="kite-train run folders")
    p.add_argument("--out", required=True, type=Path, help="folder for learning_curves.png")
    args = parse_or_status(p, argv)
    if isinstance(args, int):
        return args
    from kite_env.training import plot_learning_curves

    png = args.out / "learning_curves.png"
    for run in plot_learning_curves(args.runs, png):
        print(f"kite-train curves: warning: {run}: no eval/evaluations.npz, monitor.csv or selection.json",
              file=sys.stderr)
    print(f"kite-train curves: wrote {png}")
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["select"]:
        return select(argv[1:])
    if argv[:1] == ["curves"]:
        return curves(argv[1:])
    args = build_parser().parse_args(argv)
    if args.timesteps <= 0:
        print(f"kite-train: error: --timesteps must be positive, got {args.timesteps}", file=sys.stderr)
        return 2
    from kite_env.dynamics.simulator import NumericalFailure

    if args.optimize and args.n_trials < 1:
        print(f"kite-train: error: --n-trials must be at least 1, got {args.n_trials}", file=sys.stderr)
        return 2
    try:
        if args.optimize:
            from kite_env.cli.optimize import optimize

            args.study_name = args.study_name or f"kite-{args.algo}"
            path = optimize(args)
        else:
            path = train(args)
    except (UsageError, ConfigError) as exc:
        print(f"kite-train: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("kite-train: interrupted; continue with --resume", file=sys.stderr)
        return 130
    except NumericalFailure as exc:
        first, _, rest = str(exc).partition("\n")
        print(f"kite-train: error: {first}; checkpoint saved, continue with --resume" + (f"\n{rest}" if rest else ""),
              file=sys.stderr)
        return 3
    print(f"kite-train: wrote {path}")
    return 0


#: the command's own names, and the training setup's names it hands on (kite_env.training)
__all__ = ["ENV_ID", "FAST_ENV_ID", "UsageError", "best_row", "build_parser", "build_select_parser",
           "checkpoint_vecnormalize", "checkpoints", "curves", "default_recipe", "load_hyperparameters", "main",
           "recipe_overrides", "schedules", "select", "select_checkpoint", "ship", "train", "training_config"]


if __name__ == "__main__":
    sys.exit(main())
