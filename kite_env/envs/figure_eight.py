"""``KiteFigureEight-v1``: fly the aeroelastic kite along the figure-eight (Gymnasium environment).

The environment wraps the complete coupled model of :mod:`kite_env.dynamics.simulator` (static aeroelastic wing
solved at every time step inside the particle system of wing masses, bridle, KCU and tether). Nothing in the physics
modules imports gymnasium; this module is the only bridge.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from typing import TYPE_CHECKING

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from kite_env.config import OBSERVATION_TERMS, Config, ConfigError, config_from_dict, load_config, parse_overrides
from kite_env.control import POWER_LINES_MIN_N, LineActuator
from kite_env.dynamics.factory import make_simulator
from kite_env.dynamics.fast import SurrogateFlightSimulator
from kite_env.dynamics.simulator import FlightSimulator, NumericalFailure, SimulationError, StepRecord
from kite_env.envs import fast_step as fs
from kite_env.envs.observe import FEATURES, N_PARTS, Observer
from kite_env.trajectory import Lemniscate
from kite_env.wind import WindField

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: observation terms: (size, lower bound, upper bound) of each entry
_TERM_SPECS = {
    "position": (3, -1.0, 1.0),  # R_k, the KCU direction on the unit sphere (frame W)
    "heading": (2, -1.0, 1.0),  # sin psi, cos psi of the nose -x_k on the sphere
    "line_forces": (5, 0.0, 10.0),  # F_c of the lines A, B, C, D and the tether force, / force_scale_N
    "path": (5, -math.pi, math.pi),  # signed distance [rad], sin/cos(psi_t - psi), sin/cos of the path parameter s
    "rates": (4, -10.0, 10.0),  # angular velocity on the sphere (x_s, y_s) [rad/s], yaw rate [rad/s], speed / 25 m/s
    "actuator": (3, -5.0, 5.0),  # last action, actual (l_B - l_D) / dl_max, force ratio mu
}
#: an episode ends as crashed when the KCU comes closer to the ground than this elevation [rad]
GROUND_ELEVATION_RAD = math.radians(3.0)
_SIN_GROUND = math.sin(GROUND_ELEVATION_RAD)
V_SCALE_MPS = 25.0  # (literal 25.0 in kite_env.envs.observe._observe_kite)
#: the features of ``info`` (all of :data:`kite_env.envs.observe.FEATURES` but the last, ``tracking``)
INFO_FEATURES = FEATURES[:-1]


def slack_tether_ends(cfg) -> bool:
    """Whether a slack tether (force below ``env.slack_tether_N``) ends an episode: on the rod tether (Eq. 12-13,
    which would have to push) and with the quasi-static wing, whose tether is always the rod; the rope of the wing
    with inertia goes slack and flies on."""
    return cfg.dynamics.tether == "rod" or not cfg.structure.dynamic


def reward_terms(env, tracking, tether_N, a, last_a, failed):
    """Reward terms of one step (floats, or (n,) arrays for a batch; the same operations in both cases).

    ``env`` : EnvConfig; ``tracking`` exp(-(delta/scale)^2); ``tether_N`` [N]; ``a``, ``last_a`` this and the
    previous action; ``failed`` a physical failure (bool). Returns the dict of the four ``reward_*`` terms."""
    d = a - last_a
    if type(failed) is bool or np.ndim(failed) == 0:
        return {"reward_tracking": 0.0 if failed else env.w_tracking * tracking,
                "reward_traction": 0.0 if failed else env.w_traction * tether_N / env.traction_ref_N,
                "reward_action": -env.w_action_rate * (d * d),
                "reward_crash": -env.crash_penalty if failed else 0.0}
    return {"reward_tracking": np.where(failed, 0.0, env.w_tracking * tracking),
            "reward_traction": np.where(failed, 0.0, env.w_traction * tether_N / env.traction_ref_N),
            "reward_action": -env.w_action_rate * (d * d),
            "reward_crash": np.where(failed, -env.crash_penalty, 0.0)}


def observation_layout(terms: str | tuple[str, ...]) -> dict[str, slice]:
    """Slices of the observation vector for each term of ``env.observation`` (in its order)."""
    names = [t.strip() for t in terms.split(",") if t.strip()] if isinstance(terms, str) else list(terms)
    out, i = {}, 0
    for name in names:
        if name not in _TERM_SPECS:
            raise ValueError(f"unknown observation term {name!r} (valid: {', '.join(OBSERVATION_TERMS)})")
        n = _TERM_SPECS[name][0]
        out[name] = slice(i, i + n)
        i += n
    return out


def resolve_config(config: Config | dict | str | None = None, overrides=(), fidelity: str | None = None) -> Config:
    """The env's configuration from its ``config``, ``overrides`` and ``fidelity`` arguments (class docstring)."""
    if isinstance(config, Config):
        base = config
    elif isinstance(config, dict):
        base = config_from_dict(config)
    elif config is None or isinstance(config, (str, os.PathLike)):
        base = load_config(config)
    else:
        raise ConfigError(f"config must be a Config, a dict or a YAML path, got {type(config).__name__}")
    cfg = config_from_dict(parse_overrides(overrides), base)
    if fidelity is not None:
        cfg = config_from_dict({"sim": {"fidelity": fidelity}}, cfg)
    return cfg


