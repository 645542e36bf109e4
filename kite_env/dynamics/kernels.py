"""Compiled (numba) right-hand side of the particle system: wing force, applied forces and constrained accelerations.

:func:`particle_accelerations` computes what :meth:`kite_env.dynamics.simulator.FlightSimulator._rhs` computes with
the NumPy reference (:func:`kite_env.frames.kite_frame`, the wing force held in frame K,
:meth:`kite_env.dynamics.particles.ParticleSystem.forces` and
:meth:`~kite_env.dynamics.particles.ParticleSystem.accelerations`), term by term and in the same order, as scalar
loops over the five masses, four bridle lines and four damped pairs. The wind at the masses is evaluated in Python
by the caller (the wind model is arbitrary Python) and passed in. The results agree with NumPy to round-off
(``tests/dynamics/test_particle_kernel.py``: 1e-12 relative); the remaining differences come from the summation
order of the small matrix products (BLAS in the reference, left-to-right sums here). The formulas are documented
in the reference modules and not repeated here; comments name the reference quantity (and the paper's equation)
that each block computes.

Why: the reference ``_rhs`` costs ~0.43 ms per call on the shared 2-core development container, almost all NumPy
call overhead on (5, 3) arrays, and it is called four times per RK4 step (twice as often with the predictor-corrector
coupling). With the kernel a call costs ~10 us (best of repeats, uniform wind): ~5 us the kernel call, mostly
numba's dispatch of its 22 arguments, ~2 us the wind model, the rest Python. The first process after a change of
this file compiles (~5 s); later processes load the cache from ``__pycache__``.

Backend selection is done by :class:`kite_env.dynamics.simulator.FlightSimulator` (``backend="auto" | "numba" |
"numpy"``, resolved by :func:`kite_env.compiled.resolve_backend`: environment variable
``KITE_ENV_ELEMENT_BACKEND``, else numba when importable). Without numba the kernel below runs as plain Python
(correct, slow).

Implementation rules (as :mod:`kite_env.compiled`): ``cache=True``, ``fastmath=False`` (IEEE semantics);
scalar indexing only; no array views except the fixed slices of the caller's work array in
:func:`particle_accelerations_into` (views allocate nothing; the intermediate arrays of the right-hand side were
about a third of its cost). ``error_model="numpy"``: a division by zero (a degenerate geometry, a line of
zero length) gives ``inf``/``nan`` as in the reference, which the simulator then reports as a non-finite state,
instead of raising ``ZeroDivisionError``.
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.compiled import JIT, njit


@njit(**JIT)
def reel_out_speed(tether_force, speed, dt, force_limit, damping, speed_max, time_constant):
    """The ground station's reel-out speed for the next step (``dynamics.winch = "force"``) from the last step's tether
    force and speed: the set speed ``clip((F_t - F_set) / c_w, 0, v_max)``, followed with the time constant ``tau``
    (the exact first-order lag over ``dt``). Used by :meth:`kite_env.dynamics.simulator.FlightSimulator._winch` and
    the fast fidelity's step (:func:`kite_env.dynamics.fast.step_kites`)."""
    v_set = min(max((tether_force - force_limit) / damping, 0.0), speed_max)
    return v_set + (speed - v_set) * math.exp(-dt / time_constant)

# row indices of the state arrays (particles.A ... KCU; literals because numba's cache is keyed on this file only)
_A, _B, _C, _D, _KCU = 0, 1, 2, 3, 4


@njit(**JIT)
def particle_accelerations(r, v, wind, F0_K, F1_K, frac, interpolate, q_b_K, K_b, m, rest, k_c, c_c, rho, line_cd,
                           line_diameter, tether_diameter, tether_length, reel_speed, tip_lengths, pair_damping,
                           gravity, alpha, minv_K, wing_inertia):
    """Constrained accelerations of A, B, C, D, KCU and the constraint multipliers (``FlightSimulator._rhs``):
    :func:`particle_accelerations_into` with new arrays. Returns ``(a, lam)``."""
    a = np.empty((5, 3))
    lam = np.empty(3)
    particle_accelerations_into(r, v, wind, F0_K, F1_K, frac, interpolate, q_b_K, K_b, m, rest, k_c, c_c, rho,
                                line_cd, line_diameter, tether_diameter, tether_length, reel_speed, tip_lengths,
                                pair_damping, gravity, alpha, minv_K, wing_inertia, a, lam, np.empty(_WORK))
    return a, lam


