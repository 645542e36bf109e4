"""Fly a policy in the full model and log everything: the engine behind ``kite-eval`` (Bosch et al., Sect. IV).

Every evaluation goes through the Gymnasium environment :class:`kite_env.envs.figure_eight.KiteFigureEightEnv`
(wind, figure-eight, flight model, line actuator of Eq. 16-19) and a policy with Stable-Baselines3's ``predict``
interface (the paper's controller :class:`kite_env.policies.baseline.BaselineAgent`, a trained model, random or constant
actions). :func:`run_episode` flies one episode; :class:`FlightRecorder`, attached to the environment, logs every
physics step; :func:`fly` is the short form for one episode at the configured conditions (wind section as it is,
start at the crossing of the figure-eight, :func:`evaluation_config`).

The log (:class:`FlightLog`) holds one row per time step in ``series`` (arrays, SI units, angles in rad):

====================  ==========  ===================================================================
key                   shape       meaning
====================  ==========  ===================================================================
t                     (n,)        time [s]
r, v                  (n, 5, 3)   positions and velocities of A, B, C, D, KCU in W [m], [m/s]
R_wk                  (n, 3, 3)   kite frame (columns x_k, y_k, z_k in W)
v_kite, omega         (n, 3)      velocity of r_k [m/s], rotation rate of K [rad/s], in W
omega_k               (n, 3)      rotation rate in K components (yaw rate = omega_k[:, 2]) [rad/s]
v_wind                (n, 3)      wind at r_k [m/s]
speed                 (n,)        |v_kite| [m/s]
v_app                 (n,)        |v_kite - v_wind| [m/s]
line_tension          (n, 4)      bridle-line forces F_c of A, B, C, D (Eq. 10) [N]
line_length           (n, 4)      [m]
tether_force          (n,)        [N]
mu                    (n,)        force ratio (Eq. 18) [-]
L_B, L_D              (n,)        steering-line rest lengths [m]
steering_input        (n,)        Delta L = L_B - L_D [m]
delta_l, delta_l_star (n,)        actual l_B - l_D and the policy's dl* [m]
alpha                 (n, n_sec)  section angles of attack, right tip first [rad]
section_lift/_drag    (n, n_sec)  section lift and drag (Eq. 7-8) [N]
lift, drag            (n,)        wing lift and drag [N]; lift_to_drag = lift / drag
F_b                   (n, 4, 3)   bridle reactions in K [N]
tip_distance          (n,)        |A - C| [m]
bridle_y              (n, 4)      transverse (y_k) coordinate of A, B, C, D in K, the paper's Fig. 18 (its design
                                  values: meta ``design_bridle_y_m``) [m]
tip_disp_right/_left  (n,)        inward (towards the symmetry plane) displacement of the tip sections'
                                  centroid in K relative to the unloaded design [m]
elevation, azimuth    (n,)        of the KCU [rad]
psi                   (n,)        heading of the nose on the sphere (kite_env.trajectory) [rad]
course                (n,)        course angle of the velocity [rad]
path_s                (n,)        unwrapped path parameter of the nearest point on the figure-eight
path_distance         (n,)        geodesic distance to the figure-eight [rad]
newton_iters          (n,)        Newton iterations of the wing solve
wall_time             (n,)        wall time of the step [s]
constraint_drift      (n, 3)      constraint errors before the projection [m]
====================  ==========  ===================================================================

``snapshots``: deformed wing nodes (K) at the start and at the step with the largest steering input in the upper
half of the figure (for the Fig. 11 view). Deterministic: same config, same result, bit for bit.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from kite_env.config import Config
from kite_env.dynamics.simulator import FlightSimulator, StepRecord
from kite_env.envs.figure_eight import KiteFigureEightEnv
from kite_env.frames import kite_frame, to_frame
from kite_env.policies.baseline import BaselineAgent
from kite_env.trajectory import Lemniscate, azimuth, course_angle, elevation, heading_angle


@dataclass
class FlightLog:
    series: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)
    snapshots: dict[str, np.ndarray] = field(default_factory=dict)


class FlightRecorder:
    """Logs every physics step of an episode of :class:`kite_env.envs.figure_eight.KiteFigureEightEnv` into a
    :class:`FlightLog` (rows of the module docstring's table). The environment calls :meth:`start` after a reset
    and :meth:`record` after every physics step; :meth:`log` closes the episode."""

    def __init__(self, cfg: Config, path: Lemniscate):
        self.cfg = cfg
        self.path = path

    def start(self, sim: FlightSimulator, rec: StepRecord, s0: float, L_B: float, L_D: float, mu: float) -> None:
        self.t_wall0 = time.perf_counter()
        self.sim = sim
        mesh = sim.wing.mesh
        self.design = mesh.nodes
        o, R = kite_frame(*self.design[mesh.bridle])
        self.design_bridle_y = to_frame(self.design[mesh.bridle] - o, R)[:, 1]  # A-D in the design's own K
        self.tips = (mesh.sections[0], mesh.sections[-1])
        self.rows: dict[str, list] = {}
        self.snapshots = {"initial": rec.wing.nodes.copy(), "design": self.design.copy()}
        self.best_turn = -1.0
        self.s_hint = self.s_prev = s0
        self.s_unwrapped = s0
        self.record(rec, L_B, L_D, {"delta_l_star": 0.0, "mu": mu}, 0.0)

    def record(self, rec: StepRecord, L_B: float, L_D: float, ainfo: dict, t_step: float) -> None:
        """One row for the state ``rec``, reached with the rest lengths ``L_B``, ``L_D`` of the control decision
        ``ainfo`` (:meth:`kite_env.control.LineActuator.rest_lengths`); ``t_step`` its wall time [s]."""
        cfg = self.cfg
        r, R = rec.state.r, rec.R_wk
        near = self.path.nearest(r[4], self.s_hint)
        self.s_unwrapped += (near.s - self.s_prev + math.pi) % (2 * math.pi) - math.pi
        self.s_prev = self.s_hint = near.s
        x, design = rec.wing.nodes, self.design
        disp_r = (x[self.tips[0]] - design[self.tips[0]]).mean(axis=0)
        disp_l = (x[self.tips[1]] - design[self.tips[1]]).mean(axis=0)
        row = {
            "t": rec.t, "r": r, "v": rec.state.v, "R_wk": R, "v_kite": rec.v_kite, "omega": rec.omega,
            "omega_k": R.T @ rec.omega, "v_wind": rec.v_wind, "speed": float(np.linalg.norm(rec.v_kite)),
            "v_app": float(np.linalg.norm(rec.v_kite - rec.v_wind)), "line_tension": rec.line_tension,
            "line_length": rec.line_length, "tether_force": rec.tether_force, "mu": ainfo["mu"], "L_B": L_B,
            "L_D": L_D, "steering_input": L_B - L_D, "delta_l": rec.line_length[1] - rec.line_length[3],
            "delta_l_star": ainfo["delta_l_star"], "alpha": rec.wing.alpha, "section_lift": rec.wing.section_lift,
            "section_drag": rec.wing.section_drag, "lift": rec.wing.lift, "drag": rec.wing.drag,
            "lift_to_drag": rec.wing.lift_to_drag, "F_b": rec.wing.F_b,
            "tip_distance": float(np.linalg.norm(r[0] - r[2])),
            "bridle_y": to_frame(r[:4] - 0.5 * (r[0] + r[2]), R)[:, 1],
            "tip_disp_right": -float(disp_r[1]), "tip_disp_left": float(disp_l[1]),
            "elevation": float(elevation(r[4])), "azimuth": float(azimuth(r[4])),
            "psi": float(heading_angle(r[4], -R[:, 0])), "course": float(course_angle(r[4], rec.v_kite)),
            "path_s": self.s_unwrapped, "path_distance": near.distance_rad, "newton_iters": rec.wing.newton_iters,
            "wall_time": t_step, "constraint_drift": rec.constraint_drift, "substeps": rec.substeps,
            "tether_length": rec.tether_length, "reel_speed": rec.reel_speed,
        }
        for key, val in row.items():
            self.rows.setdefault(key, []).append(np.array(val, dtype=float, copy=True))
        upper = row["elevation"] > math.radians(cfg.trajectory.elevation_deg)
        if upper and rec.t > cfg.sim.warmup_s and abs(row["steering_input"]) > self.best_turn:
            self.best_turn = abs(row["steering_input"])
            self.snapshots["turn"] = x.copy()
            self.snapshots["turn_t"] = np.array(rec.t)

    def log(self, termination_reason: str | None, control_dt_s: float) -> FlightLog:
        """The episode's log; ``termination_reason`` None or "time limit" means completed."""
        crashed = is_crash(termination_reason)
        series = {k: np.stack(v) for k, v in self.rows.items()}
        sim, mesh, design = self.sim, self.sim.wing.mesh, self.design
        meta = {
            "crashed": crashed, "termination_reason": termination_reason if crashed else "completed",
            "sim_time_s": float(series["t"][-1]), "wall_time_s": time.perf_counter() - self.t_wall0,
            "dt_s": self.cfg.physics_dt_s, "control_dt_s": control_dt_s, "L_B0": sim.L_B0, "L_D0": sim.L_D0,
            "pair_stiffness_N_per_m": sim.pair_stiffness.tolist(), "n_sections": int(len(mesh.sections)),
            "design_tip_distance_m": float(np.linalg.norm(design[mesh.bridle[0]] - design[mesh.bridle[2]])),
            "design_bridle_y_m": self.design_bridle_y.tolist(),
            "warmup_s": self.cfg.sim.warmup_s,
        }
        return FlightLog(series=series, meta=meta, snapshots=dict(self.snapshots))


def is_crash(termination_reason: str | None) -> bool:
    """Whether an episode that ended with ``termination_reason`` crashed (anything but no end or the time limit)."""
    return termination_reason not in (None, "time limit")


def evaluation_config(cfg: Config, duration_s: float | None = None, randomize: bool = False) -> Config:
    """``cfg`` with the environment set up for an evaluation at the configured conditions: the wind section as it
    is (no randomisation), the start at the crossing at ``Config.start_speed_mps`` (``sim.initial_speed_mps`` or
    ``sim.initial_speed_per_wind``), episodes of ``duration_s`` (default ``sim.duration_s``). ``randomize``: draw wind
    and start from the ``env`` ranges instead. The training-only start rule ``sim.surrogate_start: table_only`` (a
    trained model's config) becomes ``table``: an evaluation starts every episode it draws, as the full model does."""
    duration = cfg.sim.duration_s if duration_s is None else float(duration_s)
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be positive, got {duration}")
    env = dataclasses.replace(cfg.env, randomize=randomize, max_episode_s=duration)
    start = "table" if cfg.sim.surrogate_start == "table_only" else cfg.sim.surrogate_start
    return dataclasses.replace(cfg, env=env, sim=dataclasses.replace(cfg.sim, duration_s=duration,
                                                                     surrogate_start=start))


def run_episode(env, agent, seed: int | None = None, options: dict | None = None,
                progress: Callable[[float], None] | None = None, record: bool = True):
    """Fly one episode of ``env`` (a :class:`~kite_env.envs.figure_eight.KiteFigureEightEnv`, unwrapped) with
    ``agent`` (SB3 ``predict`` interface). Returns ``(log, info)``: the :class:`FlightLog` (None without
    ``record``) and a dict with ``episode_return``, ``episode_steps``, ``termination_reason`` and the reward terms
    summed over the episode, and the episode's draws (``env.episode_info``). ``progress(t)`` is called after every
    control step."""
    env.recorder = FlightRecorder(env.cfg, env.path) if record else None
    obs, _ = env.reset(seed=seed, options=options)
    if seed is not None and hasattr(agent, "seed_episode"):
        agent.seed_episode(seed)  # a stochastic policy's draws per episode (RandomAgent)
    terms: dict[str, float] = {}
    ret, steps, done, info = 0.0, 0, False, {}
    start = True
    while not done:
        action, _ = agent.predict(obs, episode_start=np.array([start]), deterministic=True)
        start = False
        obs, reward, terminated, truncated, info = env.step(action)
        ret += float(reward)
        steps += 1
        for k, v in info.items():
            if k.startswith("reward_"):
                terms[k] = terms.get(k, 0.0) + float(v)
        done = terminated or truncated
        if progress is not None:
            progress(info["t"])
    reason = info.get("termination_reason")
    log = env.recorder.log(reason, env.control_dt) if record else None
    env.recorder = None
    return log, {**env.episode_info, "episode_return": ret, "episode_steps": steps, "termination_reason": reason,
                 **terms}


def fly(cfg: Config, policy=None, duration_s: float | None = None, progress: Callable[[float], None] | None = None,
        wing=None) -> FlightLog:
    """Fly ``policy`` (an agent with SB3's ``predict``; None: the paper's controller,
    :class:`kite_env.policies.baseline.BaselineAgent`) for ``duration_s`` (None: ``sim.duration_s``) at the
    configured wind, from the crossing of the figure-eight, through the Gymnasium environment (one evaluation path
    for every policy). ``progress(t)`` is called after every control period. Returns the log; a wing that stops
    converging, a slack tether or a kite that reaches the ground ends the flight early with ``meta['crashed']`` and
    ``meta['termination_reason']``. ``wing``: an :class:`~kite_env.fsi.AeroelasticWing` to reuse.
    """
    env = KiteFigureEightEnv(config=evaluation_config(cfg, duration_s), wing=wing)
    if policy is None:
        policy = BaselineAgent(env.cfg, env.path)
    log, _ = run_episode(env, policy, progress=progress)
    env.close()
    return log
