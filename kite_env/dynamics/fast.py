"""The fast fidelity: the particle system with the reduced-order wing, N kites advanced together as arrays.

:class:`SurrogateKites` holds the states of ``n`` independent kites (rows of ``(n, 5, 3)`` arrays: A, B, C, D, KCU
in W) and advances all of them by one RK4 step of ``sim.surrogate_dt_s``. The particle system is the one of the full
model (:func:`kite_env.dynamics.kernels.particle_accelerations_into`, Sect. II.C, Eq. 10-13: masses, bridle lines, line
drag, tip-pair dashpots, tether and tip constraints, projection after the step); only the wing differs:

* full model (:class:`kite_env.dynamics.simulator.FlightSimulator`): the static FE wing solved once per step (Fig. 6),
  its force held in K and corrected by the condensed stiffness within the step;
* fast fidelity (here): the reduced-order wing :class:`kite_env.surrogate.model.SurrogateWing`, a function of the
  bridle points, their rates, the apparent velocity and the rotation rate in K, evaluated at *every* RK4 stage
  (it is cheap; the stiffness correction of the full model is then implicit in the stage evaluations).

One compiled call (:func:`step_kites`) advances all kites; per kite and stage it evaluates the wing inputs (frame K
and its rates as :func:`kite_env.frames.kite_frame_rates`, the wind at the five masses and at the frame origin), the
MLP and the particle right-hand side. The kites go through the RK4 stages together in blocks of :data:`BLOCK`, so
that the MLP (most of the time of a step) is evaluated for a block at once (:func:`mlp_rows`: each load of a weight
serves several kites, each kite's sums in the order of the one-row :func:`mlp_row`, so bit for bit the same); all
else is per kite, in the same arithmetic and order as one kite alone. A single kite is the case ``n = 1`` of the
same code (:class:`SurrogateFlightSimulator`), so that one kite and a batch give the same trajectory, bit for bit,
for the same inputs.

The wing outputs at the end of a step (the states the flight visits) are also the first stage of the next step; they
are checked against the sampled envelope (:meth:`SurrogateWing.outside`, ``status`` ``OUTSIDE``).
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.compiled import JIT, njit
from kite_env.dynamics.kernels import _WORK, particle_accelerations_into, project_constraints, reel_out_speed
from kite_env.dynamics.particles import ParticleState, ParticleSystem
from kite_env.dynamics.simulator import FlightSimulator, SimulationError, StepRecord
from kite_env.fsi import WingSolution, nominal_wing
from kite_env.surrogate.model import filter_gain
from kite_env.wind import _turbulence_kernel

#: kite status after a step
OK, NON_FINITE, OUTSIDE = 0, 1, 2
_PROFILES = {"uniform": 0, "log": 1, "power": 2}
_TWO_PI = 2.0 * math.pi


# ---------------------------------------------------------------------------------------------------- kernels
@njit(**JIT)
def _wind_parts(t, pos, out, turb, hold, speed, profile, z_ref, z0, log_den, shear, gust_G, gust_t0, gust_T,
                turbulent, wavevec_t, phase0, omega, amp, n_modes, t_buf):
    """Wind ``out`` (P, 3) at ``pos`` (P, 3) for one kite: the turbulent part ``turb`` (P, 3), evaluated here at
    ``(t, pos)`` (``hold`` False) or the one passed in (``hold`` True: held from the start of the RK4 step), plus
    the mean profile and the gust at ``(t, pos)``. With ``hold`` False this is
    :meth:`kite_env.wind.WindField.velocity` (numba backend)."""
    if not hold:
        if turbulent:
            t_buf[0] = t
            _turbulence_kernel(t_buf, pos, wavevec_t, phase0, omega, amp, n_modes, turb)
        else:
            for i in range(pos.shape[0]):
                turb[i, 0] = 0.0
                turb[i, 1] = 0.0
                turb[i, 2] = 0.0
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
        out[i, 0] = turb[i, 0] + u
        out[i, 1] = turb[i, 1]
        out[i, 2] = turb[i, 2]


@njit(**JIT)
def _wind_at(t, pos, out, speed, profile, z_ref, z0, log_den, shear, gust_G, gust_t0, gust_T, turbulent,
             wavevec_t, phase0, omega, amp, n_modes, t_buf):
    """Wind (P, 3) at ``pos`` (P, 3) for one kite: :meth:`kite_env.wind.WindField.velocity` (numba backend)."""
    turb = np.empty_like(out)
    _wind_parts(t, pos, out, turb, False, speed, profile, z_ref, z0, log_den, shear, gust_G, gust_t0, gust_T,
                turbulent, wavevec_t, phase0, omega, amp, n_modes, t_buf)


@njit(**JIT)
def kite_inputs(t, rk, vk, q_design, wf, wi, wavevec_t, phase0, omega_m, amp, n_modes, x, wind5, R, pos, w6,
                t_buf, turb6, hold):
    """Wing inputs ``x`` (30,) of one kite (:data:`kite_env.surrogate.samples.INPUT_NAMES`), the wind ``wind5`` (5, 3)
    at its masses and its frame K ``R`` (3, 3) (columns x_k, y_k, z_k in W) at time ``t`` [s].

    ``rk``, ``vk`` (5, 3): A, B, C, D, KCU in W. ``wf`` (9,): wind speed, z_ref, z0, log(z_ref/z0), shear exponent,
    gust amplitude, start, duration, unused; ``wi`` (2,): profile code (uniform 0, log 1, power 2), turbulent (0/1);
    ``wavevec_t, phase0, omega_m, amp``: the turbulence modes of :class:`kite_env.wind.WindField`. ``turb6`` (6, 3):
    the turbulent wind at the five masses and the frame origin, evaluated and stored here (``hold`` False) or held
    (``hold`` True, :func:`_wind_parts`). ``pos``, ``w6`` (6, 3) and ``t_buf`` (1,) are work arrays. Scalar code:
    no allocation (this runs four times per kite and RK4 step).
    """
    # ---- frame K (frames.kite_frame) and its rates (frames.kite_frame_rates)
    o0 = 0.5 * (rk[0, 0] + rk[2, 0])
    o1 = 0.5 * (rk[0, 1] + rk[2, 1])
    o2 = 0.5 * (rk[0, 2] + rk[2, 2])
    vo0 = 0.5 * (vk[0, 0] + vk[2, 0])
    vo1 = 0.5 * (vk[0, 1] + vk[2, 1])
    vo2 = 0.5 * (vk[0, 2] + vk[2, 2])
    ey0 = rk[0, 0] - rk[2, 0]
    ey1 = rk[0, 1] - rk[2, 1]
    ey2 = rk[0, 2] - rk[2, 2]
    dd0 = vk[0, 0] - vk[2, 0]
    dd1 = vk[0, 1] - vk[2, 1]
    dd2 = vk[0, 2] - vk[2, 2]
    mm0 = 0.5 * (rk[1, 0] + rk[3, 0]) - o0
    mm1 = 0.5 * (rk[1, 1] + rk[3, 1]) - o1
    mm2 = 0.5 * (rk[1, 2] + rk[3, 2]) - o2
    dm0 = 0.5 * (vk[1, 0] + vk[3, 0]) - vo0
    dm1 = 0.5 * (vk[1, 1] + vk[3, 1]) - vo1
    dm2 = 0.5 * (vk[1, 2] + vk[3, 2]) - vo2
    ld = math.sqrt(ey0 ** 2 + ey1 ** 2 + ey2 ** 2)
    ey0 /= ld
    ey1 /= ld
    ey2 /= ld
    s = mm0 * ey0 + mm1 * ey1 + mm2 * ey2
    xp0 = mm0 - s * ey0
    xp1 = mm1 - s * ey1
    xp2 = mm2 - s * ey2
    lx = math.sqrt(xp0 ** 2 + xp1 ** 2 + xp2 ** 2)
    ex0 = xp0 / lx
    ex1 = xp1 / lx
    ex2 = xp2 / lx
    ez0 = ex1 * ey2 - ex2 * ey1
    ez1 = ex2 * ey0 - ex0 * ey2
    ez2 = ex0 * ey1 - ex1 * ey0
    p = ey0 * dd0 + ey1 * dd1 + ey2 * dd2
    dey0 = (dd0 - ey0 * p) / ld
    dey1 = (dd1 - ey1 * p) / ld
    dey2 = (dd2 - ey2 * p) / ld
    mdey = mm0 * dey0 + mm1 * dey1 + mm2 * dey2
    dmey = dm0 * ey0 + dm1 * ey1 + dm2 * ey2
    dxp0 = dm0 - (dmey + mdey) * ey0 - s * dey0
    dxp1 = dm1 - (dmey + mdey) * ey1 - s * dey1
    dxp2 = dm2 - (dmey + mdey) * ey2 - s * dey2
    q = ex0 * dxp0 + ex1 * dxp1 + ex2 * dxp2
    dex0 = (dxp0 - ex0 * q) / lx
    dex1 = (dxp1 - ex1 * q) / lx
    dex2 = (dxp2 - ex2 * q) / lx
    dez0 = (dex1 * ey2 - dex2 * ey1) + (ex1 * dey2 - ex2 * dey1)
    dez1 = (dex2 * ey0 - dex0 * ey2) + (ex2 * dey0 - ex0 * dey2)
    dez2 = (dex0 * ey1 - dex1 * ey0) + (ex0 * dey1 - ex1 * dey0)
    # omega = 1/2 sum_i e_i x de_i/dt (summed over x, y, z in that order)
    w0 = 0.5 * (ex1 * dex2 - ex2 * dex1)
    w1 = 0.5 * (ex2 * dex0 - ex0 * dex2)
    w2 = 0.5 * (ex0 * dex1 - ex1 * dex0)
    w0 += 0.5 * (ey1 * dey2 - ey2 * dey1)
    w1 += 0.5 * (ey2 * dey0 - ey0 * dey2)
    w2 += 0.5 * (ey0 * dey1 - ey1 * dey0)
    w0 += 0.5 * (ez1 * dez2 - ez2 * dez1)
    w1 += 0.5 * (ez2 * dez0 - ez0 * dez2)
    w2 += 0.5 * (ez0 * dez1 - ez1 * dez0)
    R[0, 0], R[1, 0], R[2, 0] = ex0, ex1, ex2
    R[0, 1], R[1, 1], R[2, 1] = ey0, ey1, ey2
    R[0, 2], R[1, 2], R[2, 2] = ez0, ez1, ez2
    # ---- wind at the five masses and at the frame origin
    for i in range(5):
        for j in range(3):
            pos[i, j] = rk[i, j]
    pos[5, 0], pos[5, 1], pos[5, 2] = o0, o1, o2
    _wind_parts(t, pos, w6, turb6, hold, wf[0], wi[0], wf[1], wf[2], wf[3], wf[4], wf[5], wf[6], wf[7], wi[1] != 0,
                wavevec_t, phase0, omega_m, amp, n_modes, t_buf)
    for i in range(5):
        for j in range(3):
            wind5[i, j] = w6[i, j]
    # ---- inputs (samples.features): q_b - q_design, qdot_b (relative to K), v_app, omega, all in K
    wK0 = w0 * R[0, 0] + w1 * R[1, 0] + w2 * R[2, 0]
    wK1 = w0 * R[0, 1] + w1 * R[1, 1] + w2 * R[2, 1]
    wK2 = w0 * R[0, 2] + w1 * R[1, 2] + w2 * R[2, 2]
    for i in range(4):
        a0, a1, a2 = rk[i, 0] - o0, rk[i, 1] - o1, rk[i, 2] - o2
        b0, b1, b2 = vk[i, 0] - vo0, vk[i, 1] - vo1, vk[i, 2] - vo2
        qb0 = a0 * R[0, 0] + a1 * R[1, 0] + a2 * R[2, 0]
        qb1 = a0 * R[0, 1] + a1 * R[1, 1] + a2 * R[2, 1]
        qb2 = a0 * R[0, 2] + a1 * R[1, 2] + a2 * R[2, 2]
        vb0 = b0 * R[0, 0] + b1 * R[1, 0] + b2 * R[2, 0]
        vb1 = b0 * R[0, 1] + b1 * R[1, 1] + b2 * R[2, 1]
        vb2 = b0 * R[0, 2] + b1 * R[1, 2] + b2 * R[2, 2]
        x[3 * i + 0] = qb0 - q_design[i, 0]
        x[3 * i + 1] = qb1 - q_design[i, 1]
        x[3 * i + 2] = qb2 - q_design[i, 2]
        x[12 + 3 * i + 0] = vb0 - (wK1 * qb2 - wK2 * qb1)
        x[12 + 3 * i + 1] = vb1 - (wK2 * qb0 - wK0 * qb2)
        x[12 + 3 * i + 2] = vb2 - (wK0 * qb1 - wK1 * qb0)
    a0, a1, a2 = vo0 - w6[5, 0], vo1 - w6[5, 1], vo2 - w6[5, 2]
    for c in range(3):
        x[24 + c] = a0 * R[0, c] + a1 * R[1, c] + a2 * R[2, c]
    x[27], x[28], x[29] = wK0, wK1, wK2


# rational approximation of tanh: tanh(x) ~ x P(u) / Q(u), u = (x / 12)^2, for |x| <= 12 (|x| > 12: x clamped,
# 1 - tanh(12) = 7.6e-11). Coefficients: linearised least squares (Loeb's iteration, 40 rounds) of tanh(x)/x on
# 6,000 Chebyshev points of [0, 12], degree 7 over 7 in u; max |error| 2.1e-10 on the real line
# (tests/dynamics/test_fast.py). Unlike libm's exp, polynomials and a division vectorise over the 64 units.
_TANH_CLAMP = 12.0
_TANH_INV_C2 = 1.0 / 144.0
_TANH_P = (0.9999999999944414, 19.155017387139473, 69.06014265160871, 32.81729030979992, -43.28042736931411,
           20.92567139802267, 24.84618491093609, 1.272300621347853)
_TANH_Q = (1.0, 67.15501736545255, 527.7009840099352, 840.6143015971842, -241.39535975836614,
           -227.91246578802185, 438.6164396440909, 103.77524164025381)


@njit(**JIT)
def tanh_inplace(h):
    """``h <- tanh(h)`` elementwise (rational approximation above; NaN stays NaN)."""
    P0, P1, P2, P3, P4, P5, P6, P7 = _TANH_P
    Q0, Q1, Q2, Q3, Q4, Q5, Q6, Q7 = _TANH_Q
    for j in range(h.shape[0]):
        x = h[j]
        if x > _TANH_CLAMP:
            x = _TANH_CLAMP
        elif x < -_TANH_CLAMP:
            x = -_TANH_CLAMP
        u = x * x * _TANH_INV_C2
        p = ((((((P7 * u + P6) * u + P5) * u + P4) * u + P3) * u + P2) * u + P1) * u + P0
        q = ((((((Q7 * u + Q6) * u + Q5) * u + Q4) * u + Q3) * u + Q2) * u + Q1) * u + Q0
        h[j] = x * p / q


@njit(**JIT)
def mlp_row(x, W0, b0, W1, b1, W2, b2, h0, h1, h2, y):
    """``y = tanh(tanh(x W0 + b0) W1 + b1) W2 + b2`` for one row ``x`` (n_in,) float64 -> ``y`` (17,) float64, in
    float32 (the weights are stored and trained in float32; the normalisations are folded into the first and last
    layers; tanh from :func:`tanh_inplace`). ``h0``, ``h1``, ``h2``: float32 work arrays of the layer widths.

    The reference of the MLP's arithmetic: each unit's sum is ``b[j]``, then ``+ x[i] W[i, j]`` for ``i = 0, 1,
    ...``, each product and sum rounded to float32. The kernels evaluate it with :func:`mlp_rows` (blocks of rows,
    the same sums in the same order: bit for bit this function's output on each row, tests/dynamics/test_fast.py)."""
    n0, n1, n2 = W0.shape[1], W1.shape[1], W2.shape[1]
    for j in range(n0):
        h0[j] = b0[j]
    for i in range(x.shape[0]):
        xi = np.float32(x[i])
        for j in range(n0):
            h0[j] += xi * W0[i, j]
    tanh_inplace(h0)
    for j in range(n1):
        h1[j] = b1[j]
    for i in range(n0):
        hi = h0[i]
        for j in range(n1):
            h1[j] += hi * W1[i, j]
    tanh_inplace(h1)
    for j in range(n2):
        h2[j] = b2[j]
    for i in range(n1):
        hi = h1[i]
        for j in range(n2):
            h2[j] += hi * W2[i, j]
    for j in range(n2):
        y[j] = h2[j]


@njit(**JIT)
def dense_rows(x, nb, W, bias, h):
    """``h[b] = x[b] W + bias`` for the rows ``b < nb`` of ``x`` (cast to float32; ``h`` float32), every sum in
    :func:`mlp_row`'s order: ``bias[j]``, then ``+ x[b, i] W[i, j]`` for ``i = 0, 1, ...``, each product and sum
    rounded to float32.

    The rows go in groups of four and the inputs in groups of four: the inner loop over the units ``j`` (vectorised)
    loads four weights ``W[i:i+4, j]`` once for four rows and adds the four products to each row's partial sum in
    registers (``a += p0 w0``, then ``+ p1 w1``, ...: the order of the sum is unchanged), so that per 16 products it
    loads and stores each row's partial sum once, not four times, and each weight once, not four times; the rows
    left over (``nb`` not a multiple of 4) go one at a time, the inputs left over (``n_in`` not a multiple of 4) one
    at a time at the end, again in order. ``fastmath=False`` (:data:`kite_env.compiled.JIT`): no reassociation or FMA
    contraction, so vectorising over ``j`` changes no bit. The groups of rows are the outer loop: with the inputs
    outer, LLVM hoists its runtime alias check between the rows' partial sums out of the loop over the groups, where
    the rows of different groups overlap, and falls back to scalar code.
    """
    n_in, n = W.shape[0], W.shape[1]
    for b in range(nb):
        for j in range(n):
            h[b, j] = bias[j]
    i4 = n_in - n_in % 4
    b4 = nb - nb % 4
    for b in range(0, b4, 4):
        for i in range(0, i4, 4):
            p00, p01, p02, p03 = (np.float32(x[b, i]), np.float32(x[b, i + 1]), np.float32(x[b, i + 2]),
                                  np.float32(x[b, i + 3]))
            p10, p11, p12, p13 = (np.float32(x[b + 1, i]), np.float32(x[b + 1, i + 1]),
                                  np.float32(x[b + 1, i + 2]), np.float32(x[b + 1, i + 3]))
            p20, p21, p22, p23 = (np.float32(x[b + 2, i]), np.float32(x[b + 2, i + 1]),
                                  np.float32(x[b + 2, i + 2]), np.float32(x[b + 2, i + 3]))
            p30, p31, p32, p33 = (np.float32(x[b + 3, i]), np.float32(x[b + 3, i + 1]),
                                  np.float32(x[b + 3, i + 2]), np.float32(x[b + 3, i + 3]))
            for j in range(n):
                a0, a1, a2, a3 = h[b, j], h[b + 1, j], h[b + 2, j], h[b + 3, j]
                w = W[i, j]
                a0 += p00 * w
                a1 += p10 * w
                a2 += p20 * w
                a3 += p30 * w
                w = W[i + 1, j]
                a0 += p01 * w
                a1 += p11 * w
                a2 += p21 * w
                a3 += p31 * w
                w = W[i + 2, j]
                a0 += p02 * w
                a1 += p12 * w
                a2 += p22 * w
                a3 += p32 * w
                w = W[i + 3, j]
                a0 += p03 * w
                a1 += p13 * w
                a2 += p23 * w
                a3 += p33 * w
                h[b, j], h[b + 1, j], h[b + 2, j], h[b + 3, j] = a0, a1, a2, a3
    for b in range(b4, nb):
        for i in range(0, i4, 4):
            p00, p01, p02, p03 = (np.float32(x[b, i]), np.float32(x[b, i + 1]), np.float32(x[b, i + 2]),
                                  np.float32(x[b, i + 3]))
            for j in range(n):
                a0 = h[b, j]
                a0 += p00 * W[i, j]
                a0 += p01 * W[i + 1, j]
                a0 += p02 * W[i + 2, j]
                a0 += p03 * W[i + 3, j]
                h[b, j] = a0
    for i in range(i4, n_in):
        for b in range(nb):
            xi = np.float32(x[b, i])
            for j in range(n):
                h[b, j] += xi * W[i, j]


@njit(**JIT)
def mlp_rows(x, nb, W0, b0, W1, b1, W2, b2, h0, h1, h2, y):
    """:func:`mlp_row` for each of the rows ``x[:nb]`` (float64, (>= nb, n_in)) -> ``y[:nb]`` (float64, (>= nb,
    17)), each row's output bit for bit :func:`mlp_row`'s on that row alone (:func:`dense_rows`, then the same
    :func:`tanh_inplace`). ``h0``, ``h1``, ``h2``: float32 work arrays (>= nb, layer width).

    Why blocks: the weights of the 128-wide model (66 x 128, 128 x 128 and 128 x 17: 108 kB in float32) do not stay
    in the 32 kB L1 cache, and one row at a time streams all of them from L2 for every row, loading and storing each
    unit's partial sum once per input. Here four rows share each load of a weight and each partial sum is loaded and
    stored once per four inputs (:func:`dense_rows`); the order of every sum is :func:`mlp_row`'s, so the result is
    bit for bit the same. Measured on the 2-core development container (AMD EPYC, AVX2): ~1.5 us per row at 8 rows
    against ~2.5 us for :func:`mlp_row` (of which tanh ~0.5 us), ~2.1 us for one row alone."""
    dense_rows(x, nb, W0, b0, h0)
    for b in range(nb):
        tanh_inplace(h0[b])
    dense_rows(h0, nb, W1, b1, h1)
    for b in range(nb):
        tanh_inplace(h1[b])
    dense_rows(h1, nb, W2, b2, h2)
    for b in range(nb):
        for j in range(W2.shape[1]):
            y[b, j] = h2[b, j]


@njit(**JIT)
def add_stiffness(x, K, y):
    """``y[:12] += K x[:12]``: the known linear part of the bridle force (:attr:`SurrogateWing.K_b`)."""
    for i in range(12):
        acc = 0.0
        for j in range(12):
            acc += K[i, j] * x[j]
        y[i] += acc


@njit(**JIT)
def history_inputs(x, z, sel):
    """The latent state's inputs of the reduced-order wing (:mod:`kite_env.fitting.fit`): ``x[30 + j n + i] =
    z[j, i] - x[sel[i]]`` for the filters ``z`` (n_tau, n) of the inputs ``sel`` (n,); nothing without filters."""
    n = sel.shape[0]
    for j in range(z.shape[0]):
        for i in range(n):
            x[30 + j * n + i] = z[j, i] - x[sel[i]]


@njit(**JIT)
def latent_update(x, z, sel, gain, reset):
    """One physics step of the latent low-pass filters: ``z <- z + c (x[sel] - z)`` with ``c = gain[j]`` (the exact
    discrete first-order filter, :func:`kite_env.surrogate.model.filter_gain`), or ``z <- x[sel]`` (``reset``: a
    steady start)."""
    for j in range(z.shape[0]):
        for i in range(sel.shape[0]):
            if reset:
                z[j, i] = x[sel[i]]
            else:
                z[j, i] += gain[j] * (x[sel[i]] - z[j, i])


#: kites per block of :func:`step_kites` and :func:`evaluate_kites` (the rows of one :func:`mlp_rows` call). 4, 8
#: and 16 measured the same within the noise of the shared container (64 kites, ~11 us per kite and physics step,
#: against ~16 us one kite at a time): :func:`dense_rows` takes the rows four at a time, so any multiple of 4 gains
#: the same; 8 keeps the block's work arrays small.
BLOCK = 8


@njit(**JIT)
def _next_block(active, k, idx):
    """The next (up to ``idx.shape[0]``) ``active`` kites from ``k`` on into ``idx``: returns their number and the
    kite after the last one looked at."""
    nb = 0
    n = active.shape[0]
    while k < n and nb < idx.shape[0]:
        if active[k]:
            idx[nb] = k
            nb += 1
        k += 1
    return nb, k


@njit(**JIT)
def evaluate_kites(t, r, v, rest, q_design, wind_f, wind_i, wavevec_t, phase0, omega_m, amp, n_modes, W0, b0, W1, b1,
                   W2, b2, k_c, c_c, lo, hi, active, X, Y, wind, turb, R, tension, length, status, Z, sel, gain, K_b):
    """Inputs ``X`` (n, n_in), wing outputs ``Y`` (n, 17), wind at the masses (n, 5, 3), its turbulent part at the
    masses and the frame origin ``turb`` (n, 6, 3) and frame K (n, 3, 3) of every ``active`` kite at its time ``t``
    (n,) and state ``r``, ``v`` (n, 5, 3), with its bridle lines and status (as :func:`step_kites`); the latent
    filters ``Z`` (n, n_tau, n_sel) start at these inputs (a steady start). The kites go in blocks of
    :data:`BLOCK` (:func:`step_kites`)."""
    pos = np.empty((6, 3))
    w6 = np.empty((6, 3))
    t_buf = np.empty(1)
    idx = np.empty(BLOCK, dtype=np.int64)
    xb = np.empty((BLOCK, X.shape[1]))
    yb = np.empty((BLOCK, Y.shape[1]))
    h0 = np.empty((BLOCK, W0.shape[1]), dtype=np.float32)
    h1 = np.empty((BLOCK, W1.shape[1]), dtype=np.float32)
    h2 = np.empty((BLOCK, W2.shape[1]), dtype=np.float32)
    k_next = 0
    while True:
        nb, k_next = _next_block(active, k_next, idx)
        if nb == 0:
            break
        for b in range(nb):
            k = idx[b]
            kite_inputs(t[k], r[k], v[k], q_design, wind_f[k], wind_i[k], wavevec_t[k], phase0[k], omega_m[k],
                        amp[k], n_modes, X[k], wind[k], R[k], pos, w6, t_buf, turb[k], False)
            latent_update(X[k], Z[k], sel, gain, True)
            history_inputs(X[k], Z[k], sel)
            for i in range(X.shape[1]):
                xb[b, i] = X[k, i]
        mlp_rows(xb, nb, W0, b0, W1, b1, W2, b2, h0, h1, h2, yb)
        for b in range(nb):
            k = idx[b]
            for j in range(Y.shape[1]):
                Y[k, j] = yb[b, j]
            add_stiffness(X[k], K_b, Y[k])
            _line_state_one(r[k], v[k], rest[k], k_c, c_c, tension[k], length[k])
            finite = True
            for i in range(5):
                for c in range(3):
                    if not (math.isfinite(r[k, i, c]) and math.isfinite(v[k, i, c])):
                        finite = False
            status[k] = _status(finite, X[k], Y[k], lo, hi)


@njit(**JIT)
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


@njit(**JIT)
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


@njit(**JIT)
def _accelerations(rk, vk, wind5, yk, F0, zero_q, zero_K, m, rest, k_c, c_c, rho, line_cd, line_diameter,
                   tether_diameter, tether_length, reel_speed, tip_lengths, pair_damping, gravity, alpha, a, lam,
                   work):
    """:func:`particle_accelerations_into` of one kite with the wing reactions ``yk[:12]`` (F_b in K; the wing
    pulls A-D with ``-F_b``) into ``a`` (5, 3) and ``lam`` (3,). The force is the wing's own (interpolation at
    fraction 0 between two equal ends: no condensed-stiffness correction, the wing is evaluated at the stage)."""
    for i in range(4):
        for c in range(3):
            F0[i, c] = -yk[3 * i + c]
    particle_accelerations_into(rk, vk, wind5, F0, F0, 0.0, True, zero_q, zero_K, m, rest, k_c, c_c, rho, line_cd,
                                line_diameter, tether_diameter, tether_length, reel_speed, tip_lengths, pair_damping,
                                gravity, alpha, zero_K, False, a, lam, work)


@njit(**JIT)
def step_work(n_in, n_out, W0, W1, W2):
    """The work arrays of :func:`step_kites_with` for ``n_in`` inputs and ``n_out`` outputs of the wing and the
    layer widths of ``W0``, ``W1``, ``W2`` (each written before it is read in a step: a caller that steps many times
    allocates them once)."""
    return (np.empty((6, 3)), np.empty((6, 3)), np.empty(1), np.empty((4, 3)), np.zeros((4, 3)), np.zeros((12, 12)),
            np.empty((3, 3)), np.empty((5, 3)), np.empty(3), np.empty(_WORK), np.empty(BLOCK, dtype=np.int64),
            np.empty(BLOCK, dtype=np.bool_),  # per kite of the block: the RK4 sums are finite
            np.empty((BLOCK, n_in)),  # the stage's inputs (with the latent state's)
            np.empty((BLOCK, n_out)), np.empty((BLOCK, 5, 3)), np.empty((BLOCK, 5, 3)),
            np.empty((BLOCK, 4, 5, 3)),  # RK4 stage velocities (k_iv) and accelerations (k_ia)
            np.empty((BLOCK, 4, 5, 3)), np.empty((BLOCK, W0.shape[1]), dtype=np.float32),
            np.empty((BLOCK, W1.shape[1]), dtype=np.float32), np.empty((BLOCK, W2.shape[1]), dtype=np.float32))


@njit(**JIT)
def step_kites(dt, active, t, r, v, rest, pair_damping, q_design, wind_f, wind_i, wavevec_t, phase0, omega_m, amp,
               n_modes, W0, b0, W1, b1, W2, b2, m, k_c, c_c, rho, line_cd, line_diameter, tether_diameter,
               tether_length, reel_speed, winch, tip_lengths, gravity, alpha, lo, hi, X, Y, wind, turb, R, tether,
               tension, length, status, Z, sel, gain, K_b):
    """One RK4 step of ``dt`` for every ``active`` kite, in place (:class:`SurrogateKites.step`).

    Stage 1 uses ``Y`` and ``wind`` of the current states (the end of the last step); stages 2-4 evaluate the wing
    at their states, with the mean wind and gust at their positions and times and the turbulent wind ``turb``
    (n, 6, 3) of the start of the step held (the Fourier sum of :class:`kite_env.wind.WindField` is the costliest
    part of a stage; over one step of 5 ms the kite moves ~0.1 m and the turbulence, of integral length ~100 m,
    changes by ~1e-3 of its size). After the step: the projection onto the constraints, then ``X``, ``Y``,
    ``wind``, ``R`` at the new states, ``tether`` the tether force at the start of the step [N], the bridle-line
    ``tension`` and ``length`` (n, 4) and ``status`` (:data:`OK`; :data:`NON_FINITE`; :data:`OUTSIDE`: an input
    beyond ``[lo, hi]`` (30,)).

    The ground station (``dynamics.winch``, :meth:`kite_env.dynamics.simulator.FlightSimulator._winch`): each kite's
    tether length ``tether_length`` (n,) grows within the step at its reel-out speed ``reel_speed`` (n,), held over
    the step; after it the speed follows the step's tether force, ``winch = (on, F_set, c_w, v_max, tau)``.

    The reduced-order wing's latent filters ``Z`` (n, n_tau, n_sel) of the inputs ``sel`` (gains ``gain``) are held
    over the stages and updated with the inputs at the end of the step (:func:`latent_update`).

    Blocks: the active kites go in blocks of :data:`BLOCK` (:func:`_next_block`; inactive kites are skipped), and a
    block goes through each stage together: every kite's inputs, then one :func:`mlp_rows` call for the block (the
    MLP is most of a step's time, and rows evaluated together share the loads of the weights), then every kite's
    accelerations; after the four stages every kite's RK4 sums, projection and inputs, then one :func:`mlp_rows`
    call for the wing outputs at the new states. Each kite's arithmetic is that of a kite alone, in the same order
    (the kites are independent; the work arrays shared by the kites are written before they are read), so the
    result is bit for bit that of ``n = 1`` and of the one-kite-at-a-time loop before the blocks.
    """
    step_kites_with(step_work(X.shape[1], Y.shape[1], W0, W1, W2), dt, active, t, r, v, rest, pair_damping, q_design,
                    wind_f, wind_i, wavevec_t, phase0, omega_m, amp, n_modes, W0, b0, W1, b1, W2, b2, m, k_c, c_c, rho,
                    line_cd, line_diameter, tether_diameter, tether_length, reel_speed, winch, tip_lengths, gravity,
                    alpha, lo, hi, X, Y, wind, turb, R, tether, tension, length, status, Z, sel, gain, K_b)


@njit(**JIT)
def step_kites_with(work_arrays, dt, active, t, r, v, rest, pair_damping, q_design, wind_f, wind_i, wavevec_t, phase0,
                    omega_m, amp, n_modes, W0, b0, W1, b1, W2, b2, m, k_c, c_c, rho, line_cd, line_diameter,
                    tether_diameter, tether_length, reel_speed, winch, tip_lengths, gravity, alpha, lo, hi, X, Y, wind,
                    turb, R, tether, tension, length, status, Z, sel, gain, K_b):
    """:func:`step_kites` with its work arrays ``work_arrays`` (:func:`step_work`)."""
    (pos, w6, t_buf, F0, zero_q, zero_K, Rs, vn, lam, work, idx, ok, xs, ys, ws, rs, kv, ka, h0, h1,
     h2) = work_arrays
    half = 0.5 * dt
    k_next = 0
    while True:
        nb, k_next = _next_block(active, k_next, idx)
        if nb == 0:
            break
        for b in range(nb):
            k = idx[b]
            _accelerations(r[k], v[k], wind[k], Y[k], F0, zero_q, zero_K, m, rest[k], k_c, c_c, rho, line_cd,
                           line_diameter, tether_diameter, tether_length[k], reel_speed[k], tip_lengths,
                           pair_damping[k], gravity, alpha, ka[b, 0], lam, work)
            tether[k] = -lam[0] * tether_length[k]
            kv[b, 0] = v[k]
        for st in range(1, 4):
            # stages 2, 3 at t + dt/2 from (kv, ka) of the stage before; stage 4 at t + dt
            h = half if st < 3 else dt
            for b in range(nb):
                k = idx[b]
                for i in range(5):
                    for c in range(3):
                        rs[b, i, c] = r[k, i, c] + h * kv[b, st - 1, i, c]
                        kv[b, st, i, c] = v[k, i, c] + h * ka[b, st - 1, i, c]
                kite_inputs(t[k] + h, rs[b], kv[b, st], q_design, wind_f[k], wind_i[k], wavevec_t[k], phase0[k],
                            omega_m[k], amp[k], n_modes, xs[b], ws[b], Rs, pos, w6, t_buf, turb[k], True)
                history_inputs(xs[b], Z[k], sel)
            mlp_rows(xs, nb, W0, b0, W1, b1, W2, b2, h0, h1, h2, ys)
            for b in range(nb):
                k = idx[b]
                ld = reel_speed[k]
                add_stiffness(xs[b], K_b, ys[b])
                _accelerations(rs[b], kv[b, st], ws[b], ys[b], F0, zero_q, zero_K, m, rest[k], k_c, c_c, rho,
                               line_cd, line_diameter, tether_diameter, tether_length[k] + h * ld, ld, tip_lengths,
                               pair_damping[k], gravity, alpha, ka[b, st], lam, work)
        for b in range(nb):
            k = idx[b]
            l0, ld = tether_length[k], reel_speed[k]
            ok[b] = True
            for i in range(5):
                for c in range(3):
                    rs[b, i, c] = r[k, i, c] + dt / 6.0 * (kv[b, 0, i, c] + 2.0 * kv[b, 1, i, c]
                                                           + 2.0 * kv[b, 2, i, c] + kv[b, 3, i, c])
                    vn[i, c] = v[k, i, c] + dt / 6.0 * (ka[b, 0, i, c] + 2.0 * ka[b, 1, i, c]
                                                        + 2.0 * ka[b, 2, i, c] + ka[b, 3, i, c])
                    if not (math.isfinite(rs[b, i, c]) and math.isfinite(vn[i, c])):
                        ok[b] = False
            t[k] = t[k] + dt
            tether_length[k] = l0 + dt * ld
            if ok[b]:
                rp, vp = project_constraints(rs[b], vn, m, tether_length[k], tip_lengths, 3, ld)
            else:
                rp, vp = rs[b], vn
            if winch[0] > 0.0:  # the reel-out speed of the next step
                reel_speed[k] = reel_out_speed(tether[k], ld, dt, winch[1], winch[2], winch[3], winch[4])
            for i in range(5):
                for c in range(3):
                    r[k, i, c] = rp[i, c]
                    v[k, i, c] = vp[i, c]
            kite_inputs(t[k], r[k], v[k], q_design, wind_f[k], wind_i[k], wavevec_t[k], phase0[k], omega_m[k],
                        amp[k], n_modes, X[k], wind[k], R[k], pos, w6, t_buf, turb[k], False)
            latent_update(X[k], Z[k], sel, gain, False)
            history_inputs(X[k], Z[k], sel)
            for i in range(X.shape[1]):
                xs[b, i] = X[k, i]
        mlp_rows(xs, nb, W0, b0, W1, b1, W2, b2, h0, h1, h2, ys)
        for b in range(nb):
            k = idx[b]
            for j in range(Y.shape[1]):
                Y[k, j] = ys[b, j]
            add_stiffness(X[k], K_b, Y[k])
            _line_state_one(r[k], v[k], rest[k], k_c, c_c, tension[k], length[k])
            status[k] = _status(ok[b], X[k], Y[k], lo, hi)


#: the float64 arrays of :meth:`SurrogateKites.pack` in the order of their offsets in its layout, then its int64 and
#: its float32 arrays (the layout: the sizes of :data:`PACK_SIZES`, then an offset per array)
PACK_F64 = ("t", "r", "v", "rest", "pair_damping", "q_design", "wind_f", "wavevec_t", "phase0", "omega_m", "amp", "m",
            "tether_length", "reel_speed", "_winch", "tip_lengths", "_lo", "_hi", "X", "Y", "wind", "turb", "R",
            "tether_force", "tension", "length", "Z", "_gain", "_K_b", "_scalars")
PACK_I64 = ("wind_i", "status", "_sel")
PACK_F32 = ("W0", "b0", "W1", "b1", "W2", "b2")
PACK_SIZES = ("n", "n_in", "n_out", "n_mode_cols", "n_tau", "n_sel", "n_modes", "n_h0", "n_h1")
_P = len(PACK_SIZES)
_PI64 = _P + len(PACK_F64)
_PF32 = _PI64 + len(PACK_I64)


@njit(**JIT)
def kite_views(f, i, w, lay):
    """The arguments of :func:`step_kites` after ``dt`` and ``active`` as views of the buffers of
    :meth:`SurrogateKites.pack` (``f`` float64, ``i`` int64, ``w`` float32, ``lay`` the layout)."""
    n, n_in, n_out, m3, n_tau, n_sel, n_modes, n_h0, n_h1 = (lay[0], lay[1], lay[2], lay[3], lay[4], lay[5], lay[6],
                                                             lay[7], lay[8])
    o = lay[_P:_PI64]
    oi = lay[_PI64:_PF32]
    ow = lay[_PF32:]
    sc = f[o[29]:o[29] + 8]  # k_c, c_c, rho, line_cd, line_diameter, tether_diameter, gravity, alpha
    return (f[o[0]:o[0] + n], f[o[1]:o[1] + 15 * n].reshape((n, 5, 3)), f[o[2]:o[2] + 15 * n].reshape((n, 5, 3)),
            f[o[3]:o[3] + 4 * n].reshape((n, 4)), f[o[4]:o[4] + 4 * n].reshape((n, 4)),
            f[o[5]:o[5] + 12].reshape((4, 3)),
            f[o[6]:o[6] + 9 * n].reshape((n, 9)), i[oi[0]:oi[0] + 2 * n].reshape((n, 2)),
            f[o[7]:o[7] + 3 * m3 * n].reshape((n, 3, m3)), f[o[8]:o[8] + m3 * n].reshape((n, m3)),
            f[o[9]:o[9] + m3 * n].reshape((n, m3)), f[o[10]:o[10] + m3 * n].reshape((n, m3)), n_modes,
            w[ow[0]:ow[0] + n_in * n_h0].reshape((n_in, n_h0)), w[ow[1]:ow[1] + n_h0],
            w[ow[2]:ow[2] + n_h0 * n_h1].reshape((n_h0, n_h1)), w[ow[3]:ow[3] + n_h1],
            w[ow[4]:ow[4] + n_h1 * n_out].reshape((n_h1, n_out)), w[ow[5]:ow[5] + n_out],
            f[o[11]:o[11] + 5], sc[0], sc[1], sc[2], sc[3], sc[4], sc[5], f[o[12]:o[12] + n], f[o[13]:o[13] + n],
            f[o[14]:o[14] + 5], f[o[15]:o[15] + 2], sc[6], sc[7], f[o[16]:o[16] + n_in], f[o[17]:o[17] + n_in],
            f[o[18]:o[18] + n * n_in].reshape((n, n_in)), f[o[19]:o[19] + n * n_out].reshape((n, n_out)),
            f[o[20]:o[20] + 15 * n].reshape((n, 5, 3)), f[o[21]:o[21] + 18 * n].reshape((n, 6, 3)),
            f[o[22]:o[22] + 9 * n].reshape((n, 3, 3)), f[o[23]:o[23] + n], f[o[24]:o[24] + 4 * n].reshape((n, 4)),
            f[o[25]:o[25] + 4 * n].reshape((n, 4)), i[oi[1]:oi[1] + n],
            f[o[26]:o[26] + n * n_tau * n_sel].reshape((n, n_tau, n_sel)), i[oi[2]:oi[2] + n_sel],
            f[o[27]:o[27] + n_tau], f[o[28]:o[28] + 144].reshape((12, 12)))


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
    (n, 4), ``tether_length`` and ``reel_speed`` (n,) of the ground station (``dynamics.winch``; the paper's constant
    tether with ``fixed``, or below the force limit of ``force``), the wind of each kite (:meth:`set_wind`). After
    :meth:`evaluate` or :meth:`step`: ``Y`` (n, 17) the wing outputs at the current states, ``X`` (n, n_in) their
    inputs, ``R`` (n, 3, 3) frame K, ``wind`` (n, 5, 3), ``tension``/``length`` (n, 4) of the bridle lines,
    ``tether_force`` (n,) [N] (constraint force at the start of the last step), ``status`` (n,) (:data:`OK`,
    :data:`NON_FINITE`, :data:`OUTSIDE`).
    """

    def __init__(self, cfg, surrogate, q_design: np.ndarray, tip_lengths, n: int, envelope_margin: float = 0.1,
                 dt: float | None = None):
        if n < 1:
            raise ValueError(f"n must be at least 1, got {n}")
        self.cfg, self.n = cfg, int(n)
        self.dt = cfg.sim.surrogate_dt_s if dt is None else float(dt)
        self.q_design = np.ascontiguousarray(q_design, dtype=float)
        self.tip_lengths = np.asarray(tip_lengths, dtype=float)
        dyn = cfg.dynamics
        ps = ParticleSystem(dyn, self.tip_lengths, np.zeros(4), cfg.aero.rho_kg_m3)
        # particle parameters shared by all kites (kernel_parameters without rest and pair damping)
        (self.m, _, self.k_c, self.c_c, self.rho, self.line_cd, self.line_d, self.tether_d, self.l_t, _, _, _,
         self.g, self.baumgarte, _, _) = ps.kernel_parameters()
        # the MLP with its normalisations folded into the first and last layers
        W, b = [w.astype(float) for w in surrogate.weights], [c.astype(float) for c in surrogate.biases]
        W[0] = W[0] / surrogate.x_std[:, None]
        b[0] = b[0] - (surrogate.x_mean / surrogate.x_std) @ surrogate.weights[0].astype(float)
        b[-1] = b[-1] * surrogate.y_std + surrogate.y_mean
        W[-1] = W[-1] * surrogate.y_std[None, :]
        if len(W) != 3:
            raise ValueError(f"the fast fidelity needs a surrogate with two hidden layers, got {len(W) - 1}")
        self._W = [np.ascontiguousarray(w, dtype=np.float32) for w in W]
        self._b = [np.ascontiguousarray(c, dtype=np.float32) for c in b]
        self._lo, self._hi = surrogate.envelope(envelope_margin)
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
        self.n_in = len(surrogate.input_names)
        self.X = np.zeros((n, self.n_in))
        # the latent state of a wing with memory (kite_env.fitting.fit): filters of the inputs sel, per kite
        self._sel = np.array(surrogate.filtered, dtype=np.int64)
        self._gain = np.array([filter_gain(self.dt, tau) for tau in surrogate.taus])
        self.Z = np.zeros((n, len(self._gain), len(self._sel)))
        self._K_b = np.ascontiguousarray(surrogate.K_b, dtype=float)
        self.Y = np.zeros((n, 17))
        self.R = np.zeros((n, 3, 3))
        self.wind = np.zeros((n, 5, 3))
        self.turb = np.zeros((n, 6, 3))
        self.tension = np.zeros((n, 4))
        self.length = np.zeros((n, 4))
        self.tether_force = np.full(n, np.nan)
        # the ground station (dynamics.winch): each kite's tether length and reel-out speed
        self.tether_length = np.full(n, float(self.l_t))
        self.reel_speed = np.zeros(n)
        self._winch = np.array([1.0 if dyn.winch == "force" else 0.0, dyn.winch_force_N, dyn.winch_damping_Ns_per_m,
                                dyn.winch_speed_max_mps, dyn.winch_time_constant_s])
        self.status = np.zeros(n, dtype=np.int64)
        self.all_kites = np.ones(n, dtype=np.bool_)  #: every kite active (the default of step and evaluate)
        self._bind_step_args()

    def _bind_step_args(self) -> None:
        # step_kites' arguments after ``dt`` and ``active``, bound once: the arrays are updated in place and never
        # rebound (but by pack), and gathering some 50 attributes per call cost a tenth of a single kite's physics step
        self._step_args = (self.t, self.r, self.v, self.rest, self.pair_damping, self.q_design, self.wind_f,
                           self.wind_i, self.wavevec_t, self.phase0, self.omega_m, self.amp, self.n_modes,
                           *self._weights, self.m, self.k_c, self.c_c, self.rho, self.line_cd, self.line_d,
                           self.tether_d, self.tether_length, self.reel_speed, self._winch, self.tip_lengths, self.g,
                           self.baumgarte, self._lo, self._hi, self.X, self.Y, self.wind, self.turb, self.R,
                           self.tether_force, self.tension, self.length, self.status, self.Z, self._sel, self._gain,
                           self._K_b)

    def pack(self):
        """Move the arrays of :func:`step_kites` into one buffer per dtype (float64 with the scalar parameters,
        int64, float32): the attributes become views of the buffers, with their values. Returns ``(f64, i64, f32,
        layout)`` for :func:`kite_views`, so that a compiled caller takes four arrays instead of some 45 arguments
        (numba unboxes every argument at every call, about 0.1 us an array). Pack again after an attribute was
        replaced: the views are the attributes only until then (an unpickled copy holds them as separate arrays)."""
        W, b = self._W, self._b
        arrays = {name: getattr(self, name) for name in PACK_F64[:-1] + PACK_I64}
        arrays["_scalars"] = np.array([self.k_c, self.c_c, self.rho, self.line_cd, self.line_d, self.tether_d,
                                       self.g, self.baumgarte], dtype=float)
        arrays.update(W0=W[0], b0=b[0], W1=W[1], b1=b[1], W2=W[2], b2=b[2])
        sizes = (self.n, self.X.shape[1], self.Y.shape[1], self.amp.shape[1], self.Z.shape[1], self.Z.shape[2],
                 self.n_modes, W[0].shape[1], W[1].shape[1])
        layout = list(sizes)
        buffers = []
        for names, dtype in ((PACK_F64, np.float64), (PACK_I64, np.int64), (PACK_F32, np.float32)):
            offsets, total = [], 0
            for name in names:
                offsets.append(total)
                total += -(-arrays[name].size // 16) * 16  # each array on a 64-byte (float64) boundary
            buf = np.zeros(total, dtype=dtype)
            for name, o in zip(names, offsets):
                a = arrays[name]
                view = buf[o:o + a.size].reshape(a.shape)
                view[...] = a
                arrays[name] = view
            layout += offsets
            buffers.append(buf)
        for name in PACK_F64[:-1] + PACK_I64:
            setattr(self, name, arrays[name])
        self._W = [arrays["W0"], arrays["W1"], arrays["W2"]]
        self._b = [arrays["b0"], arrays["b1"], arrays["b2"]]
        self._weights = tuple(a for pair in zip(self._W, self._b) for a in pair)
        self._bind_step_args()
        return buffers[0], buffers[1], buffers[2], np.array(layout, dtype=np.int64)

    # ------------------------------------------------------------------ set-up of one kite
    def set_wind(self, k: int, wind) -> None:
        """Kite ``k`` flies in ``wind`` (:class:`kite_env.wind.WindField`, same number of turbulence modes)."""
        c = wind.cfg
        if c.turbulence_modes != self.n_modes:
            raise ValueError(f"wind has {c.turbulence_modes} turbulence modes, the kites were built for {self.n_modes}")
        self.wind_f[k] = (c.speed_mps, c.ref_height_m, c.roughness_m, math.log(c.ref_height_m / c.roughness_m),
                          c.shear_exponent, c.gust_speed_mps, c.gust_start_s, c.gust_duration_s, 0.0)
        self.wind_i[k] = (_PROFILES[c.profile], 1 if wind.turbulent else 0)
        self.wavevec_t[k] = wind.wavevec_t
        self.phase0[k] = wind.phase0
        self.omega_m[k] = wind.omega
        self.amp[k] = wind.amp

    def set_kite(self, k: int, r: np.ndarray, v: np.ndarray, t: float, pair_stiffness, L_B: float, L_D: float):
        """Place kite ``k`` at positions/velocities ``r``, ``v`` (5, 3), time ``t``, with the tip-pair stiffness
        (4,) [N/m] of its start and the steering-line rest lengths."""
        self.r[k], self.v[k], self.t[k] = r, v, t
        self.tether_length[k], self.reel_speed[k] = self.l_t, 0.0
        self.pair_damping[k] = ParticleSystem(self.cfg.dynamics, self.tip_lengths, pair_stiffness,
                                              self.cfg.aero.rho_kg_m3).pair_damping
        self.rest[k, 1], self.rest[k, 3] = L_B, L_D
        self.status[k] = OK

    # ------------------------------------------------------------------ evaluation and stepping
    def evaluate(self, active: np.ndarray | None = None) -> None:
        """Wing outputs, bridle lines and status at the current states of the ``active`` kites (default all), e.g.
        after :meth:`set_kite`."""
        active = self.all_kites if active is None else np.asarray(active, dtype=np.bool_)
        evaluate_kites(self.t, self.r, self.v, self.rest, self.q_design, self.wind_f, self.wind_i, self.wavevec_t,
                       self.phase0, self.omega_m, self.amp, self.n_modes, *self._weights, self.k_c, self.c_c,
                       self._lo, self._hi, active, self.X, self.Y, self.wind, self.turb, self.R, self.tension,
                       self.length, self.status, self.Z, self._sel, self._gain, self._K_b)

    def outside(self, k: int) -> list[str]:
        """Names of the inputs of kite ``k`` beyond the envelope."""
        names = self.surrogate.input_names
        x = self.X[k]
        return [names[i] for i in np.flatnonzero((x < self._lo) | (x > self._hi))]

    def step(self, L_B: np.ndarray, L_D: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """Advance every ``active`` (default all) kite by ``dt`` with steering-line rest lengths ``L_B``, ``L_D``
        (n,) [m]: RK4 with the wing evaluated at every stage, then the projection. Returns ``status`` (n,)."""
        if active is None:
            active = self.all_kites
            if self.n == 1 and type(L_B) is float and type(L_D) is float:  # one kite: two element stores
                self.rest[0, 1] = L_B
                self.rest[0, 3] = L_D
            else:
                self.rest[:, 1] = L_B
                self.rest[:, 3] = L_D
        else:
            active = np.asarray(active, dtype=np.bool_)
            self.rest[active, 1] = np.asarray(L_B, dtype=float)[active]
            self.rest[active, 3] = np.asarray(L_D, dtype=float)[active]
        step_kites(self.dt, active, *self._step_args)
        return self.status


# ---------------------------------------------------------------------------------------------------- one kite
def _default_start_table(cfg, surrogate_path=None):
    """The start table that belongs to the surrogate (next to its weights or shipped), None if there is none."""
    from pathlib import Path

    from kite_env.config import check_model
    from kite_env.surrogate import default_start_path
    from kite_env.surrogate.start import StartTable

    if surrogate_path:
        p = Path(surrogate_path)
        p = p.with_name(p.stem + "_start.npz")
        if not p.is_file():
            return None
    else:
        try:
            p = default_start_path(cfg.kite.name)
        except FileNotFoundError:
            return None
    table = StartTable.load(p)
    check_model(table.meta.get("model"), cfg, f"start table '{p}'")
    return table


_NAN3 = np.full(3, np.nan)
_ZERO3 = np.zeros(3)


class _FastRecord(StepRecord):
    """:class:`StepRecord` of the fast fidelity: the copies of the kite's arrays, the derived fields (``wing``,
    ``v_kite``, ``omega``, ``v_wind``) built when first read (the environment reads them only at the end of a
    control step)."""

    def __init__(self, t, r, v, Y, X, R, tension, length, tether_force, nodes, tether_length, reel_speed):
        self.t, self.state, self.R_wk = t, ParticleState(r, v), R
        self.line_tension, self.line_length, self.tether_force = tension, length, tether_force
        self.tether_length, self.reel_speed = tether_length, reel_speed
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
    start : {"table", "fe", "table_only"}
    start_table : StartTable, optional (default: the shipped one, or the one next to ``surrogate_path``; without
        one the start is solved with the FE wing)

    A state beyond the sampled envelope raises :class:`SimulationError` ("outside surrogate envelope", the inputs
    named): the wing with inertia's state cannot be rebuilt from the fast state, so the flight does not go on in the
    full model.
    """

    def __init__(self, cfg, wind, surrogate=None, wing=None, start: str = "table", start_table=None,
                 surrogate_path=None):
        if start not in ("table", "fe", "table_only"):
            raise ValueError(f"start must be 'table', 'fe' or 'table_only', got {start!r}")
        # the kites' arrays hold a state newer than ``state``, ``t`` and the last record (:meth:`advanced`)
        self._stale = False
        self._last_rec: _FastRecord | None = None
        self.cfg, self.wind, self.backend = cfg, wind, "numba"
        self.wing = wing if wing is not None else nominal_wing(cfg.kite.name, cfg)
        if surrogate is None:
            from kite_env.surrogate import surrogate_for

            surrogate, surrogate_path = surrogate_for(cfg)
        self.surrogate = surrogate
        # a wing fitted to the wing with inertia carries the effective force on Table 1's point masses and flies
        # without the quasi-static wing's tip dampers (kite_env.fitting.fit)
        self.particle_wing = not surrogate.inertial
        self.start_table = start_table
        if start_table is None and start != "fe":
            self.start_table = _default_start_table(cfg, surrogate_path)
        if start == "table_only" and self.start_table is None:
            raise ValueError("start 'table_only' needs a start table; the surrogate has none")
        self.start_mode = start if self.start_table is not None else "fe"
        self.dt = cfg.sim.surrogate_dt_s
        q0 = self.wing.design_bridle
        self.tip_lengths = np.array([np.linalg.norm(q0[0] - q0[1]), np.linalg.norm(q0[2] - q0[3])])
        self.kites = SurrogateKites(cfg, self.surrogate, q0, self.tip_lengths, 1)
        self.particles = None
        self.state = None
        self.t = 0.0
        self.L_B0 = self.L_D0 = None
        self.fe_starts = 0  # starts solved with the FE wing (no start table, or none at that start)

    fidelity_now = "surrogate"

    def start_wing(self, X):
        """The start from the table; where the table has no converged cell (its grid points next to the query did not
        converge in the cold FE solve, or the query is outside the grid), solved with the FE wing, as the full
        model does (about 1 s; counted in :attr:`fe_starts`). With ``start="table_only"`` such a start fails
        (:class:`SimulationError` "no tabulated start"; the environment then draws another start)."""
        if self.start_mode in ("table", "table_only"):
            try:
                q0, F_b, k_pairs = self.start_table.lookup(np.asarray(X.v_kite) - np.asarray(X.v_wind))
                return q0, F_b, (k_pairs if self.particle_wing else np.zeros_like(k_pairs))
            except ValueError as exc:
                if self.start_mode == "table_only":
                    raise SimulationError("no tabulated start", str(exc)) from None
        self.fe_starts += 1
        return super().start_wing(X)

    # ``state`` and ``t`` (FlightSimulator's attributes): the last record's, built from the kites' arrays when read
    # after a compiled control step (:meth:`advanced`), which makes no record
    def _fresh(self) -> None:
        if self._stale:
            self._settle(self._record())

    @property
    def state(self):
        self._fresh()
        return self._state

    @state.setter
    def state(self, value):
        self._fresh()
        self._state = value

    @property
    def t(self):
        self._fresh()
        return self._t

    @t.setter
    def t(self, value):
        self._fresh()
        self._t = value

    def _settle(self, rec):
        """``rec`` is the last record: ``state`` and ``t`` are its."""
        self._stale = False
        self._last_rec = rec
        self._state, self._t = rec.state, rec.t

    def advanced(self) -> None:
        """The kites' arrays were advanced by good physics steps outside :meth:`step` (the env's compiled control
        step, :mod:`kite_env.envs.fast_step`): the record of their state, ``state`` and ``t`` are built when read
        (:meth:`last_record`)."""
        self._stale = True

    def last_record(self):
        """The record of the last step (or of the reset)."""
        if self._stale:
            self._settle(self._record())
        return self._last_rec

    def settle_snapshot(self, snap):
        """After a compiled control step whose physics step failed: the record of the last good state, from its
        snapshot ``snap`` (:func:`kite_env.envs.fast_step.control_step`), is the last record (as :meth:`step`
        leaves it when it raises); returns it."""
        from kite_env.envs import fast_step as fs

        n_in = self.kites.X.shape[1]
        s = snap.tolist()
        rec = _FastRecord(s[fs.S_T], snap[fs.S_R:fs.S_R + 15].reshape(5, 3).copy(),
                          snap[fs.S_V:fs.S_V + 15].reshape(5, 3).copy(), snap[fs.S_Y:fs.S_Y + 17].copy(),
                          snap[fs.S_X:fs.S_X + n_in].copy(), snap[fs.S_RK:fs.S_RK + 9].reshape(3, 3).copy(),
                          snap[fs.S_TENSION:fs.S_TENSION + 4].copy(), snap[fs.S_LENGTH:fs.S_LENGTH + 4].copy(),
                          s[fs.S_TETHER], self.wing.mesh.nodes, s[fs.S_TETHER_LENGTH], s[fs.S_REEL])
        self._settle(rec)
        return rec

    def _record(self):
        ks = self.kites
        return _FastRecord(ks.t.item(0), ks.r[0].copy(), ks.v[0].copy(), ks.Y[0].copy(), ks.X[0].copy(),
                           ks.R[0].copy(), ks.tension[0].copy(), ks.length[0].copy(), ks.tether_force.item(0),
                           self.wing.mesh.nodes, ks.tether_length.item(0), ks.reel_speed.item(0))

    def _solve_wing(self, first: bool = False, commit: bool = True, state=None, t=None):
        """At the end of :meth:`reset`: hand the placed kite to the batched arrays and evaluate the wing."""
        if not first:
            raise RuntimeError("the fast fidelity evaluates the wing inside step()")
        ks = self.kites
        ks.set_wind(0, self.wind)
        ks.set_kite(0, self.state.r, self.state.v, self.t, self.pair_stiffness, self.L_B0, self.L_D0)
        ks.tether_force[0] = np.nan
        ks.evaluate()
        self._raise_status()
        rec = self._last_rec = self._record()
        return rec

    def _raise_status(self):
        st = int(self.kites.status[0])
        if st == NON_FINITE:
            raise SimulationError("non-finite particle state", f"t = {self.kites.t[0]:.4f} s")
        if st == OUTSIDE:
            raise SimulationError("outside surrogate envelope", ", ".join(self.kites.outside(0)))

    def step(self, L_B: float, L_D: float):
        if self.L_B0 is None:
            raise RuntimeError("call reset() before step()")
        if not (L_B > 0 and L_D > 0 and math.isfinite(L_B) and math.isfinite(L_D)):
            raise ValueError(f"steering-line rest lengths must be positive and finite, got {L_B!r}, {L_D!r}")
        if self._stale:  # the record of the state this step starts from, before the arrays move on
            self._settle(self._record())
        self.kites.step(L_B, L_D)
        if self.kites.status.item(0) != OK:
            self._raise_status()
        rec = self._record()
        self._settle(rec)
        return rec