#: length of the work array of :func:`particle_accelerations_into` (R 9, f_K 12, dq 12, f 15, e 12, l 4, T 4, fp 12,
#: minv 5; wing inertia: f in K 12, M^-1 f in K 12, M^-1 G^T of the two tip constraints 24, their G rows 24)
_WORK = 157


@njit(**JIT)
def particle_accelerations_into(r, v, wind, F0_K, F1_K, frac, interpolate, q_b_K, K_b, m, rest, k_c, c_c, rho,
                                line_cd, line_diameter, tether_diameter, tether_length, reel_speed, tip_lengths,
                                pair_damping, gravity, alpha, minv_K, wing_inertia, a, lam, work):
    """Constrained accelerations of A, B, C, D, KCU into ``a`` (5, 3) and the constraint multipliers into ``lam``
    (3,), with the intermediate arrays in ``work`` (:data:`_WORK`,) (no allocation: the fast fidelity calls this
    16 times per kite and environment step).

    Parameters
    ----------
    r, v : (5, 3) float [m], [m/s]
        Positions and velocities of A, B, C, D, KCU in W.
    wind : (5, 3) float [m/s]
        Wind velocity at the masses in W.
    F0_K, F1_K : (4, 3) float [N]
        Wing force ``F_k = -F_b`` on A-D in frame K at the start (``F0_K``) and at the end (``F1_K``) of the step;
        ``F1_K`` is used only with ``interpolate``.
    frac : float [-]
        Fraction of the step (interpolation only).
    interpolate : bool
        True: ``F_K = F0_K + frac (F1_K - F0_K)`` (predictor-corrector). False: ``F_K = F0_K - K_b dq`` with the
        move ``dq`` of the bridle points in K since the wing solution (explicit coupling, condensed stiffness).
    q_b_K : (4, 3) float [m]
        Bridle-point positions in K of the wing solution.
    K_b : (12, 12) float [N/m]
        Condensed wing stiffness ``dF_b/dq_b`` (A, B, C, D x, y, z in K).
    m : (5,) float [kg]
    rest : (4,) float [m]
        Rest lengths L_A, L_B, L_C, L_D of the bridle lines.
    k_c, c_c : float [N/m], [N s/m]
        Bridle-line stiffness and damping (Eq. 10).
    rho, line_cd, line_diameter, tether_diameter : float [kg/m^3], [-], [m], [m]
        Line drag (Eq. 11); the tether drag is applied only with ``tether_diameter > 0``.
    tether_length : float [m]
        ``l_t`` at the time of the call.
    reel_speed : float [m/s]
        ``dl_t/dt`` (winch reel-out; 0 for the paper's constant tether), constant over the step.
    tip_lengths : (2,) float [m]
        Constrained distances A-B and C-D.
    pair_damping : (4,) float [N s/m]
        Dashpots along A-C, B-D, A-D, B-C (``particles.DAMPED_PAIRS``).
    gravity, alpha : float [m/s^2], [1/s]
        Gravity and the Baumgarte rate of the constraints.
    minv_K : (12, 12) float [1/kg]
        Inverse of the wing's mass matrix on A-D in frame K (``ParticleSystem.wing_mass_K``); read only with
        ``wing_inertia``.
    wing_inertia : bool
        A-D carry the wing's (condensed, non-diagonal) mass matrix instead of the point masses ``m[:4]``.

    a : (5, 3) float [m/s^2], output
    lam : (3,) float, output
        Lagrange multipliers of the tether, A-B and C-D constraints (``M a = f + G^T lam``).
    work : (_WORK,) float, scratch
    """
    R = work[0:9].reshape((3, 3))  # views into work (no allocation)
    f_K = work[9:21].reshape((4, 3))
    dq = work[21:33]
    f = work[33:48].reshape((5, 3))
    e = work[48:60].reshape((4, 3))
    l = work[60:64]
    T = work[64:68]
    fp = work[68:80].reshape((4, 3))
    minv = work[80:85]
    # ---------------------------------------------------------------- frame K from A-D (frames.kite_frame)
    ox = 0.5 * (r[_A, 0] + r[_C, 0])
    oy = 0.5 * (r[_A, 1] + r[_C, 1])
    oz = 0.5 * (r[_A, 2] + r[_C, 2])
    y0 = r[_A, 0] - r[_C, 0]
    y1 = r[_A, 1] - r[_C, 1]
    y2 = r[_A, 2] - r[_C, 2]
    n = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    y0, y1, y2 = y0 / n, y1 / n, y2 / n
    x0 = 0.5 * (r[_B, 0] + r[_D, 0]) - ox
    x1 = 0.5 * (r[_B, 1] + r[_D, 1]) - oy
    x2 = 0.5 * (r[_B, 2] + r[_D, 2]) - oz
    s = x0 * y0 + x1 * y1 + x2 * y2
    x0, x1, x2 = x0 - s * y0, x1 - s * y1, x2 - s * y2
    n = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    x0, x1, x2 = x0 / n, x1 / n, x2 / n
    z0 = x1 * y2 - x2 * y1
    z1 = x2 * y0 - x0 * y2
    z2 = x0 * y1 - x1 * y0
    # R: columns x_k, y_k, z_k in W
    R[0, 0], R[1, 0], R[2, 0] = x0, x1, x2
    R[0, 1], R[1, 1], R[2, 1] = y0, y1, y2
    R[0, 2], R[1, 2], R[2, 2] = z0, z1, z2

    # ---------------------------------------------------------------- wing force on A-D in K, then in W
    if interpolate:
        # corrector: the wing force interpolated in time between both ends of the step
        for i in range(4):
            for k in range(3):
                f_K[i, k] = F0_K[i, k] + frac * (F1_K[i, k] - F0_K[i, k])
    else:
        # the step's solution corrected by the condensed stiffness for the move of the bridle points in K:
        # dq = (r_i - r_k) R - q_b_K, F_K = F0_K - K_b dq
        for i in range(4):
            d0 = r[i, 0] - ox
            d1 = r[i, 1] - oy
            d2 = r[i, 2] - oz
            for k in range(3):
                dq[3 * i + k] = (d0 * R[0, k] + d1 * R[1, k] + d2 * R[2, k]) - q_b_K[i, k]
        for i in range(4):
            for k in range(3):
                row = 3 * i + k
                acc = 0.0
                for j in range(12):
                    acc += K_b[row, j] * dq[j]
                f_K[i, k] = F0_K[i, k] - acc

    # ---------------------------------------------------------------- applied forces (ParticleSystem.forces)
    for i in range(5):
        f[i, 0] = 0.0
        f[i, 1] = 0.0
        f[i, 2] = 0.0 - m[i] * gravity
    if wing_inertia:  # gravity on the wing mass enters as an acceleration (below)
        for i in range(4):
            f[i, 2] = 0.0
    for i in range(4):
        for j in range(3):  # f_wing = f_K R^T
            f[i, j] += f_K[i, 0] * R[j, 0] + f_K[i, 1] * R[j, 1] + f_K[i, 2] * R[j, 2]

    # bridle lines, Eq. (10): F_c = k_c (l - L) + c_c dl/dt >= 0 along the line from the KCU to the wing point
    for i in range(4):
        li, e0, e1, e2, ldot = _line_geometry(r, v, i, _KCU)
        Ti = k_c * (li - rest[i]) + c_c * ldot
        if Ti < 0.0:  # a line cannot push (np.maximum(T, 0), nan propagates)
            Ti = 0.0
        e[i, 0], e[i, 1], e[i, 2] = e0, e1, e2
        l[i] = li
        T[i] = Ti
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for i in range(4):
        f[i, 0] -= T[i] * e[i, 0]
        f[i, 1] -= T[i] * e[i, 1]
        f[i, 2] -= T[i] * e[i, 2]
        s0 += T[i] * e[i, 0]
        s1 += T[i] * e[i, 1]
        s2 += T[i] * e[i, 2]
    f[_KCU, 0] += s0
    f[_KCU, 1] += s1
    f[_KCU, 2] += s2

    # line drag, Eq. (11): F_D = -1/2 rho C_D l d_c |v_a,n| v_a,n, normal component of the line's apparent wind
    # (mean of the end velocities minus the mean wind), half to each end
    cd = -0.5 * rho * line_cd * line_diameter
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for i in range(4):
        va0 = 0.5 * (v[i, 0] + v[_KCU, 0]) - 0.5 * (wind[i, 0] + wind[_KCU, 0])
        va1 = 0.5 * (v[i, 1] + v[_KCU, 1]) - 0.5 * (wind[i, 1] + wind[_KCU, 1])
        va2 = 0.5 * (v[i, 2] + v[_KCU, 2]) - 0.5 * (wind[i, 2] + wind[_KCU, 2])
        p = va0 * e[i, 0] + va1 * e[i, 1] + va2 * e[i, 2]
        vn0 = va0 - p * e[i, 0]
        vn1 = va1 - p * e[i, 1]
        vn2 = va2 - p * e[i, 2]
        c = cd * (l[i] * math.sqrt(vn0 * vn0 + vn1 * vn1 + vn2 * vn2))
        fd0, fd1, fd2 = c * vn0, c * vn1, c * vn2
        f[i, 0] += 0.5 * fd0
        f[i, 1] += 0.5 * fd1
        f[i, 2] += 0.5 * fd2
        s0 += fd0
        s1 += fd1
        s2 += fd2
    f[_KCU, 0] += 0.5 * s0
    f[_KCU, 1] += 0.5 * s1
    f[_KCU, 2] += 0.5 * s2

    if tether_diameter > 0.0:
        # optional tether drag (not in the paper's model): Eq. (11) for the tether as one straight line, mean
        # velocity of its ends (ground end at rest), wind at the KCU; half to the KCU
        lt = math.sqrt(r[_KCU, 0] * r[_KCU, 0] + r[_KCU, 1] * r[_KCU, 1] + r[_KCU, 2] * r[_KCU, 2])
        et0, et1, et2 = r[_KCU, 0] / lt, r[_KCU, 1] / lt, r[_KCU, 2] / lt
        vt0 = 0.5 * v[_KCU, 0] - wind[_KCU, 0]
        vt1 = 0.5 * v[_KCU, 1] - wind[_KCU, 1]
        vt2 = 0.5 * v[_KCU, 2] - wind[_KCU, 2]
        p = vt0 * et0 + vt1 * et1 + vt2 * et2
        vn0, vn1, vn2 = vt0 - p * et0, vt1 - p * et1, vt2 - p * et2
        c = 0.5 * (-0.5 * rho * line_cd * tether_diameter * lt * math.sqrt(vn0 * vn0 + vn1 * vn1 + vn2 * vn2))
        f[_KCU, 0] += c * vn0
        f[_KCU, 1] += c * vn1
        f[_KCU, 2] += c * vn2

    # relative damping between the wing points: dashpots c_ij along the pairs A-C, B-D, A-D, B-C (reference: all
    # -fp added to the first points of the pairs, then all +fp to the second points, as np.add.at)
    for q in range(4):
        i, j = pair_index(q)
        _, e0, e1, e2, pdot = _line_geometry(r, v, i, j)
        c = pair_damping[q] * pdot
        fp[q, 0], fp[q, 1], fp[q, 2] = c * e0, c * e1, c * e2
    for q in range(4):
        i, j = pair_index(q)
        f[i, 0] -= fp[q, 0]
        f[i, 1] -= fp[q, 1]
        f[i, 2] -= fp[q, 2]
    for q in range(4):
        i, j = pair_index(q)
        f[j, 0] += fp[q, 0]
        f[j, 1] += fp[q, 1]
        f[j, 2] += fp[q, 2]

    # ---------------------------------------------------------------- constrained accelerations, Eq. (12-13)
    # M a = f + G^T lam, G a = -dG/dt v - 2 alpha G v - alpha^2 g (Baumgarte), g = 1/2 (|d|^2 - L^2) for the tether
    # (d = r_KCU, ground station at the origin) and the tip beams A-B, C-D. The three constraints share no mass, so
    # S = G M^-1 G^T is diagonal and lam_c = rhs_c / S_cc (what np.linalg.solve returns for a diagonal S).
    for i in range(5):
        minv[i] = 1.0 / m[i]
        for k in range(3):
            a[i, k] = minv[i] * f[i, k]  # a_free
    if wing_inertia:
        _wing_inertia_free(f, R, minv_K, gravity, a, work[85:97], work[97:109])
    # tether: G = [0 ... r_KCU]
    rk0, rk1, rk2 = r[_KCU, 0], r[_KCU, 1], r[_KCU, 2]
    # reeling tether l_t(t) with constant dl_t/dt over the step: g = 1/2 (|r|^2 - l_t^2), dg/dt = G v - l_t l_t',
    # d2g/dt2 = G a + |v|^2 - l_t'^2
    g = 0.5 * ((rk0 * rk0 + rk1 * rk1 + rk2 * rk2) - tether_length * tether_length)
    gdot_v = v[_KCU, 0] * v[_KCU, 0] + v[_KCU, 1] * v[_KCU, 1] + v[_KCU, 2] * v[_KCU, 2] - reel_speed * reel_speed
    Gv = rk0 * v[_KCU, 0] + rk1 * v[_KCU, 1] + rk2 * v[_KCU, 2] - tether_length * reel_speed
    Ga = rk0 * a[_KCU, 0] + rk1 * a[_KCU, 1] + rk2 * a[_KCU, 2]
    S = rk0 * minv[_KCU] * rk0 + rk1 * minv[_KCU] * rk1 + rk2 * minv[_KCU] * rk2
    lam[0] = (-gdot_v - 2.0 * alpha * Gv - alpha * alpha * g - Ga) / S
    for k in range(3):
        a[_KCU, k] += minv[_KCU] * (r[_KCU, k] * lam[0])
    if wing_inertia:
        _wing_inertia_tips(r, v, R, minv_K, tip_lengths, alpha, a, lam, work[109:133].reshape((2, 12)),
                           work[133:157].reshape((2, 4, 3)))
        return
    # tip beams: G = [... d ... -d ...] at (i, j) = (A, B), (C, D)
    for c in range(1, 3):
        i = 2 * (c - 1)
        j = i + 1
        d0, d1, d2, rhs = _tip_constraint(r, v, a, i, j, tip_lengths[c - 1], alpha)
        S = (d0 * minv[i] * d0 + d1 * minv[i] * d1 + d2 * minv[i] * d2
             + d0 * minv[j] * d0 + d1 * minv[j] * d1 + d2 * minv[j] * d2)
        lc = rhs / S
        lam[c] = lc
        a[i, 0] += minv[i] * (d0 * lc)
        a[i, 1] += minv[i] * (d1 * lc)
        a[i, 2] += minv[i] * (d2 * lc)
        a[j, 0] += minv[j] * (-d0 * lc)
        a[j, 1] += minv[j] * (-d1 * lc)
        a[j, 2] += minv[j] * (-d2 * lc)


