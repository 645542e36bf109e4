"""Aeroelastic polar of a kite: sweep of the kite angle of attack at a fixed airspeed.

Definitions (also in the README):

* Kite angle of attack ``alpha_k``: angle between the inflow (air relative to the kite) and ``x_k`` in the kite's
  symmetry plane ``x_k``-``z_k``, positive when the air comes from the ``-z_k`` (bridle) side. No sideslip, no
  rotation; the bridle is symmetric.
* Reference area ``S_ref``: the flat canopy area of the unloaded design mesh, ``sum_i c_i w_i`` over the sections
  (chord of Eq. 4 times strip width). This is the area kite makers quote (the Rhino's "16 m2").
* ``CL = L / (q S_ref)``, ``CD = D / (q S_ref)`` with ``q = rho V^2 / 2``; lift perpendicular to the inflow, drag
  along it (totals of the section forces, Eq. 7-8).
* ``CM``: pitching moment of the aerodynamic forces about the kite-frame origin ``r_k`` (mid-point of the LE bridle
  points A and C) around ``y_k``, positive nose-up, divided by ``q S_ref c_ref`` with ``c_ref`` the chord of the
  centre section of the design mesh.
* Support: ``support="lines"`` of :class:`kite_env.fsi.AeroelasticWing`: bridle points held in ``x_k`` and ``z_k``,
  free in ``y_k`` and pulled towards the kite control unit by their lines, so the tips can be drawn inward.

Each point is warm-started from the neighbouring converged point; the sweep starts cold at the angle closest to
``start_alpha``. A point that does not converge is recorded with ``converged = False`` and NaN coefficients (the
reason in ``message``) and the sweep continues from the last converged shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kite_env.aero.sections import section_geometry
from kite_env.fsi import AeroelasticWing, FlightState, WingConvergenceError

POLAR_COLUMNS = ("alpha_deg", "CL", "CD", "L_over_D", "CM", "tip_distance_m", "max_displacement_m",
                 "coupling_iterations", "newton_iterations", "converged")


@dataclass
class PolarPoint:
    alpha_deg: float
    CL: float
    CD: float
    L_over_D: float
    CM: float
    tip_distance_m: float
    max_displacement_m: float
    coupling_iterations: int
    newton_iterations: int
    converged: bool
    message: str = ""
    nodes: np.ndarray | None = None

    def row(self) -> list:
        return [getattr(self, c) for c in POLAR_COLUMNS]


def reference_values(wing: AeroelasticWing) -> tuple[float, float]:
    """Flat reference area ``S_ref`` [m2] and reference chord ``c_ref`` [m] of the unloaded design."""
    mesh = wing.mesh
    geo = section_geometry(mesh.nodes[mesh.sections], mesh.section_tube_d)
    area = float(np.sum(geo.chord * mesh.section_width))
    c_ref = float(geo.chord[len(geo.chord) // 2])
    return area, c_ref


def parse_alpha_range(spec: str) -> np.ndarray:
    """``"a:b:c"`` [deg] -> angles from a to b (inclusive) in steps of c; ``"a"`` -> one angle."""
    parts = spec.split(":")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"--alpha-deg must look like START:STOP:STEP in degrees, got {spec!r}") from None
    if len(vals) == 1:
        vals = [vals[0], vals[0], 1.0]
    if len(vals) != 3:
        raise ValueError(f"--alpha-deg must look like START:STOP:STEP in degrees, got {spec!r}")
    a, b, c = vals
    if not all(np.isfinite(vals)) or c <= 0 or b < a:
        raise ValueError(f"--alpha-deg {spec!r}: need START <= STOP and STEP > 0")
    n = int(np.floor((b - a) / c + 1e-9)) + 1
    if n > 361:
        raise ValueError(f"--alpha-deg {spec!r} gives {n} points; at most 361 are allowed")
    if a < -30 or b > 45:
        raise ValueError(f"--alpha-deg {spec!r}: angles must lie within -30..45 deg")
    return a + c * np.arange(n)


def _point(wing, sol, alpha_deg, area, c_ref, rho, airspeed) -> PolarPoint:
    q = 0.5 * rho * airspeed**2
    # pitching moment of the aero forces about r_k around y_k
    r = sol.nodes[wing.mesh.sections]  # (n_sec, m, 3)
    m_vec = np.einsum("ijk->k", np.cross(r, sol.section_forces))
    # with x_k aft and z_k up, a rotation about +y_k moves the trailing edge down: +M_y is nose-up
    cm = m_vec[1] / (q * area * c_ref)
    A, _, C, _ = wing.bridle
    return PolarPoint(
        alpha_deg=float(alpha_deg), CL=sol.lift / (q * area), CD=sol.drag / (q * area),
        L_over_D=sol.lift_to_drag, CM=float(cm),
        tip_distance_m=float(np.linalg.norm(sol.nodes[A] - sol.nodes[C])),
        max_displacement_m=float(np.max(np.linalg.norm(sol.nodes - wing.mesh.nodes, axis=1))),
        coupling_iterations=sol.coupling_iters, newton_iterations=sol.newton_iters, converged=True,
        nodes=sol.nodes)


def sweep(wing: AeroelasticWing, airspeed_mps: float, alphas_deg, start_alpha_deg: float = 8.0,
          support: str = "lines", progress=None) -> list[PolarPoint]:
    """Polar points for ``alphas_deg`` (sorted ascending in the result)."""
    if not airspeed_mps > 0:
        raise ValueError(f"airspeed must be > 0 m/s, got {airspeed_mps}")
    alphas = np.sort(np.asarray(alphas_deg, dtype=float))
    area, c_ref = reference_values(wing)
    rho = wing.cfg.aero.rho_kg_m3
    i0 = int(np.argmin(np.abs(alphas - start_alpha_deg)))
    order = [list(range(i0, len(alphas))), list(range(i0 - 1, -1, -1))]
    points: dict[int, PolarPoint] = {}
    wing.reset()
    # cold start at the first angle: the ramp of dynamic pressure is in AeroelasticWing.solve(warm=False)
    start_state = None
    for branch in order:
        if start_state is not None:
            wing.state = start_state.copy()
        for i in branch:
            a = alphas[i]
            flight = FlightState.wind_tunnel(airspeed_mps, np.deg2rad(a))
            try:
                try:
                    sol = wing.solve(None, flight, support=support, warm=start_state is not None)
                    points[i] = _point(wing, sol, a, area, c_ref, rho, airspeed_mps)
                except WingConvergenceError:
                    if start_state is None:  # that was already a cold start
                        raise
                    # second attempt: cold start with the dynamic-pressure ramp from the unloaded wing
                    good = wing.state.copy()
                    try:
                        sol = wing.solve(None, flight, support=support, warm=False)
                        points[i] = _point(wing, sol, a, area, c_ref, rho, airspeed_mps)
                    except WingConvergenceError:
                        wing.state = good
                        raise
            except WingConvergenceError as exc:
                first_line = str(exc).splitlines()[0]
                points[i] = PolarPoint(float(a), *([np.nan] * 6), 0, 0, False, first_line)
            if progress is not None:
                progress(points[i])
            if start_state is None and points[i].converged:
                start_state = wing.state.copy()
        if start_state is None:
            break
    return [points[i] for i in sorted(points)]
