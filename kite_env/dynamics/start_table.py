"""The start table's build: the full model's start (:meth:`kite_env.dynamics.simulator.FlightSimulator.start_wing`)
run on a grid of apparent velocities (``kite-fit start-table``), stored as the reduced-order wing's
:class:`~kite_env.surrogate.start.StartTable` (the table, its interpolation and its file live with the wing, below
the dynamics; the fast fidelity's reset reads it).
"""

from __future__ import annotations

import time

import numpy as np

from kite_env.config import fingerprint
from kite_env.dynamics.simulator import FlightSimulator, SimulationError
from kite_env.fsi import FlightState, WingConvergenceError
from kite_env.surrogate.samples import git_commit
from kite_env.surrogate.start import StartTable


class _NoWind:
    """Still air: the table's flight states carry the apparent velocity in ``v_kite`` (the wing sees only v_app)."""

    def velocity(self, t, r):
        return np.zeros((len(np.atleast_2d(r)), 3))


def start_state(cfg, s: float, w: float):
    """The full model's start at one grid point: a fresh :class:`FlightSimulator` (so that the result does not
    depend on earlier solves; the tip-pair stiffness's finite differences are sensitive to the solver's warm state),
    the wing reset with the configured power-line length as in ``reset``, and ``start_wing`` at
    ``v_app = (-s, 0, w)``. Returns ``(q0, F_b, k_pairs)``; raises ``SimulationError`` or
    :class:`~kite_env.fsi.WingConvergenceError` where the full model does not converge."""
    sim = FlightSimulator(cfg, _NoWind())
    sim.particle_wing = not cfg.structure.dynamic  # (the wing with inertia's start has no tip dampers)
    sim.wing.reset()
    sim.wing.line_length_m = cfg.dynamics.power_line_length_m
    X = FlightState(v_kite=np.array([-float(s), 0.0, float(w)]), omega=np.zeros(3), v_wind=np.zeros(3))
    return sim.start_wing(X)


def build_start_table(cfg, s_values, w_values, log=None) -> StartTable:
    """Run the full model's start (:func:`start_state`) at every (s, w) of the grid ``s_values`` x ``w_values``
    [m/s]; points that do not converge are stored as NaN and listed in ``meta["failed"]``. ``log(str)`` reports
    each point."""
    s_values, w_values = np.asarray(s_values, float), np.asarray(w_values, float)
    n_s, n_w = len(s_values), len(w_values)
    q0 = np.full((n_s, n_w, 4, 3), np.nan)
    F_b = np.full((n_s, n_w, 4, 3), np.nan)
    k = np.full((n_s, n_w, 4), np.nan)
    failed, t0 = [], time.perf_counter()
    for a, s in enumerate(s_values):
        for b, w in enumerate(w_values):
            t1 = time.perf_counter()
            try:
                q0[a, b], F_b[a, b], k[a, b] = start_state(cfg, s, w)
                msg = f"|F| = {np.linalg.norm(F_b[a, b].sum(axis=0)):8.1f} N  k_pairs = {np.round(k[a, b], 1)}"
            except (SimulationError, WingConvergenceError) as exc:
                failed.append({"s": float(s), "w": float(w), "error": str(exc).splitlines()[0][:200]})
                msg = "did not converge"
            if log is not None:
                log(f"start table  s = {s:5.1f}  w = {w:6.1f}  {time.perf_counter() - t1:5.2f} s  {msg}")
    meta = {"git_commit": git_commit(), "kite": cfg.kite.name, "config": cfg.to_dict(), "model": fingerprint(cfg),
            "power_line_length_m": float(cfg.dynamics.power_line_length_m), "s_mps": s_values.tolist(),
            "w_mps": w_values.tolist(), "n_points": n_s * n_w, "n_failed": len(failed), "failed": failed,
            "wall_time_s": time.perf_counter() - t0}
    return StartTable(s_values, w_values, q0, F_b, k, meta)