@njit(**JIT)
def _tip_constraint(r, v, a, i, j, L, alpha):
    """Tip-beam constraint ``g = 1/2 (|d|^2 - L^2)``, ``d = r_i - r_j``: ``d`` (three floats) and the right-hand side
    of ``G a_c = -dG/dt v - 2 alpha G v - alpha^2 g - G a`` for the constraint correction ``a_c`` of the
    unconstrained accelerations ``a`` (Baumgarte)."""
    d0 = r[i, 0] - r[j, 0]
    d1 = r[i, 1] - r[j, 1]
    d2 = r[i, 2] - r[j, 2]
    dv0 = v[i, 0] - v[j, 0]
    dv1 = v[i, 1] - v[j, 1]
    dv2 = v[i, 2] - v[j, 2]
    g = 0.5 * ((d0 * d0 + d1 * d1 + d2 * d2) - L * L)
    gdot_v = dv0 * dv0 + dv1 * dv1 + dv2 * dv2
    Gv = d0 * v[i, 0] + d1 * v[i, 1] + d2 * v[i, 2] - d0 * v[j, 0] - d1 * v[j, 1] - d2 * v[j, 2]
    Ga = d0 * a[i, 0] + d1 * a[i, 1] + d2 * a[i, 2] - d0 * a[j, 0] - d1 * a[j, 1] - d2 * a[j, 2]
    return d0, d1, d2, -gdot_v - 2.0 * alpha * Gv - alpha * alpha * g - Ga


