"""Open-loop steering authority: the yaw rate a held steering input gives, in the full flight model.

The paper (Sect. IV, Fig. 16) calls the steering input and the yaw rate "linearly correlated" in the upper half of
the figure-eight. Here the relation is measured without a controller: the kite starts at the figure's crossing
point flying along the path, the steering-line rest lengths are set to ``L_B = L_0 + dL / 2``, ``L_D = L_0 - dL / 2``
at ``t_hold`` and held; the yaw rate ``omega_k . z_k`` is averaged over a window after the transient, and the same
flight with ``dL = 0`` is subtracted (gravity and the start turn the kite a little by themselves).

``psi_dot / dL`` [rad/s per m] at a few speeds is the number the model's steering is judged by: about 5 in the
paper's Fig. 16 (its two axis scales, +-0.3 m against +-1.5 rad/s), about 2.5-5 in TU Delft V3 flight data
(README, "Steering authority").
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from kite_env.config import Config
from kite_env.dynamics.simulator import FlightSimulator, SimulationError
from kite_env.trajectory import Lemniscate
from kite_env.wind import WindField


@dataclass(frozen=True)
class TurnRate:
    """One open-loop flight: held input ``dl_m`` [m], mean yaw rate [rad/s] in the window (raw, not
    neutral-subtracted), mean airspeed [m/s], how the flight ended (``"ok"`` or the failure reason) and when [s]."""

    dl_m: float
    yaw_rate_rad_s: float
    airspeed_mps: float
    end: str
    t_end_s: float


def open_loop_flight(cfg: Config, dl_m: float, t_hold_s: float = 0.5, window_s: tuple[float, float] = (1.0, 2.5),
                     speed_mps: float | None = None) -> TurnRate:
    """Fly the kite open loop with ``L_B - L_D = dl_m`` held from ``t_hold_s`` and average the yaw rate over
    ``t_hold_s + window_s``.

    Parameters
    ----------
    cfg : Config
        The model (wind from ``cfg.wind``, start at the crossing of ``cfg.trajectory``).
    dl_m : float [m]
        Held steering-line rest-length difference (positive: the right line B longer).
    t_hold_s : float [s]
    window_s : (2,) float [s]
        Averaging window after ``t_hold_s``.
    speed_mps : float, optional [m/s]
        Start speed (default ``cfg.start_speed_mps``).
    """
    path = Lemniscate(cfg.trajectory)
    sim = FlightSimulator(cfg, WindField(cfg.wind))
    rec = sim.reset(path.point(0.0), path.tangent(0.0), speed_mps)
    t0, t1 = t_hold_s + window_s[0], t_hold_s + window_s[1]
    yaw, speed = [], []
    end = "ok"
    try:
        while rec.t < t1 - 1e-9:
            d = dl_m if rec.t >= t_hold_s - 1e-9 else 0.0
            rec = sim.step(sim.L_B0 + 0.5 * d, sim.L_D0 - 0.5 * d)
            if rec.t >= t0 - 1e-9:
                yaw.append(float(rec.omega @ rec.R_wk[:, 2]))
                speed.append(float(np.linalg.norm(rec.v_kite - rec.v_wind)))
    except SimulationError as exc:
        end = exc.reason
    return TurnRate(dl_m=float(dl_m), yaw_rate_rad_s=float(np.mean(yaw)) if yaw else float("nan"),
                    airspeed_mps=float(np.mean(speed)) if speed else float("nan"), end=end, t_end_s=float(sim.t))


def turn_rate_table(cfg: Config, dls_m=(-0.2, 0.1, 0.2, 0.3), wind_speeds_mps=(5.0,), **kwargs) -> list[dict]:
    """Neutral-subtracted yaw rate per input for each wind speed: rows with ``wind_mps``, ``dl_m``,
    ``yaw_rate_rad_s`` (minus the ``dL = 0`` flight), ``per_m`` [rad/s per m], ``airspeed_mps`` and ``end``."""
    rows = []
    for w in wind_speeds_mps:
        c = dataclasses.replace(cfg, wind=dataclasses.replace(cfg.wind, speed_mps=float(w)))
        neutral = open_loop_flight(c, 0.0, **kwargs)
        for dl in dls_m:
            r = open_loop_flight(c, dl, **kwargs)
            d = r.yaw_rate_rad_s - neutral.yaw_rate_rad_s
            rows.append({"wind_mps": float(w), "dl_m": float(dl), "yaw_rate_rad_s": d, "per_m": d / dl,
                         "airspeed_mps": r.airspeed_mps, "end": r.end if r.end == "ok" else f"{r.end} at {r.t_end_s:.2f} s"})
    return rows
