"""Fly a policy in the full model and log everything: the engine behind ``kite-eval`` (Bosch et al., Sect. IV).

:func:`fly` sets up the wind (:mod:`kite_env.wind`), the figure-eight (:mod:`kite_env.trajectory`), the flight
model (:class:`kite_env.dynamics.simulator.FlightSimulator`) and the line actuator (:class:`kite_env.control.
LineActuator`), starts the kite at the crossing point of the figure-eight flying along it, and runs the policy at
``control.control_dt_s``. A policy maps an observation (dict, below) to the desired steering-line length
difference ``dl* = l_B - l_D`` [m]; the actuator turns it into rest lengths (Eq. 16-19).

Observation dict (frame W): ``t`` [s], ``r_kcu`` (3,) [m], ``nose`` (3,) unit vector ``-x_k``, ``v_kite`` (3,)
[m/s], ``omega`` (3,) [rad/s], ``line_tension`` (4,) [N], ``line_length`` (4,) [m], ``mu``.

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

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from kite_env.config import Config
from kite_env.control import LineActuator
from kite_env.dynamics.simulator import FlightSimulator, SimulationError, StepRecord
from kite_env.trajectory import Lemniscate, azimuth, course_angle, elevation, heading_angle
from kite_env.wind import WindField

#: the flight ends as crashed when the KCU comes closer to the ground than this elevation [rad]
GROUND_ELEVATION_RAD = math.radians(3.0)


@dataclass
class FlightLog:
    series: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)
    snapshots: dict[str, np.ndarray] = field(default_factory=dict)


def observation(rec: StepRecord, mu: float) -> dict:
    """The policy's view of a step record (module docstring)."""
    return {"t": rec.t, "r_kcu": rec.state.r[4].copy(), "nose": -rec.R_wk[:, 0].copy(), "v_kite": rec.v_kite.copy(),
            "omega": rec.omega.copy(), "line_tension": rec.line_tension.copy(),
            "line_length": rec.line_length.copy(), "mu": mu}


class BaselineAdapter:
    """:class:`agents.baseline.BaselinePolicy` as an observation -> dl* policy."""

    def __init__(self, cfg: Config, path: Lemniscate):
        from agents.baseline import BaselinePolicy

        self.policy = BaselinePolicy(cfg.control, path)

    def reset(self, s0: float = 0.0) -> None:
        self.policy.reset(s0)

    def act(self, obs: dict) -> float:
        dl, self.last_info = self.policy(obs["r_kcu"], obs["nose"], obs["v_kite"])
        return dl


def fly(cfg: Config, policy=None, duration_s: float | None = None, progress: Callable[[float], None] | None = None,
        wing=None) -> FlightLog:
    """Fly ``policy`` (None: the paper's baseline controller) for ``duration_s`` (None: ``sim.duration_s``).

    ``progress(t)`` is called after every control period. Returns the log; a wing that stops converging or a kite
    that reaches the ground ends the flight early with ``meta['crashed']`` and ``meta['termination_reason']``.
    """
    duration = cfg.sim.duration_s if duration_s is None else float(duration_s)
    if not duration > 0:
        raise ValueError(f"duration must be positive, got {duration}")
    t_wall0 = time.perf_counter()
    path = Lemniscate(cfg.trajectory)
    wind = WindField(cfg.wind)
    sim = FlightSimulator(cfg, wind, wing)
    policy = BaselineAdapter(cfg, path) if policy is None else policy
    rec = sim.reset(path.point(0.0), path.tangent(0.0), cfg.sim.initial_speed_mps)
    policy.reset(0.0)
    act = LineActuator(cfg.control, sim.L_B0, sim.L_D0)
    mesh = sim.wing.mesh
    design = mesh.nodes
    tip_r, tip_l = mesh.sections[0], mesh.sections[-1]
    n_ctrl = max(1, int(round(cfg.control.control_dt_s / cfg.dynamics.dt_s)))
    n_steps = int(math.ceil(duration / cfg.dynamics.dt_s - 1e-9))
    rows: dict[str, list] = {}
    snapshots = {"initial": rec.wing.nodes.copy(), "design": design.copy()}
    best_turn = -1.0
    s_hint, s_unwrapped, s_prev = 0.0, 0.0, 0.0
    dls = 0.0
    L_B, L_D = sim.L_B0, sim.L_D0
    ainfo = {"delta_l": 0.0, "delta_l_star": 0.0, "mu": act.force_ratio(rec.line_tension)}
    crashed, reason = False, "completed"
    t_step = 0.0
    for k in range(n_steps + 1):
        # ---- log the current state (step k)
        r = rec.state.r
        R = rec.R_wk
        near = path.nearest(r[4], s_hint)
        ds = (near.s - s_prev + math.pi) % (2 * math.pi) - math.pi
        s_unwrapped += ds
        s_prev = s_hint = near.s
        x = rec.wing.nodes
        disp_r = (x[tip_r] - design[tip_r]).mean(axis=0)
        disp_l = (x[tip_l] - design[tip_l]).mean(axis=0)
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
            "tip_disp_right": -float(disp_r[1]), "tip_disp_left": float(disp_l[1]),
            "elevation": float(elevation(r[4])), "azimuth": float(azimuth(r[4])),
            "psi": float(heading_angle(r[4], -R[:, 0])), "course": float(course_angle(r[4], rec.v_kite)),
            "path_s": s_unwrapped, "path_distance": near.distance_rad, "newton_iters": rec.wing.newton_iters,
            "wall_time": t_step, "constraint_drift": rec.constraint_drift,
        }
        for key, val in row.items():
            rows.setdefault(key, []).append(np.array(val, dtype=float, copy=True))
        upper = row["elevation"] > math.radians(cfg.trajectory.elevation_deg)
        if upper and rec.t > cfg.sim.warmup_s and abs(row["steering_input"]) > best_turn:
            best_turn = abs(row["steering_input"])
            snapshots["turn"] = x.copy()
            snapshots["turn_t"] = np.array(rec.t)
        if k == n_steps:
            break
        if r[4, 2] < math.sin(GROUND_ELEVATION_RAD) * cfg.dynamics.tether_length_m:
            crashed, reason = True, "ground"
            break
        # ---- control
        if k % n_ctrl == 0:
            mu = act.force_ratio(rec.line_tension)
            dls = float(policy.act(observation(rec, mu)))
            if not math.isfinite(dls):
                crashed, reason = True, "policy returned a non-finite action"
                break
            L_B, L_D, ainfo = act.rest_lengths(dls, rec.line_length, rec.line_tension)
            if progress is not None:
                progress(rec.t)
        # ---- step
        t0 = time.perf_counter()
        try:
            rec = sim.step(L_B, L_D)
        except SimulationError as exc:
            crashed, reason = True, exc.reason
            break
        t_step = time.perf_counter() - t0
    series = {k: np.stack(v) for k, v in rows.items()}
    meta = {
        "crashed": crashed, "termination_reason": reason, "sim_time_s": float(series["t"][-1]),
        "wall_time_s": time.perf_counter() - t_wall0, "dt_s": cfg.dynamics.dt_s,
        "control_dt_s": n_ctrl * cfg.dynamics.dt_s, "L_B0": sim.L_B0, "L_D0": sim.L_D0,
        "pair_stiffness_N_per_m": sim.pair_stiffness.tolist(), "n_sections": int(len(mesh.sections)),
        "design_tip_distance_m": float(np.linalg.norm(design[mesh.bridle[0]] - design[mesh.bridle[2]])),
        "warmup_s": cfg.sim.warmup_s,
    }
    return FlightLog(series=series, meta=meta, snapshots=snapshots)
