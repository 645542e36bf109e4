"""Policies for ``kite-eval``: every one has Stable-Baselines3's ``predict(obs, state, episode_start,
deterministic) -> (action, state)`` so that the baseline, simple references and trained agents go through one
evaluation path (:func:`kite_env.flight.run_episode`).

Policy specifications (``kite-eval --policy``):

=========================  ==========================================================================================
``baseline``               the paper's steering controller (:class:`kite_env.policies.baseline.BaselineAgent`)
``random``                 uniform random actions in [-1, 1] (seeded: same seed, same actions)
``constant:<value>``       the same normalised action ``value`` in [-1, 1] at every step (``constant:0``: dl* = 0)
``ppo``, ``sac``           the shipped trained model of that name: ``agents/models/<name>/model.zip`` (with the
                           ``vecnormalize.pkl`` and the ``config.yml`` of its ``kite-train`` run next to it; see
                           ``agents/models/README.md``)
``<path>/model.zip``       a PPO or SAC model saved by ``kite-train`` (or SB3); the ``vecnormalize.pkl`` next to it,
                           if any, normalises the observations as in training
=========================  ==========================================================================================
"""

from __future__ import annotations

import json
import pickle
import zipfile
from pathlib import Path

import numpy as np

#: folder of the shipped trained models, one sub-folder per name (``<name>/model.zip``): the data folder
#: ``agents/models`` of the top-level ``agents`` package, found by its path (the library imports no ``agents``)
MODELS_DIR = Path(__file__).resolve().parents[2] / "agents" / "models"
#: names of the shipped models (``kite-eval --policy ppo``)
SHIPPED = ("ppo", "sac")


class PolicyError(ValueError):
    """A policy specification or model file that cannot be used (the message names the problem)."""


def shipped_model(name: str) -> Path:
    """Path of the shipped model ``name`` (one of :data:`SHIPPED`), whether or not it is there."""
    return MODELS_DIR / name / "model.zip"


def model_path(spec: str) -> Path | None:
    """The model file a policy specification names (a shipped name or a ``.zip`` path), None for the others."""
    if spec in SHIPPED:
        return shipped_model(spec)
    if spec.endswith(".zip"):
        return Path(spec)
    return None


