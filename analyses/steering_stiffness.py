"""Where a steering input goes: the wing's stiffness at the steering-line points B and D along their lines, at states
of the baseline flight, split by what supplies it.

    python analyses/steering_stiffness.py [--times 4,6,8,12] [--set section.key=value ...]

Flies the paper's controller with the quasi-static wing (``structure.dynamic=false``: the stiffness is that of the
static aeroelastic equilibrium) and, at each time, solves the wing at the step's end state and linearises it there
with A-D held (:func:`kite_env.analysis.turn_rate.steering_point_stiffness`; the flight goes on from that solution, a
warm start within the solver's tolerance of its own). A change ``dL`` of a steering line's rest length moves its
wing point by ``share dL``, ``share = k_line / (k_line + k_wing)``; the rest stretches the line (its stiffness
``dynamics.line_stiffness_N_per_m``, Table 1: 4.52 kN/m). Columns: the stiffness with the aerodynamic loads
following the shape (``coupled``) and held (``frozen``) [kN/m], each group's ``u^T K_g u`` along the coupled
deformation [kN/m] (``aero`` is minus the work the loads do), the share, and the pitch change of the point's tip
section per metre [deg/m].

Reported in docs/steering.md, "Where a steering input goes". Not run in CI; tests/dynamics/test_steering_stiffness.py
checks the linearisation (at the wind-tunnel state) against the static solve.
"""

from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    import numpy as np

    from kite_env.analysis.turn_rate import STIFFNESS_PARTS, steering_point_stiffness
    from kite_env.config import ConfigError, load_config
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.flight import evaluation_config
    from kite_env.policies.baseline import BaselineAgent

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--times", default="4,6,8,12", help="flight times [s], comma separated, increasing")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    try:
        times = sorted(float(t) for t in args.times.split(","))
        cfg = load_config(None, ["structure.dynamic=false", *args.set])
    except (ConfigError, ValueError) as exc:
        print(f"steering_stiffness: {exc}", file=sys.stderr)
        return 2
    if not times or times[0] <= 0.0:
        print("steering_stiffness: --times must be positive", file=sys.stderr)
        return 2
    env = KiteFigureEightEnv(config=evaluation_config(cfg, times[-1] + 1.0))
    agent = BaselineAgent(env.cfg, env.path)
    obs, _ = env.reset()
    k_line = cfg.dynamics.line_stiffness_N_per_m
    head = "".join(f"{g:>9}" for g in STIFFNESS_PARTS)
    print(f"{'t [s]':>6} {'V [m/s]':>7} {'pt':>3} {'F [N]':>6} {'coupled':>8} {'frozen':>7}{head} {'share':>6} "
          f"{'tip pitch':>10}")
    start, i = True, 0
    while i < len(times):
        action, _ = agent.predict(obs, episode_start=np.array([start]), deterministic=True)
        start = False
        obs, _, terminated, truncated, info = env.step(action)
        if info["t"] + 1e-9 >= times[i]:
            sim = env.sim
            origin, R, _, _, _, X, q_b = sim._flight_state(sim.t, sim.state)
            sol = sim.wing.solve(q_b, X, support="prescribed")  # the state linearised at
            rows = steering_point_stiffness(sim.wing, X, (sim.state.r[4] - origin) @ R, k_line)
            V = float(np.linalg.norm(X.v_wind - X.v_kite))
            for r, j, tip in zip(rows, (1, 3), (0, -1)):
                parts = "".join(f"{r.parts_N_per_m[g] / 1e3:9.2f}" for g in STIFFNESS_PARTS)
                print(f"{info['t']:6.2f} {V:7.1f} {r.point:>3} {np.linalg.norm(sol.F_b[j]):6.0f} "
                      f"{r.coupled_N_per_m / 1e3:8.2f} {r.frozen_N_per_m / 1e3:7.2f}{parts} {r.share:6.2f} "
                      f"{np.rad2deg(r.pitch_per_m[tip]):10.1f}")
            i += 1
        if terminated or truncated:
            print(f"steering_stiffness: the flight ended at t = {info['t']:.2f} s ({info.get('termination_reason')})",
                  file=sys.stderr)
            return 1
    env.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