class StartError(RuntimeError):
    """``reset()`` found no start: the wing did not converge at any drawn start (``env.reset_attempts``)."""


class KiteFigureEightEnv(gym.Env):
    """Steer a flexible leading-edge-inflatable kite along a figure-eight with the steering lines.

    ## Description

    The full aeroelastic model of Bosch et al.: a nonlinear FE wing (shell canopy, inflated-beam tubes) with Breukels'
    section aerodynamics, integrated in time with its own and its added mass (the wing with inertia; the paper's
    quasi-static wing with ``structure.dynamic=false``), coupled at the bridle points to a particle model of the kite
    control unit, the bridle lines and an 80 m tether held by a ground station that reels out above 15 kN. The
    agent sets the desired steering-line length difference; the paper's inner steering-line loops (Eq. 16-17) and,
    by default, its force controller (Eq. 18-19) turn it into rest lengths of the steering lines. The task is to fly
    the Bernoulli lemniscate on the unit sphere (``trajectory`` section of the config) with a high traction force.

    ## Action Space

    ``Box(-1, 1, (1,), float32)``: desired ``dl* = l_B - l_D`` divided by ``control.delta_l_max_m`` (1.5 m by
    default). ``dl* < 0`` pulls the right steering line and turns the kite to its right. The action is held for
    ``control.control_dt_s`` (0.02 s: four physics steps of ``dynamics.dt_s`` in the full model, two of
    ``sim.surrogate_dt_s`` in the fast fidelity); the steering actuator follows it at
    up to ``control.line_speed_max_mps`` (2 m/s). An action is one finite number (shape ``(1,)``, ``()`` or any
    shape with one element; anything else is a ``ValueError``); values beyond [-1, 1] are clipped to it.

    ## Observation Space

    ``Box(low, high, (n,), float32)`` with finite bounds, stacked from the terms listed in ``env.observation``
    (all by default, n = 22):

    | term          | size | content                                                                      |
    |---------------|------|------------------------------------------------------------------------------|
    | `position`    | 3    | KCU direction ``R_k`` on the unit sphere (wind frame W: x downwind, z up)    |
    | `heading`     | 2    | sin, cos of the heading ``psi`` of the nose on the sphere (0 = to the zenith) |
    | `line_forces` | 5    | tensions of the bridle lines A, B, C, D and the tether / ``env.force_scale_N`` |
    | `path`        | 5    | signed geodesic distance to the figure-eight [rad] (> 0 left of the path),   |
    |               |      | sin, cos of (path heading - psi) at the nearest point, sin, cos of its phase |
    | `rates`       | 4    | angular velocity on the sphere along x_s, y_s [rad/s], yaw rate [rad/s],     |
    |               |      | flight speed / 25 m/s                                                        |
    | `actuator`    | 3    | last action, actual ``(l_B - l_D) / delta_l_max``, force ratio ``mu``        |

    Values are clipped to the bounds (which they reach only in failing flights).

    ## Rewards

    Per step, the sum of the terms reported in ``info``: ``reward_tracking = w_tracking exp(-(delta / scale)^2)``
    (``delta`` the distance to the figure-eight, ``scale = env.tracking_scale_deg``), ``reward_traction =
    w_traction F_tether / traction_ref_N``, ``reward_action = -w_action_rate (a_k - a_{k-1})^2`` and, on a physical
    failure, ``reward_crash = -crash_penalty``.

    ## Starting State

    The KCU at the crossing of the figure-eight (or, with ``env.random_start``, a path point drawn uniformly in the
    path parameter among those whose geodesic curvature is at most ``env.start_curvature_max`` in magnitude), flying
    along the path at a speed drawn from ``[env.initial_speed_min_mps, env.initial_speed_max_mps]`` (or that many
    times the wind: ``env.initial_speed_per_wind_min/_max``); the wing in static aeroelastic equilibrium on its bridle.
    Wind speed, turbulence intensity and turbulence realisation are drawn from ``self.np_random`` (ranges in the
    ``env`` section). A quantity given without its range (``overrides=["wind.speed_mps=8"]``) is flown at that value:
    its range is pinned to it (:data:`kite_env.config.RANDOMISED`). With ``env.randomize = false`` nothing is drawn: the
    ``wind`` section as configured, the start at the crossing at ``Config.start_speed_mps``
    (``sim.initial_speed_mps`` or ``sim.initial_speed_per_wind``) (``kite-eval``).
    ``reset(options={"wind_seed": n})`` fixes the turbulence realisation.

    ## Episode End

    ``terminated``: ground contact (KCU below 3 deg elevation) or a slack tether (force below
    ``env.slack_tether_N``; on the rod tether, or with the quasi-static wing); ``info["termination_reason"]`` says
    which. With the wing with inertia (``structure.dynamic``, the default) nothing else ends an episode: a step
    whose wing does not converge is made in halves (``dynamics.max_substep_halvings``, ``info["substepped_steps"]``),
    and one that fails even so, or a non-finite state, raises
    :class:`~kite_env.dynamics.simulator.NumericalFailure` with the episode's conditions and the solver's residual
    history: a bug of the simulator, not an end of the flight. The paper's quasi-static wing
    (``structure.dynamic=false``) and the surrogate end the episode there instead ("wing did not converge",
    "non-finite state", "outside surrogate envelope").
    ``truncated``: at ``env.max_episode_s`` of simulated time.

    ## Arguments

    ``gymnasium.make("KiteFigureEight-v1", config=None, overrides=(), render_mode=None, wing=None, fidelity=None)``:
    ``config`` is a :class:`kite_env.config.Config`, a nested dict or the path of a YAML file; ``overrides`` are
    ``"section.key=value"`` strings applied on top; ``wing`` an :class:`kite_env.fsi.AeroelasticWing` to reuse;
    ``fidelity`` ``"fe"`` (the aeroelastic FE wing) or ``"surrogate"`` (the reduced-order wing fitted to it,
    :mod:`kite_env.surrogate`; overrides ``sim.fidelity``). ``KiteFigureEightFast-v1`` is this env with
    ``fidelity="surrogate"``. In the surrogate fidelity a state beyond the sampled envelope ends the episode
    (``termination_reason`` "outside surrogate envelope", the inputs named in ``info["termination_detail"]``).
    ``render_mode`` is ``"rgb_array"`` (flight path and deformed wing as a uint8 image) or ``"human"`` (the same in
    a matplotlib window); the surrogate fidelity draws the design wing.

    ## Version History

    * v1: the flying model: the wing with inertia, the rope tether, the steering actuator's speed limit and the
      ground station's force limit; ``KiteFigureEightFast-v1``'s reduced-order wing fitted to it (with a latent
      state); action +-1 is +-1.5 m of steering; a randomised quantity given without its range is flown at that value.
    * v0 (removed): the model before it flew (the quasi-static wing with Eq. 3 as printed, a rod tether of constant
      length, action +-1 = +-0.25 m), in which every flight ended within seconds.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 25}
    observation_space: spaces.Box
    action_space: spaces.Box

    def __init__(self, config: Config | dict | str | None = None, overrides=(), render_mode: str | None = None,
                 wing=None, fidelity: str | None = None):
        cfg = resolve_config(config, overrides, fidelity)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.cfg = cfg
        self.render_mode = render_mode
        self.path = Lemniscate(cfg.trajectory)
        if cfg.env.random_start:
            try:
                self.path.parameter_of_fraction(0.0, cfg.env.start_curvature_max)
            except ValueError as exc:
                raise ValueError(f"config key 'env.start_curvature_max': {exc}") from None
        self.layout = observation_layout(cfg.env.observation)
        lo = np.concatenate([np.full(_TERM_SPECS[t][0], _TERM_SPECS[t][1]) for t in self.layout]).astype(np.float32)
        hi = np.concatenate([np.full(_TERM_SPECS[t][0], _TERM_SPECS[t][2]) for t in self.layout]).astype(np.float32)
        self.observation_space = spaces.Box(lo, hi, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.n_physics = max(1, int(round(cfg.control.control_dt_s / cfg.physics_dt_s)))
        self.control_dt = self.n_physics * cfg.physics_dt_s
        self.max_steps = int(math.ceil(cfg.env.max_episode_s / self.control_dt - 1e-9))
        ctrl = cfg.control if cfg.env.force_controller else dataclasses.replace(cfg.control, k3_m=0.0)
        #: the control section the env flies (the force loop's gain zeroed where ``env.force_controller`` is false)
        self.control_cfg = ctrl
        self.sim: FlightSimulator | None = None  # built on the first reset (the wing mesh is reused afterwards)
        self._wing = wing
        #: optional :class:`kite_env.flight.FlightRecorder`: gets every physics step (kite-eval's time series)
        self.recorder = None
        self._rec: StepRecord | None = None
        self._rec_pending = False  # ``rec`` is the simulator's last record, not yet built (the compiled step)
        # ``rec`` is the record of the simulator's current state (no physics step failed since): the compiled step
        # (kite_env.envs.fast_step) starts from the kites' arrays, so it runs only then
        self._rec_live = False
        # the compiled step's arguments around the action's (bound at the first step of the fast fidelity)
        self._fast_sim = False
        self._fast_head: tuple | None = None
        self._fast_tail: tuple | None = None
        #: KCU positions [x, y, z] [m] after each step, for the drawing (normalised there)
        self._trail: list[list[float]] = []
        self._fig: Figure | None = None
        #: the observation's compiled kernel with its layout (shared by the batched env)
        self.observer = Observer(cfg, self.path, self.layout)
        # the observer's outputs, reused by every step
        self._parts, self._feats = np.zeros(N_PARTS), np.zeros(len(FEATURES))
        self._n_obs = len(self.observer.index)
        self._kcu: list[float] = []  # KCU position [m] of ``rec``
        self._tracking = 0.0
        self._slack_ends = slack_tether_ends(cfg)

    @property
    def rec(self) -> StepRecord | None:
        """The record of the last good physics step (or of the reset)."""
        if self._rec_pending:
            assert isinstance(self.sim, SurrogateFlightSimulator)
            self._rec, self._rec_pending = self.sim.last_record(), False
        return self._rec

    @rec.setter
    def rec(self, value: StepRecord | None) -> None:
        self._rec, self._rec_pending = value, False

    def _bind_fast(self, sim: SurrogateFlightSimulator) -> None:
        """Bind the compiled control step's arguments (:func:`kite_env.envs.fast_step.control_step`): this env's
        constants, path and outputs in one float64 buffer (``_parts``, ``_feats`` become views of it), ``sim``'s
        kite in the buffers of :meth:`SurrogateKites.pack`."""
        cfg, c, e = self.cfg, self.control_cfg, self.cfg.env
        ctrl = np.zeros(10)
        ctrl[[fs.C_DL_MAX_ACTION, fs.C_DL_MAX, fs.C_K2, fs.C_K3, fs.C_K3I, fs.C_MU_TARGET, fs.C_INTEGRAL_MAX,
              fs.C_CONTROL_DT, fs.C_LINE_SPEED_MAX, fs.C_POWER_MIN]] = (
            cfg.control.delta_l_max_m, c.delta_l_max_m, c.k2, c.k3_m, c.k3i_per_s, c.mu_target,
            c.force_integral_max_m, c.control_dt_s, c.line_speed_max_mps, POWER_LINES_MIN_N)
        envp = np.zeros(9)
        envp[[fs.E_N_PHYSICS, fs.E_SIN_GROUND, fs.E_SLACK_ENDS, fs.E_SLACK_N, fs.E_W_TRACKING, fs.E_W_TRACTION,
              fs.E_TRACTION_REF, fs.E_W_ACTION, fs.E_CRASH]] = (
            self.n_physics, _SIN_GROUND, 1.0 if self._slack_ends else 0.0, e.slack_tether_N, e.w_tracking,
            e.w_traction, e.traction_ref_N, e.w_action_rate, e.crash_penalty)
        (samples, s_samples, window, ds, path_a, path_b, rot, force_scale, dl_max,
         tracking_scale) = self.observer.consts
        ks = sim.kites
        kf, ki, kw, klay = ks.pack()
        parts = {"ctrl": ctrl, "envp": envp, "samples": samples, "s_samples": s_samples, "rot": rot,
                 "scalars": np.array([window, ds, path_a, path_b, force_scale, dl_max, tracking_scale], dtype=float),
                 "parts": self._parts, "feats": self._feats, "snap": np.zeros(fs.S_X + ks.X.shape[1]),
                 "out": np.zeros(fs.N_OUT)}
        offsets, total = [], 0
        for name in fs.ENV_F64:
            offsets.append(total)
            total += -(-parts[name].size // 8) * 8
        ef = np.zeros(total)
        for name, o in zip(fs.ENV_F64, offsets):
            view = ef[o:o + parts[name].size].reshape(parts[name].shape)
            view[...] = parts[name]
            parts[name] = view
        self._parts, self._feats, self._snap, self._out = parts["parts"], parts["feats"], parts["snap"], parts["out"]
        ei = np.array([len(s_samples), self._snap.size, *offsets, *self.observer.index], dtype=np.int64)
        ew = np.concatenate([self.observation_space.low, self.observation_space.high]).astype(np.float32)
        self._fast_head = (ef, ei, ew)
        self._fast_tail = (ks.dt, ks.all_kites, kf, ki, kw, klay)
        # numba loads the kernel from its cache (or compiles it) at its first call, some 0.1 s: here, with the reset,
        # and not in the first step. A dry call: rest lengths of -inf are refused before anything is stepped (it
        # writes only the scratch ``out``)
        ninf = -math.inf
        fs.control_step(0.0, 0.0, 0.0, ninf, ninf, 0.0, ninf, ninf, *self._fast_head,
                        np.empty(self._n_obs, dtype=np.float32), *self._fast_tail)

    def __getstate__(self):
        # the compiled step's buffers are views that a pickle would copy apart: bound again at the next step
        state = self.__dict__.copy()
        state["_fast_head"] = state["_fast_tail"] = None
        return state

    # ------------------------------------------------------------------ gymnasium API
    def share_wing(self, wing) -> None:
        """Build this env's simulator, at its first reset, on ``wing`` (a wing geometry another env already made:
        the batched env's kites share one), unless it has a simulator or a wing already."""
        if self.sim is None and self._wing is None:
            self._wing = wing

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        env = self.cfg.env
        last_error = None
        options = options or {}
        unknown = set(options) - {"wind_seed"}
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)} (valid: 'wind_seed')")
        last_error = None
        failed_starts = 0  # draws whose start did not converge (a numerical failure; the env draws again)
        for _ in range(env.reset_attempts if env.randomize else 1):
            rng = self.np_random
            if env.randomize:
                wind_speed = float(rng.uniform(env.wind_speed_min_mps, env.wind_speed_max_mps))
                ti = (float(rng.uniform(env.turbulence_intensity_min, env.turbulence_intensity_max))
                      if env.turbulence_intensity_max > 0
                      else 0.0)
                wind_seed = int(rng.integers(0, 2**31 - 1))
                # one uniform draw either way (2 pi u is the unbounded draw, bit for bit as uniform(0, 2 pi))
                s0 = (self.path.parameter_of_fraction(float(rng.uniform(0.0, 1.0)), env.start_curvature_max)
                      if env.random_start else 0.0)
                if env.initial_speed_per_wind_max > 0.0:  # the start speed scales with the drawn wind
                    v0 = float(rng.uniform(env.initial_speed_per_wind_min, env.initial_speed_per_wind_max)) * wind_speed
                else:
                    v0 = float(rng.uniform(env.initial_speed_min_mps, env.initial_speed_max_mps))
            else:  # the configured conditions (kite-eval): nothing drawn
                wind_speed, ti = self.cfg.wind.speed_mps, self.cfg.wind.turbulence_intensity
                wind_seed, s0, v0 = self.cfg.wind.seed, 0.0, self.cfg.start_speed_mps
            if "wind_seed" in options:
                wind_seed = int(options["wind_seed"])
            wind_cfg = dataclasses.replace(self.cfg.wind, speed_mps=wind_speed, turbulence_intensity=ti, seed=wind_seed)
            wind = WindField(wind_cfg)
            if self.sim is None:
                self.sim = make_simulator(self.cfg, wind, self._wing)
                self._wing = None
            else:
                self.sim.wind = wind
            try:
                self.rec = self.sim.reset(self.path.point(s0), self.path.tangent(s0), v0)
                break
            except SimulationError as exc:
                last_error = exc
                failed_starts += 1
        else:
            raise StartError(f"reset failed: the wing did not converge at the start ({last_error})")
        self._rec_live = True
        self._fast_sim = isinstance(self.sim, SurrogateFlightSimulator)
        if self._fast_sim and self._fast_head is None:
            self._bind_fast(self.sim)  # type: ignore[arg-type]
        assert self.sim is not None and self.sim.L_B0 is not None and self.sim.L_D0 is not None  # set by the reset
        self.actuator = LineActuator(self.control_cfg, self.sim.L_B0, self.sim.L_D0)
        self.L_B, self.L_D = self.sim.L_B0, self.sim.L_D0
        self.s_hint = s0
        self.last_action = 0.0
        self.steps = 0
        self.substepped_steps = 0  # physics steps split because the wing failed at the full step (sim.step)
        self.episode_info = {"wind_speed_mps": wind_speed, "turbulence_intensity": ti, "wind_seed": wind_seed,
                             "start_s": s0, "initial_speed_mps": v0, "failed_starts": failed_starts}
        self._kcu = self.rec.state.r[4].tolist()
        self._trail = [self._kcu]
        if self.recorder is not None:
            self.recorder.start(self.sim, self.rec, s0, self.L_B, self.L_D,
                                LineActuator.force_ratio(self.rec.line_tension))
        obs, feats = self._observe(self.rec)
        if not np.all(np.isfinite(obs)):
            raise RuntimeError(f"reset produced a non-finite observation: {obs}")
        obs = np.clip(obs, self.observation_space.low, self.observation_space.high)
        info = {**self.episode_info, **feats}
        if self.render_mode == "human":
            self.render()
        return obs, info

    def _failure_raises(self) -> bool:
        """Whether a numerical failure raises (the FE wing with inertia, ``structure.dynamic``: the simulator is total,
        a failure is a bug) instead of ending the episode (the paper's quasi-static wing, which has no state to carry
        it through a luffing canopy, and the surrogate's non-finite states)."""
        assert self.sim is not None
        return self.cfg.structure.dynamic and self.sim.fidelity_now == "fe"

    def _conditions(self) -> str:
        """The episode's drawn conditions, to reproduce a failure."""
        e = self.episode_info
        return (f"wind {e['wind_speed_mps']:.3f} m/s, turbulence {e['turbulence_intensity']:.4f}, wind seed "
                f"{e['wind_seed']}, start s {e['start_s']:.4f}, start speed {e['initial_speed_mps']:.3f} m/s")

    def step(self, action):
        if self._rec is None:
            raise RuntimeError("call reset() before step()")
        sim = self.sim
        assert sim is not None  # built with the first record
        if type(action) is np.ndarray and action.size == 1 and action.dtype.kind == "f":
            a = float(action.item())  # a float's float64 value, as np.asarray(action, dtype=np.float64) gives it
        elif type(action) is float:
            a = action
        else:
            arr = np.asarray(action, dtype=np.float64).reshape(-1)
            if arr.size != 1:
                raise ValueError(f"action must have one element, got shape {np.shape(action)}")
            a = float(arr[0])
        if not math.isfinite(a):
            raise ValueError(f"action must be finite, got {a!r}")
        a = min(1.0, max(-1.0, a))
        if self._rec_live and self._fast_sim and self.recorder is None:
            if self._fast_head is None:
                self._bind_fast(self.sim)  # type: ignore[arg-type]
            if self._fast_head is not None:
                return self._fast_step(a)
        cfg = self.cfg
        dl_star = a * cfg.control.delta_l_max_m
        rec0 = self.rec
        assert rec0 is not None  # checked above
        L_B, L_D, ainfo = self.actuator.rest_lengths(dl_star, rec0.line_length, rec0.line_tension)
        self.L_B, self.L_D = L_B, L_D
        reason = detail = None
        # a slack tether ends the episode on a rod; the default rope goes slack and flies on (the quasi-static wing's
        # tether is always the rod)
        slack_ends = self._slack_ends
        recorder = self.recorder
        newton = []  # Newton iterations of each physics step's FE wing (none from the surrogate)
        live = True
        for _ in range(self.n_physics):
            t0 = time.perf_counter() if recorder is not None else 0.0
            try:
                rec = sim.step(L_B, L_D)
            except SimulationError as exc:
                if self._failure_raises():  # the wing with inertia: a bug, not an end
                    raise NumericalFailure(exc, sim.t, self._conditions()) from exc
                reason, detail = exc.reason, exc.detail
                live = False
                break
            self.rec = rec
            if sim.fidelity_now == "fe":
                newton.append(int(rec.wing.newton_iters))
            if recorder is not None:
                recorder.record(rec, L_B, L_D, ainfo, time.perf_counter() - t0)
            kcu = rec.state.r[4].tolist()
            self._kcu = kcu
            x, y, z = kcu
            self.substepped_steps += rec.substeps > 1
            if z < _SIN_GROUND * math.sqrt(x * x + y * y + z * z):  # the batch: the same sums
                reason = "ground"
                break
            if slack_ends and rec.tether_force < cfg.env.slack_tether_N:
                reason = "slack tether"
                break
        self._rec_live = live
        self.steps += 1
        prev_action, self.last_action = self.last_action, a  # the observation holds the action just applied
        obs, feats, finite = self._observe_finite(self.rec)  # type: ignore[arg-type]
        if reason is None and not finite:
            if self._failure_raises():
                raise NumericalFailure(SimulationError("non-finite state", f"observation {obs}"), sim.t,
                                       self._conditions())
            reason = "non-finite state"
        terms = reward_terms(cfg.env, self._tracking, feats["tether_force_N"], a, prev_action, reason is not None)
        reward = float(sum(terms.values()))
        terminated = reason is not None
        truncated = (not terminated) and self.steps >= self.max_steps
        if not finite:
            obs = np.nan_to_num(obs, nan=0.0, posinf=0.0, neginf=0.0)
        obs = obs.clip(self.observation_space.low, self.observation_space.high)  # np.clip's own call
        info = terms
        info.update(feats)
        info["delta_l_star_m"] = ainfo["delta_l_star"]
        info["L_B_m"] = L_B
        info["L_D_m"] = L_D
        info["termination_reason"] = reason if terminated else ("time limit" if truncated else None)
        info["fidelity"] = sim.fidelity_now
        info["substepped_steps"] = self.substepped_steps
        if newton:
            info["newton_iters"] = newton
        if detail:
            info["termination_detail"] = detail
        self._trail.append(self._kcu)
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, truncated, info

    def _fast_step(self, a: float):
        """:meth:`step` of the fast fidelity from the action ``a`` (a float in [-1, 1]) in one compiled call
        (:func:`kite_env.envs.fast_step.control_step`: the same operations, bit for bit); here the Gymnasium API."""
        sim = self.sim
        assert isinstance(sim, SurrogateFlightSimulator) and self._fast_head is not None and self._fast_tail is not None
        act = self.actuator
        L_B_prev, L_D_prev = act.last
        obs = np.empty(self._n_obs, dtype=np.float32)
        L_B0, L_D0 = act.L_B0, act.L_D0
        if act.depower_offset_m:  # as LineActuator.rest_lengths
            L_B0, L_D0 = L_B0 + act.depower_offset_m, L_D0 + act.depower_offset_m
        fs.control_step(a, self.last_action, self.s_hint, L_B0, L_D0, act.integral, L_B_prev, L_D_prev,
                        *self._fast_head, obs, *self._fast_tail)
        o = self._out.tolist()
        code = int(o[fs.O_CODE])
        L_B, L_D = o[fs.O_L_B], o[fs.O_L_D]
        act.integral, act.last = o[fs.O_INTEGRAL], (L_B, L_D)
        self.L_B, self.L_D = L_B, L_D
        if code == fs.BAD_REST:  # SurrogateFlightSimulator.step's refusal; nothing was stepped
            raise ValueError(f"steering-line rest lengths must be positive and finite, got {L_B!r}, {L_D!r}")
        detail = None
        if code == fs.NON_FINITE_PARTICLES or code == fs.OUTSIDE_ENVELOPE:  # SurrogateFlightSimulator._raise_status
            ks = sim.kites
            detail = f"t = {ks.t[0]:.4f} s" if code == fs.NON_FINITE_PARTICLES else ", ".join(ks.outside(0))
            self.rec = sim.settle_snapshot(self._snap)
            self._rec_live = False
        else:
            sim.advanced()
            self._rec_pending = True
        self._kcu = o[fs.O_KCU:fs.O_KCU + 3]
        self.steps += 1
        self.last_action = a
        self.s_hint = o[fs.O_HINT]
        terminated = code != fs.NONE
        truncated = (not terminated) and self.steps >= self.max_steps
        feats = self._feats.tolist()
        self._tracking = feats[-1]
        info = {"reward_tracking": o[fs.O_TRACKING], "reward_traction": o[fs.O_TRACTION],
                "reward_action": o[fs.O_ACTION], "reward_crash": o[fs.O_CRASH]}
        info.update(zip(INFO_FEATURES, feats))
        info["delta_l_star_m"] = o[fs.O_DLS]
        info["L_B_m"] = L_B
        info["L_D_m"] = L_D
        info["termination_reason"] = fs.REASONS[code] if terminated else ("time limit" if truncated else None)
        info["fidelity"] = sim.fidelity_now
        info["substepped_steps"] = self.substepped_steps
        if detail:
            info["termination_detail"] = detail
        self._trail.append(self._kcu)
        if self.render_mode == "human":
            self.render()
        return obs, o[fs.O_REWARD], terminated, truncated, info

    # ------------------------------------------------------------------ observation
    def _observe(self, rec: StepRecord):
        """Observation (float32, unclipped) and features of the record ``rec`` (:mod:`kite_env.envs.observe`);
        advances the nearest-point hint ``s_hint``. The features include ``tracking`` = exp(-(delta/scale)^2)."""
        obs, feats, _ = self._observe_finite(rec)
        return obs, feats

    def _observe_finite(self, rec: StepRecord):
        """:meth:`_observe` and whether the observation is finite."""
        obs = np.empty(self._n_obs, dtype=np.float32)
        # the scalars as float64 values, as the batch's arrays hold them
        self.s_hint, finite = self.observer.one(
            rec.state.r, rec.state.v, rec.R_wk, rec.omega, rec.v_kite, rec.line_tension, rec.line_length,
            float(rec.tether_force), float(rec.t), float(self.s_hint), float(self.last_action), self._parts,
            self._feats, obs)
        vals = self._feats.tolist()
        self._tracking = vals[-1]
        return obs, dict(zip(INFO_FEATURES, vals)), finite

    # ------------------------------------------------------------------ rendering
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode (use render_mode='rgb_array' or 'human')")
            return None
        if self.rec is None:
            raise RuntimeError("call reset() before render()")
        import matplotlib

        if self.render_mode == "rgb_array":
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            fig = Figure(figsize=(8, 4), dpi=80)
            canvas = FigureCanvasAgg(fig)
            self._draw(fig)
            canvas.draw()
            return np.asarray(canvas.buffer_rgba())[..., :3].copy()
        import matplotlib.pyplot as plt

        if self._fig is None or not plt.fignum_exists(self._fig.number):
            self._fig = plt.figure(figsize=(8, 4))
        self._fig.clf()
        self._draw(self._fig)
        if matplotlib.get_backend().lower() != "agg":
            plt.pause(1.0 / self.metadata["render_fps"])
        return None

    def _draw(self, fig) -> None:
        assert self.sim is not None and self.rec is not None  # render() checks that reset() was called
        s = np.linspace(0.0, 2.0 * math.pi, 400)
        P = self.path.point(s)
        trail = np.array([np.asarray(r) / np.linalg.norm(r) for r in self._trail])
        ax = fig.add_subplot(1, 2, 1)
        ax.plot(np.degrees(np.arctan2(P[:, 1], P[:, 0])), np.degrees(np.arcsin(P[:, 2])), "k--", lw=0.8)
        ax.plot(np.degrees(np.arctan2(trail[:, 1], trail[:, 0])), np.degrees(np.arcsin(trail[:, 2])), "C0", lw=1.2)
        ax.plot(np.degrees(math.atan2(trail[-1, 1], trail[-1, 0])), np.degrees(math.asin(trail[-1, 2])), "C3o")
        ax.set_xlabel("azimuth [deg]")
        ax.set_ylabel("elevation [deg]")
        ax.set_title(f"t = {self.rec.t:.2f} s, tether {self.rec.tether_force / 1e3:.1f} kN", fontsize=9)
        ax.invert_xaxis()
        ax3 = fig.add_subplot(1, 2, 2, projection="3d")
        mesh = self.sim.wing.mesh
        x = self.rec.wing.nodes
        for sec in mesh.sections:
            ax3.plot(x[sec, 0], x[sec, 1], x[sec, 2], "C0", lw=0.7)
        ax3.plot(x[mesh.sections[:, 0], 0], x[mesh.sections[:, 0], 1], x[mesh.sections[:, 0], 2], "k", lw=1.2)
        ax3.set_title("deformed wing (kite frame)", fontsize=9)
        ax3.set_box_aspect((1, 3, 1))
        ax3.view_init(elev=25, azim=-60)
        ax3.set_axis_off()

    def close(self):
        if self._fig is not None:
            import matplotlib.pyplot as plt

            plt.close(self._fig)
            self._fig = None

