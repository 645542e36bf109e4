"""Speed benchmark of the static aeroelastic wing (cold solve, warm time steps, resolution study).

A *warm step* is what the flight-dynamics integrator asks of the wing at every time step: new bridle-point
positions ``q_b`` and a new flight state, solved from the previous step's shape. The benchmark drives the wing
through a steering manoeuvre sampled at the paper's mean RK45 step (5.3 ms): the rear bridle points B and D move
up and down in opposite phase (0.02 m amplitude, 2 s period), the kite angle of attack varies by +-0.5 deg and the
kite yaws at up to 0.2 rad/s, starting from the converged nominal state (25 m/s, alpha_k = 16 deg). Steps that
fail to converge are counted (``failed_steps``) and the wing is reset to the last converged state.
"""

from __future__ import annotations

import time

import numpy as np

from kite_env.config import Config
from kite_env.fsi import AeroelasticWing, FlightState, WingConvergenceError

PAPER_STEP_S = 5.3e-3  # mean RK45 step of the paper (Sect. IV) [s]
PAPER_WALL_PER_STEP_MS = 27.5 / (1.0 / PAPER_STEP_S) * 1e3  # 27.5 s wall per s of flight -> ms per step


def pin_to_one_core() -> None:
    """Run the calling process on its first allowed CPU (the benchmarks report one-core figures); no-op where the
    platform does not support affinity."""
    import os

    if os.name == "posix" and hasattr(os, "sched_setaffinity"):
        try:
            os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
        except OSError:
            pass


def write_json(out_dir, name: str, result: dict) -> None:
    """Write ``result`` to ``out_dir/name`` (folder created) through a temporary file, so that an interrupted run
    leaves no half-written file."""
    import json
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / f".{name}.tmp"
    tmp.write_text(json.dumps(result, indent=2))
    tmp.replace(out / name)


def bench_resolution(kite: str, n_sections: int, n_chord: int, n_steps: int = 100, cfg: Config | None = None,
                     airspeed: float = 25.0, alpha_deg: float = 16.0) -> dict:
    """Time one cold solve and ``n_steps`` warm steps of one mesh resolution."""
    from kite_env.geometry import build_kite

    cfg = cfg or Config()
    mesh = build_kite(kite, n_sections=n_sections, n_chord=n_chord)
    wing = AeroelasticWing(mesh, cfg)
    flight0 = FlightState.wind_tunnel(airspeed, np.deg2rad(alpha_deg))
    row = {"kite": kite, "n_sections": n_sections, "n_chord": n_chord, "nodes": int(mesh.n_nodes),
           "shells": int(len(mesh.shells)), "beams": int(len(mesh.beams)), "dof": int(6 * mesh.n_nodes)}
    t0 = time.perf_counter()
    try:
        sol = wing.solve(None, flight0, support="lines", warm=False)
    except WingConvergenceError:
        nan = float("nan")
        return {**row, "cold_solve_s": nan, "warm_step_ms_median": nan, "warm_step_ms_p90": nan,
                "newton_iters_mean": nan, "coupling_iters_mean": nan, "n_steps": 0, "failed_steps": 0,
                "lift_to_drag_nominal": nan, "cold_failed": True}
    cold = time.perf_counter() - t0
    q0 = sol.nodes[wing.bridle].copy()
    times, newton, coupling = [], [], []
    failed = 0
    for k in range(1, n_steps + 1):
        t = k * PAPER_STEP_S
        s = np.sin(2 * np.pi * t / 2.0)
        q = q0.copy()
        q[1, 2] -= 0.02 * s  # B (right rear) pulled towards the bridle
        q[3, 2] += 0.02 * s  # D released
        fl = FlightState.wind_tunnel(airspeed, np.deg2rad(alpha_deg + 0.5 * s))
        fl = FlightState(fl.v_kite, np.array([0.0, 0.0, 0.2 * s]), fl.v_wind)
        good = wing.state.copy()
        t1 = time.perf_counter()
        try:
            r = wing.solve(q, fl, dt=PAPER_STEP_S, support="prescribed", warm=True)
        except WingConvergenceError:
            failed += 1
            wing.state = good
            continue
        times.append(time.perf_counter() - t1)
        newton.append(r.newton_iters)
        coupling.append(r.coupling_iters)
    times = np.array(times) * 1e3 if times else np.array([np.nan])
    return {
        **row, "cold_solve_s": cold, "failed_steps": failed, "cold_failed": False,
        "warm_step_ms_median": float(np.median(times)), "warm_step_ms_p90": float(np.percentile(times, 90)),
        "newton_iters_mean": float(np.mean(newton)) if newton else float("nan"),
        "coupling_iters_mean": float(np.mean(coupling)) if coupling else float("nan"),
        "n_steps": n_steps, "lift_to_drag_nominal": float(sol.lift_to_drag),
    }


