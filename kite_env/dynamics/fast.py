"""The fast fidelity: the particle system with the reduced-order wing, N kites advanced together as arrays.

:class:`SurrogateKites` holds the states of ``n`` independent kites (rows of ``(n, 5, 3)`` arrays: A, B, C, D, KCU
in W) and advances all of them by one RK4 step of ``dynamics.dt_s``. The particle system is the one of the full
model (:func:`kite_env.dynamics.kernels.particle_accelerations`, Sect. II.C, Eq. 10-13: masses, bridle lines, line
drag, tip-pair dashpots, tether and tip constraints, projection after the step); only the wing differs:

* full model (:class:`kite_env.dynamics.simulator.FlightSimulator`): the static FE wing solved once per step (Fig. 6),
  its force held in K and corrected by the condensed stiffness within the step;
* fast fidelity (here): the reduced-order wing :class:`kite_env.surrogate.model.SurrogateWing`, a function of the
  bridle points, their rates, the apparent velocity and the rotation rate in K, evaluated at *every* RK4 stage
  (it is cheap; the stiffness correction of the full model is then implicit in the stage evaluations).

One compiled call (:func:`step_kites`) advances all kites; per kite and stage it evaluates the wing inputs (frame K
and its rates as :func:`kite_env.frames.kite_frame_rates`, the wind at the five masses and at the frame origin), the
MLP one row at a time (:func:`mlp_row`) and the particle right-hand side. A single kite is the case ``n = 1`` of the
same code (:class:`SurrogateFlightSimulator`), so that one kite and a batch give the same trajectory for the same
inputs.

The wing outputs at the end of a step (the states the flight visits) are also the first stage of the next step; they
are checked against the sampled envelope (:meth:`SurrogateWing.outside`, ``status`` ``OUTSIDE``).
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.dynamics.kernels import particle_accelerations, project_constraints
from kite_env.dynamics.particles import ParticleState, ParticleSystem
from kite_env.dynamics.simulator import FlightSimulator, SimulationError, StepRecord
from kite_env.fsi import WingSolution
from kite_env.structure.kernels import njit
from kite_env.wind import _turbulence_kernel

_JIT = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")

#: kite status after a step
OK, NON_FINITE, OUTSIDE = 0, 1, 2
_PROFILES = {"uniform": 0, "log": 1, "power": 2}
_TWO_PI = 2.0 * math.pi


# ---------------------------------------------------------------------------------------------------- kernels
@njit(**_JIT)
def _wind_at(t, pos, out, speed, profile, z_ref, z0, log_den, shear, gust_G, gust_t0, gust_T, turbulent,
             wavevec_t, phase0, omega, amp, n_modes, t_buf):
    """Wind (P, 3) at ``pos`` (P, 3) for one kite: :meth:`kite_env.wind.WindField.velocity` (numba backend)."""
    if turbulent:
        t_buf[0] = t
        _turbulence_kernel(t_buf, pos, wavevec_t, phase0, omega, amp, n_modes, out)
    else:
        for i in range(pos.shape[0]):
            out[i, 0] = 0.0
            out[i, 1] = 0.0
            out[i, 2] = 0.0
    g = 0.0
    if gust_G != 0.0:
        tau = (t - gust_t0) / gust_T
        if 0.0 <= tau <= 1.0:
            g = 0.5 * gust_G * (1.0 - math.cos(_TWO_PI * tau))
    for i in range(pos.shape[0]):
        if profile == 0:
            u = speed + g
        elif profile == 1:
            z = max(pos[i, 2], z0)
            u = speed * math.log(z / z0) / log_den + g
        else:
            z = max(pos[i, 2], 0.0)
            u = speed * (z / z_ref) ** shear + g
        out[i, 0] += u


@njit(**_JIT)
def kite_inputs(t, rk, vk, q_design, wf, wi, wavevec_t, phase0, omega_m, amp, n_modes, x, wind5, R, pos, w6,
                t_buf):
    """Wing inputs ``x`` (30,) of one kite (:data:`kite_env.surrogate.samples.INPUT_NAMES`), the wind ``wind5`` (5, 3)
    at its masses and its frame K ``R`` (3, 3) (columns x_k, y_k, z_k in W) at time ``t`` [s].

    ``rk``, ``vk`` (5, 3): A, B, C, D, KCU in W. ``wf`` (9,): wind speed, z_ref, z0, log(z_ref/z0), shear exponent,
    gust amplitude, start, duration, unused; ``wi`` (2,): profile code (uniform 0, log 1, power 2), turbulent (0/1);
    ``wavevec_t, phase0, omega_m, amp``: the turbulence modes of :class:`kite_env.wind.WindField`. ``pos``, ``w6``
    (6, 3) and ``t_buf`` (1,) are work arrays.
    """
    # ---- frame K (frames.kite_frame) and its rates (frames.kite_frame_rates)
    o = np.empty(3)
    ey = np.empty(3)
    mm = np.empty(3)
    vo = np.empty(3)
    dd = np.empty(3)
    dm = np.empty(3)
    for j in range(3):
        o[j] = 0.5 * (rk[0, j] + rk[2, j])
        ey[j] = rk[0, j] - rk[2, j]
        dd[j] = vk[0, j] - vk[2, j]
        vo[j] = 0.5 * (vk[0, j] + vk[2, j])
        mm[j] = 0.5 * (rk[1, j] + rk[3, j]) - o[j]
        dm[j] = 0.5 * (vk[1, j] + vk[3, j]) - vo[j]
    ld = math.sqrt(ey[0] ** 2 + ey[1] ** 2 + ey[2] ** 2)
    for j in range(3):
        ey[j] /= ld
    s = mm[0] * ey[0] + mm[1] * ey[1] + mm[2] * ey[2]
    xp = np.empty(3)
    for j in range(3):
        xp[j] = mm[j] - s * ey[j]
    lx = math.sqrt(xp[0] ** 2 + xp[1] ** 2 + xp[2] ** 2)
    ex = xp / lx
    ez = np.array([ex[1] * ey[2] - ex[2] * ey[1], ex[2] * ey[0] - ex[0] * ey[2], ex[0] * ey[1] - ex[1] * ey[0]])
    p = ey[0] * dd[0] + ey[1] * dd[1] + ey[2] * dd[2]
    dey = (dd - ey * p) / ld
    mdey = mm[0] * dey[0] + mm[1] * dey[1] + mm[2] * dey[2]
    dmey = dm[0] * ey[0] + dm[1] * ey[1] + dm[2] * ey[2]
    dxp = dm - (dmey + mdey) * ey - s * dey
    q = ex[0] * dxp[0] + ex[1] * dxp[1] + ex[2] * dxp[2]
    dex = (dxp - ex * q) / lx
    dez = np.array([dex[1] * ey[2] - dex[2] * ey[1], dex[2] * ey[0] - dex[0] * ey[2],
                    dex[0] * ey[1] - dex[1] * ey[0]])
    dez += np.array([ex[1] * dey[2] - ex[2] * dey[1], ex[2] * dey[0] - ex[0] * dey[2],
                     ex[0] * dey[1] - ex[1] * dey[0]])
    w = np.zeros(3)  # omega = 1/2 sum_i e_i x de_i/dt
    for e, de in ((ex, dex), (ey, dey), (ez, dez)):
        w[0] += 0.5 * (e[1] * de[2] - e[2] * de[1])
        w[1] += 0.5 * (e[2] * de[0] - e[0] * de[2])
        w[2] += 0.5 * (e[0] * de[1] - e[1] * de[0])
    for j in range(3):
        R[j, 0] = ex[j]
        R[j, 1] = ey[j]
        R[j, 2] = ez[j]
    # ---- wind at the five masses and at the frame origin
    for i in range(5):
        for j in range(3):
            pos[i, j] = rk[i, j]
    for j in range(3):
        pos[5, j] = o[j]
    _wind_at(t, pos, w6, wf[0], wi[0], wf[1], wf[2], wf[3], wf[4], wf[5], wf[6], wf[7], wi[1] != 0, wavevec_t,
             phase0, omega_m, amp, n_modes, t_buf)
    for i in range(5):
        for j in range(3):
            wind5[i, j] = w6[i, j]
    # ---- inputs (samples.features): q_b - q_design, qdot_b (relative to K), v_app, omega, all in K
    wK = np.empty(3)
    for c in range(3):
        wK[c] = w[0] * R[0, c] + w[1] * R[1, c] + w[2] * R[2, c]
    qb = np.empty(3)
    vb = np.empty(3)
    for i in range(4):
        for c in range(3):
            qb[c] = (rk[i, 0] - o[0]) * R[0, c] + (rk[i, 1] - o[1]) * R[1, c] + (rk[i, 2] - o[2]) * R[2, c]
            vb[c] = (vk[i, 0] - vo[0]) * R[0, c] + (vk[i, 1] - vo[1]) * R[1, c] + (vk[i, 2] - vo[2]) * R[2, c]
        x[3 * i + 0] = qb[0] - q_design[i, 0]
        x[3 * i + 1] = qb[1] - q_design[i, 1]
        x[3 * i + 2] = qb[2] - q_design[i, 2]
        x[12 + 3 * i + 0] = vb[0] - (wK[1] * qb[2] - wK[2] * qb[1])
        x[12 + 3 * i + 1] = vb[1] - (wK[2] * qb[0] - wK[0] * qb[2])
        x[12 + 3 * i + 2] = vb[2] - (wK[0] * qb[1] - wK[1] * qb[0])
    for c in range(3):
        x[24 + c] = ((vo[0] - w6[5, 0]) * R[0, c] + (vo[1] - w6[5, 1]) * R[1, c] + (vo[2] - w6[5, 2]) * R[2, c])
        x[27 + c] = wK[c]


@njit(**_JIT)
def _tanh(x):
    """tanh from one exponential, ``sign(x) (1 - e) / (1 + e)`` with ``e = exp(-2|x|)`` (agrees with ``math.tanh``
    to ~2e-16; 2.5x faster here than libm's tanh)."""
    e = math.exp(-2.0 * abs(x))
    return math.copysign((1.0 - e) / (1.0 + e), x)


@njit(**_JIT)
def mlp_row(x, W0, b0, W1, b1, W2, b2, h0, h1, y):
    """``y = tanh(tanh(x W0 + b0) W1 + b1) W2 + b2`` for one row (normalisations folded into the weights)."""
    n0, n1, n2 = W0.shape[1], W1.shape[1], W2.shape[1]
    for j in range(n0):
        h0[j] = b0[j]
    for i in range(x.shape[0]):
        xi = x[i]
        for j in range(n0):
            h0[j] += xi * W0[i, j]
    for j in range(n0):
        h0[j] = _tanh(h0[j])
    for j in range(n1):
        h1[j] = b1[j]
    for i in range(n0):
        hi = h0[i]
        for j in range(n1):
            h1[j] += hi * W1[i, j]
    for j in range(n1):
        h1[j] = _tanh(h1[j])
    for j in range(n2):
        y[j] = b2[j]
    for i in range(n1):
        hi = h1[i]
        for j in range(n2):
            y[j] += hi * W2[i, j]


@njit(**_JIT)
def evaluate_kites(t, r, v, rest, q_design, wind_f, wind_i, wavevec_t, phase0, omega_m, amp, n_modes, W0, b0, W1, b1,
                   W2, b2, k_c, c_c, lo, hi, active, X, Y, wind, R, tension, length, status):
    """Inputs ``X`` (n, 30), wing outputs ``Y`` (n, 17), wind at the masses (n, 5, 3) and frame K (n, 3, 3) of
    every ``active`` kite at its time ``t`` (n,) and state ``r``, ``v`` (n, 5, 3), with its bridle lines and status
    (as :func:`step_kites`)."""
    pos = np.empty((6, 3))
    w6 = np.empty((6, 3))
    t_buf = np.empty(1)
    h0 = np.empty(W0.shape[1])
    h1 = np.empty(W1.shape[1])
    for k in range(r.shape[0]):
        if not active[k]:
            continue
        kite_inputs(t[k], r[k], v[k], q_design, wind_f[k], wind_i[k], wavevec_t[k], phase0[k], omega_m[k], amp[k],
                    n_modes, X[k], wind[k], R[k], pos, w6, t_buf)
        mlp_row(X[k], W0, b0, W1, b1, W2, b2, h0, h1, Y[k])
        _line_state_one(r[k], v[k], rest[k], k_c, c_c, tension[k], length[k])
        finite = True
        for i in range(5):
            for c in range(3):
                if not (math.isfinite(r[k, i, c]) and math.isfinite(v[k, i, c])):
                    finite = False
        status[k] = _status(finite, X[k], Y[k], lo, hi)


@njit(**_JIT)
def _status(finite, x, y, lo, hi):
    if not finite:
        return NON_FINITE
    for j in range(y.shape[0]):
        if not math.isfinite(y[j]):
            return NON_FINITE
    for j in range(x.shape[0]):
        if x[j] < lo[j] or x[j] > hi[j]:
            return OUTSIDE
    return OK


@njit(**_JIT)
def _line_state_one(rk, vk, rest, k_c, c_c, T_out, l_out):
    for i in range(4):
        d0 = rk[i, 0] - rk[4, 0]
        d1 = rk[i, 1] - rk[4, 1]
        d2 = rk[i, 2] - rk[4, 2]
        li = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        ldot = (d0 * (vk[i, 0] - vk[4, 0]) + d1 * (vk[i, 1] - vk[4, 1]) + d2 * (vk[i, 2] - vk[4, 2])) / li
        T = k_c * (li - rest[i]) + c_c * ldot
        T_out[i] = 0.0 if T < 0.0 else T  # NaN propagates (np.maximum)
        l_out[i] = li


@njit(**_JIT)
def _accelerations(rk, vk, wind5, yk, F0, zero_q, zero_K, m, rest, k_c, c_c, rho, line_cd, line_diameter,
                   tether_diameter, tether_length, tip_lengths, pair_damping, gravity, alpha):
    """:func:`particle_accelerations` of one kite with the wing reactions ``yk[:12]`` (F_b in K; the wing pulls
    A-D with ``-F_b``)."""
    for i in range(4):
        for c in range(3):
            F0[i, c] = -yk[3 * i + c]
    return particle_accelerations(rk, vk, wind5, F0, F0, 0.0, False, zero_q, zero_K, m, rest, k_c, c_c, rho, line_cd,
                                  line_diameter, tether_diameter, tether_length, tip_lengths, pair_damping, gravity,
                                  alpha)


@njit(**_JIT)
def step_kites(dt, active, t, r, v, rest, pair_damping, q_design, wind_f, wind_i, wavevec_t, phase0, omega_m, amp,
               n_modes, W0, b0, W1, b1, W2, b2, m, k_c, c_c, rho, line_cd, line_diameter, tether_diameter,
               tether_length, tip_lengths, gravity, alpha, lo, hi, X, Y, wind, R, tether, tension, length, status):
    """One RK4 step of ``dt`` for every ``active`` kite, in place (:class:`SurrogateKites.step`).

    Stage 1 uses ``Y`` and ``wind`` of the current states (the end of the last step); stages 2-4 evaluate the wing
    at their states. After the step: the projection onto the constraints, then ``X``, ``Y``, ``wind``, ``R`` at the
    new states, ``tether`` the tether force at the start of the step [N], the bridle-line ``tension`` and ``length``
    (n, 4) and ``status`` (:data:`OK`; :data:`NON_FINITE`; :data:`OUTSIDE`: an input beyond ``[lo, hi]`` (30,)).
    """
    pos = np.empty((6, 3))
    w6 = np.empty((6, 3))
    t_buf = np.empty(1)
    h0 = np.empty(W0.shape[1])
    h1 = np.empty(W1.shape[1])
    F0 = np.empty((4, 3))
    zero_q = np.zeros((4, 3))
    zero_K = np.zeros((12, 12))
    xs = np.empty(X.shape[1])
    ys = np.empty(Y.shape[1])
    ws = np.empty((5, 3))
    Rs = np.empty((3, 3))
    rs = np.empty((5, 3))
    vn = np.empty((5, 3))
    kv = np.empty((4, 5, 3))  # RK4 stage velocities (k_iv) and accelerations (k_ia)
    ka = np.empty((4, 5, 3))
    half = 0.5 * dt
    for k in range(r.shape[0]):
        if not active[k]:
            continue
        r0, v0 = r[k], v[k]
        a1, lam = _accelerations(r0, v0, wind[k], Y[k], F0, zero_q, zero_K, m, rest[k], k_c, c_c, rho, line_cd,
                                 line_diameter, tether_diameter, tether_length, tip_lengths, pair_damping[k],
                                 gravity, alpha)
        tether[k] = -lam[0] * tether_length
        kv[0] = v0
        ka[0] = a1
        for st in range(1, 4):
            # stages 2, 3 at t + dt/2 from (kv, ka) of the stage before; stage 4 at t + dt
            h = half if st < 3 else dt
            for i in range(5):
                for c in range(3):
                    rs[i, c] = r0[i, c] + h * kv[st - 1, i, c]
                    kv[st, i, c] = v0[i, c] + h * ka[st - 1, i, c]
            vs = kv[st]
            kite_inputs(t[k] + h, rs, vs, q_design, wind_f[k], wind_i[k], wavevec_t[k], phase0[k], omega_m[k],
                        amp[k], n_modes, xs, ws, Rs, pos, w6, t_buf)
            mlp_row(xs, W0, b0, W1, b1, W2, b2, h0, h1, ys)
            a_st, _ = _accelerations(rs, vs, ws, ys, F0, zero_q, zero_K, m, rest[k], k_c, c_c, rho, line_cd,
                                     line_diameter, tether_diameter, tether_length, tip_lengths, pair_damping[k],
                                     gravity, alpha)
            ka[st] = a_st
        ok = True
        for i in range(5):
            for c in range(3):
                rs[i, c] = r0[i, c] + dt / 6.0 * (kv[0, i, c] + 2.0 * kv[1, i, c] + 2.0 * kv[2, i, c] + kv[3, i, c])
                vn[i, c] = v0[i, c] + dt / 6.0 * (ka[0, i, c] + 2.0 * ka[1, i, c] + 2.0 * ka[2, i, c] + ka[3, i, c])
                if not (math.isfinite(rs[i, c]) and math.isfinite(vn[i, c])):
                    ok = False
        t[k] = t[k] + dt
        if ok:
            rp, vp = project_constraints(rs, vn, m, tether_length, tip_lengths, 3)
        else:
            rp, vp = rs, vn
        for i in range(5):
            for c in range(3):
                r[k, i, c] = rp[i, c]
                v[k, i, c] = vp[i, c]
        kite_inputs(t[k], r[k], v[k], q_design, wind_f[k], wind_i[k], wavevec_t[k], phase0[k], omega_m[k], amp[k],
                    n_modes, X[k], wind[k], R[k], pos, w6, t_buf)
        mlp_row(X[k], W0, b0, W1, b1, W2, b2, h0, h1, Y[k])
        _line_state_one(r[k], v[k], rest[k], k_c, c_c, tension[k], length[k])
        status[k] = _status(ok, X[k], Y[k], lo, hi)


# ---------------------------------------------------------------------------------------------------- N kites
class SurrogateKites:
    """``n`` kites with the reduced-order wing, advanced together (module docstring).

    Parameters
    ----------
    cfg : Config
    surrogate : SurrogateWing
    q_design : (4, 3) float [m], unloaded bridle points in K (the surrogate's reference)
    tip_lengths : (2,) float [m], constrained distances A-B, C-D
    n : int, number of kites

    State (rows = kites): ``r``, ``v`` (n, 5, 3), ``t`` (n,), ``rest`` (n, 4) line rest lengths, ``pair_damping``
    (n, 4), the wind of each kite (:meth:`set_wind`). After :meth:`evaluate` or :meth:`step`: ``Y`` (n, 17) the
    wing outputs at the current states, ``X`` (n, 30) their inputs, ``R`` (n, 3, 3) frame K, ``wind`` (n, 5, 3),
    ``tension``/``length`` (n, 4) of the bridle lines, ``tether_force`` (n,) [N] (constraint force at the start of
    the last step), ``status`` (n,) (:data:`OK`, :data:`NON_FINITE`, :data:`OUTSIDE`).
    """

    def __init__(self, cfg, surrogate, q_design: np.ndarray, tip_lengths, n: int, envelope_margin: float = 0.1):
        if n < 1:
            raise ValueError(f"n must be at least 1, got {n}")
        self.cfg, self.n, self.dt = cfg, int(n), cfg.dynamics.dt_s
        self.q_design = np.ascontiguousarray(q_design, dtype=float)
        self.tip_lengths = np.asarray(tip_lengths, dtype=float)
        dyn = cfg.dynamics
        ps = ParticleSystem(dyn, self.tip_lengths, np.zeros(4), cfg.aero.rho_kg_m3)
        # particle parameters shared by all kites (kernel_parameters without rest and pair damping)
        (self.m, _, self.k_c, self.c_c, self.rho, self.line_cd, self.line_d, self.tether_d, self.l_t, _, _,
         self.g, self.baumgarte) = ps.kernel_parameters()
        # the MLP with its normalisations folded into the first and last layers
        W, b = [w.astype(float) for w in surrogate.weights], [c.astype(float) for c in surrogate.biases]
        W[0] = W[0] / surrogate.x_std[:, None]
        b[0] = b[0] - (surrogate.x_mean / surrogate.x_std) @ surrogate.weights[0].astype(float)
        b[-1] = b[-1] * surrogate.y_std + surrogate.y_mean
        W[-1] = W[-1] * surrogate.y_std[None, :]
        if len(W) != 3:
            raise ValueError(f"the fast fidelity needs a surrogate with two hidden layers, got {len(W) - 1}")
        self._W, self._b = [np.ascontiguousarray(w) for w in W], [np.ascontiguousarray(c) for c in b]
        span = surrogate.x_max - surrogate.x_min
        self._lo = surrogate.x_min - envelope_margin * span
        self._hi = surrogate.x_max + envelope_margin * span
        self.surrogate = surrogate
        self._weights = tuple(a for pair in zip(self._W, self._b) for a in pair)
        n_modes = cfg.wind.turbulence_modes
        self.n_modes = n_modes
        self.wind_f = np.zeros((n, 9))
        self.wind_i = np.zeros((n, 2), dtype=np.int64)
        self.wavevec_t = np.zeros((n, 3, 3 * n_modes))
        self.phase0 = np.zeros((n, 3 * n_modes))
        self.omega_m = np.zeros((n, 3 * n_modes))
        self.amp = np.zeros((n, 3 * n_modes))
        self.r = np.zeros((n, 5, 3))
        self.v = np.zeros((n, 5, 3))
        self.t = np.zeros(n)
        self.rest = np.full((n, 4), float(dyn.power_line_length_m))
        self.pair_damping = np.zeros((n, 4))
        self.X = np.zeros((n, 30))
        self.Y = np.zeros((n, 17))
        self.R = np.zeros((n, 3, 3))
        self.wind = np.zeros((n, 5, 3))
        self.tension = np.zeros((n, 4))
        self.length = np.zeros((n, 4))
        self.tether_force = np.full(n, np.nan)
        self.status = np.zeros(n, dtype=np.int64)
        self._all = np.ones(n, dtype=np.bool_)

    # ------------------------------------------------------------------ set-up of one kite
    def set_wind(self, k: int, wind) -> None:
        """Kite ``k`` flies in ``wind`` (:class:`kite_env.wind.WindField`, same number of turbulence modes)."""
        c = wind.cfg
        if c.turbulence_modes != self.n_modes:
            raise ValueError(f"wind has {c.turbulence_modes} turbulence modes, the kites were built for {self.n_modes}")
        self.wind_f[k] = (c.speed_mps, c.ref_height_m, c.roughness_m, math.log(c.ref_height_m / c.roughness_m),
                          c.shear_exponent, c.gust_speed_mps, c.gust_start_s, c.gust_duration_s, 0.0)
        self.wind_i[k] = (_PROFILES[c.profile], 1 if wind.turbulent else 0)
        self.wavevec_t[k] = wind._wavevec_t
        self.phase0[k] = wind._phase0
        self.omega_m[k] = wind._omega
        self.amp[k] = wind._amp

    def set_kite(self, k: int, r: np.ndarray, v: np.ndarray, t: float, pair_stiffness, L_B: float, L_D: float):
        """Place kite ``k`` at positions/velocities ``r``, ``v`` (5, 3), time ``t``, with the tip-pair stiffness
        (4,) [N/m] of its start and the steering-line rest lengths."""
        self.r[k], self.v[k], self.t[k] = r, v, t
        self.pair_damping[k] = ParticleSystem(self.cfg.dynamics, self.tip_lengths, pair_stiffness,
                                              self.cfg.aero.rho_kg_m3).pair_damping
        self.rest[k, 1], self.rest[k, 3] = L_B, L_D
        self.status[k] = OK

    # ------------------------------------------------------------------ evaluation and stepping
    def evaluate(self, active: np.ndarray | None = None) -> None:
        """Wing outputs, bridle lines and status at the current states of the ``active`` kites (default all), e.g.
        after :meth:`set_kite`."""
        active = self._all if active is None else np.asarray(active, dtype=np.bool_)
        evaluate_kites(self.t, self.r, self.v, self.rest, self.q_design, self.wind_f, self.wind_i, self.wavevec_t,
                       self.phase0, self.omega_m, self.amp, self.n_modes, *self._weights, self.k_c, self.c_c,
                       self._lo, self._hi, active, self.X, self.Y, self.wind, self.R, self.tension, self.length,
                       self.status)

    def outside(self, k: int) -> list[str]:
        """Names of the inputs of kite ``k`` beyond the envelope."""
        from kite_env.surrogate.samples import INPUT_NAMES

        x = self.X[k]
        return [INPUT_NAMES[i] for i in np.flatnonzero((x < self._lo) | (x > self._hi))]

    def step(self, L_B: np.ndarray, L_D: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """Advance every ``active`` (default all) kite by ``dt`` with steering-line rest lengths ``L_B``, ``L_D``
        (n,) [m]: RK4 with the wing evaluated at every stage, then the projection. Returns ``status`` (n,)."""
        if active is None:
            active = self._all
            self.rest[:, 1] = L_B
            self.rest[:, 3] = L_D
        else:
            active = np.asarray(active, dtype=np.bool_)
            self.rest[active, 1] = np.asarray(L_B, dtype=float)[active]
            self.rest[active, 3] = np.asarray(L_D, dtype=float)[active]
        step_kites(self.dt, active, self.t, self.r, self.v, self.rest, self.pair_damping, self.q_design, self.wind_f,
                   self.wind_i, self.wavevec_t, self.phase0, self.omega_m, self.amp, self.n_modes, *self._weights,
                   self.m, self.k_c, self.c_c, self.rho, self.line_cd, self.line_d, self.tether_d, self.l_t,
                   self.tip_lengths, self.g, self.baumgarte, self._lo, self._hi, self.X, self.Y, self.wind, self.R,
                   self.tether_force, self.tension, self.length, self.status)
        return self.status


# ---------------------------------------------------------------------------------------------------- one kite
def _default_start_table(cfg, surrogate_path=None):
    """The start table that belongs to the surrogate (next to its weights or shipped), None if there is none."""
    from pathlib import Path

    from kite_env.surrogate import default_start_path
    from kite_env.surrogate.start import StartTable

    if surrogate_path:
        p = Path(surrogate_path)
        p = p.with_name(p.stem + "_start.npz")
        return StartTable.load(p) if p.is_file() else None
    try:
        return StartTable.load(default_start_path(cfg.kite.name))
    except FileNotFoundError:
        return None


_NAN3 = np.full(3, np.nan)
_ZERO3 = np.zeros(3)


class _FastRecord(StepRecord):
    """:class:`StepRecord` of the fast fidelity: the copies of the kite's arrays, the derived fields (``wing``,
    ``v_kite``, ``omega``, ``v_wind``) built when first read (the environment reads them only at the end of a
    control step)."""

    def __init__(self, t, r, v, Y, X, R, tension, length, tether_force, nodes):
        self.t, self.state, self.R_wk = t, ParticleState(r, v), R
        self.line_tension, self.line_length, self.tether_force = tension, length, tether_force
        self.constraint_drift = _ZERO3
        self._Y, self._X, self._nodes = Y, X, nodes

    @property
    def v_kite(self):
        v = self.state.v
        return 0.5 * (v[0] + v[2])

    @property
    def omega(self):
        return self.R_wk @ self._X[27:30]

    @property
    def v_wind(self):
        return self.v_kite - self.R_wk @ self._X[24:27]

    @property
    def wing(self):
        Y = self._Y
        return WingSolution(F_b=Y[:12].reshape(4, 3), nodes=self._nodes, alpha=Y[12:15], CL=_NAN3, CD=_NAN3,
                            CM=_NAN3, aero_force=_NAN3, lift=float(Y[15]), drag=float(Y[16]), coupling_iters=0,
                            newton_iters=0)


class SurrogateFlightSimulator(FlightSimulator):
    """One kite in the fast fidelity, with the interface of :class:`~kite_env.dynamics.simulator.FlightSimulator`
    (``reset``, ``step`` -> :class:`~kite_env.dynamics.simulator.StepRecord`): the case ``n = 1`` of
    :class:`SurrogateKites`.

    The start (:meth:`reset`) is the full model's start (the kite placed as the full model places it, the wing held
    by its lines at the start's apparent velocity), taken from the surrogate's start table (fitted to FE solves at the
    start states, :mod:`kite_env.surrogate.start`) or, with ``start="fe"`` or without a table, solved with the FE wing.

    The record's ``wing`` carries the surrogate outputs: ``F_b``, ``alpha`` (3,) of the right tip, mid and left
    tip sections, ``lift``, ``drag``; ``nodes`` are the design mesh (the surrogate does not return the shape).

    Parameters
    ----------
    cfg : Config
    wind : WindField
    surrogate : SurrogateWing, optional (default: the shipped model of ``cfg.kite.name``)
    surrogate_path : path of ``surrogate``'s weights, optional: its start table is ``<stem>_start.npz`` next to it
    wing : AeroelasticWing, optional (geometry, FE start; built from ``cfg.kite`` when not given)
    start : {"table", "fe"}
    start_table : StartTable, optional (default: the shipped one, or the one next to ``surrogate_path``; without
        one the start is solved with the FE wing)
    on_outside : {"error", "fe"}
        A state beyond the sampled envelope raises :class:`SimulationError` ("outside surrogate envelope"), or the
        kite continues in the full model from there (``"fe"``, :attr:`fallback_t` says when).
    """

    def __init__(self, cfg, wind, surrogate=None, wing=None, start: str = "table", on_outside: str = "error",
                 start_table=None, surrogate_path=None):
        from kite_env.polar import nominal_wing

        if start not in ("table", "fe"):
            raise ValueError(f"start must be 'table' or 'fe', got {start!r}")
        if on_outside not in ("error", "fe"):
            raise ValueError(f"on_outside must be 'error' or 'fe', got {on_outside!r}")
        self.cfg, self.wind, self.backend = cfg, wind, "numba"
        self.wing = wing if wing is not None else nominal_wing(cfg.kite.name, cfg)
        if surrogate is None:
            from kite_env.surrogate import load_default

            surrogate = load_default(cfg.kite.name)
        self.surrogate = surrogate
        self.start_table = start_table
        if start_table is None and start == "table":
            self.start_table = _default_start_table(cfg, surrogate_path)
        self.start_mode = start if self.start_table is not None else "fe"
        self.on_outside = on_outside
        self.dt = cfg.dynamics.dt_s
        q0 = self.wing.design_bridle
        self.tip_lengths = np.array([np.linalg.norm(q0[0] - q0[1]), np.linalg.norm(q0[2] - q0[3])])
        self.kites = SurrogateKites(cfg, self.surrogate, q0, self.tip_lengths, 1)
        self.particles = None
        self.state = None
        self.t = 0.0
        self.L_B0 = self.L_D0 = None
        self.fallback_t = None
        self._fe = None
        self.fe_starts = 0  # starts solved with the FE wing (no start table, or none at that start)

    @property
    def fidelity_now(self) -> str:
        return "surrogate" if self._fe is None else "fe"

    def _start_wing(self, X):
        """The start from the table; where the table has no converged cell (its grid points next to the query did not
        converge in the cold FE solve, or the query is outside the grid), solved with the FE wing, as the full
        model does (about 1 s; counted in :attr:`fe_starts`)."""
        if self.start_mode == "table":
            try:
                return self.start_table.lookup(np.asarray(X.v_kite) - np.asarray(X.v_wind))
            except ValueError:
                pass
        self.fe_starts += 1
        return super()._start_wing(X)

    def _record(self):
        ks = self.kites
        return _FastRecord(float(ks.t[0]), ks.r[0].copy(), ks.v[0].copy(), ks.Y[0].copy(), ks.X[0].copy(),
                           ks.R[0].copy(), ks.tension[0].copy(), ks.length[0].copy(), float(ks.tether_force[0]),
                           self.wing.mesh.nodes)

    def _solve_wing(self, first: bool = False, commit: bool = True, state=None, t=None):
        """At the end of :meth:`reset`: hand the placed kite to the batched arrays and evaluate the wing."""
        if not first:
            raise RuntimeError("the fast fidelity evaluates the wing inside step()")
        ks = self.kites
        ks.set_wind(0, self.wind)
        ks.set_kite(0, self.state.r, self.state.v, self.t, self.pair_stiffness, self.L_B0, self.L_D0)
        ks.tether_force[0] = np.nan
        ks.evaluate()
        self.fallback_t = None
        self._fe = None
        self._raise_status(at_start=True)
        return self._record()

    def _raise_status(self, at_start: bool = False):
        st = int(self.kites.status[0])
        if st == NON_FINITE:
            raise SimulationError("non-finite particle state", f"t = {self.kites.t[0]:.4f} s")
        if st == OUTSIDE:
            names = ", ".join(self.kites.outside(0))
            if self.on_outside == "fe" and not at_start:
                self._switch_to_fe()
                return
            raise SimulationError("outside surrogate envelope", names)

    def _switch_to_fe(self):
        """Continue this flight in the full model from the current state (cold FE wing solve there)."""
        fe = FlightSimulator(self.cfg, self.wind, self.wing)
        fe.particles = ParticleSystem(self.cfg.dynamics, self.tip_lengths, self.pair_stiffness,
                                      self.cfg.aero.rho_kg_m3)
        fe.pair_stiffness = self.pair_stiffness
        fe.L_B0, fe.L_D0 = self.L_B0, self.L_D0
        fe.particles.set_steering(float(self.kites.rest[0, 1]), float(self.kites.rest[0, 3]))
        fe.state = ParticleState(self.kites.r[0].copy(), self.kites.v[0].copy())
        fe.t = float(self.kites.t[0])
        self.wing.reset()
        self._fe_rec = fe._solve_wing(first=True)
        self._fe = fe
        self.fallback_t = fe.t

    def step(self, L_B: float, L_D: float):
        if self.L_B0 is None:
            raise RuntimeError("call reset() before step()")
        if not (L_B > 0 and L_D > 0 and math.isfinite(L_B) and math.isfinite(L_D)):
            raise ValueError(f"steering-line rest lengths must be positive and finite, got {L_B!r}, {L_D!r}")
        if self._fe is not None:
            rec = self._fe.step(L_B, L_D)
            self.state, self.t = rec.state, rec.t
            return rec
        self.kites.step(L_B, L_D)
        if self.kites.status[0] != OK:
            self._raise_status()
        if self._fe is not None:  # switched to the full model at this state: its cold wing solve there
            rec = self._fe_rec
            rec.tether_force = float(self.kites.tether_force[0])
        else:
            rec = self._record()
        self.state, self.t = rec.state, rec.t
        return rec
