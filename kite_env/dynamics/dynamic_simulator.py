"""Flight with the wing that has inertia (``structure.dynamic: true``; :mod:`kite_env.dynamics.wing_dynamics`).

The partition sits at the bridle lines: A-D are nodes of the FE wing, integrated implicitly with it; the KCU and the
tether stay in the particle model. One step of ``dt``:

1. the KCU's explicit RK4 step (forces of :class:`~kite_env.dynamics.particles.ParticleSystem`: gravity, the four
   bridle lines of Eq. 10 and half their drag, the optional tether drag; the tether constraint ``|r_KCU| = l_t``
   with Baumgarte's stabilisation, Eq. 12-13), with A-D moving on their Taylor expansion from the start of the step
   (position, velocity and acceleration of the wing's nodes); then its projection onto the tether;
2. the wing's generalized-alpha step in the frame K of the step's start, with the KCU at its new position
   (:meth:`WingDynamics.step`);
3. the new positions of A-D in W, the new frame K from them, and the wing's state re-expressed in it.

Sub-stepping (:meth:`FlightSimulator.step`), the winch, the records and everything the environment reads are those
of :class:`~kite_env.dynamics.simulator.FlightSimulator`; the start is its quasi-static start, from which the wing
moves with the kite's velocity.
"""

from __future__ import annotations

import numpy as np

from kite_env.dynamics.kernels import kcu_line_force
from kite_env.dynamics.lines import LINE_SMOOTHING_N, line_drag, line_tension, tether_drag
from kite_env.dynamics.particles import KCU, ParticleState
from kite_env.dynamics.simulator import FlightSimulator, SimulationError, StepRecord
from kite_env.dynamics.wing_dynamics import WingDynamics
from kite_env.fsi import WingConvergenceError