@njit(**JIT)
def _minv_W(R, minv_K, x, out):
    """``out = M^-1 x`` for a (4, 3)-shaped force ``x`` on A-D in W, with the mass matrix held in K:
    ``M_W^-1 = blkdiag(R) M_K^-1 blkdiag(R)^T``; ``out`` (12,) in W."""
    for i in range(4):
        for k in range(3):
            acc = 0.0
            for j in range(12):
                jj = j // 3
                jk = j - 3 * jj
                # (R^T x)_j: K component jk of point jj
                acc += minv_K[3 * i + k, j] * (R[0, jk] * x[jj, 0] + R[1, jk] * x[jj, 1] + R[2, jk] * x[jj, 2])
            out[3 * i + k] = acc  # K components, rotated back below
    for i in range(4):
        t0, t1, t2 = out[3 * i], out[3 * i + 1], out[3 * i + 2]
        for k in range(3):
            out[3 * i + k] = R[k, 0] * t0 + R[k, 1] * t1 + R[k, 2] * t2


@njit(**JIT)
def _wing_inertia_free(f, R, minv_K, gravity, a, fk, t):
    """Unconstrained accelerations of A-D with the wing's mass matrix: ``a = M^-1 f - g e_z`` (gravity on the whole
    wing mass; the condensed mass reproduces rigid translations exactly, so its generalized weight is ``M g``)."""
    _minv_W(R, minv_K, f, t)
    for i in range(4):
        a[i, 0] = t[3 * i]
        a[i, 1] = t[3 * i + 1]
        a[i, 2] = t[3 * i + 2] - gravity


