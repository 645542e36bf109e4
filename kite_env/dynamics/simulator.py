"""Flight simulation: the particle system coupled with the static aeroelastic wing (Bosch et al., Sect. II.D, Fig. 6).

One time step ``dt`` (``dynamics.dt_s``):

1. frame K, its origin velocity ``v_k`` and rotation rate ``omega_k`` from A-D
   (:func:`kite_env.frames.kite_frame_rates`); the wing state X = (v_k, omega_k, v_w) and the bridle-point
   positions ``q_b`` in K;
2. the static aeroelastic wing at ``q_b`` and X (:class:`kite_env.fsi.AeroelasticWing`), warm-started from the last
   step, with the deformation velocity of Eq. (3) over ``dt``; it returns ``F_b``, and ``F_k = -F_b`` acts on A-D;
3. the particle system (:mod:`kite_env.dynamics.particles`) advanced by one classical Runge-Kutta step (RK4). The
   wing force is held constant in frame K over the step (it turns with the kite through the stage frames), as in
   the staggered scheme of Fig. 6 where the wing is solved once per step;
4. positions and velocities projected onto the tether and tip constraints (the drift before the projection is
   recorded).

The paper used Matlab's adaptive RK45 (mean step 5.3 ms); we use a fixed step of the same size so that a run is
reproducible bit for bit and the wing's warm start sees equal steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kite_env.compiled import resolve_backend
from kite_env.config import Config
from kite_env.dynamics.kernels import particle_accelerations, project_constraints, reel_out_speed
from kite_env.dynamics.particles import DAMPED_PAIRS, A, B, C, D, ParticleState, ParticleSystem
from kite_env.dynamics.wing_mass import condensed_wing_mass, nodal_wing_mass
from kite_env.frames import kite_frame, kite_frame_rates
from kite_env.fsi import AeroelasticWing, FlightState, WingConvergenceError, WingSolution, nominal_wing
from kite_env.structure.rotations import expm


class SimulationError(RuntimeError):
    """The flight simulation cannot continue (wing did not converge, non-finite state); ``reason`` says why,
    ``detail`` in one line; ``history`` the wing solver's whole message with its residual history, where it failed."""

    def __init__(self, reason: str, detail: str = "", history: str = ""):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail
        self.history = history


class NumericalFailure(SimulationError):
    """A step of the wing with inertia that failed even when made in halves down to its smallest sub-step, or a
    non-finite state: a bug of the simulator, never an episode end (docs/environment.md, "NumericalFailure").
    Raised by the environment's ``step``; the message has the time, the conditions of the episode and the wing
    solver's residual history."""

    def __init__(self, error: SimulationError, t: float, conditions: str):
        super().__init__(error.reason, error.detail, error.history)
        self.t = t
        self.conditions = conditions
        self.args = (f"numerical failure at t = {t:.4f} s ({conditions}): {error.reason}"
                     + (f": {error.detail}" if error.detail else "")
                     + "\nthis is a bug of the simulator, not an end of the flight; please report it with the command"
                     + (f"\n{error.history}" if error.history else ""),)

    def __reduce__(self):  # rebuilt from its parts when pickled (a worker process hands it back whole)
        return NumericalFailure, (SimulationError(self.reason, self.detail, self.history), self.t, self.conditions)


@dataclass
class StepRecord:
    """What one time step produced (frame W unless noted)."""

    t: float
    state: ParticleState
    wing: WingSolution
    R_wk: np.ndarray  # (3, 3) kite frame at the start of the step
    v_kite: np.ndarray  # (3,) velocity of r_k [m/s]
    omega: np.ndarray  # (3,) rotation rate of K [rad/s]
    v_wind: np.ndarray  # (3,) wind at r_k [m/s]
    line_tension: np.ndarray  # (4,) F_c of the bridle lines A, B, C, D [N]
    line_length: np.ndarray  # (4,) [m]
    tether_force: float  # [N], constraint force of the tether
    constraint_drift: np.ndarray  # (3,) [m] before the projection
    substeps: int = 1  # steps the time step was made in (FlightSimulator.step: halved where the wing failed)
    tether_length: float = float("nan")  # l_t at the end of the step [m]
    reel_speed: float = 0.0  # winch reel-out speed of the next step [m/s]