class DynamicFlightSimulator(FlightSimulator):
    """:class:`FlightSimulator` with the FE wing integrated in time (module docstring)."""

    particle_wing = False  # A-D are wing nodes: no tip dampers, no condensed wing mass

    def __init__(self, cfg, wind, wing=None, backend: str = "auto"):
        super().__init__(cfg, wind, wing, backend)
        self.dyn = WingDynamics(self.wing)
        self._frame_now = None  # (origin, R) of frame K in which the wing's state is expressed
        self._X_now = None  # (particle state, its wing state X): computed for the last record, reused by the next step

    # ------------------------------------------------------------------ set-up
    def reset(self, R0, e_t, speed_mps=None, t0: float = 0.0) -> StepRecord:
        rec = super().reset(R0, e_t, speed_mps, t0)
        st = self.state
        origin, R, _, _, _, X, _ = self._flight_state(self.t, st)
        self._frame_now = (origin, R)
        self._X_now = (st, X)
        x = self.wing.state.x
        v_nodes = X.v_kite[None, :] + np.cross(X.omega[None, :], x)
        g_K = R.T @ np.array([0.0, 0.0, -self.cfg.dynamics.gravity_mps2])
        self.dyn.start(self.wing.state, v_nodes, R.T @ (st.r[KCU] - origin), R.T @ st.v[KCU], self.particles.rest,
                       g_K, self.wing.downwashed(X).v_wind)
        return rec

    # ------------------------------------------------------------------ the KCU
    def _kcu_acceleration(self, t: float, r_k, v_k, r_b, v_b, taut: bool = True):
        """Acceleration (3,) of the KCU on the tether and the tether's multiplier at ``t``, A-D at ``r_b``, ``v_b``;
        ``taut=False``: the KCU flies free (a slack rope, multiplier 0)."""
        p, d = self.particles, self.cfg.dynamics
        wind = np.asarray(self.wind.velocity(t, np.vstack([r_b, r_k[None, :]])), dtype=float)
        m = p.m[KCU]
        f = np.array([0.0, 0.0, -m * d.gravity_mps2])
        # bridle lines (Eq. 10, the wing's smoothed pull-only law) and half their drag (Eq. 11)
        if self.backend == "numba":  # (the same sums, compiled: four calls per step)
            fl = np.empty(3)
            kcu_line_force(np.ascontiguousarray(r_b), np.ascontiguousarray(v_b), r_k, v_k, wind, p.rest,
                           d.line_stiffness_N_per_m, d.line_damping_Ns_per_m, self.dyn.line_drag, LINE_SMOOTHING_N,
                           fl)
            f += fl
        else:
            dl = r_b - r_k
            l = np.linalg.norm(dl, axis=1)
            e = dl / l[:, None]
            T, _ = line_tension(d.line_stiffness_N_per_m * (l - p.rest)
                                + d.line_damping_Ns_per_m * np.einsum("ij,ij->i", e, v_b - v_k))
            f += T @ e
            f += 0.5 * line_drag(self.dyn.line_drag, 0.5 * (v_b + v_k) - 0.5 * (wind[:4] + wind[4]), e, l).sum(axis=0)
        if d.tether_diameter_m > 0.0:
            f += tether_drag(-0.5 * p.rho * d.line_cd * d.tether_diameter_m, r_k, v_k, wind[4])
        if not taut:
            return f / m, 0.0
        self._set_tether(t)
        l, ld = p.tether_length, p.reel_speed
        al = self.cfg.dynamics.baumgarte_1_per_s
        g = 0.5 * (r_k @ r_k - l * l)
        rhs = -(v_k @ v_k - ld * ld) - 2.0 * al * (r_k @ v_k - l * ld) - al * al * g
        lam = m * (rhs - (r_k @ f) / m) / (r_k @ r_k)
        return (f + lam * r_k) / m, lam

    def _kcu_step(self, t: float, dt: float, a_b):
        """The KCU's RK4 step: ``(r, v, lam, drift, jerk)``. On a rope (``dynamics.tether``) the step is made on the
        tether when the KCU starts on it and the tether pulls (``lam < 0``), else in free flight; a free KCU that
        ends beyond the sphere is put back on it and loses its outward radial speed (an inelastic jerk of the
        rope, whose impulse per step ``jerk`` [N] is returned; 0 otherwise)."""
        st = self.state
        r_b0, v_b0 = st.r[:4], st.v[:4]
        taut = True

        def ends(tau):
            return r_b0 + tau * v_b0 + 0.5 * tau * tau * a_b, v_b0 + tau * a_b

        def rhs(tau, r, v):
            rb, vb = ends(tau)
            a, lam = self._kcu_acceleration(t + tau, r, v, rb, vb, taut)
            return v, a, lam

        r0, v0 = st.r[KCU], st.v[KCU]
        k1v, k1a, lam = rhs(0.0, r0, v0)
        if self.cfg.dynamics.tether == "rope":
            on = float(np.linalg.norm(r0)) >= self.particles.tether_length * (1.0 - 1e-9)
            if lam >= 0.0 or not on:
                taut = False
                k1a, lam = k1a - lam * r0 / self.particles.m[KCU], 0.0  # the same forces without the tether
        k2v, k2a, _ = rhs(0.5 * dt, r0 + 0.5 * dt * k1v, v0 + 0.5 * dt * k1a)
        k3v, k3a, _ = rhs(0.5 * dt, r0 + 0.5 * dt * k2v, v0 + 0.5 * dt * k2a)
        k4v, k4a, _ = rhs(dt, r0 + dt * k3v, v0 + dt * k3a)
        r = r0 + dt / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        v = v0 + dt / 6.0 * (k1a + 2 * k2a + 2 * k3a + k4a)
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(v))):
            raise SimulationError("non-finite particle state", f"t = {t + dt:.4f} s")
        self._set_tether(t + dt)
        p = self.particles
        drift = float(np.linalg.norm(r)) - p.tether_length
        jerk = 0.0
        if not taut:
            if drift <= 0.0:
                return r, v, 0.0, 0.0, 0.0  # slack: inside the sphere
            drift = 0.0
        e = r / np.linalg.norm(r)
        r = p.tether_length * e
        dv = v @ e - p.reel_speed
        if not taut:
            jerk = max(dv, 0.0) * p.m[KCU] / dt
            dv = max(dv, 0.0)
        v = v - dv * e
        return r, v, lam, drift, jerk

    # ------------------------------------------------------------------ stepping
    def _step(self, dt: float) -> StepRecord:
        t = self.t
        st = self.state
        dyn, wing = self.dyn, self.wing
        origin, R = self._frame_now
        self._t_step = t
        b = dyn.bridle
        r_k, v_k, lam, drift, jerk = self._kcu_step(t, dt, dyn.a[b] @ R.T)
        X = self._X_now[1] if self._X_now is not None and self._X_now[0] is st else self._flight_state(t, st)[5]
        X_loads = wing.downwashed(X)
        v_w_end = np.asarray(self.wind.velocity(t + dt, origin[None, :]), dtype=float).reshape(3)
        g_K = R.T @ np.array([0.0, 0.0, -self.cfg.dynamics.gravity_mps2])
        v_wind = R.T @ v_w_end + (X_loads.v_wind - X.v_wind)  # the wind at the step's end, with the downwash
        try:
            sol = dyn.step(dt, R.T @ (r_k - origin), R.T @ v_k, self.particles.rest, g_K, v_wind, X)
        except WingConvergenceError as exc:
            raise SimulationError("wing did not converge", str(exc).splitlines()[0], str(exc)) from exc
        if self.cfg.aero.induced_drag:
            wing.update_downwash(sol, X, dt)
        x_b, v_b = dyn.state.x[b], dyn.v[b]
        r = np.vstack([origin + x_b @ R.T, r_k[None, :]])
        v = np.vstack([v_b @ R.T, v_k[None, :]])
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(v))):
            raise SimulationError("non-finite particle state", f"t = {t + dt:.4f} s")
        new = ParticleState(r, v)
        o2, R2, v_ke, om_e, v_we, X_e, _ = self._flight_state(t + dt, new)  # the next frame, and the record's state
        Q, p = R2.T @ R, R2.T @ (origin - o2)
        dyn.rebase(Q, p)
        self._frame_now = (o2, R2)
        self._X_now = (new, X_e)  # the wing state of the next step's start
        wing.rotate_downwash(Q)
        sol.nodes = dyn.state.x.copy()
        sol.F_b = sol.F_b @ Q.T
        sol.aero_force = Q @ sol.aero_force
        self.state = new
        self.t = t + dt
        T, l = self.particles.line_forces(r, v)
        rec = StepRecord(t=self.t, state=new.copy(), wing=sol, R_wk=R2, v_kite=v_ke, omega=om_e, v_wind=v_we,
                         line_tension=T, line_length=l, tether_force=float(-lam * self.tether_length) + jerk,
                         constraint_drift=np.array([drift, 0.0, 0.0]))
        self.tether_length += dt * self.reel_speed
        self._winch(rec.tether_force, dt)
        rec.tether_length, rec.reel_speed = self.tether_length, self.reel_speed
        return rec