@njit(**JIT)
def _wing_inertia_tips(r, v, R, minv_K, tip_lengths, alpha, a, lam, w, gd):
    """Multipliers of the two tip-beam constraints (A-B, C-D) with the non-diagonal wing mass: both share the wing's
    mass, so ``S = G M^-1 G^T`` is a full 2 x 2 matrix; ``a += M^-1 G^T lam``. ``w`` (2, 12) and ``gd`` (2, 4, 3)
    are scratch (the columns ``M^-1 G^T`` and the rows of ``G``)."""
    rhs0 = 0.0
    rhs1 = 0.0
    for c in range(2):
        i = 2 * c
        j = i + 1
        d0, d1, d2, rhs = _tip_constraint(r, v, a, i, j, tip_lengths[c], alpha)
        if c == 0:
            rhs0 = rhs
        else:
            rhs1 = rhs
        for q in range(4):
            gd[c, q, 0] = gd[c, q, 1] = gd[c, q, 2] = 0.0
        gd[c, i, 0], gd[c, i, 1], gd[c, i, 2] = d0, d1, d2
        gd[c, j, 0], gd[c, j, 1], gd[c, j, 2] = -d0, -d1, -d2
        _minv_W(R, minv_K, gd[c], w[c])
    s00 = s01 = s10 = s11 = 0.0
    for i in range(4):
        for k in range(3):
            s00 += gd[0, i, k] * w[0, 3 * i + k]
            s01 += gd[0, i, k] * w[1, 3 * i + k]
            s10 += gd[1, i, k] * w[0, 3 * i + k]
            s11 += gd[1, i, k] * w[1, 3 * i + k]
    det = s00 * s11 - s01 * s10
    l1 = (s11 * rhs0 - s01 * rhs1) / det
    l2 = (s00 * rhs1 - s10 * rhs0) / det
    lam[1] = l1
    lam[2] = l2
    for i in range(4):
        for k in range(3):
            a[i, k] += w[0, 3 * i + k] * l1 + w[1, 3 * i + k] * l2