class FlightSimulator:
    """The complete flight model: five masses, bridle, tether and the aeroelastic wing.

    Parameters
    ----------
    cfg : Config
    wind : object with ``velocity(t, r) -> (n, 3)`` in W
    wing : AeroelasticWing, optional
        Built from ``cfg.kite`` when not given.
    backend : {"auto", "numba", "numpy"}
        Right-hand side of the particle system (:meth:`_rhs`): ``"numpy"`` the reference
        (:class:`~kite_env.dynamics.particles.ParticleSystem`), ``"numba"`` the compiled kernel
        :func:`kite_env.dynamics.kernels.particle_accelerations` (same results to round-off); ``"auto"``: see
        :func:`kite_env.compiled.resolve_backend`.
    """

    #: the wing model flying: "fe" here, "surrogate" in the fast fidelity
    fidelity_now = "fe"
    #: A-D are particles that carry the quasi-static wing's reaction: the start measures the wing's stiffness between
    #: them for the tip dampers and condenses the wing's distributed mass onto them (False: the wing with inertia,
    #: whose A-D are wing nodes; no tip dampers, ``pair_stiffness`` zero)
    particle_wing = True

    def __init__(self, cfg: Config, wind, wing: AeroelasticWing | None = None, backend: str = "auto"):
        self.cfg = cfg
        self.wind = wind
        self.backend = resolve_backend(backend)
        self.wing = wing if wing is not None else nominal_wing(cfg.kite.name, cfg)
        self.dt = cfg.dynamics.dt_s
        q0 = self.wing.design_bridle
        self.tip_lengths = np.array([np.linalg.norm(q0[0] - q0[1]), np.linalg.norm(q0[2] - q0[3])])
        self.particles: ParticleSystem | None = None
        self.state: ParticleState | None = None
        self.t = 0.0
        self.L_B0 = self.L_D0 = None
        self._F_k_K = None  # wing force on A-D held over the step, frame K
        self._F_end_K = None  # predictor-corrector: wing force at the end of the step
        self.tether_length = cfg.dynamics.tether_length_m  # l_t [m] (the winch: dynamics.winch)
        self.reel_speed = 0.0  # dl_t/dt [m/s], held over a step
        self._t_step = 0.0  # start of the step being made (tether length within it)

    # ------------------------------------------------------------------ set-up
    def _flight_state(self, t: float, st: ParticleState):
        origin, R, v_k, omega = kite_frame_rates(st.r[:4], st.v[:4])
        v_w = np.asarray(self.wind.velocity(t, origin[None, :]), dtype=float).reshape(3)
        X = FlightState(v_kite=R.T @ v_k, omega=R.T @ omega, v_wind=R.T @ v_w)
        q_b = (st.r[:4] - origin) @ R
        return origin, R, v_k, omega, v_w, X, q_b

    def reset(self, R0: np.ndarray, e_t: np.ndarray, speed_mps: float | None = None, t0: float = 0.0) -> StepRecord:
        """Place the kite with its KCU at ``l_t R0`` flying along the unit tangent ``e_t`` and solve the wing cold.

        The kite frame is oriented with the nose (``-x_k``) along the tangential part of the apparent velocity
        (no sideslip) and pitched about ``y_k`` so that the bridle (KCU to r_k) continues the tether. The KCU sits
        below the tip mid-chord (as :meth:`AeroelasticWing.kcu_position`) at the power-line rest length plus the
        static line stretch. The steering-line rest lengths ``L_B0 = L_D0`` are set so that the initial steering
        lines carry their share of the initial wing force (the controllers adjust them from there).
        """
        cfg = self.cfg
        speed = cfg.start_speed_mps if speed_mps is None else float(speed_mps)
        R0 = np.asarray(R0, float) / np.linalg.norm(R0)
        e_t = np.asarray(e_t, float)
        e_t = e_t - (e_t @ R0) * R0
        e_t /= np.linalg.norm(e_t)
        wing = self.wing
        wing.reset()
        wing.line_length_m = cfg.dynamics.power_line_length_m
        v0 = speed * e_t
        v_wind = np.asarray(self.wind.velocity(t0, (cfg.dynamics.tether_length_m * R0)[None, :])).reshape(3)
        # orientation before the pitch: nose (-x') along the tangential part of the apparent velocity v0 - v_w (no
        # sideslip, a symmetric start), z' = R0 (away from the ground)
        nose = v0 - v_wind
        nose = nose - (nose @ R0) * R0
        xp, zp = -nose / np.linalg.norm(nose), R0
        yp = np.cross(zp, xp)
        R_base = np.stack([xp, yp, zp], axis=1)
        X = FlightState(v_kite=R_base.T @ v0, omega=np.zeros(3), v_wind=R_base.T @ v_wind)
        q0, F_b0, k_pairs = self.start_wing(X)
        kcu = wing.kcu_position()
        e_line = kcu - q0
        e_line /= np.linalg.norm(e_line, axis=1, keepdims=True)
        T0 = np.maximum(np.einsum("ij,ij->i", -F_b0, -e_line), 1.0)  # wing pull along each line [N]
        k_c = cfg.dynamics.line_stiffness_N_per_m
        # KCU on the symmetry plane at the stretched power-line length from A and C
        L_pow = cfg.dynamics.power_line_length_m + 0.5 * (T0[0] + T0[2]) / k_c
        a = q0[0]
        h = np.sqrt(max(L_pow**2 - a[1] ** 2 - (kcu[0] - a[0]) ** 2, 1.0))
        kcu = np.array([kcu[0], 0.0, a[2] - h])
        theta = np.arctan2(-kcu[0], -kcu[2])
        R_wk = expm(theta * yp) @ R_base  # rotation by theta about the unit vector y'
        r_kcu = cfg.dynamics.tether_length_m * R0
        origin = r_kcu - R_wk @ kcu
        r = np.vstack([origin + q0 @ R_wk.T, r_kcu[None, :]])
        v = np.repeat(v0[None, :], 5, axis=0)
        l_B, l_D = np.linalg.norm(r[B] - r_kcu), np.linalg.norm(r[D] - r_kcu)
        self.L_B0 = float(0.5 * (l_B + l_D) - 0.5 * (T0[1] + T0[3]) / k_c)
        self.L_D0 = self.L_B0
        self.pair_stiffness = k_pairs
        self.particles = ParticleSystem(cfg.dynamics, self.tip_lengths, k_pairs, cfg.aero.rho_kg_m3)
        self.tether_length, self.reel_speed, self._t_step = cfg.dynamics.tether_length_m, 0.0, t0
        self.particles.set_steering(self.L_B0, self.L_D0)
        r, v = self._project(r, v)
        self.state = ParticleState(r, v)
        self.t = t0
        rec = self._solve_wing(first=True)
        rec.tether_length = self.tether_length
        f = cfg.dynamics.wing_point_mass_share
        if f < 1.0 and self.particle_wing:  # the wing mass: a share at the four points, the rest condensed onto them
            M = condensed_wing_mass(wing, nodal_wing_mass(wing.mesh, cfg.dynamics), shape=rec.wing.nodes)
            self.particles.set_wing_mass((1.0 - f) * M + f * np.diag(np.repeat(self.particles.m[:4], 3)))
        return rec

    def start_wing(self, X: FlightState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The wing at the start: static equilibrium held by its bridle lines (tips free to move in y_k) at the
        flight state ``X`` (frame of the start, no rotation), so that the flight does not start with the unloaded
        design tip distance. Returns the bridle points ``q0`` (4, 3) [m] and forces ``F_b`` (4, 3) [N] in K and the
        tip-pair stiffness (4,) [N/m] (:func:`tip_stiffness`). The solution is the wing's warm start."""
        wing = self.wing
        try:
            sol = wing.solve(None, X, support="lines", warm=False)
        except WingConvergenceError as exc:
            sol = self._start_by_continuation(X, exc)
        q0 = sol.nodes[wing.bridle].copy()
        k_pairs = tip_stiffness(wing, q0, X, sol) if self.particle_wing else np.zeros(len(DAMPED_PAIRS))
        return q0, sol.F_b.copy(), k_pairs

    #: kite speeds (times the start's) from which the start's wing is continued when its cold solve fails
    START_SPEED_FACTORS = (1.25, 1.5, 2.0)

    def _start_by_continuation(self, X: FlightState, first: WingConvergenceError):
        """The start's static wing where its cold solve (a load ramp from the unloaded wing) fails: a continuation in
        the kite's speed. The cold solve is made at the same start flown faster (``START_SPEED_FACTORS``: the
        apparent wind closer to the chord, a smaller angle of attack), then the speed is brought back to the
        start's in warm solves by :meth:`AeroelasticWing.continuation` (a quarter of the way at most, halved where
        a solve fails). Where the cold solve failed, a start in turbulence at 4 m/s (17.6 m/s: the inflow 11 deg off
        the path) had no converged wing and the env drew the start again (docs/environment.md, "Starts")."""
        wing = self.wing
        errors = [str(first).splitlines()[0]]
        for f in self.START_SPEED_FACTORS:
            def at(lam, f=f):
                return FlightState(v_kite=X.v_kite * (f + (1.0 - f) * lam), omega=X.omega, v_wind=X.v_wind)

            last = []

            def solve_at(state, lam, last=last):
                last[:] = [wing.solve(None, at(lam), support="lines", warm=True)]
                return wing.state

            wing.reset()  # (a failed solve leaves its factorisations, secants and line tensions behind)
            try:
                last[:] = [wing.solve(None, at(0.0), support="lines", warm=False)]
                wing.continuation(wing.state, 0.0, 1.0, 0.25, solve_at, [])
            except WingConvergenceError as exc:
                errors.append(f"x{f}: {str(exc).splitlines()[0]}")
                continue
            return last[0]
        raise SimulationError("wing did not converge at the initial state", "; ".join(errors))

    # ------------------------------------------------------------------ stepping
    def _solve_wing(self, first: bool = False, commit: bool = True, state: ParticleState | None = None,
                    t: float | None = None, dt: float | None = None) -> StepRecord:
        """Wing at the particle ``state`` and time ``t`` (default: the current ones). With ``commit`` the solution
        is the wing's new warm start and Eq. 3 reference, and its force is held over the next step."""
        st = self.state if state is None else state
        t = self.t if t is None else t
        origin, R, v_k, omega, v_w, X, q_b = self._flight_state(t, st)
        try:
            step = None if first else (self.dt if dt is None else dt)
            sol = self.wing.solve(q_b, X, dt=step, support="prescribed", warm=True, commit=commit)
        except WingConvergenceError as exc:
            raise SimulationError("wing did not converge", str(exc).splitlines()[0], str(exc)) from exc
        if commit:
            self._F_k_K = -sol.F_b
            self._q_b_K = q_b
            self._K_b = self.wing.bridle_stiffness()
        T, l = self.particles.line_forces(st.r, st.v)
        return StepRecord(t=t, state=st.copy(), wing=sol, R_wk=R, v_kite=v_k, omega=omega, v_wind=v_w,
                          line_tension=T, line_length=l, tether_force=float("nan"), constraint_drift=np.zeros(3))

    def _rhs(self, t: float, r: np.ndarray, v: np.ndarray, frac: float = 0.0):
        """Velocities ``v``, constrained accelerations ``a`` (5, 3) and multipliers ``lam`` (3,) at ``t``, with the wing
        force of the step (``frac``: fraction of the step, used by the predictor-corrector interpolation)."""
        self._set_tether(t)
        if self.backend == "numba":
            interpolate = self._F_end_K is not None
            wind = np.asarray(self.wind.velocity(t, r), dtype=float)
            a, lam = particle_accelerations(r, v, wind, self._F_k_K, self._F_end_K if interpolate else self._F_k_K,
                                            float(frac), interpolate, self._q_b_K, self._K_b,
                                            *self.particles.kernel_parameters())
            return v, a, lam
        origin, R = _frame(r)
        if self._F_end_K is not None:
            # corrector: the wing force interpolated in time between the solutions at both ends of the step
            f_K = self._F_k_K + frac * (self._F_end_K - self._F_k_K)
        else:
            # the step's solution, corrected linearly for the bridle points' move within the step (condensed wing
            # stiffness): without it the held force lags the motion and the tip modes of the wing are excited
            dq = ((r[:4] - origin) @ R - self._q_b_K).ravel()
            f_K = self._F_k_K - (self._K_b @ dq).reshape(4, 3)
        f_wing = f_K @ R.T
        wind = np.asarray(self.wind.velocity(t, r), dtype=float)
        f, _ = self.particles.forces(r, v, wind, f_wing)
        a, lam = self.particles.accelerations(r, v, f)
        return v, a, lam

    def _set_tether(self, t: float) -> None:
        """The particle system's tether length at ``t`` within the step: ``l_t + (t - t_step) dl_t/dt``."""
        p = self.particles
        p.tether_length = self.tether_length + (t - self._t_step) * self.reel_speed
        p.reel_speed = self.reel_speed

    def _project(self, r: np.ndarray, v: np.ndarray):
        """Positions and velocities projected onto the distance constraints (compiled or NumPy reference), with the
        tether length as last set (:meth:`_set_tether`)."""
        if self.backend == "numba":
            p = self.particles
            return project_constraints(r, v, p.m, p.tether_length, p.tip_lengths, 3, p.reel_speed)
        return self.particles.project(r, v)

    def _rk4(self, t, r0, v0, dt: float | None = None):
        dt = self.dt if dt is None else dt
        k1v, k1a, lam = self._rhs(t, r0, v0, 0.0)
        k2v, k2a, _ = self._rhs(t + 0.5 * dt, r0 + 0.5 * dt * k1v, v0 + 0.5 * dt * k1a, 0.5)
        k3v, k3a, _ = self._rhs(t + 0.5 * dt, r0 + 0.5 * dt * k2v, v0 + 0.5 * dt * k2a, 0.5)
        k4v, k4a, _ = self._rhs(t + dt, r0 + dt * k3v, v0 + dt * k3a, 1.0)
        r = r0 + dt / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        v = v0 + dt / 6.0 * (k1a + 2 * k2a + 2 * k3a + k4a)
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(v))):
            raise SimulationError("non-finite particle state", f"t = {t + dt:.4f} s")
        self._set_tether(t + dt)
        drift = self.particles.constraint_violation(r)
        r, v = self._project(r, v)
        return r, v, lam, drift

    def step(self, L_B: float, L_D: float) -> StepRecord:
        """Advance by ``dt`` with the steering-line rest lengths ``L_B`` (right), ``L_D`` (left) [m].

        A step whose wing solve does not converge is repeated as two half steps, each of them halved again where it
        fails, down to ``dt / 2**dynamics.max_substep_halvings`` (a quasi-static wing passing through a luffing
        event follows its aerodynamically damped motion, whose backward-Euler step matrix ``K_T - J + C/dt`` is
        positive definite again for a small enough step; docs/validation.md, "The overloaded wing on the constant
        tether"). The record's
        ``substeps`` says how many steps were made (1: none split). Only a sub-step of the smallest size that still
        fails raises :class:`SimulationError`, with the wing's message.
        """
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        self.particles.set_steering(L_B, L_D)
        rec, n = self._step_split(self.dt, self.cfg.dynamics.max_substep_halvings)
        rec.substeps = n
        return rec

    def _step_split(self, dt: float, halvings: int) -> tuple[StepRecord, int]:
        try:
            return self._step(dt), 1
        except SimulationError as exc:
            if exc.reason != "wing did not converge" or halvings <= 0:
                raise
        rec1, n1 = self._step_split(0.5 * dt, halvings - 1)
        rec2, n2 = self._step_split(0.5 * dt, halvings - 1)
        rec2.wing.newton_iters += rec1.wing.newton_iters
        return rec2, n1 + n2

    def _step(self, dt: float) -> StepRecord:
        """One step of ``dt`` (explicit particle step, then the wing at its end); on a wing failure the simulator
        is left as it was before the step."""
        t = self.t
        r0, v0 = self.state.r, self.state.v
        self._F_end_K = None
        self._t_step = t
        r, v, lam, drift = self._rk4(t, r0, v0, dt)
        if self.cfg.dynamics.coupling == "predictor_corrector":
            # predictor: wing at the end of the explicit step (not committed); corrector: the step again with the
            # wing force interpolated between both ends (a trapezoidal coupling of the wing force)
            pred = self._solve_wing(commit=False, state=ParticleState(r, v), t=t + dt, dt=dt)
            self._F_end_K = -pred.wing.F_b
            r, v, lam, drift = self._rk4(t, r0, v0, dt)
            self._F_end_K = None
        rec = self._solve_wing(state=ParticleState(r, v), t=t + dt, dt=dt)
        self.state = rec.state
        self.t = t + dt
        rec.constraint_drift = drift
        # tether tension at the start of the step: the constraint force G^T lambda = lambda r_KCU pulls the KCU
        # towards the ground station (lambda < 0)
        rec.tether_force = float(-lam[0] * self.tether_length)
        self.tether_length += dt * self.reel_speed
        self._winch(rec.tether_force, dt)
        rec.tether_length, rec.reel_speed = self.tether_length, self.reel_speed
        return rec

    def _winch(self, F_t: float, dt: float) -> None:
        """Reel-out speed of the next step (``dynamics.winch``): "fixed" keeps the paper's constant tether; "force"
        lets the speed follow ``clip((F_t - F_set) / c_w, 0, v_max)`` with the time constant ``tau`` (exact
        first-order lag over ``dt``): a winch in force control during the traction phase (reel-in, the other phase
        of a pumping cycle, is not modelled)."""
        d = self.cfg.dynamics
        if d.winch == "fixed":
            return
        self.reel_speed = float(reel_out_speed(F_t, self.reel_speed, dt, d.winch_force_N, d.winch_damping_Ns_per_m,
                                               d.winch_speed_max_mps, d.winch_time_constant_s))


