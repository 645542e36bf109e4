"""``KiteFigureEightFast-v1`` batched: ``num_envs`` kites of the fast fidelity advanced together in one process.

:class:`KiteFigureEightVectorEnv` is a :class:`gymnasium.vector.VectorEnv` whose kites live in ONE
:class:`kite_env.dynamics.fast.SurrogateKites`: every physics step is one compiled call over all kites, the
observation one call of :func:`kite_env.envs.observe.observe_kites`, the actuator, checks and rewards array
operations. Per kite it is the single environment :class:`~kite_env.envs.figure_eight.KiteFigureEightEnv` with
``fidelity="surrogate"``:

* ``reset`` is the single env's ``reset``: one ``KiteFigureEightEnv`` per kite (``self.envs``) draws the start from
  its own ``np_random``, places the kite and observes it; the placed kite is then copied into the batch. Seeds
  follow :class:`gymnasium.vector.SyncVectorEnv` (``seed`` int -> ``seed + i`` for kite ``i``; a list; ``None``).
* ``step``: the single env's step in array form: :class:`~kite_env.control.LineActuator` (Eq. 16-19), then
  ``n_physics`` physics steps in which a kite that ends (ground, slack tether, non-finite state, outside the
  surrogate envelope) stops being stepped; the observation of a kite whose physics step failed is that of its
  last good state (as the single env, whose record is not replaced by a failed step); rewards, termination,
  truncation and ``info`` as there.
* Autoreset: ``AutoresetMode.NEXT_STEP`` (SyncVectorEnv's default): the step after a kite's episode ended resets it
  (its action is ignored, reward 0, not terminated/truncated, ``info`` the reset info). ``reset(options=
  {"reset_mask": mask})`` resets only the masked kites (and clears their pending autoreset).

With the same seeds and actions the batch gives the trajectories of ``SyncVectorEnv`` over single
``KiteFigureEightFast-v1`` envs (``tests/envs/test_vector.py``). ``info`` is a dict of arrays with ``_key`` masks
(Gymnasium's vector convention). Not supported in the batch: rendering and the flight recorder.

:class:`SB3VecEnv` adapts the batch to stable-baselines3's ``VecEnv`` (reset at episode end in the same step,
``terminal_observation`` in ``infos``). :func:`make_vector_env` is the ``vector_entry_point`` of both env ids.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from kite_env.config import Config
from kite_env.control import actuate, force_integral, force_ratio_error
from kite_env.dynamics.fast import NON_FINITE, OK, SurrogateKites
from kite_env.envs.fast_step import kite_omega_rows
from kite_env.envs.figure_eight import (
    GROUND_ELEVATION_RAD,
    INFO_FEATURES,
    KiteFigureEightEnv,
    resolve_config,
    reward_terms,
    slack_tether_ends,
)
from kite_env.envs.observe import FEATURES, N_PARTS

#: per-kite rows of SurrogateKites copied from a single env's simulator after its reset
_KITE_ROWS = ("r", "v", "t", "rest", "pair_damping", "wind_f", "wind_i", "wavevec_t", "phase0", "omega_m", "amp",
              "X", "Y", "wind", "turb", "R", "tension", "length", "tether_force", "tether_length", "reel_speed",
              "status", "Z")
#: rows an observation needs (kept from before a physics step that fails)
_OBS_ROWS = ("r", "v", "t", "R", "X", "tension", "length", "tether_force")
_REASONS = (None, "ground", "slack tether", "non-finite particle state", "outside surrogate envelope",
            "non-finite state")
_GROUND, _SLACK, _NON_FINITE, _OUTSIDE, _NON_FINITE_OBS = 1, 2, 3, 4, 5


class KiteFigureEightVectorEnv(VectorEnv):
    """``num_envs`` kites of ``KiteFigureEight-v1`` in the fast fidelity, stepped as one batch (module docstring).

    Parameters
    ----------
    num_envs : int
    config, overrides, fidelity : as :class:`KiteFigureEightEnv` (the fidelity must resolve to ``"surrogate"``)
    wing : AeroelasticWing, optional, shared by all kites. Without it each kite builds its own wing as the single
        env does when its start is the FE solve (that start depends slightly on what the wing solved before, so a
        shared wing would change the starts), and all kites share the first one when the start is a table lookup.
    render_mode : must be None (no rendering in the batch)
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, config: Config | dict | str | None = None, overrides=(),
                 render_mode: str | None = None, wing=None, fidelity: str | None = "surrogate"):
        if int(num_envs) < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        if render_mode is not None:
            raise ValueError("the batched environment does not render (render_mode must be None)")
        cfg = resolve_config(config, overrides, fidelity)
        if cfg.sim.fidelity != "surrogate":
            raise ValueError(f"the batched environment needs sim.fidelity 'surrogate', got {cfg.sim.fidelity!r} "
                             "(use gymnasium.vector.SyncVectorEnv for the FE model)")
        n = self.num_envs = int(num_envs)
        self.cfg = cfg
        self.render_mode = None
        self.envs = [KiteFigureEightEnv(config=cfg, wing=wing) for _ in range(n)]
        e0 = self.envs[0]
        self.single_observation_space = e0.observation_space
        self.single_action_space = e0.action_space
        self.observation_space = batch_space(e0.observation_space, n)
        self.action_space = batch_space(e0.action_space, n)
        self.n_physics, self.control_dt, self.max_steps = e0.n_physics, e0.control_dt, e0.max_steps
        self._ctrl = e0.control_cfg
        self._observer = e0.observer
        self._low, self._high = e0.observation_space.low, e0.observation_space.high
        self._sin_ground = math.sin(GROUND_ELEVATION_RAD)  # ground contact: the KCU below 3 deg elevation
        self._slack_ends = slack_tether_ends(cfg)
        self.kites: SurrogateKites | None = None  # built at the first reset (from the first kite's simulator)
        self.steps = np.zeros(n, dtype=np.int64)
        self.last_action = np.zeros(n)
        self.s_hint = np.zeros(n)
        self.L_B0 = np.zeros(n)
        self.L_D0 = np.zeros(n)
        self.force_integral = np.zeros(n)
        self.L_B = np.zeros(n)
        self.L_D = np.zeros(n)
        self._autoreset = np.zeros(n, dtype=np.bool_)
        self._obs = np.zeros((n,) + e0.observation_space.shape, dtype=np.float32)
        self._parts = np.zeros((n, N_PARTS))
        self._feats = np.zeros((n, len(FEATURES)))
        self._snap: dict[str, np.ndarray] = {}

    # ------------------------------------------------------------------ reset
    def _adopt(self, i: int) -> None:
        """Copy kite ``i``'s freshly reset single env (simulator rows, actuator, hint) into the batch."""
        env = self.envs[i]
        if env.sim.start_mode == "table":  # the wing is geometry only: the kites not yet built share it
            for other in self.envs:
                other.share_wing(env.sim.wing)
        one = env.sim.kites
        if self.kites is None:
            self.kites = SurrogateKites(self.cfg, env.sim.surrogate, one.q_design, one.tip_lengths, self.num_envs)
            self._snap = {name: getattr(self.kites, name).copy() for name in _OBS_ROWS}
        for name in _KITE_ROWS:
            getattr(self.kites, name)[i] = getattr(one, name)[0]
        self.L_B0[i], self.L_D0[i] = env.actuator.L_B0, env.actuator.L_D0
        self.force_integral[i] = env.actuator.integral
        self.L_B[i], self.L_D[i] = env.L_B, env.L_D
        self.s_hint[i] = env.s_hint
        self.last_action[i] = env.last_action
        self.steps[i] = env.steps

    def _reset_one(self, i: int, seed=None, options=None):
        obs, info = self.envs[i].reset(seed=seed, options=options)
        self._adopt(i)
        self._obs[i] = obs
        return info

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        """Reset all kites (or those of ``options["reset_mask"]``); seeds as :class:`SyncVectorEnv`."""
        n = self.num_envs
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(f"seed list of length {len(seeds)} for num_envs={n}")
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is None:
            mask = np.ones(n, dtype=np.bool_)
        else:
            mask = np.asarray(mask)
            if mask.shape != (n,) or mask.dtype != np.bool_ or not mask.any():
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({n},) with a True value")
        infos: dict = {}
        for i in np.flatnonzero(mask):
            infos = self._add_info(infos, self._reset_one(int(i), seeds[i], options or None), int(i))
        self._autoreset[mask] = False
        return self._obs.copy(), infos

    # ------------------------------------------------------------------ step
    def step(self, actions):
        """One control step of every kite (autoreset of the kites whose episode ended at the last step)."""
        if self.kites is None:
            raise RuntimeError("call reset() before step()")
        n, cfg, ks = self.num_envs, self.cfg, self.kites
        a = np.asarray(actions, dtype=np.float64).reshape(n, -1)
        if a.shape[1] != 1:
            raise ValueError(f"actions must have shape ({n}, 1), got {np.shape(actions)}")
        a = a[:, 0].copy()
        auto = self._autoreset.copy()
        run = ~auto
        if not np.all(np.isfinite(a[run])):
            raise ValueError(f"actions must be finite, got {a[run]!r}")
        a = np.minimum(1.0, np.maximum(-1.0, a))
        reset_infos = {}
        for i in np.flatnonzero(auto):
            reset_infos[int(i)] = self._reset_one(int(i))
        # inner steering loops and force controller (LineActuator.rest_lengths in array form), Eq. (16)-(19)
        c = self._ctrl
        dls = np.clip(a * cfg.control.delta_l_max_m, -c.delta_l_max_m, c.delta_l_max_m)
        dl = ks.length[:, 1] - ks.length[:, 3]
        T = ks.tension
        _, err = force_ratio_error(T, c.mu_target)  # Eq. (18)
        self.force_integral = np.where(run, force_integral(self.force_integral, err, c), self.force_integral)
        L3 = -c.k3_m * err - c.k3i_per_s * self.force_integral  # Eq. (19) + integral (control.py)
        e = dls - dl
        L_B, L_D = actuate(self.L_B0 + c.k2 * e + L3, self.L_D0 - c.k2 * e + L3, self.L_B, self.L_D, c)  # Eq. 16-17
        L_B, L_D = np.where(run, L_B, self.L_B), np.where(run, L_D, self.L_D)
        if not (np.all(L_B[run] > 0) and np.all(L_D[run] > 0) and np.all(np.isfinite(L_B[run]))
                and np.all(np.isfinite(L_D[run]))):
            raise ValueError(f"steering-line rest lengths must be positive and finite, got {L_B}, {L_D}")
        self.L_B, self.L_D = L_B, L_D
        # physics steps; a kite that ends is not stepped any further
        code = np.zeros(n, dtype=np.int64)
        details: dict[int, str] = {}
        active = run.copy()
        snap = self._snap
        for _ in range(self.n_physics):
            for name in _OBS_ROWS:
                np.copyto(snap[name], getattr(ks, name))
            ks.step(L_B, L_D, active)
            bad = active & (ks.status != OK)
            if bad.any():
                for i in np.flatnonzero(bad):
                    if ks.status[i] == NON_FINITE:
                        code[i], details[int(i)] = _NON_FINITE, f"t = {ks.t[i]:.4f} s"
                    else:
                        code[i], details[int(i)] = _OUTSIDE, ", ".join(ks.outside(int(i)))
                    for name in _OBS_ROWS:  # the observation is that of the last good state
                        getattr(ks, name)[i] = snap[name][i]
                active &= ~bad
            # the single env's checks (KiteFigureEightEnv.step), with its sums: the KCU below 3 deg elevation of its own
            # distance (a slack rope is shorter than the tether), a slack tether only where it ends an episode
            r4 = ks.r[:, 4]
            ground = active & (r4[:, 2] < self._sin_ground * np.sqrt(r4[:, 0] * r4[:, 0] + r4[:, 1] * r4[:, 1]
                                                                      + r4[:, 2] * r4[:, 2]))
            slack = active & ~ground & (ks.tether_force < cfg.env.slack_tether_N) & self._slack_ends
            code[ground] = _GROUND
            code[slack] = _SLACK
            active &= ~(ground | slack)
            if not active.any():
                break
        self.steps[run] += 1
        # observation of the stepped kites
        parts, feats = self._parts, self._feats
        omega = np.empty((n, 3))
        kite_omega_rows(ks.R, ks.X, omega)  # the single env's omega, in the order of NumPy's product here
        v_kite = 0.5 * (ks.v[:, 0] + ks.v[:, 2])
        prev_action = self.last_action.copy()
        self.last_action[run] = a[run]  # the observation holds the action just applied
        self._observer(run, ks.r[:, 4], ks.v[:, 4], ks.R, omega, v_kite, ks.tension, ks.length, ks.tether_force,
                       ks.t, self.s_hint, self.last_action, parts, feats)
        obs = parts[:, self._observer.index].astype(np.float32)
        code[run & (code == 0) & ~np.all(np.isfinite(obs), axis=1)] = _NON_FINITE_OBS
        failed = code != 0
        terms = reward_terms(cfg.env, feats[:, -1], feats[:, 4], a, prev_action, failed)
        reward = terms["reward_tracking"] + terms["reward_traction"] + terms["reward_action"] + terms["reward_crash"]
        reward[auto] = 0.0
        terminated = run & failed
        truncated = run & ~terminated & (self.steps >= self.max_steps)
        obs = np.clip(np.nan_to_num(obs, nan=0.0, posinf=0.0, neginf=0.0), self._low, self._high)
        self._obs[run] = obs[run]
        self._autoreset = terminated | truncated
        infos = self._step_infos(run, auto, terms, feats, dls, code, details, truncated, reset_infos)
        return self._obs.copy(), reward, terminated, truncated, infos

    def _step_infos(self, run, auto, terms, feats, dls, code, details, truncated, reset_infos) -> dict:
        """``info`` of a step as arrays with ``_key`` masks: the single env's step info for the stepped kites, its
        reset info for the kites reset in this step."""
        infos: dict = {}

        def put(key, values, mask):
            infos[key] = values
            infos["_" + key] = mask

        for j, k in enumerate(INFO_FEATURES):  # every kite has them (stepped or reset)
            put(k, np.where(run, feats[:, j], 0.0), np.ones(self.num_envs, dtype=np.bool_))
        if run.any():  # the keys of a step
            for k, v in terms.items():
                put(k, np.where(run, v, 0.0), run)
            put("delta_l_star_m", np.where(run, dls, 0.0), run)
            put("L_B_m", np.where(run, self.L_B, 0.0), run)
            put("L_D_m", np.where(run, self.L_D, 0.0), run)
            reason = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(code):
                reason[i] = _REASONS[code[i]]
            reason[truncated] = "time limit"
            put("termination_reason", reason, run.copy())
            fid = np.full(self.num_envs, None, dtype=object)
            fid[run] = "surrogate"
            put("fidelity", fid, run.copy())
            # the surrogate wing has no failing solve to split (FlightSimulator.step); the key as in the single env
            put("substepped_steps", np.zeros(self.num_envs, dtype=np.int64), run.copy())
            if details:
                det = np.full(self.num_envs, None, dtype=object)
                mask = np.zeros(self.num_envs, dtype=np.bool_)
                for i, d in details.items():
                    if d:
                        det[i], mask[i] = d, True
                if mask.any():
                    put("termination_detail", det, mask)
        for i, info in reset_infos.items():
            for k in INFO_FEATURES:
                infos[k][i] = info[k]
            infos = self._add_info(infos, {k: v for k, v in info.items() if k not in INFO_FEATURES}, i)
        return infos

    def close_extras(self, **kwargs) -> None:
        for env in self.envs:
            env.close()