@njit(**JIT)
def _line_geometry(r, v, i, j):
    """Length ``l`` of the segment from mass ``j`` to mass ``i``, its unit vector ``e`` (three floats) and the rate
    of change of its length ``e · (v_i - v_j)``: ``(l, e0, e1, e2, ldot)``."""
    d0 = r[i, 0] - r[j, 0]
    d1 = r[i, 1] - r[j, 1]
    d2 = r[i, 2] - r[j, 2]
    l = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    e0, e1, e2 = d0 / l, d1 / l, d2 / l
    ldot = e0 * (v[i, 0] - v[j, 0]) + e1 * (v[i, 1] - v[j, 1]) + e2 * (v[i, 2] - v[j, 2])
    return l, e0, e1, e2, ldot


@njit(**JIT)
def pair_index(q):
    """Mass indices (i, j) of the damped pair ``q`` (particles.DAMPED_PAIRS: A-C, B-D, A-D, B-C)."""
    if q == 0:
        return _A, _C
    if q == 1:
        return _B, _D
    if q == 2:
        return _A, _D
    return _B, _C


@njit(**JIT)
def _pair_difference(x, m, i, j):
    """Inverse masses ``1/m_i, 1/m_j`` and the difference ``x_i - x_j`` of a constraint pair (``j < 0``: the ground
    station at the origin, no mass)."""
    if j < 0:
        return 1.0 / m[i], 0.0, x[i, 0], x[i, 1], x[i, 2]
    return 1.0 / m[i], 1.0 / m[j], x[i, 0] - x[j, 0], x[i, 1] - x[j, 1], x[i, 2] - x[j, 2]


