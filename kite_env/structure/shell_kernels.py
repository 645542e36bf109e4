"""Compiled (numba) kernel of the flat shell triangles (:class:`kite_env.structure.shell.ShellSet`).

:func:`shell_internal` computes the internal force, tangent and energy of :meth:`ShellSet.internal
<kite_env.structure.shell.ShellSet.internal>` with :mod:`.shell_membrane` and :mod:`.shell_bending` (the NumPy
reference, vectorised over elements with ``np.einsum``; at the kite's 360 triangles it is dominated by the
overhead of several hundred NumPy calls on small arrays), term by term and with the same branch thresholds (the
series of the rotation functions, :mod:`.rotation_kernels`; the wrinkling states with ``TAUT_TOL``), as one compiled
loop over the elements; the results agree with NumPy to round-off (``tests/structure/test_kernels.py``: 1e-10
relative, observed ~1e-15).  A few products are regrouped for speed (symmetric ``B^T D B``, ``Q^T K_l Q`` as
``Q^T (K_l Q)``, reciprocals instead of repeated divisions), which changes only round-off.  :func:`_wrinkle_terms`
and :func:`_wrinkled_general` are the relaxed membrane law of any plane-stress matrix
(``shell_membrane.relaxed_general``).

The derivations are in the docstrings of the reference modules and are not repeated here; comments name the
reference quantity each block computes.  Backends, compilation, cost and the implementation rule (no array view
and no array passed to a helper inside the element loop): :mod:`kite_env.compiled`.
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.compiled import JIT, njit

from .rotation_kernels import _cross, _log_rotation, _tinv_coeffs

# Thresholds of the reference implementations.  Literals, not imports: numba's cache is keyed on this file only,
# so a changed import would not recompile; tests/structure/test_kernels.py checks that they stay equal.
_TAUT_TOL = 1e-12  # shell_membrane.TAUT_TOL
_WRINKLE_MAX_ITER = 30  # shell_membrane._WRINKLE_MAX_ITER
_WRINKLE_MAX_STEP = 0.3  # shell_membrane._WRINKLE_MAX_STEP
_WRINKLE_STEP_TOL = 1e-13  # shell_membrane._WRINKLE_STEP_TOL


@njit(**JIT)
def _wrinkle_terms(c00, c01, c02, c11, c12, c22, S0, S1, S2, t):
    """Terms of the wrinkled energy at the angle ``t`` (shell_membrane.relaxed_general, ``terms``)."""
    c2, s2 = math.cos(2.0 * t), math.sin(2.0 * t)
    v0, v1, v2 = 0.5 * (1.0 + c2), 0.5 * (1.0 - c2), s2
    t0, t1, t2 = -s2, s2, 2.0 * c2
    a0 = c00 * v0 + c01 * v1 + c02 * v2
    a1 = c01 * v0 + c11 * v1 + c12 * v2
    a2 = c02 * v0 + c12 * v1 + c22 * v2
    b0 = c00 * t0 + c01 * t1 + c02 * t2
    b1 = c01 * t0 + c11 * t1 + c12 * t2
    b2 = c02 * t0 + c12 * t1 + c22 * t2
    s = S0 * v0 + S1 * v1 + S2 * v2
    st = S0 * t0 + S1 * t1 + S2 * t2
    stt = -2.0 * c2 * S0 + 2.0 * c2 * S1 - 4.0 * s2 * S2
    d = v0 * a0 + v1 * a1 + v2 * a2
    dt = 2.0 * (t0 * a0 + t1 * a1 + t2 * a2)
    dtt = 2.0 * ((t0 * b0 + t1 * b1 + t2 * b2) + (-2.0 * c2 * a0 + 2.0 * c2 * a1 - 4.0 * s2 * a2))
    w = -s / d
    wt = -(st * d - s * dt) / (d * d)
    W_t = w * st + 0.5 * w * w * dt
    W_tt = wt * st + w * stt + w * wt * dt + 0.5 * w * w * dtt
    return a0, a1, a2, b0, b1, b2, s, d, w, wt, W_t, W_tt


@njit(**JIT)
def _wrinkled_general(c00, c01, c02, c11, c12, c22, S0, S1, S2):
    """The wrinkled state of the relaxed law of any plane-stress matrix (shell_membrane.relaxed_general): energy
    change ``w s / 2``, stress ``S + w a`` and the tangent's corrections ``a a^T / d + g g^T / W_tt``, as the angle
    ``t``'s Newton iteration from the most compressive direction of the taut stress ``(S0, S1, S2)``."""
    t = 0.5 * math.atan2(S2, 0.5 * (S0 - S1)) + 0.5 * math.pi
    for _ in range(_WRINKLE_MAX_ITER):
        W_t, W_tt = _wrinkle_terms(c00, c01, c02, c11, c12, c22, S0, S1, S2, t)[10:]
        if W_tt > 0.0:
            step = -W_t / W_tt
        else:
            step = -_WRINKLE_MAX_STEP if W_t > 0.0 else _WRINKLE_MAX_STEP
        step = min(max(step, -_WRINKLE_MAX_STEP), _WRINKLE_MAX_STEP)
        t += step
        if abs(step) <= _WRINKLE_STEP_TOL:
            break
    a0, a1, a2, b0, b1, b2, s, d, w, wt, W_t, W_tt = _wrinkle_terms(c00, c01, c02, c11, c12, c22, S0, S1, S2, t)
    g0, g1, g2 = wt * a0 + w * b0, wt * a1 + w * b1, wt * a2 + w * b2
    curv = 1.0 / W_tt if W_tt > 0.0 else 0.0
    return 0.5 * w * s, w * a0, w * a1, w * a2, a0, a1, a2, 1.0 / d, g0, g1, g2, curv


