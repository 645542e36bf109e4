"""Training setup of ``kite-train`` (Stable-Baselines3): the recipes (shipped in ``agents/recipes``, read as data),
their hyperparameters and config layers, the vectorised training and evaluation envs (with the report of a
``subproc`` worker's numerical failure) and the checkpoints of a run folder. :mod:`kite_env.cli.train` (one run) and
:mod:`kite_env.cli.optimize` (a hyperparameter study) both build their runs from here.
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from kite_env.config import config_from_dict, load_config, parse_overrides
from kite_env.envs import ENV_ID, FAST_ENV_ID

ALGOS = ("ppo", "sac")
VEC_ENVS = ("batched", "subproc", "dummy")
#: recipe keys that are not constructor arguments of the algorithm
_META_KEYS = {"policy", "normalize", "checkpoint_freq", "eval_freq", "eval_episodes", "n_envs", "env", "vec_env"}
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


def _make_env(cfg, report_dir: Path | None = None):
    """A thunk making the env of ``cfg``; with ``report_dir`` (``subproc`` workers) the env writes a
    :class:`~kite_env.dynamics.simulator.NumericalFailure` that ends its worker into that folder first, so that the
    main process can report it as in one process (:func:`_worker_failure`)."""

    def thunk():
        from kite_env.envs.figure_eight import KiteFigureEightEnv

        env = KiteFigureEightEnv(config=cfg)
        return env if report_dir is None else _reporting(env, report_dir)

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
             monitor_file: Path | None = None, append: bool = False, report_dir: Path | None = None):
    """``n_envs`` envs of ``cfg`` as a ``kind`` VecEnv (``VEC_ENVS``) seeded ``seed + i``, in ``VecMonitor`` (writing
    ``monitor_file``, appended to with ``append``) and, with ``normalize``, ``VecNormalize``; ``subproc`` workers
    report a NumericalFailure into ``report_dir`` (:func:`_make_env`)."""
    from stable_baselines3.common.monitor import ResultsWriter
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor, VecNormalize

    if kind == "batched":
        from kite_env.envs.vector import KiteFigureEightVectorEnv, SB3VecEnv

        try:
            venv = SB3VecEnv(KiteFigureEightVectorEnv(n_envs, config=cfg, fidelity=None))
        except ValueError as exc:  # not the surrogate fidelity
            raise UsageError(f"--vec-env batched: {exc}") from None
    else:
        if kind == "subproc":
            venv = SubprocVecEnv([_make_env(cfg, report_dir) for _ in range(n_envs)])
        else:
            venv = DummyVecEnv([_make_env(cfg) for _ in range(n_envs)])
    venv.seed(seed)  # env i: reset(seed=seed + i) at the first reset
    if monitor_file is not None and append and monitor_file.is_file():
        venv = VecMonitor(venv)  # continue the run's monitor file (the column t restarts at 0 in a resumed run)
        venv.results_writer = ResultsWriter(str(monitor_file), override_existing=False)
    else:
        venv = VecMonitor(venv, filename=None if monitor_file is None else str(monitor_file))
    if normalize:
        venv = VecNormalize(venv, gamma=gamma, training=training, norm_reward=training)
    return venv


def _vec_env_kind(requested: str | None, fidelity: str, n_envs: int) -> str:
    if requested is None:
        if fidelity == "surrogate" and n_envs > 1:
            return "batched"
        return "subproc" if n_envs > 1 else "dummy"
    if requested == "batched" and fidelity != "surrogate":
        raise UsageError(f"vec_env 'batched' needs sim.fidelity surrogate, got {fidelity!r} (use subproc or dummy)")
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