@njit(**JIT)
def _pair_update(x, i, j, wi, wj, s, d0, d1, d2):
    """``x_i -= w_i s d``, ``x_j += w_j s d`` in place (the mass-weighted correction of one constraint)."""
    x[i, 0] -= wi * s * d0
    x[i, 1] -= wi * s * d1
    x[i, 2] -= wi * s * d2
    if j >= 0:
        x[j, 0] += wj * s * d0
        x[j, 1] += wj * s * d1
        x[j, 2] += wj * s * d2


@njit(**JIT)
def project_constraints(r, v, m, tether_length, tip_lengths, iters, reel_speed):
    """Mass-weighted projection of positions (``iters`` passes), then velocities, onto the tether and tip-beam
    distance constraints: :meth:`kite_env.dynamics.particles.ParticleSystem.project` in scalar loops.

    The three constraints ``g = 1/2 (|d|^2 - L^2)`` (tether at the KCU, A-B, C-D) involve disjoint masses, so
    ``G M^-1 G^T`` is diagonal and each constraint is projected on its own: ``r -= M^-1 G^T g / (G M^-1 G^T)``,
    then ``v -= M^-1 G^T (G v) / (G M^-1 G^T)`` (the tether's radial KCU speed set to ``reel_speed`` [m/s], the
    winch's dl_t/dt). Returns new arrays ``r, v`` (5, 3).
    """
    r = r.copy()
    v = v.copy()
    # (i, j, L): constraint between masses i and j (j < 0: the ground station at the origin)
    pairs_i = (_KCU, _A, _C)
    pairs_j = (-1, _B, _D)
    lengths = (tether_length, tip_lengths[0], tip_lengths[1])
    for _ in range(iters):
        for c in range(3):
            i, j, L = pairs_i[c], pairs_j[c], lengths[c]
            wi, wj, d0, d1, d2 = _pair_difference(r, m, i, j)
            dd = d0 * d0 + d1 * d1 + d2 * d2
            _pair_update(r, i, j, wi, wj, (0.5 * (dd - L * L)) / (dd * (wi + wj)), d0, d1, d2)
    for c in range(3):
        i, j = pairs_i[c], pairs_j[c]
        wi, wj, d0, d1, d2 = _pair_difference(r, m, i, j)
        _, _, u0, u1, u2 = _pair_difference(v, m, i, j)
        target = lengths[0] * reel_speed if c == 0 else 0.0  # G v of the reeling tether: l_t dl_t/dt
        _pair_update(v, i, j, wi, wj, (d0 * u0 + d1 * u1 + d2 * u2 - target)
                     / ((d0 * d0 + d1 * d1 + d2 * d2) * (wi + wj)), d0, d1, d2)
    return r, v


@njit(**JIT)
def _bridle_line(x_b, v_b, i, r_k, v_k, rest_i, k_c, c_c, eps2):
    """Line ``i`` from the KCU at ``r_k`` (velocity ``v_k``) to the wing end ``x_b[i]`` (velocity ``v_b[i]``):
    unit vector ``e0, e1, e2`` (KCU -> wing), length ``l``, the spring-damper force ``s`` of Eq. (10),
    ``root = sqrt(s^2 + eps2)`` and the smoothed pull-only tension ``T``
    (:func:`kite_env.dynamics.lines.line_tension`)."""
    a0, a1, a2 = x_b[i, 0] - r_k[0], x_b[i, 1] - r_k[1], x_b[i, 2] - r_k[2]
    l = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    e0, e1, e2 = a0 / l, a1 / l, a2 / l
    ld = e0 * (v_b[i, 0] - v_k[0]) + e1 * (v_b[i, 1] - v_k[1]) + e2 * (v_b[i, 2] - v_k[2])
    s = k_c * (l - rest_i) + c_c * ld
    root = math.sqrt(s * s + eps2)
    T = 0.5 * (s + root) if s >= 0.0 else 0.5 * eps2 / (root - s)
    return e0, e1, e2, l, s, root, T


@njit(**JIT)
def _line_drag(va0, va1, va2, e0, e1, e2, l, drag_coef):
    """Eq. (11)'s drag of a straight line of length ``l`` along ``e`` in the apparent wind ``va`` (the whole of it:
    :func:`kite_env.dynamics.lines.line_drag`, ``drag_coef = -1/2 rho C_D d``)."""
    p = va0 * e0 + va1 * e1 + va2 * e2
    n0, n1, n2 = va0 - p * e0, va1 - p * e1, va2 - p * e2
    g = drag_coef * (l * math.sqrt(n0 * n0 + n1 * n1 + n2 * n2))
    return g * n0, g * n1, g * n2