def format_table(rows: list[dict]) -> str:
    cols = [("n_sections", "sections", "d"), ("n_chord", "chord pts", "d"), ("nodes", "nodes", "d"),
            ("shells", "shells", "d"), ("beams", "beams", "d"), ("dof", "DOF", "d"),
            ("cold_solve_s", "cold solve [s]", ".2f"), ("warm_step_ms_median", "warm step median [ms]", ".1f"),
            ("warm_step_ms_p90", "warm step p90 [ms]", ".1f"), ("newton_iters_mean", "Newton it/step", ".2f"),
            ("coupling_iters_mean", "coupling it/step", ".2f"), ("failed_steps", "failed steps", "d")]
    head = "| " + " | ".join(c[1] for c in cols) + " |"
    sep = "|" + "|".join("---:" for _ in cols) + "|"
    lines = [head, sep]
    for r in rows:
        lines.append("| " + " | ".join(format(r[c[0]], c[2]) for c in cols) + " |")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- whole flight model
PAPER_REAL_TIME_FACTOR = 27.5  # wall seconds per simulated second of the paper's Matlab model (Sect. III)


def bench_flight(cfg: Config | None = None, duration_s: float = 3.0, dt_values=(5e-3, 1e-2)) -> list[dict]:
    """Real-time factor of the baseline figure-eight in the full model (wing + particles + controller + logging).

    For each time step in ``dt_values`` the baseline flies ``duration_s`` from the crossing point after a short
    untimed flight (numba compilation and caches). Wall time per simulated second is measured on the whole
    :func:`kite_env.flight.fly` call except its initial cold wing solve (reset), and per step for the simulator
    step (wing solve + RK4) from the flight log. A flight that ends early (the wing fails) is timed up to its end
    and flagged.
    """
    import dataclasses

    from kite_env.flight import fly

    cfg = cfg or Config()
    fly(cfg, None, 0.05)  # warm-up: compile and load the numba kernels
    rows = []
    for dt in dt_values:
        c = dataclasses.replace(cfg, dynamics=dataclasses.replace(cfg.dynamics, dt_s=float(dt)))
        log = fly(c, None, duration_s)
        sim_t = float(log.meta["sim_time_s"])
        step_wall = np.asarray(log.series["wall_time"], dtype=float)[1:]  # step k's wall time is logged at k + 1
        reset_wall = float(log.meta["wall_time_s"]) - float(np.sum(step_wall))  # reset, control, logging
        rows.append({
            "dt_ms": 1e3 * dt, "sim_time_s": sim_t, "completed": log.meta["termination_reason"] == "completed",
            "wall_time_s": float(log.meta["wall_time_s"]),
            "real_time_factor": float(log.meta["wall_time_s"]) / sim_t if sim_t > 0 else float("nan"),
            "step_ms_median": 1e3 * float(np.median(step_wall)),
            "step_ms_p90": 1e3 * float(np.percentile(step_wall, 90)),
            "other_wall_s": reset_wall,
        })
    return rows


def format_flight_table(rows: list[dict]) -> str:
    cols = [("dt_ms", "time step [ms]", ".1f"), ("sim_time_s", "simulated [s]", ".2f"),
            ("wall_time_s", "wall [s]", ".1f"), ("real_time_factor", "wall / simulated", ".2f"),
            ("step_ms_median", "step median [ms]", ".1f"), ("step_ms_p90", "step p90 [ms]", ".1f"),
            ("other_wall_s", "reset + control + logging [s]", ".1f")]
    lines = ["| " + " | ".join(c[1] for c in cols) + " |", "|" + "|".join("---:" for _ in cols) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(format(r[c[0]], c[2]) for c in cols) + " |")
    return "\n".join(lines)