class RandomAgent:
    """Uniformly random actions in [-1, 1], from its own seeded generator; :func:`kite_env.flight.run_episode`
    reseeds it with the episode's seed (:meth:`seed_episode`), so an episode's actions do not depend on the episodes
    flown before it (``kite-eval --episodes`` and ``kite-eval end-reasons``, each episode in a fresh env, agree)."""

    def __init__(self, seed: int = 0):
        self.rng = np.random.default_rng(seed)

    def seed_episode(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        obs = np.asarray(observation)
        shape = (1,) if obs.ndim == 1 else (obs.shape[0], 1)
        return self.rng.uniform(-1.0, 1.0, size=shape).astype(np.float32), None


class ConstantAgent:
    """The same normalised action at every step."""

    def __init__(self, value: float):
        if not (np.isfinite(value) and -1.0 <= value <= 1.0):
            raise PolicyError(f"constant policy value must be in [-1, 1] (a normalised action), got {value!r}")
        self.value = float(value)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        obs = np.asarray(observation)
        shape = (1,) if obs.ndim == 1 else (obs.shape[0], 1)
        return np.full(shape, self.value, dtype=np.float32), None


class ModelAgent:
    """A saved SB3 model (PPO or SAC) with the observation normalisation it was trained with; an agent trained to
    decide every ``action_hold``-th control step (:mod:`kite_env.envs.hold`) decides at the first step of an
    episode and every ``action_hold`` steps after it, and repeats its last action in between."""

    def __init__(self, model, obs_norm=None, action_hold: int = 1):
        self.model = model
        self.obs_norm = obs_norm
        self.action_hold = int(action_hold)
        self._held: np.ndarray | None = None
        self._age: np.ndarray | None = None

    def _decide(self, observation, state, episode_start, deterministic):
        obs = np.asarray(observation, dtype=np.float32)
        if self.obs_norm is not None:
            obs = self.obs_norm.normalize_obs(obs)
        return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        if self.action_hold == 1:
            return self._decide(observation, state, episode_start, deterministic)
        obs = np.asarray(observation)
        n = 1 if obs.ndim == 1 else obs.shape[0]
        if self._age is None or self._age.shape[0] != n:  # the first call: every row starts
            self._age, self._held = np.zeros(n, dtype=np.int64), None
        elif episode_start is not None:
            self._age[np.asarray(episode_start, dtype=bool).reshape(-1)] = 0
        due = self._age % self.action_hold == 0
        if self._held is not None and not due.any():  # no row decides: the network is not evaluated
            self._age += 1
            return self._held.copy(), state
        action, state = self._decide(observation, state, episode_start, deterministic)
        action = np.array(action)
        if self._held is not None and not due.all():  # the rows not due repeat their action
            rows = action.reshape(n, -1)
            rows[~due] = self._held.reshape(n, -1)[~due]
        self._held = action.copy()
        self._age += 1
        return action, state


def model_algorithm(path: Path) -> str:
    """``'ppo'`` or ``'sac'`` for an SB3 model zip (from the saved attributes), or :class:`PolicyError`."""
    try:
        with zipfile.ZipFile(path) as zf:
            data = json.loads(zf.read("data").decode())
    except (zipfile.BadZipFile, KeyError, UnicodeDecodeError, json.JSONDecodeError, OSError) as exc:
        raise PolicyError(f"model file '{path}' is not a Stable-Baselines3 model zip ({exc})") from None
    if "clip_range" in data or "n_epochs" in data:
        return "ppo"
    if "ent_coef" in data and "target_entropy" in data:
        return "sac"
    raise PolicyError(f"model file '{path}': neither a PPO nor a SAC model")


def _run_file(path: Path, name: str) -> Path | None:
    """The file ``name`` of the ``kite-train`` run folder of the model ``path``: next to it, or one folder up for
    ``checkpoints/`` and ``eval/``; None without one."""
    for folder in (path.parent, path.parent.parent):
        if (folder / name).is_file():
            return folder / name
    return None


def model_record(path: Path) -> dict | None:
    """The model an agent was trained on (:func:`kite_env.config.fingerprint`): the ``model.json`` of its
    ``kite-train`` run folder (:func:`_run_file`)."""
    f = _run_file(path, "model.json")
    if f is None:
        return None
    try:
        return json.loads(f.read_text())
    except json.JSONDecodeError as exc:
        raise PolicyError(f"'{f}' is not valid JSON: {exc}") from None


def model_action_hold(path: Path) -> int:
    """The control steps an agent holds each action (``action_hold`` of its recipe, :mod:`kite_env.envs.hold`): from
    the ``args.yml`` of its ``kite-train`` run folder (:func:`_run_file`), 1 without one."""
    import yaml

    from kite_env.envs.hold import check_action_hold

    f = _run_file(path, "args.yml")
    if f is None:
        return 1
    try:
        args = yaml.safe_load(f.read_text()) or {}
    except yaml.YAMLError as exc:
        raise PolicyError(f"'{f}' is not valid YAML: {exc}") from None
    try:
        return check_action_hold((args.get("hyperparameters") or {}).get("action_hold", 1))
    except ValueError as exc:
        raise PolicyError(f"'{f}': {exc}") from None


def load_model_agent(path: str | Path, env, vecnormalize: str | Path | None = None) -> ModelAgent:
    """Load ``path`` (PPO or SAC zip) for ``env``; the observation normalisation ``vecnormalize`` (default: a
    ``vecnormalize.pkl`` next to the model, if there is one) is applied to observations."""
    path = Path(path)
    if not path.is_file():
        raise PolicyError(f"model file '{path}' does not exist")
    algo = model_algorithm(path)
    from stable_baselines3 import PPO, SAC

    classes: dict[str, type[PPO] | type[SAC]] = {"ppo": PPO, "sac": SAC}
    cls = classes[algo]
    try:
        model = cls.load(path, device="cpu")
    except Exception as exc:  # SB3 raises many kinds on a damaged file
        raise PolicyError(f"model file '{path}' could not be loaded as {algo.upper()}: {exc}") from None
    record = model_record(path)
    try:
        from kite_env.config import ModelMismatch, check_model

        check_model(record, env.cfg, f"agent '{path}'")
    except ModelMismatch as exc:
        raise PolicyError(str(exc)) from None
    if model.observation_space.shape != env.observation_space.shape:
        raise PolicyError(f"model '{path}' expects observations of shape {model.observation_space.shape}, the "
                          f"environment gives {env.observation_space.shape} (check env.observation in the config)")
    norm = None
    vn = path.with_name("vecnormalize.pkl") if vecnormalize is None else Path(vecnormalize)
    if vecnormalize is not None and not vn.is_file():
        raise PolicyError(f"normalisation file '{vn}' does not exist")
    if vn.is_file():
        try:
            norm = pickle.loads(vn.read_bytes())
        except Exception as exc:
            raise PolicyError(f"normalisation file '{vn}' could not be read: {exc}") from None
        if not hasattr(norm, "normalize_obs"):
            raise PolicyError(f"normalisation file '{vn}' is not a VecNormalize object")
        norm.training = False
    return ModelAgent(model, norm, model_action_hold(path))


def make_agent(spec: str, env, seed: int = 0):
    """The policy named by ``spec`` (module docstring) for ``env`` (unwrapped :class:`KiteFigureEightEnv`)."""
    if spec == "baseline":
        from kite_env.policies.baseline import BaselineAgent

        try:
            return BaselineAgent(env.cfg, env.path)
        except ValueError as exc:
            raise PolicyError(str(exc)) from None
    if spec == "random":
        return RandomAgent(seed)
    if spec.startswith("constant:"):
        raw = spec.split(":", 1)[1]
        try:
            value = float(raw)
        except ValueError:
            raise PolicyError(f"constant policy needs a number, got {raw!r} (e.g. constant:0)") from None
        return ConstantAgent(value)
    if spec in SHIPPED:
        path = shipped_model(spec)
        if not path.is_file():
            raise PolicyError(f"policy {spec!r}: no shipped model, '{path}' does not exist (train one with kite-train "
                              f"and copy its run folder there, or give the path of a model.zip)")
        return load_model_agent(path, env)
    if spec.endswith(".zip") or Path(spec).exists():
        return load_model_agent(spec, env)
    raise PolicyError(f"unknown policy {spec!r} (valid: baseline, random, constant:<value in [-1, 1]>, "
                      f"{', '.join(SHIPPED)}, <path to model.zip>)")


def policy_label(spec: str) -> str:
    """A short name for tables and folder names: ``baseline``, ``random``, ``constant_0``, ``ppo`` / ``sac`` (the
    shipped models), ``ppo_<folder>`` (a model file)."""
    if spec in ("baseline", "random", *SHIPPED):
        return spec
    if spec.startswith("constant:"):
        return "constant_" + spec.split(":", 1)[1].replace("-", "m").replace(".", "p")
    p = Path(spec)
    try:
        algo = model_algorithm(p)
    except PolicyError:
        algo = "model"
    return f"{algo}_{p.resolve().parent.name}"


__all__ = ["MODELS_DIR", "SHIPPED", "ConstantAgent", "ModelAgent", "PolicyError", "RandomAgent", "load_model_agent",
           "make_agent", "model_action_hold", "model_algorithm", "model_path", "policy_label", "shipped_model"]