@njit(**JIT)
def kcu_line_force(r_b, v_b, r_k, v_k, wind, rest, k_c, c_c, drag_coef, eps, out):
    """The bridle lines' pull on the KCU and its half of their drag (3,) [N] into ``out``: what
    :meth:`kite_env.dynamics.dynamic_simulator.DynamicFlightSimulator._kcu_acceleration` adds with NumPy, the
    smoothed pull-only tension of Eq. (10) (:func:`kite_env.dynamics.lines.line_tension`, width ``eps``
    [N]) along each line A-D -> KCU and half of Eq. (11)'s drag (:func:`kite_env.dynamics.lines.line_drag`,
    ``drag_coef = -1/2 rho C_D d``) with the apparent wind of the lines' mean velocity minus the mean of the wind
    at their ends (``wind`` (5, 3): A-D, KCU). ``r_b``, ``v_b`` (4, 3): A-D; ``r_k``, ``v_k`` (3,): the KCU."""
    eps2 = eps * eps
    f0, f1, f2 = 0.0, 0.0, 0.0
    d0, d1, d2 = 0.0, 0.0, 0.0
    for i in range(4):
        e0, e1, e2, l, _, _, T = _bridle_line(r_b, v_b, i, r_k, v_k, rest[i], k_c, c_c, eps2)
        f0 += T * e0
        f1 += T * e1
        f2 += T * e2
        va0 = 0.5 * (v_b[i, 0] + v_k[0]) - 0.5 * (wind[i, 0] + wind[4, 0])
        va1 = 0.5 * (v_b[i, 1] + v_k[1]) - 0.5 * (wind[i, 1] + wind[4, 1])
        va2 = 0.5 * (v_b[i, 2] + v_k[2]) - 0.5 * (wind[i, 2] + wind[4, 2])
        g0, g1, g2 = _line_drag(va0, va1, va2, e0, e1, e2, l, drag_coef)
        d0 += g0
        d1 += g1
        d2 += g2
    out[0] = f0 + 0.5 * d0
    out[1] = f1 + 0.5 * d1
    out[2] = f2 + 0.5 * d2


@njit(**JIT)
def wing_bridle_lines(x_b, v_b, r_k, v_k, v_wind, rest, k_c, c_c, drag_coef, eps, e, l, T, dT, drag):
    """The bridle lines at the wing's ends A-D (:meth:`kite_env.dynamics.wing_dynamics.StepLoad._lines` and the
    drag that ``force`` adds, compiled: a Newton iterate's NumPy calls on four lines cost more than the arithmetic).
    Into ``e`` (4, 3) the unit vectors KCU -> A-D, ``l`` (4,) [m] the lengths, ``T``, ``dT`` (4,) the smoothed
    pull-only tension of Eq. (10) and its derivative (:func:`kite_env.dynamics.lines.line_tension`, width
    ``eps`` [N]), ``drag`` (4, 3) [N] the wing end's half of Eq. (11)'s drag
    (:func:`kite_env.dynamics.lines.line_drag`, ``drag_coef = -1/2 rho C_D d``) with the lines' mean velocity
    and the wind ``v_wind`` (3,). ``x_b``, ``v_b`` (4, 3): A-D; ``r_k``, ``v_k`` (3,): the KCU; frame of the step."""
    eps2 = eps * eps
    for i in range(4):
        e0, e1, e2, li, s, root, Ti = _bridle_line(x_b, v_b, i, r_k, v_k, rest[i], k_c, c_c, eps2)
        T[i] = Ti
        dT[i] = 0.5 * (1.0 + s / root)
        e[i, 0], e[i, 1], e[i, 2] = e0, e1, e2
        l[i] = li
        g0, g1, g2 = _line_drag(0.5 * (v_b[i, 0] + v_k[0]) - v_wind[0], 0.5 * (v_b[i, 1] + v_k[1]) - v_wind[1],
                                0.5 * (v_b[i, 2] + v_k[2]) - v_wind[2], e0, e1, e2, li, drag_coef)
        drag[i, 0], drag[i, 1], drag[i, 2] = 0.5 * g0, 0.5 * g1, 0.5 * g2
