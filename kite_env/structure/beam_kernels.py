"""Compiled (numba) kernels of the co-rotational beams (:class:`kite_env.structure.beam.BeamSet`).

:func:`beam_internal` computes the internal force, tangent and energy of :meth:`BeamSet.internal
<kite_env.structure.beam.BeamSet.internal>` (the NumPy reference, vectorised over elements with ``np.einsum``;
at the kite's 107 beams it is dominated by the overhead of several hundred NumPy calls on small arrays), term by
term and with the same branch thresholds (the series of the rotation functions, :mod:`.rotation_kernels`), as one
compiled loop over the elements; the results agree with NumPy to round-off (``tests/structure/test_kernels.py``:
1e-10 relative, observed ~1e-15).  A few products are regrouped for speed (reciprocals instead of repeated
divisions), which changes only round-off.  :func:`beam_set_bending_torsion` (``BeamSet.set_bending_torsion``, the
same bits) and :func:`beam_local_rotations` (the chord and local end rotations of ``BeamSet._frame``, for the
inflated tubes' secant stiffness, :mod:`.tube_kernels`) are the cheap per-iterate parts.

The derivations are in the docstrings of the reference modules and are not repeated here; comments name the
reference quantity each block computes.  Backends, compilation, cost and the implementation rule (no array view
and no array passed to a helper inside the element loop): :mod:`kite_env.compiled`.
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.compiled import JIT, njit

from .rotation_kernels import _cross, _quat_logm, _tinv_coeffs


@njit(**JIT)
def beam_local_rotations(x_e, R_e, R0, l_out, th_out):
    """Chord length and local end rotations of co-rotational beams, as ``BeamSet._frame`` (``l``, ``theta``).

    x_e : (n, 2, 3), R_e : (n, 2, 3, 3), R0 : (n, 3, 3) as :func:`beam_internal`; outputs ``l_out`` (n,) [m] and
    ``th_out`` (n, 2, 3) [rad] (overwritten). Used for the inflated-tube secant stiffness once per iteration.
    """
    n = x_e.shape[0]
    r1, r2, r3, q, tmp3 = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    qn = np.empty((2, 3))
    Rr, Rb, tmp = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    for e in range(n):
        for i in range(3):
            tmp3[i] = x_e[e, 1, i] - x_e[e, 0, i]
        l = math.sqrt(tmp3[0] * tmp3[0] + tmp3[1] * tmp3[1] + tmp3[2] * tmp3[2])
        l_out[e] = l
        for i in range(3):
            r1[i] = tmp3[i] / l
        for k in range(2):
            for i in range(3):
                qn[k, i] = R_e[e, k, i, 0] * R0[e, 0, 1] + R_e[e, k, i, 1] * R0[e, 1, 1] + R_e[e, k, i, 2] * R0[e, 2, 1]
        for i in range(3):
            q[i] = 0.5 * (qn[0, i] + qn[1, i])
        tmp3[0], tmp3[1], tmp3[2] = _cross(r1[0], r1[1], r1[2], q[0], q[1], q[2])
        nn3 = math.sqrt(tmp3[0] * tmp3[0] + tmp3[1] * tmp3[1] + tmp3[2] * tmp3[2])
        for i in range(3):
            r3[i] = tmp3[i] / nn3
        r2[0], r2[1], r2[2] = _cross(r3[0], r3[1], r3[2], r1[0], r1[1], r1[2])
        for i in range(3):
            Rr[i, 0], Rr[i, 1], Rr[i, 2] = r1[i], r2[i], r3[i]
        for k in range(2):
            for i in range(3):
                for j in range(3):
                    tmp[i, j] = R_e[e, k, i, 0] * R0[e, 0, j] + R_e[e, k, i, 1] * R0[e, 1, j] \
                        + R_e[e, k, i, 2] * R0[e, 2, j]
            for i in range(3):
                for j in range(3):
                    Rb[i, j] = Rr[0, i] * tmp[0, j] + Rr[1, i] * tmp[1, j] + Rr[2, i] * tmp[2, j]
            th_out[e, k, 0], th_out[e, k, 1], th_out[e, k, 2] = _quat_logm(
                Rb[0, 0], Rb[0, 1], Rb[0, 2], Rb[1, 0], Rb[1, 1], Rb[1, 2], Rb[2, 0], Rb[2, 1], Rb[2, 2])


@njit(**JIT)
def beam_set_bending_torsion(rows, EI, GJ, g_bend, g_twist, L0, EI2, EI3, GJ_out, k11, k12, kmat):
    """``BeamSet.set_bending_torsion`` in one loop (the inflated tubes' secant stiffness, set at every iterate):
    ``EI2 = EI3 = EI``, ``GJ`` and the diagonal local blocks ``k11 = (GJ, 4 EI, 4 EI) / L0``, ``k12 = (-GJ, 2 EI,
    2 EI) / L0`` of the beams ``rows``, and the material terms ``kmat = (g_bend, g_twist)`` (zero-length arrays:
    0). The same operations as the NumPy method, so the same bits."""
    has_b, has_t = g_bend.shape[0] > 0, g_twist.shape[0] > 0
    for i in range(rows.shape[0]):
        r = rows[i]
        ei, gj = EI[i], GJ[i]
        EI2[r] = ei
        EI3[r] = ei
        GJ_out[r] = gj
        iL = 1.0 / L0[r]
        k11[r, 0] = gj * iL
        k11[r, 1] = 4.0 * ei * iL
        k11[r, 2] = 4.0 * ei * iL
        k12[r, 0] = -gj * iL
        k12[r, 1] = 2.0 * ei * iL
        k12[r, 2] = 2.0 * ei * iL
        kmat[r, 0] = g_bend[i] if has_b else 0.0
        kmat[r, 1] = g_twist[i] if has_t else 0.0


@njit(**JIT)
def beam_internal(x_e, R_e, R0, L0, EA, k11, k12, kmat, f_out, K_out, U_out, want_K=True):
    """Co-rotational Euler-Bernoulli beams, as :meth:`kite_env.structure.beam.BeamSet.internal`.

    Parameters
    ----------
    x_e : (n, 2, 3) float [m]; R_e : (n, 2, 3, 3) float   node positions and nodal rotations.
    R0 : (n, 3, 3) float                                   reference element frames (columns e1, e2, e3).
    L0, EA : (n,) float [m], [N];  k11, k12 : (n, 3) float [N m]   local stiffness diagonals (``BeamSet._k11``).
    kmat : (n, 2) float [1/(N m)]   rank-one material terms of a moment law ``m = k(theta) theta``
                                  (``BeamSet._kmat``): ``dm/dtheta = K_l + g m m^T`` over the bending (column 0) and
                                  the torsion (column 1) components; 0 for a linear element.
    f_out : (n, 12), K_out : (n, 12, 12), U_out : (n,) float   outputs (overwritten).
    want_K : bool   compute the tangent; False: only ``f_out`` and ``U_out`` are written (same values).
    """
    n = x_e.shape[0]
    r1, r2, r3, q, tmp3 = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    qn, th, m, Mi, gw = np.empty((2, 3)), np.empty((2, 3)), np.empty((2, 3)), np.empty((2, 3)), np.empty((2, 3))
    Rr, Rb, tmp, A = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    Tinv, dT, TR = np.empty((2, 3, 3)), np.empty((2, 3, 3)), np.empty((2, 3, 3))
    M, AM, Aq, qr1, qr2 = np.empty(3), np.empty(3), np.empty(3), np.empty((2, 3)), np.empty((2, 3))
    g, bu, dgam, dD = np.empty(12), np.zeros(12), np.empty(12), np.empty(12)
    W, RrTW, Y, Zs = np.empty((3, 12)), np.empty((3, 12)), np.empty((3, 12)), np.empty((3, 12))
    Bth, KlB = np.empty((2, 3, 12)), np.empty((2, 3, 12))
    for e in range(n):
        # ---- co-rotated frame (BeamSet._frame)
        for i in range(3):
            tmp3[i] = x_e[e, 1, i] - x_e[e, 0, i]
        l = math.sqrt(tmp3[0] * tmp3[0] + tmp3[1] * tmp3[1] + tmp3[2] * tmp3[2])
        il = 1.0 / l
        for i in range(3):
            r1[i] = tmp3[i] / l
        for k in range(2):
            for i in range(3):
                qn[k, i] = R_e[e, k, i, 0] * R0[e, 0, 1] + R_e[e, k, i, 1] * R0[e, 1, 1] + R_e[e, k, i, 2] * R0[e, 2, 1]
        for i in range(3):
            q[i] = 0.5 * (qn[0, i] + qn[1, i])
        tmp3[0], tmp3[1], tmp3[2] = _cross(r1[0], r1[1], r1[2], q[0], q[1], q[2])
        nn3 = math.sqrt(tmp3[0] * tmp3[0] + tmp3[1] * tmp3[1] + tmp3[2] * tmp3[2])
        for i in range(3):
            r3[i] = tmp3[i] / nn3
        r2[0], r2[1], r2[2] = _cross(r3[0], r3[1], r3[2], r1[0], r1[1], r1[2])
        for i in range(3):
            Rr[i, 0], Rr[i, 1], Rr[i, 2] = r1[i], r2[i], r3[i]
        for k in range(2):
            for i in range(3):  # Rb = Rr^T R_e[e, k] R0[e]
                for j in range(3):
                    tmp[i, j] = R_e[e, k, i, 0] * R0[e, 0, j] + R_e[e, k, i, 1] * R0[e, 1, j] \
                        + R_e[e, k, i, 2] * R0[e, 2, j]
            for i in range(3):
                for j in range(3):
                    Rb[i, j] = Rr[0, i] * tmp[0, j] + Rr[1, i] * tmp[1, j] + Rr[2, i] * tmp[2, j]
            th[k, 0], th[k, 1], th[k, 2] = _quat_logm(Rb[0, 0], Rb[0, 1], Rb[0, 2], Rb[1, 0], Rb[1, 1], Rb[1, 2],
                                                     Rb[2, 0], Rb[2, 1], Rb[2, 2])
        # ---- local forces: m_k = K_l theta, M_k = Rr T_k^{-T} m_k
        N = EA[e] / L0[e] * (l - L0[e])
        for a in range(3):
            m[0, a] = k11[e, a] * th[0, a] + k12[e, a] * th[1, a]
            m[1, a] = k12[e, a] * th[0, a] + k11[e, a] * th[1, a]
        for k in range(2):
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
            for b in range(3):  # T^{-T} m
                tmp3[b] = Tinv[k, 0, b] * m[k, 0] + Tinv[k, 1, b] * m[k, 1] + Tinv[k, 2, b] * m[k, 2]
            for a in range(3):
                Mi[k, a] = Rr[a, 0] * tmp3[0] + Rr[a, 1] * tmp3[1] + Rr[a, 2] * tmp3[2]
            for a in range(3):  # T_k^{-1} Rr^T
                for c in range(3):
                    TR[k, a, c] = Tinv[k, a, 0] * Rr[c, 0] + Tinv[k, a, 1] * Rr[c, 1] + Tinv[k, a, 2] * Rr[c, 2]
        U_out[e] = 0.5 * EA[e] / L0[e] * (l - L0[e]) ** 2 + 0.5 * (
            m[0, 0] * th[0, 0] + m[0, 1] * th[0, 1] + m[0, 2] * th[0, 2]
            + m[1, 0] * th[1, 0] + m[1, 1] * th[1, 1] + m[1, 2] * th[1, 2])
        # ---- spin of the element frame: dw_r = W dd
        Dd = q[0] * r2[0] + q[1] * r2[1] + q[2] * r2[2]
        iD = 1.0 / Dd
        gam = q[0] * r1[0] + q[1] * r1[1] + q[2] * r1[2]
        sfac = gam / (l * Dd)
        for k in range(2):
            tmp3[0], tmp3[1], tmp3[2] = _cross(qn[k, 0], qn[k, 1], qn[k, 2], r3[0], r3[1], r3[2])
            for i in range(3):
                gw[k, i] = tmp3[i] / (2.0 * Dd)
        for i in range(3):
            g[i] = sfac * r3[i]
            g[3 + i] = gw[0, i]
            g[6 + i] = -g[i]
            g[9 + i] = gw[1, i]
        for a in range(3):
            for j in range(12):
                W[a, j] = r1[a] * g[j]
        s0, s1, s2 = r1[0] * il, r1[1] * il, r1[2] * il  # W[:, 0:3] -= [r1]x / l, W[:, 6:9] += [r1]x / l
        W[0, 1] += s2
        W[0, 2] -= s1
        W[1, 0] -= s2
        W[1, 2] += s0
        W[2, 0] += s1
        W[2, 1] -= s0
        W[0, 7] -= s2
        W[0, 8] += s1
        W[1, 6] += s2
        W[1, 8] -= s0
        W[2, 6] -= s1
        W[2, 7] += s0
        # ---- internal force f = N bu + sum_k E_k^T M_k, E_k = P_k - W
        for i in range(3):
            bu[i] = -r1[i]
            bu[6 + i] = r1[i]
            M[i] = Mi[0, i] + Mi[1, i]
        for j in range(12):
            f_out[e, j] = N * bu[j] - (W[0, j] * M[0] + W[1, j] * M[1] + W[2, j] * M[2])
        for i in range(3):
            f_out[e, 3 + i] += Mi[0, i]
            f_out[e, 9 + i] += Mi[1, i]
        if not want_K:
            continue
        # ---- d theta_k / dd = T_k^{-1} Rr^T E_k = T_k^{-1} Rr^T (P_k - W)
        for a in range(3):
            ra0, ra1, ra2 = Rr[0, a], Rr[1, a], Rr[2, a]
            for j in range(12):
                RrTW[a, j] = ra0 * W[0, j] + ra1 * W[1, j] + ra2 * W[2, j]
        for k in range(2):
            for a in range(3):
                t0, t1, t2 = Tinv[k, a, 0], Tinv[k, a, 1], Tinv[k, a, 2]
                for j in range(12):
                    Bth[k, a, j] = -(t0 * RrTW[0, j] + t1 * RrTW[1, j] + t2 * RrTW[2, j])
                for c in range(3):
                    Bth[k, a, 6 * k + 3 + c] += TR[k, a, c]
        for a in range(3):  # K_l B (diagonal 3x3 blocks k11, k12)
            a11, a12 = k11[e, a], k12[e, a]
            for j in range(12):
                KlB[0, a, j] = a11 * Bth[0, a, j] + a12 * Bth[1, a, j]
                KlB[1, a, j] = a12 * Bth[0, a, j] + a11 * Bth[1, a, j]
        gb, gt = kmat[e, 0], kmat[e, 1]
        if gb != 0.0 or gt != 0.0:  # (dm/dtheta) B = K_l B + g m (m^T B) per component group
            for j in range(12):
                sb = m[0, 1] * Bth[0, 1, j] + m[0, 2] * Bth[0, 2, j] + m[1, 1] * Bth[1, 1, j] + m[1, 2] * Bth[1, 2, j]
                st = m[0, 0] * Bth[0, 0, j] + m[1, 0] * Bth[1, 0, j]
                for k in range(2):
                    KlB[k, 0, j] += gt * m[k, 0] * st
                    KlB[k, 1, j] += gb * m[k, 1] * sb
                    KlB[k, 2, j] += gb * m[k, 2] * sb
        # ---- Z_k = Rr (T_k^{-T} (K_l B)_k + dT_k B_k) - [M_k]x W;  Zs = Z_0 + Z_1
        for k in range(2):
            for a in range(3):
                t0, t1, t2 = Tinv[k, 0, a], Tinv[k, 1, a], Tinv[k, 2, a]
                d0, d1, d2 = dT[k, a, 0], dT[k, a, 1], dT[k, a, 2]
                for j in range(12):
                    Y[a, j] = (t0 * KlB[k, 0, j] + t1 * KlB[k, 1, j] + t2 * KlB[k, 2, j]) \
                        + (d0 * Bth[k, 0, j] + d1 * Bth[k, 1, j] + d2 * Bth[k, 2, j])
            mx, my, mz = Mi[k, 0], Mi[k, 1], Mi[k, 2]
            row = 3 + 6 * k
            for j in range(12):
                w0, w1, w2 = W[0, j], W[1, j], W[2, j]
                y0, y1, y2 = Y[0, j], Y[1, j], Y[2, j]
                z0 = Rr[0, 0] * y0 + Rr[0, 1] * y1 + Rr[0, 2] * y2 - (-mz * w1 + my * w2)
                z1 = Rr[1, 0] * y0 + Rr[1, 1] * y1 + Rr[1, 2] * y2 - (mz * w0 - mx * w2)
                z2 = Rr[2, 0] * y0 + Rr[2, 1] * y1 + Rr[2, 2] * y2 - (-my * w0 + mx * w1)
                # K = sum_k E_k^T Z_k = sum_k P_k^T Z_k - W^T (Z_0 + Z_1): the P_k^T Z_k rows here
                K_out[e, row, j] = z0
                K_out[e, row + 1, j] = z1
                K_out[e, row + 2, j] = z2
                if k == 0:
                    Zs[0, j], Zs[1, j], Zs[2, j] = z0, z1, z2
                else:
                    Zs[0, j] += z0
                    Zs[1, j] += z1
                    Zs[2, j] += z2
        for i in range(12):
            w0, w1, w2 = W[0, i], W[1, i], W[2, i]
            rot = (i % 6) >= 3
            for j in range(12):
                v = -(w0 * Zs[0, j] + w1 * Zs[1, j] + w2 * Zs[2, j])
                K_out[e, i, j] = K_out[e, i, j] + v if rot else v
        # ---- axial stiffness EA/L0 bu bu^T and axial-force (geometric) term N A (translation blocks only)
        kax = EA[e] / L0[e]
        for a in range(3):
            for b in range(3):
                A[a, b] = ((1.0 if a == b else 0.0) - r1[a] * r1[b]) * il
        for a in range(3):
            for b in range(3):
                v = kax * r1[a] * r1[b] + N * A[a, b]
                K_out[e, a, b] += v
                K_out[e, a, 6 + b] -= v
                K_out[e, 6 + a, b] -= v
                K_out[e, 6 + a, 6 + b] += v
        # ---- variation of W^T M at fixed M: H = [M]x A / l - (M x r1) r1^T / l^2
        tmp3[0], tmp3[1], tmp3[2] = _cross(M[0], M[1], M[2], r1[0], r1[1], r1[2])
        il2 = il * il
        for a in range(3):
            AM[a] = A[a, 0] * M[0] + A[a, 1] * M[1] + A[a, 2] * M[2]
            Aq[a] = A[a, 0] * q[0] + A[a, 1] * q[1] + A[a, 2] * q[2]
        for b in range(3):
            h0 = (-M[2] * A[1, b] + M[1] * A[2, b]) * il - tmp3[0] * r1[b] * il2
            h1 = (M[2] * A[0, b] - M[0] * A[2, b]) * il - tmp3[1] * r1[b] * il2
            h2 = (-M[1] * A[0, b] + M[0] * A[1, b]) * il - tmp3[2] * r1[b] * il2
            K_out[e, 0, b] -= h0
            K_out[e, 1, b] -= h1
            K_out[e, 2, b] -= h2
            K_out[e, 0, 6 + b] += h0
            K_out[e, 1, 6 + b] += h1
            K_out[e, 2, 6 + b] += h2
            K_out[e, 6, b] += h0
            K_out[e, 7, b] += h1
            K_out[e, 8, b] += h2
            K_out[e, 6, 6 + b] -= h0
            K_out[e, 7, 6 + b] -= h1
            K_out[e, 8, 6 + b] -= h2
        for i in range(12):  # - g (AM12)^T, AM12 = [-AM, 0, AM, 0]
            for b in range(3):
                K_out[e, i, b] += g[i] * AM[b]
                K_out[e, i, 6 + b] -= g[i] * AM[b]
        # ---- - alpha dg, alpha = r1 . M, dg = d g / dd (rows [ds, dgw_0, -ds, dgw_1])
        alpha = r1[0] * M[0] + r1[1] * M[1] + r1[2] * M[2]
        for k in range(2):
            tmp3[0], tmp3[1], tmp3[2] = _cross(qn[k, 0], qn[k, 1], qn[k, 2], r1[0], r1[1], r1[2])
            for i in range(3):
                qr1[k, i] = 0.5 * tmp3[i]
            tmp3[0], tmp3[1], tmp3[2] = _cross(qn[k, 0], qn[k, 1], qn[k, 2], r2[0], r2[1], r2[2])
            for i in range(3):
                qr2[k, i] = 0.5 * tmp3[i]
        for i in range(3):
            dgam[i], dgam[3 + i], dgam[6 + i], dgam[9 + i] = -Aq[i], qr1[0, i], Aq[i], qr1[1, i]
            gr2 = gam * il * r2[i]
            dD[i], dD[3 + i], dD[6 + i], dD[9 + i] = gr2, qr2[0, i], -gr2, qr2[1, i]
        ilD = il * iD
        # ds = (r3 dgam^T + gam dr3) / (l D) - s bu^T / l - s dD^T / D,  dr3 = -[r3]x W
        for j in range(12):
            w0, w1, w2 = W[0, j], W[1, j], W[2, j]
            dr0 = r3[2] * w1 - r3[1] * w2
            dr1 = r3[0] * w2 - r3[2] * w0
            dr2 = r3[1] * w0 - r3[0] * w1
            cj = bu[j] * il + dD[j] * iD
            ds0 = (r3[0] * dgam[j] + gam * dr0) * ilD - sfac * r3[0] * cj
            ds1 = (r3[1] * dgam[j] + gam * dr1) * ilD - sfac * r3[1] * cj
            ds2 = (r3[2] * dgam[j] + gam * dr2) * ilD - sfac * r3[2] * cj
            K_out[e, 0, j] -= alpha * ds0
            K_out[e, 1, j] -= alpha * ds1
            K_out[e, 2, j] -= alpha * ds2
            K_out[e, 6, j] += alpha * ds0
            K_out[e, 7, j] += alpha * ds1
            K_out[e, 8, j] += alpha * ds2
        # dgw_k = ((qn_k.r3) W - r3 qn_k^T W + [node-k block]) / (2 D) - gw_k dD^T / D
        i2D = 0.5 * iD
        for k in range(2):
            q0, q1, q2 = qn[k, 0], qn[k, 1], qn[k, 2]
            qr3 = q0 * r3[0] + q1 * r3[1] + q2 * r3[2]
            row = 3 + 6 * k
            for j in range(12):
                w0, w1, w2 = W[0, j], W[1, j], W[2, j]
                qW = q0 * w0 + q1 * w1 + q2 * w2
                dDj = dD[j] * iD
                K_out[e, row, j] -= alpha * ((qr3 * w0 - r3[0] * qW) * i2D - gw[k, 0] * dDj)
                K_out[e, row + 1, j] -= alpha * ((qr3 * w1 - r3[1] * qW) * i2D - gw[k, 1] * dDj)
                K_out[e, row + 2, j] -= alpha * ((qr3 * w2 - r3[2] * qW) * i2D - gw[k, 2] * dDj)
            for a in range(3):
                for b in range(3):
                    K_out[e, row + a, 6 * k + 3 + b] -= alpha * ((qn[k, a] * r3[b] - (qr3 if a == b else 0.0)) * i2D)
