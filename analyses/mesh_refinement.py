"""The wing under mesh refinement: the static aeroelastic wing at one wind-tunnel state on several meshes.

    python analyses/mesh_refinement.py [--meshes 37x6,55x6,73x6,37x4,37x5,37x7] [--airspeed 25] [--alpha-deg 8]
                                       [--set section.key=value ...]

For each mesh ``SECTIONSxCHORD`` (``kite.n_sections`` x ``kite.n_chord``) the nominal wing is solved cold at the
wind-tunnel state (A-D prescribed at their design positions, the inflow in the ``x_k``-``z_k`` plane at
``alpha_k``) and the script prints: the wing's aerodynamic force and L/D; that L/D split into its two factors, the
sections' own lift-to-drag ratio ``sum_i |L_i| / sum_i D_i`` (Breukels' 2-D regression at each section's angle) and
the C-shaped arc's projection ``|sum_i L_i| / sum_i |L_i|`` (the sections' lifts point in different directions,
their drags add up); the mid-wing angle of attack; and the wing's stiffness at the steering point B along its line
with A, C, D held (``kite_env.analysis.turn_rate.steering_point_stiffness``) with the share of a steering input that
moves the wing against Table 1's line. A mesh whose cold solve does not reach an equilibrium is reported as such.

Reported in docs/validation.md, "Mesh refinement, L/D, the figure's elevation" (and docs/model.md, "The aeroelastic
wing"). Not run in CI; tests/aero/test_mesh_refinement.py checks the convergence and the L/D split
(:func:`kite_env.analysis.lift_to_drag.lift_to_drag_factors`) on fewer meshes.
"""

from __future__ import annotations

import argparse
import sys
import time


def _meshes(spec: str) -> list[tuple[int, int]]:
    out = []
    for item in spec.split(","):
        ns, _, nc = item.strip().partition("x")
        if not (ns.isdigit() and nc.isdigit()):
            raise ValueError(f"--meshes: {item!r} is not SECTIONSxCHORD (e.g. 37x6)")
        out.append((int(ns), int(nc)))
    if not out:
        raise ValueError("--meshes is empty")
    return out


def main(argv=None) -> int:
    import numpy as np

    from kite_env.analysis.lift_to_drag import lift_to_drag_factors
    from kite_env.analysis.turn_rate import steering_point_stiffness
    from kite_env.config import ConfigError, load_config
    from kite_env.fsi import FlightState, WingConvergenceError, nominal_wing

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--meshes", default="37x6,55x6,73x6,37x4,37x5,37x7", help="SECTIONSxCHORD, comma separated")
    p.add_argument("--airspeed", type=float, default=25.0, help="[m/s]")
    p.add_argument("--alpha-deg", type=float, default=8.0, help="kite angle of attack alpha_k [deg]")
    p.add_argument("--kite", default="rhino16")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    try:
        meshes = _meshes(args.meshes)
        cfgs = [load_config(None, [*args.set, f"kite.n_sections={ns}", f"kite.n_chord={nc}"]) for ns, nc in meshes]
    except (ConfigError, ValueError) as exc:
        print(f"mesh_refinement: {exc}", file=sys.stderr)
        return 2
    if not (args.airspeed > 0.0 and np.isfinite(args.airspeed)):
        print("mesh_refinement: --airspeed must be positive", file=sys.stderr)
        return 2
    flight = FlightState.wind_tunnel(args.airspeed, np.deg2rad(args.alpha_deg))
    print(f"wind tunnel: {args.airspeed:g} m/s, alpha_k {args.alpha_deg:g} deg, A-D at their design positions")
    print(f"{'mesh':>6} {'DOF':>5} {'force [N]':>9} {'L/D':>6} {'sect. L/D':>9} {'projection':>10} "
          f"{'mid alpha':>9} {'k_B [kN/m]':>10} {'share':>6} {'solve [s]':>9}")
    failed = 0
    for (ns, nc), cfg in zip(meshes, cfgs):
        wing = nominal_wing(args.kite, cfg)
        t0 = time.perf_counter()
        try:
            sol = wing.solve(None, flight, warm=False)
        except WingConvergenceError as exc:
            print(f"{ns:>3}x{nc:<2} {6 * wing.mesh.n_nodes:5d}  no equilibrium from the cold start: "
                  f"{str(exc).splitlines()[0]}")
            failed += 1
            continue
        wall = time.perf_counter() - t0
        ld, ld_sec, proj = lift_to_drag_factors(sol.section_forces, flight.v_kite - flight.v_wind)
        rB = steering_point_stiffness(wing, flight, wing.kcu_position(), cfg.dynamics.line_stiffness_N_per_m)[0]
        mid = np.rad2deg(sol.alpha[ns // 2])
        print(f"{ns:>3}x{nc:<2} {6 * wing.mesh.n_nodes:5d} {np.linalg.norm(sol.aero_force):9.0f} {ld:6.2f} "
              f"{ld_sec:9.2f} {proj:10.3f} {mid:9.2f} {rB.coupled_N_per_m / 1e3:10.2f} {rB.share:6.3f} {wall:9.1f}")
    return 1 if failed == len(meshes) else 0


if __name__ == "__main__":
    raise SystemExit(main())