def _frame(r: np.ndarray):
    return kite_frame(r[A], r[B], r[C], r[D])


def tip_stiffness(wing: AeroelasticWing, q_b: np.ndarray, X: FlightState, sol: WingSolution,
                  h: float = 5e-3) -> np.ndarray:
    """Stiffness ``k_ij`` [N/m] of the wing between the damped point pairs (A-C, B-D, A-D, B-C).

    The paper derives its tip damping "from the bending stiffness between the wing tips from numerical experiments";
    here: the two points are moved apart by ``h`` along their connecting line (static, prescribed bridle, warm from
    ``sol``) and ``k = d(F_b,i - F_b,j) . e_ij / d(l_ij)`` from central differences. Negative values (a pair the
    loaded wing pushes apart) are returned as they are and give no damping.
    """
    state0 = wing.state.copy()
    out = np.zeros(len(DAMPED_PAIRS))
    for n, (i, j) in enumerate(DAMPED_PAIRS):
        e = q_b[i] - q_b[j]
        e /= np.linalg.norm(e)
        dF = []
        for sgn in (1.0, -1.0):
            q = q_b.copy()
            q[i] += 0.25 * sgn * h * e
            q[j] -= 0.25 * sgn * h * e
            wing.state = state0.copy()
            s = wing.solve(q, X, support="prescribed", warm=True, commit=False)
            dF.append((s.F_b[i] - s.F_b[j]) @ e)
        # l_ij changed by h between the two solves; a spring k between i and j gives d(F_i - F_j).e = 2 k dl
        out[n] = (dF[0] - dF[1]) / (2.0 * h)
    wing.state = state0
    return out
