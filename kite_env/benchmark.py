"""Speed benchmarks of ``kite-bench`` (:mod:`kite_env.cli.bench`): the environments on one core and the static wing.

:func:`bench_env` times env steps of one fidelity under the paper's controller (the full model's wall time per
simulated second and its Newton iterations per physics step; a time step other than the default is ``--set
dynamics.dt_s=...``), :func:`bench_batched` the fast fidelity's vector env, :func:`bench_wing` the static aeroelastic
wing alone at several mesh resolutions (:func:`bench_resolution`).

A *warm step* of the static wing is what the flight-dynamics integrator asks of the wing at every time step: new
bridle-point positions ``q_b`` and a new flight state, solved from the previous step's shape. The benchmark drives the
wing through a steering manoeuvre sampled at the paper's mean RK45 step (5.3 ms): the rear bridle points B and D move
up and down in opposite phase (0.02 m amplitude, 2 s period), the kite angle of attack varies by +-0.5 deg and the
kite yaws at up to 0.2 rad/s, starting from the converged nominal state (25 m/s, alpha_k = 16 deg). Steps that
fail to converge are counted (``failed_steps``) and the wing is reset to the last converged state.
"""

from __future__ import annotations

import time

import numpy as np

from kite_env.config import Config

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
    from kite_env.fsi import AeroelasticWing, FlightState, WingConvergenceError
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


#: the static wing's default mesh resolutions (sections x chord points); 37 x 6 is the model's own
WING_RESOLUTIONS = ((21, 4), (37, 6), (51, 8))


def bench_wing(kite: str = "rhino16", resolutions=WING_RESOLUTIONS, n_steps: int = 100, progress=None) -> dict:
    """One cold solve and ``n_steps`` warm steps of the static wing of ``kite`` per ``(sections, chord points)`` of
    ``resolutions`` (:func:`bench_resolution`); ``progress(kite, sections, chord)`` is called before each. Returns
    the row of the default resolution 37 x 6 (the first row without it) with ``resolutions`` (all rows), the paper's
    wall time per step and the machine."""
    import platform

    rows = []
    for ns, nc in resolutions:
        if progress is not None:
            progress(kite, ns, nc)
        rows.append(bench_resolution(kite, ns, nc, n_steps=n_steps))
    default = next((r for r in rows if (r["n_sections"], r["n_chord"]) == (37, 6)), rows[0])
    return {**default, "resolutions": rows, "paper_wall_per_step_ms": PAPER_WALL_PER_STEP_MS,
            "machine": {"python": platform.python_version(), "cpu": platform.processor() or platform.machine()}}


# ---------------------------------------------------------------------------------------------- the environments
def bench_env(n_steps: int = 100, overrides=(), seed: int = 0, fidelity: str = "fe", config=None) -> dict:
    """Time ``n_steps`` env steps of KiteFigureEight-v1 in ``fidelity`` driven by the baseline agent (``config``: a
    YAML path or None for the defaults, then ``overrides``). The env is reset (timed separately) and then stepped
    with the paper's controller, so that the flight is the one users see; an episode that ends early is reset and the
    count goes on."""
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.policies.baseline import BaselineAgent

    env = KiteFigureEightEnv(config=config, overrides=overrides, fidelity=fidelity)
    agent = BaselineAgent(env.cfg)
    t0 = time.perf_counter()
    obs, _ = env.reset(seed=seed)
    t_reset = time.perf_counter() - t0
    start, wall, steps, resets = True, 0.0, 0, 0
    newton = []
    while steps < n_steps:
        a, _ = agent.predict(obs, episode_start=start)
        start = False
        t0 = time.perf_counter()
        obs, _, term, trunc, info = env.step(a)
        wall += time.perf_counter() - t0
        newton += info.get("newton_iters", [])
        steps += 1
        if term or trunc:
            obs, _ = env.reset(seed=seed + resets + 1)
            resets += 1
            start = True
    sim = steps * env.control_dt
    out = {"env_steps_per_s": steps / wall, "real_time_factor": wall / sim, "steps": steps,
           "control_dt_s": env.control_dt, "reset_s": t_reset, "resets_during_run": resets}
    if newton:  # the full model's wing: Newton iterations per physics step
        out.update(newton_iters_mean=float(np.mean(newton)), newton_iters_p99=float(np.percentile(newton, 99)),
                   newton_iters_max=int(np.max(newton)))
    return out


def bench_batched(n_kites: int = 64, n_steps: int = 1000, overrides=(), seed: int = 0, config=None) -> dict:
    """Time ``n_steps`` steps of the batched env (``n_kites`` kites in the surrogate fidelity, one process) with
    random actions; kite-steps per second = ``n_kites * n_steps / wall``."""
    import gymnasium as gym

    import kite_env  # noqa: F401  (registers the envs)

    env = gym.make_vec("KiteFigureEightFast-v1", num_envs=n_kites, vectorization_mode="vector_entry_point",
                       config=config, overrides=list(overrides))
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    wall = 0.0
    for _ in range(n_steps):
        a = rng.uniform(-0.3, 0.3, (n_kites, 1)).astype(np.float32)
        t0 = time.perf_counter()
        env.step(a)
        wall += time.perf_counter() - t0
    control_dt = env.unwrapped.control_dt if hasattr(env.unwrapped, "control_dt") else 0.02
    env.close()
    return {"n_kites": n_kites, "kite_steps_per_s": n_kites * n_steps / wall, "steps": n_steps,
            "real_time_factor": wall / (n_kites * n_steps * control_dt)}


def warm_kernels(fidelity: str) -> float:
    """Compile the numba kernels that ``fidelity`` (``fe``, ``surrogate`` or ``batched``) flies with into numba's
    on-disk cache (:mod:`kite_env.compiled`) by a short turbulent flight; returns the wall time [s]. A later process
    loads the cache instead of compiling (a cold full model costs about 30 s of compilation per process on the 2-core
    development machine, the fast fidelity as much again): the test command runs this once per fidelity, in parallel
    with the type check, before its workers start."""
    t0 = time.perf_counter()
    turbulent = ["wind.turbulence_intensity=0.1"]
    if fidelity == "batched":
        bench_batched(n_kites=2, n_steps=3, overrides=turbulent)
    elif fidelity in ("fe", "surrogate"):
        bench_env(n_steps=3, overrides=turbulent, fidelity=fidelity)
    else:
        raise ValueError(f"fidelity must be fe, surrogate or batched, got {fidelity!r}")
    return time.perf_counter() - t0