@njit(**JIT)
def shell_internal(x_e, R_e, R0, G, A0h, Y, nu, C, K_l, eps, wrinkling, bending, f_out, K_out, U_out, want_K=True,
                   vk=False):
    """Flat shell triangles (relaxed SVK membrane + co-rotational DKT + drilling), as ``ShellSet.internal``.

    Parameters
    ----------
    x_e : (n, 3, 3) float [m]; R_e : (n, 3, 3, 3) float   node positions and nodal rotations.
    R0 : (n, 3, 3) float     reference element frames;  G : (n, 3, 2) float [1/m] shape-function gradients.
    A0h : (n,) float [m^3];  Y, nu : (n,) float [Pa], [-];  C : (n, 3, 3) float [Pa] plane-stress matrices.
    K_l : (n, 9, 9) float [N m]   local bending + drilling stiffness;  eps : float  slack fraction.
    wrinkling : int               the membrane law, ``ShellSet.membrane_law``: 0 plain SVK, 1 the isotropic relaxed
                                  law, 2 the relaxed law of any ``C`` (a woven fabric).
    bending : bool                as the ``ShellSet`` option.
    f_out : (n, 18), K_out : (n, 18, 18), U_out : (n,) float   outputs (overwritten).
    want_K : bool   compute the tangent; False: only ``f_out`` and ``U_out`` are written (same values), ``K_out`` is
                    left untouched (for the residual-only assemblies of the modified Newton iteration).
    vk : bool       von Karman membrane kinematics in the reference frames ``R0`` (``shell_membrane``); False:
                    Green-Lagrange.
    """
    n = x_e.shape[0]
    F, S, D = np.empty((3, 2)), np.empty(3), np.empty((3, 3))
    Fb = np.empty((3, 2))
    B, DB, fm, Km = np.empty((3, 9)), np.empty((3, 9)), np.empty(9), np.empty((9, 9))
    av, bv, nv, r1, r2, r3 = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    M, br1, br2, ar2 = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    Rr, Rb, tmp, Ksum = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    th, m, Mi = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    Tinv, Qm, dT = np.empty((3, 3, 3)), np.empty((3, 3, 3)), np.empty((3, 3, 3))
    W, KthR, P = np.empty((3, 9)), np.empty((3, 9)), np.empty((3, 9))
    Kth, KthC, H, X = np.empty((9, 9)), np.empty((9, 3)), np.empty((9, 9)), np.empty((9, 9))
    Hs, V, ft = np.empty((4, 3, 3)), np.empty((12, 3)), np.empty(9)
    for e in range(n):
        # ---- membrane (shell_membrane.membrane_internal): f_m (9,), K_m (9, 9), energy U
        for i in range(3):
            for II in range(2):
                F[i, II] = x_e[e, 0, i] * G[e, 0, II] + x_e[e, 1, i] * G[e, 1, II] + x_e[e, 2, i] * G[e, 2, II]
        if vk:  # von Karman: the gradient's rows in the reference frame [e1, e2, n0] (shell_membrane)
            h00 = R0[e, 0, 0] * F[0, 0] + R0[e, 1, 0] * F[1, 0] + R0[e, 2, 0] * F[2, 0]
            h01 = R0[e, 0, 0] * F[0, 1] + R0[e, 1, 0] * F[1, 1] + R0[e, 2, 0] * F[2, 1]
            h10 = R0[e, 0, 1] * F[0, 0] + R0[e, 1, 1] * F[1, 0] + R0[e, 2, 1] * F[2, 0]
            h11 = R0[e, 0, 1] * F[0, 1] + R0[e, 1, 1] * F[1, 1] + R0[e, 2, 1] * F[2, 1]
            w0 = R0[e, 0, 2] * F[0, 0] + R0[e, 1, 2] * F[1, 0] + R0[e, 2, 2] * F[2, 0]
            w1 = R0[e, 0, 2] * F[0, 1] + R0[e, 1, 2] * F[1, 1] + R0[e, 2, 2] * F[2, 1]
            Ev0, Ev1, Ev2 = h00 - 1.0 + 0.5 * w0 * w0, h11 - 1.0 + 0.5 * w1 * w1, h01 + h10 + w0 * w1
            for i in range(3):
                Fb[i, 0] = R0[e, i, 0] + R0[e, i, 2] * w0
                Fb[i, 1] = R0[e, i, 1] + R0[e, i, 2] * w1
        else:
            c00 = F[0, 0] * F[0, 0] + F[1, 0] * F[1, 0] + F[2, 0] * F[2, 0]
            c11 = F[0, 1] * F[0, 1] + F[1, 1] * F[1, 1] + F[2, 1] * F[2, 1]
            c01 = F[0, 0] * F[0, 1] + F[1, 0] * F[1, 1] + F[2, 0] * F[2, 1]
            Ev0, Ev1, Ev2 = 0.5 * (c00 - 1.0), 0.5 * (c11 - 1.0), c01
            for i in range(3):
                Fb[i, 0] = F[i, 0]
                Fb[i, 1] = F[i, 1]
        # ---- relaxed SVK law (shell_membrane.relaxed_svk)
        Sf0 = C[e, 0, 0] * Ev0 + C[e, 0, 1] * Ev1 + C[e, 0, 2] * Ev2
        Sf1 = C[e, 1, 0] * Ev0 + C[e, 1, 1] * Ev1 + C[e, 1, 2] * Ev2
        Sf2 = C[e, 2, 0] * Ev0 + C[e, 2, 1] * Ev1 + C[e, 2, 2] * Ev2
        Wf = 0.5 * (Sf0 * Ev0 + Sf1 * Ev1 + Sf2 * Ev2)
        if not wrinkling:
            Wd = Wf
            S[0], S[1], S[2] = Sf0, Sf1, Sf2
            for i in range(3):
                for j in range(3):
                    D[i, j] = C[e, i, j]
        elif wrinkling == 2:  # the relaxed law of any C (shell_membrane.relaxed_general)
            hs = 0.5 * (Sf0 - Sf1)
            s_min = 0.5 * (Sf0 + Sf1) - math.sqrt(hs * hs + Sf2 * Sf2)
            taut = s_min > -_TAUT_TOL * 0.5 * (C[e, 0, 0] + C[e, 1, 1])
            E1 = 0.5 * (Ev0 + Ev1) + math.sqrt((0.5 * (Ev0 - Ev1)) ** 2 + (0.5 * Ev2) ** 2)
            wrink = (E1 > 0.0) and not taut
            cT = (1.0 - eps) * (1.0 if taut else 0.0) + eps
            cW = (1.0 - eps) * (1.0 if wrink else 0.0)
            for i in range(3):
                for j in range(3):
                    D[i, j] = (cT + cW) * C[e, i, j]
            Wd = (cT + cW) * Wf
            S[0], S[1], S[2] = (cT + cW) * Sf0, (cT + cW) * Sf1, (cT + cW) * Sf2
            if wrink:
                dW, dS0, dS1, dS2, a0, a1, a2, di, g0, g1, g2, curv = _wrinkled_general(
                    C[e, 0, 0], C[e, 0, 1], C[e, 0, 2], C[e, 1, 1], C[e, 1, 2], C[e, 2, 2], Sf0, Sf1, Sf2)
                Wd += cW * dW
                S[0] += cW * dS0
                S[1] += cW * dS1
                S[2] += cW * dS2
                aw, gw = (a0, a1, a2), (g0, g1, g2)
                for i in range(3):
                    for j in range(3):
                        D[i, j] -= cW * (aw[i] * aw[j] * di + gw[i] * gw[j] * curv)
        else:
            mean = 0.5 * (Ev0 + Ev1)
            hd = 0.5 * (Ev0 - Ev1)
            e12 = 0.5 * Ev2
            rad = math.sqrt(hd**2 + e12**2)
            if rad > 0.0:
                c2, s2 = hd / rad, e12 / rad
            else:
                c2, s2 = 1.0, 0.0
            E1, E2 = mean + rad, mean - rad
            taut = E2 + nu[e] * E1 > -_TAUT_TOL
            wrink = (E1 > 0.0) and not taut
            E1p = E1 if wrink else 0.0
            gap = E1 - E2 if wrink else 1.0
            mw1 = (0.5 * (1.0 + c2), 0.5 * (1.0 - c2), 0.5 * s2)  # m1
            mw12 = (-0.5 * s2, 0.5 * s2, 0.5 * c2)  # m12
            Ye = Y[e]
            YE = Ye * E1p
            cT = (1.0 - eps) * (1.0 if taut else 0.0) + eps
            cW = (1.0 - eps) * (1.0 if wrink else 0.0)
            Wd = cT * Wf + cW * (0.5 * YE * E1p)
            S[0] = cT * Sf0 + cW * (YE * mw1[0])
            S[1] = cT * Sf1 + cW * (YE * mw1[1])
            S[2] = cT * Sf2 + cW * (YE * mw1[2])
            g2 = 2.0 * YE / gap
            for i in range(3):
                for j in range(3):
                    D[i, j] = cT * C[e, i, j] + cW * (Ye * mw1[i] * mw1[j] + g2 * mw12[i] * mw12[j])
        # ---- B = dE_v/dx (3, 9), node-major x (of Fb);  f = A0 h S^T B;  K = A0 h (B^T D B + (G S G^T) (x) I_3)
        for a in range(3):
            for i in range(3):
                B[0, 3 * a + i] = G[e, a, 0] * Fb[i, 0]
                B[1, 3 * a + i] = G[e, a, 1] * Fb[i, 1]
                B[2, 3 * a + i] = G[e, a, 0] * Fb[i, 1] + G[e, a, 1] * Fb[i, 0]
        ah = A0h[e]
        for k in range(9):
            fm[k] = ah * (S[0] * B[0, k] + S[1] * B[1, k] + S[2] * B[2, k])
        U = ah * Wd
        if want_K:  # membrane tangent K_m = A0 h (B^T D B + (G S G^T) (x) I_3)
            for k in range(9):
                for v in range(3):
                    DB[v, k] = D[v, 0] * B[0, k] + D[v, 1] * B[1, k] + D[v, 2] * B[2, k]
            for k in range(9):  # B^T D B (symmetric)
                b0, b1, b2 = B[0, k], B[1, k], B[2, k]
                for ll in range(k, 9):
                    v = b0 * DB[0, ll] + b1 * DB[1, ll] + b2 * DB[2, ll]
                    Km[k, ll] = v
                    Km[ll, k] = v
            for a in range(3):
                for b in range(3):
                    gsg = G[e, a, 0] * (S[0] * G[e, b, 0] + S[2] * G[e, b, 1]) \
                        + G[e, a, 1] * (S[2] * G[e, b, 0] + S[1] * G[e, b, 1])
                    if vk:  # the prestress's geometric stiffness on the out-of-plane motion only
                        for i in range(3):
                            for j in range(3):
                                Km[3 * a + i, 3 * b + j] += gsg * R0[e, i, 2] * R0[e, j, 2]
                    else:
                        for i in range(3):
                            Km[3 * a + i, 3 * b + i] += gsg
            for k in range(9):
                for ll in range(9):
                    Km[k, ll] *= ah
        if not bending:
            for aa in range(3):
                for i in range(3):
                    f_out[e, 6 * aa + i] = fm[3 * aa + i]
                    f_out[e, 6 * aa + 3 + i] = 0.0
            if want_K:
                for i in range(18):
                    for j in range(18):
                        K_out[e, i, j] = 0.0
                for aa in range(3):
                    for bb in range(3):
                        for i in range(3):
                            for j in range(3):
                                K_out[e, 6 * aa + i, 6 * bb + j] = Km[3 * aa + i, 3 * bb + j]
            U_out[e] = U
            continue
        # ---- element frame (shell_bending.element_frame)
        for i in range(3):
            av[i] = x_e[e, 1, i] - x_e[e, 0, i]
            bv[i] = x_e[e, 2, i] - x_e[e, 0, i]
        nv[0], nv[1], nv[2] = _cross(av[0], av[1], av[2], bv[0], bv[1], bv[2])
        lam = av[0] * av[0] + av[1] * av[1] + av[2] * av[2]
        nu2 = nv[0] * nv[0] + nv[1] * nv[1] + nv[2] * nv[2]
        l = math.sqrt(lam)
        nn = math.sqrt(nu2)
        for i in range(3):
            r1[i] = av[i] / l
            r3[i] = nv[i] / nn
        r2[0], r2[1], r2[2] = _cross(r3[0], r3[1], r3[2], r1[0], r1[1], r1[2])
        for i in range(3):
            Rr[i, 0], Rr[i, 1], Rr[i, 2] = r1[i], r2[i], r3[i]
        # ---- local rotations theta_k, moments m = K_l theta, M_k = Rr T_k^{-T} m_k, Qm_k = T_k^{-1} Rr^T
        for k in range(3):
            for i in range(3):  # Rb = Rr^T R_e[e, k] R0[e]
                for j in range(3):
                    tmp[i, j] = R_e[e, k, i, 0] * R0[e, 0, j] + R_e[e, k, i, 1] * R0[e, 1, j] \
                        + R_e[e, k, i, 2] * R0[e, 2, j]
            for i in range(3):
                for j in range(3):
                    Rb[i, j] = Rr[0, i] * tmp[0, j] + Rr[1, i] * tmp[1, j] + Rr[2, i] * tmp[2, j]
            th[k, 0], th[k, 1], th[k, 2] = _log_rotation(Rb[0, 0], Rb[0, 1], Rb[0, 2], Rb[1, 0], Rb[1, 1], Rb[1, 2],
                                                     Rb[2, 0], Rb[2, 1], Rb[2, 2])
        Ub = 0.0
        for k in range(3):
            for a in range(3):
                s_ = 0.0
                for l2 in range(3):
                    for b in range(3):
                        s_ += K_l[e, 3 * k + a, 3 * l2 + b] * th[l2, b]
                m[k, a] = s_
                Ub += s_ * th[k, a]
        U_out[e] = U + 0.5 * Ub
        for i in range(3):
            M[i] = 0.0
        for k in range(3):
            # T_k = T_s^{-1}(theta_k), dT_k = d(T_s^{-T} m_k)/d theta_k (rotations.tangent_inv, beam._dTinvT_m)
            eta, cT, detat, dct, cD = _tinv_coeffs(th[k, 0] * th[k, 0] + th[k, 1] * th[k, 1] + th[k, 2] * th[k, 2])
            tm = th[k, 0] * m[k, 0] + th[k, 1] * m[k, 1] + th[k, 2] * m[k, 2]
            tmd = tm * dct
            for i in range(3):
                dm, tt, ct = detat * m[k, i], tmd * th[k, i], cD * th[k, i]
                for j in range(3):
                    Tinv[k, i, j] = cT * (th[k, i] * th[k, j])
                    dT[k, i, j] = dm * th[k, j] + tt * th[k, j] + ct * m[k, j]
                Tinv[k, i, i] += eta
                dT[k, i, i] += cD * tm
            Tinv[k, 0, 1] += 0.5 * th[k, 2]  # - [theta]x / 2
            Tinv[k, 0, 2] -= 0.5 * th[k, 1]
            Tinv[k, 1, 0] -= 0.5 * th[k, 2]
            Tinv[k, 1, 2] += 0.5 * th[k, 0]
            Tinv[k, 2, 0] += 0.5 * th[k, 1]
            Tinv[k, 2, 1] -= 0.5 * th[k, 0]
            dT[k, 0, 1] += 0.5 * m[k, 2]  # + [m]x / 2
            dT[k, 0, 2] -= 0.5 * m[k, 1]
            dT[k, 1, 0] -= 0.5 * m[k, 2]
            dT[k, 1, 2] += 0.5 * m[k, 0]
            dT[k, 2, 0] += 0.5 * m[k, 1]
            dT[k, 2, 1] -= 0.5 * m[k, 0]
            for b in range(3):
                tmp[0, b] = Tinv[k, 0, b] * m[k, 0] + Tinv[k, 1, b] * m[k, 1] + Tinv[k, 2, b] * m[k, 2]
            for a in range(3):
                Mi[k, a] = Rr[a, 0] * tmp[0, 0] + Rr[a, 1] * tmp[0, 1] + Rr[a, 2] * tmp[0, 2]
                M[a] += Mi[k, a]
            for a in range(3):
                for c in range(3):
                    Qm[k, a, c] = Tinv[k, a, 0] * Rr[c, 0] + Tinv[k, a, 1] * Rr[c, 1] + Tinv[k, a, 2] * Rr[c, 2]
        # ---- frame spin W (shell_bending.frame_spin)
        inn = 1.0 / nn
        il = 1.0 / l
        br2[0], br2[1], br2[2] = _cross(bv[0], bv[1], bv[2], r2[0], r2[1], r2[2])
        br1[0], br1[1], br1[2] = _cross(bv[0], bv[1], bv[2], r1[0], r1[1], r1[2])
        ar2[0], ar2[1], ar2[2] = _cross(av[0], av[1], av[2], r2[0], r2[1], r2[2])
        for i in range(3):
            for j in range(3):
                wa = (-r1[i] * br2[j] + r2[i] * br1[j]) * inn + r3[i] * r2[j] * il
                wb = r1[i] * ar2[j] * inn
                W[i, j] = -wa - wb
                W[i, 3 + j] = wa
                W[i, 6 + j] = wb
        for j in range(9):
            ft[j] = -(W[0, j] * M[0] + W[1, j] * M[1] + W[2, j] * M[2])
        if not want_K:
            for aa in range(3):
                for i in range(3):
                    f_out[e, 6 * aa + i] = fm[3 * aa + i] + ft[3 * aa + i]
                    f_out[e, 6 * aa + 3 + i] = Mi[aa, i]
            continue
        # ---- K_th = Q^T K_l Q + blockdiag(Rr dT_k Qm_k),  Q = blockdiag(Qm_k); X = K_l Q first
        for l2 in range(3):
            for j in range(3):
                u0, u1, u2 = Qm[l2, 0, j], Qm[l2, 1, j], Qm[l2, 2, j]
                for r in range(9):
                    X[r, 3 * l2 + j] = K_l[e, r, 3 * l2] * u0 + K_l[e, r, 3 * l2 + 1] * u1 + K_l[e, r, 3 * l2 + 2] * u2
        for k in range(3):
            q00, q01, q02 = Qm[k, 0, 0], Qm[k, 0, 1], Qm[k, 0, 2]
            q10, q11, q12 = Qm[k, 1, 0], Qm[k, 1, 1], Qm[k, 1, 2]
            q20, q21, q22 = Qm[k, 2, 0], Qm[k, 2, 1], Qm[k, 2, 2]
            for c in range(9):
                x0, x1, x2 = X[3 * k, c], X[3 * k + 1, c], X[3 * k + 2, c]
                Kth[3 * k, c] = q00 * x0 + q10 * x1 + q20 * x2
                Kth[3 * k + 1, c] = q01 * x0 + q11 * x1 + q21 * x2
                Kth[3 * k + 2, c] = q02 * x0 + q12 * x1 + q22 * x2
            for i in range(3):  # + (Rr dT_k) Qm_k
                g0 = Rr[i, 0] * dT[k, 0, 0] + Rr[i, 1] * dT[k, 1, 0] + Rr[i, 2] * dT[k, 2, 0]
                g1 = Rr[i, 0] * dT[k, 0, 1] + Rr[i, 1] * dT[k, 1, 1] + Rr[i, 2] * dT[k, 2, 1]
                g2 = Rr[i, 0] * dT[k, 0, 2] + Rr[i, 1] * dT[k, 1, 2] + Rr[i, 2] * dT[k, 2, 2]
                Kth[3 * k + i, 3 * k] += g0 * q00 + g1 * q10 + g2 * q20
                Kth[3 * k + i, 3 * k + 1] += g0 * q01 + g1 * q11 + g2 * q21
                Kth[3 * k + i, 3 * k + 2] += g0 * q02 + g1 * q12 + g2 * q22
        # ---- column / row sums: K_th W_st = KthC W, W_st^T K_th = W^T KthR, Ksum = sum of all 3x3 blocks
        for r in range(9):
            for j in range(3):
                KthC[r, j] = Kth[r, j] + Kth[r, 3 + j] + Kth[r, 6 + j]
        for i in range(3):
            for c in range(9):
                KthR[i, c] = Kth[i, c] + Kth[3 + i, c] + Kth[6 + i, c]
            for j in range(3):
                Ksum[i, j] = KthC[i, j] + KthC[3 + i, j] + KthC[6 + i, j]
        Ksum[0, 1] -= M[2]  # + [M]x
        Ksum[0, 2] += M[1]
        Ksum[1, 0] += M[2]
        Ksum[1, 2] -= M[0]
        Ksum[2, 0] -= M[1]
        Ksum[2, 1] += M[0]
        # ---- H = d(W^T M)/dx at fixed M (shell_bending.frame_spin_hessian), (a, b) blocks first
        a0, a1, a2 = av[0], av[1], av[2]
        b0, b1, b2 = bv[0], bv[1], bv[2]
        n0, n1, n2 = nv[0], nv[1], nv[2]
        M0, M1, M2 = M[0], M[1], M[2]
        p0, p1, p2 = _cross(n0, n1, n2, M0, M1, M2)
        s = n0 * M0 + n1 * M1 + n2 * M2
        Ma = M0 * a0 + M1 * a1 + M2 * a2
        Mb = M0 * b0 + M1 * b1 + M2 * b2
        ab = a0 * b0 + a1 * b1 + a2 * b2
        inu = 1.0 / nu2
        inl = 1.0 / (nu2 * lam)
        inu2 = inu**2
        # rows of V: 0 dnu_a = 2 b x n, 1 dnu_b = 2 n x a, 2 q = n x a, 3 bp, 4 ap, 5 Va, 6 Vb, 8-11 skew vectors
        x0, x1, x2 = _cross(b0, b1, b2, n0, n1, n2)
        V[0, 0], V[0, 1], V[0, 2] = 2.0 * x0, 2.0 * x1, 2.0 * x2
        x0, x1, x2 = _cross(n0, n1, n2, a0, a1, a2)
        V[1, 0], V[1, 1], V[1, 2] = 2.0 * x0, 2.0 * x1, 2.0 * x2
        V[2, 0], V[2, 1], V[2, 2] = x0, x1, x2
        x0, x1, x2 = _cross(b0, b1, b2, p0, p1, p2)
        V[3, 0], V[3, 1], V[3, 2] = x0 * inu2, x1 * inu2, x2 * inu2
        x0, x1, x2 = _cross(a0, a1, a2, p0, p1, p2)
        V[4, 0], V[4, 1], V[4, 2] = x0 * inu2, x1 * inu2, x2 * inu2
        x0, x1, x2 = _cross(b0, b1, b2, M0, M1, M2)
        y0, y1, y2 = _cross(M0, M1, M2, a0, a1, a2)
        V[5, 0] = x0 - s * (V[0, 0] * inu + 2.0 * a0 / lam)
        V[5, 1] = x1 - s * (V[0, 1] * inu + 2.0 * a1 / lam)
        V[5, 2] = x2 - s * (V[0, 2] * inu + 2.0 * a2 / lam)
        V[6, 0] = y0 - (s * inu) * V[1, 0]
        V[6, 1] = y1 - (s * inu) * V[1, 1]
        V[6, 2] = y2 - (s * inu) * V[1, 2]
        # skew-symmetric and diagonal parts of the (a, b) blocks
        V[8, 0], V[8, 1], V[8, 2] = (Mb * inu) * b0 + (s * inl) * n0, (Mb * inu) * b1 + (s * inl) * n1, \
            (Mb * inu) * b2 + (s * inl) * n2
        V[9, 0], V[9, 1], V[9, 2] = (p0 - Ma * b0) * inu, (p1 - Ma * b1) * inu, (p2 - Ma * b2) * inu
        V[10, 0], V[10, 1], V[10, 2] = (-p0 - Mb * a0) * inu, (-p1 - Mb * a1) * inu, (-p2 - Mb * a2) * inu
        V[11, 0], V[11, 1], V[11, 2] = (Ma * inu) * a0, (Ma * inu) * a1, (Ma * inu) * a2
        for blk in range(4):
            r = 8 + blk
            Hs[blk, 0, 0], Hs[blk, 0, 1], Hs[blk, 0, 2] = 0.0, -V[r, 2], V[r, 1]
            Hs[blk, 1, 0], Hs[blk, 1, 1], Hs[blk, 1, 2] = V[r, 2], 0.0, -V[r, 0]
            Hs[blk, 2, 0], Hs[blk, 2, 1], Hs[blk, 2, 2] = -V[r, 1], V[r, 0], 0.0
        for k in range(3):
            Hs[0, k, k] -= s * ab * inl
            Hs[1, k, k] += s * inu
        # rank-one parts
        for i in range(3):
            qs = V[2, i] * inl
            sb = (s * inl) * bv[i]
            sa = (s * inl) * av[i]
            nM = nv[i] * inu
            bp = V[3, i]
            ap = V[4, i]
            for j in range(3):
                Hs[0, i, j] += bp * V[0, j] + qs * V[5, j] + sb * av[j]
                Hs[1, i, j] += bp * V[1, j] + qs * V[6, j] - nM * M[j] - sa * av[j]
                Hs[2, i, j] += -ap * V[0, j] + nM * M[j]
                Hs[3, i, j] += -ap * V[1, j]
        # chain rule to node-major x: a = x1 - x0, b = x2 - x0
        for i in range(3):
            for j in range(3):
                haa, hab, hba, hbb = Hs[0, i, j], Hs[1, i, j], Hs[2, i, j], Hs[3, i, j]
                ha_, hb_ = haa + hba, hab + hbb
                H[i, j] = ha_ + hb_
                H[i, 3 + j] = -ha_
                H[i, 6 + j] = -hb_
                H[3 + i, j] = -(haa + hab)
                H[3 + i, 3 + j] = haa
                H[3 + i, 6 + j] = hab
                H[6 + i, j] = -(hba + hbb)
                H[6 + i, 3 + j] = hba
                H[6 + i, 6 + j] = hbb
        for i in range(3):  # P = (Ksum + [M]x) W
            for c in range(9):
                P[i, c] = Ksum[i, 0] * W[0, c] + Ksum[i, 1] * W[1, c] + Ksum[i, 2] * W[2, c]
        # ---- scatter into the 18x18 node-major [u, w] layout:
        #      K_tt = W^T P - H + K_m,  K_tr = -W^T KthR,  K_rt = -(KthC + [M_k]x) W,  K_rr = K_th
        for aa in range(3):
            for i in range(3):
                ra, rr = 6 * aa, 6 * aa + 3
                r9 = 3 * aa + i
                f_out[e, ra + i] = fm[r9] + ft[r9]
                f_out[e, rr + i] = Mi[aa, i]
                if i == 0:
                    s0, s1, s2 = 0.0, -Mi[aa, 2], Mi[aa, 1]
                elif i == 1:
                    s0, s1, s2 = Mi[aa, 2], 0.0, -Mi[aa, 0]
                else:
                    s0, s1, s2 = -Mi[aa, 1], Mi[aa, 0], 0.0
                c0, c1, c2 = KthC[r9, 0] + s0, KthC[r9, 1] + s1, KthC[r9, 2] + s2
                w0, w1, w2 = W[0, r9], W[1, r9], W[2, r9]
                for bb in range(3):
                    for j in range(3):
                        c9 = 3 * bb + j
                        K_out[e, ra + i, 6 * bb + j] = (w0 * P[0, c9] + w1 * P[1, c9] + w2 * P[2, c9]) \
                            - H[r9, c9] + Km[r9, c9]
                        K_out[e, ra + i, 6 * bb + 3 + j] = -(w0 * KthR[0, c9] + w1 * KthR[1, c9] + w2 * KthR[2, c9])
                        K_out[e, rr + i, 6 * bb + j] = -(c0 * W[0, c9] + c1 * W[1, c9] + c2 * W[2, c9])
                        K_out[e, rr + i, 6 * bb + 3 + j] = Kth[r9, c9]
