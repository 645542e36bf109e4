"""Training setup of ``kite-train`` (Stable-Baselines3): the recipes (shipped in ``agents/recipes``, read as data),
their hyperparameters and config layers, the vectorised training and evaluation envs (with the report of a
``subproc`` worker's numerical failure) and the checkpoints of a run folder. :mod:`kite_env.cli.train` (one run) and
:mod:`kite_env.cli.optimize` (a hyperparameter study) both build their runs from here. The choice of the checkpoint
to ship on validation seeds and its copy into ``agents/models`` (:func:`select_checkpoint`, :func:`ship`; the
project's seed ranges are in the former's docstring) are ``kite-train select``.
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from kite_env.config import ConfigError, config_from_dict, load_config, parse_overrides, without_retired
from kite_env.envs import ENV_ID, FAST_ENV_ID

ALGOS = ("ppo", "sac")
VEC_ENVS = ("batched", "subproc", "dummy")
#: recipe keys that are not constructor arguments of the algorithm
_META_KEYS = {"policy", "normalize", "checkpoint_freq", "eval_freq", "eval_episodes", "n_envs", "env", "vec_env",
              "action_hold"}
#: offset of the evaluation env's seed from the training seed (held-out episodes)
EVAL_SEED_OFFSET = 10_000
_DEFAULT_HP = {
    "ppo": {"policy": "MlpPolicy", "normalize": True, "learning_rate": 3.0e-4, "n_steps": 512, "batch_size": 64,
            "gamma": 0.99, "gae_lambda": 0.95, "n_epochs": 10, "ent_coef": 0.0, "clip_range": 0.2,
            "checkpoint_freq": 5000, "eval_freq": 5000, "eval_episodes": 2},
    "sac": {"policy": "MlpPolicy", "normalize": True, "learning_rate": 3.0e-4, "buffer_size": 200000,
            "learning_starts": 1000, "batch_size": 256, "gamma": 0.99, "tau": 0.005, "train_freq": 1,
            "gradient_steps": 1, "checkpoint_freq": 5000, "eval_freq": 5000, "eval_episodes": 2},
}


def default_recipe(algo: str) -> Path:
    """The recipe shipped for ``algo`` (``agents/recipes/<algo>.yaml``)."""
    from importlib.resources import files

    return Path(str(files("agents") / "recipes" / f"{algo}.yaml"))


class UsageError(Exception):
    pass


def algorithm_arguments(algo: str) -> set[str]:
    """The constructor arguments of the Stable-Baselines3 class of ``algo`` a recipe may set."""
    import inspect

    return {n for n in inspect.signature(_algo_class(algo).__init__).parameters if n not in ("self", "env")}


def validate_recipe(data, p: Path, algo: str) -> None:
    """One clear :class:`UsageError` for a recipe that is not one (module docstring)."""
    from kite_env.config import Config

    if not isinstance(data, dict):
        raise UsageError(f"recipe '{p}' must map env ids (and 'default') to settings")
    sections = {f for f in Config.__dataclass_fields__}
    if set(data) & sections:
        raise UsageError(f"recipe '{p}' is a physics config (sections {', '.join(sorted(set(data) & sections))}), not "
                         f"a training recipe: give it with --config (the recipe is --recipe)")
    valid_ids = ("default", ENV_ID, FAST_ENV_ID)
    for key, entry in data.items():
        if key not in valid_ids:
            raise UsageError(f"recipe '{p}': unknown env id '{key}' (valid: {', '.join(valid_ids)})")
        if entry is None:
            continue
        if not isinstance(entry, dict):
            raise UsageError(f"recipe '{p}': entry '{key}' must be a mapping")
        allowed = algorithm_arguments(algo) | _META_KEYS
        for name in entry:
            if name not in allowed:
                import difflib

                near = difflib.get_close_matches(str(name), sorted(allowed), n=1)
                raise UsageError(f"recipe '{p}': '{key}.{name}' is neither an argument of {algo.upper()} nor a recipe "
                                 f"key" + (f" (did you mean '{near[0]}'?)" if near else ""))
        env = entry.get("env") or {}
        if not isinstance(env, dict):
            raise UsageError(f"recipe '{p}': '{key}.env' must map 'section.key' to values")


def load_hyperparameters(path: str | Path | None, algo: str, env_id: str = FAST_ENV_ID) -> dict:
    """Hyperparameters for ``algo``: built-in defaults, then the recipe's ``default`` entry, then its ``env_id``
    entry (``path`` None: the shipped recipe, :func:`default_recipe`)."""
    hp = dict(_DEFAULT_HP[algo])
    p = Path(path) if path is not None else default_recipe(algo)
    if not p.is_file():
        raise UsageError(f"recipe '{p}' does not exist")
    try:
        data = yaml.safe_load(p.read_text()) or {}
    except yaml.YAMLError as exc:
        raise UsageError(f"recipe '{p}' is not valid YAML: {exc}") from None
    validate_recipe(data, p, algo)
    env_overrides: dict = {}
    for key in ("default", env_id):
        entry = data.get(key) or {}
        env_overrides.update(entry.get("env") or {})
        hp.update(entry)
    if env_overrides:
        hp["env"] = env_overrides
    vec = hp.get("vec_env")
    if vec is not None and vec not in VEC_ENVS:
        raise UsageError(f"recipe '{p}': vec_env must be one of {', '.join(VEC_ENVS)}, got {vec!r}")
    from kite_env.envs.hold import check_action_hold

    try:
        check_action_hold(hp.get("action_hold", 1))
    except ValueError as exc:
        raise UsageError(f"recipe '{p}': {exc}") from None
    return hp


#: hyperparameters that may be given as a linear schedule ``lin_<initial value>`` (rl-baselines3-zoo's convention)
SCHEDULED = ("learning_rate", "clip_range", "clip_range_vf")


def schedules(kwargs: dict) -> dict:
    """``kwargs`` with every :data:`SCHEDULED` value written ``lin_<x>`` replaced by SB3's schedule falling linearly
    from ``x`` at the start of training to 0 at ``--timesteps`` (SB3 computes the progress from the model's step
    count over the run's total, so a resumed run follows the same schedule as an uninterrupted one)."""
    from stable_baselines3.common.utils import LinearSchedule

    out = dict(kwargs)
    for key in SCHEDULED:
        value = out.get(key)
        if isinstance(value, str):  # (YAML reads 3e-4, without a decimal point, as a string)
            linear = value.startswith("lin_")
            try:
                x = float(value[4:] if linear else value)
            except ValueError:
                raise UsageError(f"hyperparameter {key}: expected a number or 'lin_<number>', got {value!r}") from None
            out[key] = LinearSchedule(x, 0.0, 1.0) if linear else x
    return out


def recipe_overrides(hp: dict) -> list[str]:
    """The recipe's ``env`` mapping as ``--set`` strings ``section.key=value`` (values as YAML scalars)."""
    out = []
    for key, value in (hp.get("env") or {}).items():
        if isinstance(value, bool):
            text = "true" if value else "false"
        elif isinstance(value, (int, float, str)):
            text = repr(value) if isinstance(value, float) else str(value)
        else:
            raise UsageError(f"recipe env override '{key}': expected a scalar, got {value!r}")
        out.append(f"{key}={text}")
    return out


#: in a subproc worker, a NumericalFailure is written here (in the run folder) before the worker ends with it
WORKER_FAILURES = ".worker_failures"


def _make_env(cfg, report_dir: Path | None = None, action_hold: int = 1):
    """A thunk making the env of ``cfg``; with ``report_dir`` (``subproc`` workers) the env writes a
    :class:`~kite_env.dynamics.simulator.NumericalFailure` that ends its worker into that folder first, so that the
    main process can report it as in one process (:func:`_worker_failure`); with ``action_hold`` > 1 the agent's
    action is held that many control steps (:class:`kite_env.envs.hold.HeldAction`)."""

    def thunk():
        from kite_env.envs.figure_eight import KiteFigureEightEnv
        from kite_env.envs.hold import HeldAction

        env = KiteFigureEightEnv(config=cfg)
        env = env if report_dir is None else _reporting(env, report_dir)
        return env if action_hold == 1 else HeldAction(env, action_hold)

    return thunk


def _report_failure(report_dir: Path, exc) -> None:
    import os
    import pickle

    report_dir.mkdir(parents=True, exist_ok=True)
    tmp = report_dir / f"{os.getpid()}.tmp"
    tmp.write_bytes(pickle.dumps(exc))
    tmp.replace(report_dir / f"{os.getpid()}.pkl")  # whole or not at all


def _reporting(env, report_dir: Path):
    """``env`` in a ``gymnasium.Wrapper`` whose ``step`` and ``reset`` write a NumericalFailure to ``report_dir``
    (:func:`_report_failure`) before raising it on."""
    import gymnasium as gym

    from kite_env.dynamics.simulator import NumericalFailure

    class ReportNumericalFailure(gym.Wrapper):
        def step(self, action):
            try:
                return self.env.step(action)
            except NumericalFailure as exc:
                _report_failure(report_dir, exc)
                raise

        def reset(self, **kwargs):
            try:
                return self.env.reset(**kwargs)
            except NumericalFailure as exc:
                _report_failure(report_dir, exc)
                raise

    return ReportNumericalFailure(env)


def _worker_failure(report_dir: Path):
    """The NumericalFailure a ``subproc`` worker wrote before it ended (the first, by time), or None; the folder is
    removed."""
    import pickle
    import shutil

    files = sorted(report_dir.glob("*.pkl"), key=lambda f: f.stat().st_mtime) if report_dir.is_dir() else []
    exc = pickle.loads(files[0].read_bytes()) if files else None
    shutil.rmtree(report_dir, ignore_errors=True)
    return exc


def _close(venv) -> None:
    """Close ``venv``; a ``subproc`` VecEnv whose worker has ended cannot be closed by SB3 (it waits on the dead
    worker's pipe): its processes are then terminated."""
    try:
        venv.close()
    except (EOFError, OSError):
        inner = venv.unwrapped
        for proc in getattr(inner, "processes", []):
            if proc.is_alive():
                proc.terminate()
            proc.join(timeout=10)
        for remote in getattr(inner, "remotes", []):
            remote.close()
        inner.closed = True


def _vec_env(cfg, n_envs: int, seed: int, normalize: bool, gamma: float, kind: str, training: bool = True,
             monitor_file: Path | None = None, append: bool = False, report_dir: Path | None = None,
             action_hold: int = 1):
    """``n_envs`` envs of ``cfg`` as a ``kind`` VecEnv (``VEC_ENVS``) seeded ``seed + i``, in ``VecMonitor`` (writing
    ``monitor_file``, appended to with ``append``) and, with ``normalize``, ``VecNormalize``; ``subproc`` workers
    report a NumericalFailure into ``report_dir`` (:func:`_make_env`); each env holds the agent's action
    ``action_hold`` control steps (``dummy`` and ``subproc``; :func:`_vec_env_kind` checks the kind)."""
    from stable_baselines3.common.monitor import ResultsWriter
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor, VecNormalize

    if kind == "batched":  # (with action_hold 1: _vec_env_kind refuses a hold with the batched env)
        from kite_env.envs.vector import KiteFigureEightVectorEnv, SB3VecEnv

        try:
            venv = SB3VecEnv(KiteFigureEightVectorEnv(n_envs, config=cfg, fidelity=None))
        except ValueError as exc:  # not the surrogate fidelity
            raise UsageError(f"--vec-env batched: {exc}") from None
    else:
        if kind == "subproc":
            venv = SubprocVecEnv([_make_env(cfg, report_dir, action_hold) for _ in range(n_envs)])
        else:
            venv = DummyVecEnv([_make_env(cfg, action_hold=action_hold) for _ in range(n_envs)])
    venv.seed(seed)  # env i: reset(seed=seed + i) at the first reset
    if monitor_file is not None and append and monitor_file.is_file():
        venv = VecMonitor(venv)  # continue the run's monitor file (the column t restarts at 0 in a resumed run)
        venv.results_writer = ResultsWriter(str(monitor_file), override_existing=False)
    else:
        venv = VecMonitor(venv, filename=None if monitor_file is None else str(monitor_file))
    if normalize:
        venv = VecNormalize(venv, gamma=gamma, training=training, norm_reward=training)
    return venv


def _vec_env_kind(requested: str | None, fidelity: str, n_envs: int, action_hold: int = 1) -> str:
    if requested is None:
        if fidelity == "surrogate" and n_envs > 1 and action_hold == 1:
            return "batched"
        return "subproc" if n_envs > 1 and fidelity != "surrogate" else "dummy"
    if requested == "batched" and fidelity != "surrogate":
        raise UsageError(f"vec_env 'batched' needs sim.fidelity surrogate, got {fidelity!r} (use subproc or dummy)")
    if requested == "batched" and action_hold != 1:
        raise UsageError(f"action_hold {action_hold} needs vec_env dummy or subproc (the batched env steps every "
                         "kite every control step)")
    return requested


def checkpoints(ckpt_dir: Path) -> list[tuple[int, Path]]:
    """(steps, path) of every ``model_<steps>_steps.zip`` in ``ckpt_dir``, by steps."""
    out = []
    for f in ckpt_dir.glob("model_*_steps.zip"):
        m = re.fullmatch(r"model_(\d+)_steps\.zip", f.name)
        if m:
            out.append((int(m.group(1)), f))
    return sorted(out)


def checkpoint_vecnormalize(ckpt_dir: Path, steps: int) -> Path:
    """The normalisation statistics saved with the checkpoint of ``steps`` (SB3 CheckpointCallback's name)."""
    return ckpt_dir / f"model_vecnormalize_{steps}_steps.pkl"


def _latest_checkpoint(ckpt_dir: Path):
    found = checkpoints(ckpt_dir)
    return found[-1] if found else None


def _algo_class(algo: str):
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[algo]


def training_config(args) -> tuple:
    """``(cfg, env_id, hp)``: the config flown (``--config``, then the recipe's ``env``, then ``--set`` and the
    fidelity, each a layer of :func:`kite_env.config.config_from_dict`) and the recipe's hyperparameters."""
    fidelity = args.fidelity or "surrogate"
    env_id = FAST_ENV_ID if fidelity == "surrogate" else ENV_ID
    hp = load_hyperparameters(args.recipe, args.algo, env_id)
    cfg = load_config(args.config)
    cfg = config_from_dict(parse_overrides(recipe_overrides(hp)), cfg)
    if cfg.sim.fidelity != "fe":
        raise UsageError(f"the recipe for {env_id} sets sim.fidelity (set the fidelity with --fidelity)")
    cfg = config_from_dict(parse_overrides(args.set), cfg)
    cfg = config_from_dict({"sim": {"fidelity": fidelity}}, cfg)
    return cfg, env_id, hp


# --------------------------------------------------------------------------- choosing and shipping a checkpoint
#: the first validation seed of :func:`select_checkpoint` (the project's seed ranges: its docstring)
SELECTION_SEED = 30_000
#: what :func:`ship` copies from the run folder next to the chosen checkpoint
SHIPPED_FILES = ("model.json", "config.yml", "args.yml", "command.txt", "selection.json")


def run_checkpoints(run_dir: Path) -> list[tuple[int, Path, Path]]:
    """(steps, model zip, vecnormalize pkl) of every checkpoint of the run folder ``run_dir`` saved with its
    normalisation, by steps."""
    found = [(n, p, checkpoint_vecnormalize(p.parent, n)) for n, p in checkpoints(Path(run_dir) / "checkpoints")]
    return [c for c in found if c[2].is_file()]


def validate(env, agent, seeds) -> dict:
    """Mean/std return, mean flight time and crashes of ``agent`` over one episode of ``env`` per seed
    (``reset(seed=s)``, deterministic actions)."""
    import numpy as np

    from kite_env.flight import is_crash, run_episode

    rets, times, crashes = [], [], 0
    for s in seeds:
        _, info = run_episode(env, agent, seed=int(s), record=False)
        rets.append(info["episode_return"])
        times.append(info["episode_steps"] * env.control_dt)
        crashes += is_crash(info["termination_reason"])
    return {"mean_return": float(np.mean(rets)), "std_return": float(np.std(rets)),
            "flight_time_mean_s": float(np.mean(times)), "crashes": int(crashes), "episodes": len(seeds)}


def select_checkpoint(run_dir: str | Path, episodes: int = 16, seed: int = SELECTION_SEED, every: int = 1,
                      min_steps: int = 0, duration: float | None = None, on_row=None) -> dict:
    """Pick the checkpoint of a ``kite-train`` run to ship: the best mean return on validation seeds.

    Every checkpoint ``RUN_DIR/checkpoints/model_<N>_steps.zip`` (with its ``model_vecnormalize_<N>_steps.pkl``) of
    at least ``min_steps`` training steps, every ``every``-th counted from the newest, flies ``episodes`` episodes
    with deterministic actions in the run's own environment (``RUN_DIR/config.yml``: the training recipe's
    randomised wind, turbulence and start; ``duration`` [s] shortens its episodes), episode ``i`` from
    ``reset(seed=seed + i)``; the paper's controller flies the same episodes for reference. The seeds of the
    project's evaluations are disjoint, so that each stays an honest test of the checkpoint chosen here:

    =============  ==================================================================
    0 - 9,999      kite-train's training episodes (``--seed`` and its env seeds)
    10,000 +       kite-train's periodic evaluations (``EvalCallback``)
    20,000 +       ``kite-train --optimize``'s validation of each trial
    30,000 +       this selection (default, ``kite-train select``)
    50,000 +       the held-out evaluation in the full model (README, "Agents")
    70,000 +       the policy benchmark of the tests (tests/agents/test_policy_benchmark.py)
    =============  ==================================================================

    Returns what it writes to ``RUN_DIR/selection.json``: ``{"run", "validation_seeds": [first, last],
    "best_steps", "rows"}``, one row per policy flown (``checkpoint``: ``baseline`` or the steps, ``steps``,
    ``model``, and :func:`validate`'s numbers), the baseline first; the best is the checkpoint row of the highest
    mean return (:func:`best_row`). ``on_row(row)`` is called as each row is done. A folder that is not a run, no
    checkpoint with its normalisation, or ``episodes`` / ``every`` below 1 raise :class:`UsageError` before anything
    is flown or written.
    """
    import dataclasses
    import json

    run = Path(run_dir)
    if episodes < 1 or every < 1:
        raise UsageError("--episodes and --every must be at least 1")
    cfg_path = run / "config.yml"
    if not cfg_path.is_file():
        raise UsageError(f"'{run}' is not a kite-train run folder ({cfg_path} missing)")
    ckpts = [c for c in run_checkpoints(run) if c[0] >= min_steps][::-1][::every][::-1]
    if not ckpts:
        raise UsageError(f"no checkpoints with their normalisation in '{run / 'checkpoints'}'")

    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.policies import load_model_agent, make_agent

    try:  # a run recorded before keys were retired flies on where they held the value every model has now
        cfg = config_from_dict(without_retired(yaml.safe_load(cfg_path.read_text()) or {}))
    except ConfigError as exc:
        raise UsageError(f"'{cfg_path}': {exc}") from None
    # the run's environment as it trained: its randomised draws, its start rule, its episode length
    env_cfg = dataclasses.replace(cfg.env, randomize=True)
    if duration is not None:
        env_cfg = dataclasses.replace(env_cfg, max_episode_s=duration)
    cfg = dataclasses.replace(cfg, env=env_cfg)
    env = KiteFigureEightEnv(config=cfg)
    seeds = range(seed, seed + episodes)
    rows = [{"checkpoint": "baseline", "steps": None, **validate(env, make_agent("baseline", env), seeds)}]
    if on_row is not None:
        on_row(rows[-1])
    for n, zp, vn in ckpts:
        agent = load_model_agent(zp, env, vecnormalize=vn)
        rows.append({"checkpoint": str(n), "steps": n, "model": f"checkpoints/{zp.name}",
                     **validate(env, agent, seeds)})
        if on_row is not None:
            on_row(rows[-1])
    env.close()
    best = max(rows[1:], key=lambda r: r["mean_return"])
    result = {"run": run.name, "validation_seeds": [seed, seed + episodes - 1], "best_steps": best["steps"],
              "rows": rows}
    (run / "selection.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def best_row(selection: dict) -> dict:
    """The row of the chosen checkpoint of a :func:`select_checkpoint` result (``selection.json``)."""
    return next(r for r in selection["rows"] if r["steps"] is not None and r["steps"] == selection["best_steps"])


def ship(run_dir: str | Path, dest: str | Path, force: bool = False) -> Path:
    """Copy the checkpoint chosen by :func:`select_checkpoint` (``RUN_DIR/selection.json``) into ``dest`` as
    ``model.zip`` + ``vecnormalize.pkl`` with the run's :data:`SHIPPED_FILES` (the model it was trained on, its config,
    arguments, command line and the selection): what ``kite-eval --policy NAME`` loads from ``agents/models/NAME``.
    The folder is assembled beside ``dest`` and renamed into place; an existing ``dest`` is replaced only with
    ``force`` (else :class:`UsageError`, nothing written)."""
    import json
    import shutil

    run, dest = Path(run_dir), Path(dest)
    if dest.exists() and not force:
        raise UsageError(f"'{dest}' exists (use --force to replace it)")
    sel = run / "selection.json"
    if not sel.is_file():
        raise UsageError(f"'{sel}' missing: choose a checkpoint first (kite-train select)")
    best = best_row(json.loads(sel.read_text()))
    tmp = dest.with_name(dest.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    ckpt = run / best["model"]
    shutil.copy(ckpt, tmp / "model.zip")
    shutil.copy(checkpoint_vecnormalize(ckpt.parent, best["steps"]), tmp / "vecnormalize.pkl")
    for name in SHIPPED_FILES:
        if (run / name).is_file():
            shutil.copy(run / name, tmp / name)
    shutil.rmtree(dest, ignore_errors=True)
    tmp.rename(dest)
    return dest


# --------------------------------------------------------------------------------------------- learning curves
def read_monitor(path: str | Path) -> tuple:
    """Episode returns of a (Vec)Monitor file and the training steps at which each episode ended (cumulative
    episode lengths over all envs), as two arrays."""
    import numpy as np

    data = np.genfromtxt(path, delimiter=",", skip_header=2, usecols=(0, 1), ndmin=2)
    if data.size == 0:
        return np.zeros(0), np.zeros(0)
    return data[:, 0], np.cumsum(data[:, 1])


def plot_learning_curves(runs, out_png: str | Path) -> list[str]:
    """Three panels for the ``kite-train`` run folders ``runs``: the evaluation returns against training steps (mean
    and std over the evaluation episodes, ``RUN/eval/evaluations.npz``), the training episode returns
    (``RUN/monitor.csv``, with their moving average) and, where ``kite-train select`` ran, the checkpoints' validation
    returns with the baseline's on the same episodes (``RUN/selection.json``); written to ``out_png``. Returns the
    runs that had none of these files."""
    import json

    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_e, ax_t, ax_v) = plt.subplots(1, 3, figsize=(16, 4), constrained_layout=True)
    missing = []
    for k, run in enumerate(Path(r) for r in runs):
        color = f"C{k % 10}"
        found = False
        ev = run / "eval" / "evaluations.npz"
        if ev.is_file():
            d = np.load(ev)
            steps, res = d["timesteps"], np.asarray(d["results"], dtype=float).reshape(len(d["timesteps"]), -1)
            mean, std = res.mean(axis=1), res.std(axis=1)
            ax_e.plot(steps, mean, "o-", color=color, label=run.name)
            ax_e.fill_between(steps, mean - std, mean + std, color=color, alpha=0.2)
            found = True
        mon = run / "monitor.csv"
        if mon.is_file():
            ret, steps = read_monitor(mon)
            if ret.size:
                n = max(1, ret.size // 20)
                ax_t.plot(steps, ret, ".", color=color, alpha=0.15, ms=2)
                ax_t.plot(steps[n - 1:], np.convolve(ret, np.ones(n) / n, mode="valid"), color=color,
                          label=f"{run.name} (mean of {n})")
            found = True
        sel = run / "selection.json"
        if sel.is_file():
            d = json.loads(sel.read_text())
            rows = [r for r in d["rows"] if r.get("steps") is not None]
            base = [r for r in d["rows"] if r.get("checkpoint") == "baseline"]
            lo, hi = d["validation_seeds"]
            ax_v.plot([r["steps"] for r in rows], [r["mean_return"] for r in rows], "o-", color=color,
                      label=f"{run.name} (seeds {lo}-{hi}); best {d['best_steps']:,}")
            if base:
                ax_v.axhline(base[0]["mean_return"], color=color, ls="--", lw=1,
                             label=f"baseline on {run.name}'s seeds")
            found = True
        if not found:
            missing.append(str(run))
    ax_e.set(xlabel="training steps", ylabel="episode return", title="evaluation (held-out seeds, deterministic)")
    ax_t.set(xlabel="training steps (cumulative episode lengths)", ylabel="episode return",
             title="training episodes (monitor.csv)")
    ax_v.set(xlabel="training steps", ylabel="mean episode return", title="checkpoint validation (kite-train select)")
    for ax in (ax_e, ax_t, ax_v):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=120)
    plt.close(fig)
    return missing