def make_vector_env(num_envs: int = 1, config=None, overrides=(), render_mode=None, wing=None, fidelity=None,
                    **kwargs):
    """``vector_entry_point`` of ``KiteFigureEight-v1`` and ``KiteFigureEightFast-v1``: the batched
    :class:`KiteFigureEightVectorEnv` for the surrogate fidelity, a :class:`gymnasium.vector.SyncVectorEnv` of
    single envs for the FE model (or with rendering)."""
    kwargs.pop("max_episode_steps", None)  # the env truncates itself (env.max_episode_s)
    if kwargs:
        raise TypeError(f"unexpected arguments {sorted(kwargs)}")
    cfg = resolve_config(config, overrides, fidelity)
    if cfg.sim.fidelity == "surrogate" and render_mode is None:
        return KiteFigureEightVectorEnv(num_envs, config=cfg, wing=wing, fidelity=None)
    return gym.vector.SyncVectorEnv([lambda: KiteFigureEightEnv(config=cfg, render_mode=render_mode, wing=wing)
                                     for _ in range(num_envs)])


# ---------------------------------------------------------------------------------------------------- SB3
_SB3_CLASS = None


def __getattr__(name: str):
    """``SB3VecEnv`` is built on first access (importing stable-baselines3 imports torch, ~2 s)."""
    global _SB3_CLASS
    if name == "SB3VecEnv":
        if _SB3_CLASS is None:
            _SB3_CLASS = _sb3_vec_env_class()
        return _SB3_CLASS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _sb3_vec_env_class():
    from stable_baselines3.common.vec_env import VecEnv

    class SB3VecEnv(VecEnv):
        """stable-baselines3 ``VecEnv`` over :class:`KiteFigureEightVectorEnv` (one process, all kites in one batch).

        SB3's protocol: ``step_wait`` returns ``(obs, rewards, dones, infos)`` with the finished kites already reset
        (their last observation in ``infos[i]["terminal_observation"]``, ``"TimeLimit.truncated"`` and
        ``"termination_reason"`` there too); ``infos`` are otherwise empty unless ``info_keys`` names keys of the batch
        ``info`` to copy (per-kite dicts cost ~1 us per key and kite). Seeds and options of :meth:`seed` /
        :meth:`set_options` apply at the next :meth:`reset` (one options dict for all kites).

        Parameters
        ----------
        venv : KiteFigureEightVectorEnv, or the arguments of one (``num_envs`` and keyword arguments)
        info_keys : tuple of str
        """

        def __init__(self, venv: KiteFigureEightVectorEnv | None = None, info_keys: tuple[str, ...] = (), **kwargs):
            self.venv = venv if venv is not None else KiteFigureEightVectorEnv(**kwargs)
            self.info_keys = tuple(info_keys)
            self._actions = None
            super().__init__(self.venv.num_envs, self.venv.single_observation_space, self.venv.single_action_space)

        def reset(self):
            seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
            opts = [o for o in self._options if o]
            obs, info = self.venv.reset(seed=seeds, options=dict(opts[0]) if opts else None)
            self.reset_infos = [{} for _ in range(self.num_envs)]
            self._reset_seeds()
            self._reset_options()
            return obs

        def step_async(self, actions: np.ndarray) -> None:
            self._actions = actions

        def step_wait(self):
            obs, reward, terminated, truncated, info = self.venv.step(self._actions)
            dones = terminated | truncated
            infos = [{k: info[k][i] for k in self.info_keys if info.get("_" + k, np.zeros(1, bool))[i]}
                     for i in range(self.num_envs)] if self.info_keys else [{} for _ in range(self.num_envs)]
            if dones.any():
                for i in np.flatnonzero(dones):
                    infos[i]["terminal_observation"] = obs[i]
                    infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                    infos[i]["termination_reason"] = info["termination_reason"][i]
                obs_new, _ = self.venv.reset(options={"reset_mask": dones})
                obs[dones] = obs_new[dones]
            return obs, reward.astype(np.float32), dones, infos

        def close(self) -> None:
            self.venv.close()

        def _targets(self, indices):
            return [self.venv.envs[i] for i in self._get_indices(indices)]

        def get_attr(self, attr_name: str, indices=None) -> list:
            """Attribute of the per-kite single envs (``render_mode`` etc.; their physics state is not the batch's)."""
            if attr_name == "render_mode":
                return [None for _ in self._get_indices(indices)]
            return [getattr(env, attr_name) for env in self._targets(indices)]

        def set_attr(self, attr_name: str, value, indices=None) -> None:
            for env in self._targets(indices):
                setattr(env, attr_name, value)

        def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list:
            return [getattr(env, method_name)(*method_args, **method_kwargs) for env in self._targets(indices)]

        def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
            return [False for _ in self._get_indices(indices)]

        def get_images(self):
            return [None for _ in range(self.num_envs)]

    SB3VecEnv.__module__ = __name__
    SB3VecEnv.__qualname__ = "SB3VecEnv"
    return SB3VecEnv
