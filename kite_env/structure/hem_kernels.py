"""Compiled (numba) kernel of the frame-free hem rods (:class:`kite_env.structure.hem.HemSet`).

:func:`hem_internal` computes the internal force and tangent of :meth:`HemSet.internal
<kite_env.structure.hem.HemSet.internal>` (the NumPy reference, whose docstring and module docstring derive the
energy, force and tangent) with the same terms, element by element; the results agree with NumPy to round-off
(``tests/structure/test_kernels.py``).

The derivations are in the docstrings of the reference modules and are not repeated here; comments name the
reference quantity each block computes.  Backends, compilation, cost and the implementation rule (no array view
and no array passed to a helper inside the element loop): :mod:`kite_env.compiled`.
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.compiled import JIT, njit

from .rotation_kernels import _cross


@njit(**JIT)
def _mm3(A, B, out):
    """``out = A @ B`` for 3 x 3 arrays (``out`` distinct from both)."""
    for p in range(3):
        for q in range(3):
            out[p, q] = A[p, 0] * B[0, q] + A[p, 1] * B[1, q] + A[p, 2] * B[2, q]


@njit(**JIT)
def hem_internal(x_e, R_e, e1, e2, L0, EA, EI, GJ, f_out, K_out, want_K=True):
    """Frame-free hem rods, as :meth:`kite_env.structure.hem.HemSet.internal` (the NumPy reference, whose docstring
    and module docstring derive the energy, force and tangent; the same terms here, element by element).

    Parameters
    ----------
    x_e : (n, 2, 3) float [m]; R_e : (n, 2, 3, 3) float   node positions and nodal rotations.
    e1, e2 : (n, 3) float            the undeformed axis and up vector (the directors ``a_i = R_i e1``, ``b_i = R_i
                                     e2``).
    L0, EA, EI, GJ : (n,) float      [m], [N], [N m^2], [N m^2].
    f_out : (n, 12) float            internal forces ``[u1, w1, u2, w2]`` (written).
    K_out : (n, 12, 12) float        tangents (written when ``want_K``; else may be (1, 12, 12)).
    """
    n = x_e.shape[0]
    D = np.empty((4, 3))  # the directors a1, b1, a2, b2 (index 2 i + (0: a, 1: b) for node i)
    g = np.empty((4, 3))  # the energy's gradient in each director
    r = np.empty(3)
    gr = np.empty(3)
    sr = np.empty(3)  # d s / d r = b1 x b2
    sb = np.empty((4, 3))  # d s / d b1, d s / d b2 at rows 1, 3
    Hrr = np.empty((3, 3))
    Hr = np.empty((4, 3, 3))  # H(r, u)
    Huv = np.zeros((4, 4, 3, 3))
    S = np.empty((4, 3, 3))  # skew(u)
    P = np.empty((3, 3))
    T1 = np.empty((3, 3))
    T2 = np.empty((3, 3))
    Acc = np.empty((3, 3))
    Acc2 = np.empty((3, 3))
    for e in range(n):
        d0 = x_e[e, 1, 0] - x_e[e, 0, 0]
        d1 = x_e[e, 1, 1] - x_e[e, 0, 1]
        d2 = x_e[e, 1, 2] - x_e[e, 0, 2]
        l = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        il = 1.0 / l
        r[0], r[1], r[2] = d0 * il, d1 * il, d2 * il
        for i in range(2):
            for p in range(3):
                D[2 * i, p] = R_e[e, i, p, 0] * e1[e, 0] + R_e[e, i, p, 1] * e1[e, 1] + R_e[e, i, p, 2] * e1[e, 2]
                D[2 * i + 1, p] = (R_e[e, i, p, 0] * e2[e, 0] + R_e[e, i, p, 1] * e2[e, 1]
                                   + R_e[e, i, p, 2] * e2[e, 2])
        c1 = r[0] * D[0, 0] + r[1] * D[0, 1] + r[2] * D[0, 2]
        c2 = r[0] * D[2, 0] + r[1] * D[2, 1] + r[2] * D[2, 2]
        # s = r . (b1 x b2) and its gradients: s_r = b1 x b2, s_b1 = b2 x r, s_b2 = r x b1
        sr[0], sr[1], sr[2] = _cross(D[1, 0], D[1, 1], D[1, 2], D[3, 0], D[3, 1], D[3, 2])
        sb[1, 0], sb[1, 1], sb[1, 2] = _cross(D[3, 0], D[3, 1], D[3, 2], r[0], r[1], r[2])
        sb[3, 0], sb[3, 1], sb[3, 2] = _cross(r[0], r[1], r[2], D[1, 0], D[1, 1], D[1, 2])
        s = r[0] * sr[0] + r[1] * sr[1] + r[2] * sr[2]
        cb = D[1, 0] * D[3, 0] + D[1, 1] * D[3, 1] + D[1, 2] * D[3, 2]
        k = EI[e] / L0[e]
        G = GJ[e] / L0[e]
        N = EA[e] * (l - L0[e]) / L0[e]
        Gs = G * s
        Goc = G * (1.0 - cb)
        f2, f1 = 4.0 + 2.0 * c2, 4.0 + 2.0 * c1
        for p in range(3):
            gr[p] = k * (-f2 * D[0, p] - f1 * D[2, p]) + Gs * sr[p]
            g[0, p] = k * (2.0 * D[2, p] - f2 * r[p])
            g[2, p] = k * (2.0 * D[0, p] - f1 * r[p])
            g[1, p] = Gs * sb[1, p] - Goc * D[3, p]
            g[3, p] = Gs * sb[3, p] - Goc * D[1, p]
        rg = r[0] * gr[0] + r[1] * gr[1] + r[2] * gr[2]
        for p in range(3):
            fd = N * r[p] + (gr[p] - rg * r[p]) * il
            f_out[e, p] = -fd
            f_out[e, 6 + p] = fd
        for i in range(2):
            m0, m1, m2 = _cross(D[2 * i, 0], D[2 * i, 1], D[2 * i, 2], g[2 * i, 0], g[2 * i, 1], g[2 * i, 2])
            n0, n1, n2 = _cross(D[2 * i + 1, 0], D[2 * i + 1, 1], D[2 * i + 1, 2],
                                g[2 * i + 1, 0], g[2 * i + 1, 1], g[2 * i + 1, 2])
            f_out[e, 6 * i + 3] = m0 + n0
            f_out[e, 6 * i + 4] = m1 + n1
            f_out[e, 6 * i + 5] = m2 + n2
        if not want_K:
            continue
        # the energy's second derivatives (the reference's dictionary H; absent pairs are zero)
        for p in range(3):
            for q in range(3):
                dl = 1.0 if p == q else 0.0
                P[p, q] = dl - r[p] * r[q]
                Hrr[p, q] = -2.0 * k * (D[0, p] * D[2, q] + D[2, p] * D[0, q]) + G * sr[p] * sr[q]
                Hr[0, p, q] = k * (-f2 * dl - 2.0 * D[2, p] * r[q])
                Hr[2, p, q] = k * (-f1 * dl - 2.0 * D[0, p] * r[q])
                Hr[1, p, q] = G * sr[p] * sb[1, q]
                Hr[3, p, q] = G * sr[p] * sb[3, q]
                Huv[1, 1, p, q] = G * (sb[1, p] * sb[1, q] + D[3, p] * D[3, q])
                Huv[3, 3, p, q] = G * (sb[3, p] * sb[3, q] + D[1, p] * D[1, q])
                Huv[1, 3, p, q] = G * (sb[1, p] * sb[3, q] + D[3, p] * D[1, q]) - Goc * dl
        # the skew parts: H(r, b1) -= Gs [b2]x, H(r, b2) += Gs [b1]x, H(b1, b2) -= Gs [r]x
        for u in range(4):
            S[u, 0, 0], S[u, 0, 1], S[u, 0, 2] = 0.0, -D[u, 2], D[u, 1]
            S[u, 1, 0], S[u, 1, 1], S[u, 1, 2] = D[u, 2], 0.0, -D[u, 0]
            S[u, 2, 0], S[u, 2, 1], S[u, 2, 2] = -D[u, 1], D[u, 0], 0.0
        for p in range(3):
            for q in range(3):
                Hr[1, p, q] -= Gs * S[3, p, q]
                Hr[3, p, q] += Gs * S[1, p, q]
        Huv[1, 3, 0, 1] += Gs * r[2]
        Huv[1, 3, 0, 2] -= Gs * r[1]
        Huv[1, 3, 1, 0] -= Gs * r[2]
        Huv[1, 3, 1, 2] += Gs * r[0]
        Huv[1, 3, 2, 0] += Gs * r[1]
        Huv[1, 3, 2, 1] -= Gs * r[0]
        for p in range(3):
            for q in range(3):
                Huv[0, 2, p, q] = 2.0 * k * P[p, q]
                Huv[2, 0, p, q] = 2.0 * k * P[q, p]
                Huv[3, 1, p, q] = Huv[1, 3, q, p]
        # K_dd = EA/L0 r r^T + N/l P - (rg P + r Pg^T + Pg r^T) / l^2 + P Hrr P / l^2
        _mm3(P, Hrr, T1)
        _mm3(T1, P, T2)
        il2 = il * il
        for p in range(3):
            pgp = gr[p] - rg * r[p]
            for q in range(3):
                pgq = gr[q] - rg * r[q]
                v = (EA[e] / L0[e] * r[p] * r[q] + N * il * P[p, q]
                     - il2 * (rg * P[p, q] + r[p] * pgq + pgp * r[q]) + il2 * T2[p, q])
                K_out[e, p, q] = v
                K_out[e, 6 + p, 6 + q] = v
                K_out[e, p, 6 + q] = -v
                K_out[e, 6 + p, q] = -v
        for i in range(2):
            # K_dw = -P (sum_u H(r, u) S_u) / l;  K_wd = (sum_u S_u H(r, u)^T) P / l
            for p in range(3):
                for q in range(3):
                    Acc[p, q] = 0.0
                    Acc2[p, q] = 0.0
            for u in range(2 * i, 2 * i + 2):
                for p in range(3):
                    for q in range(3):
                        Acc[p, q] += Hr[u, p, 0] * S[u, 0, q] + Hr[u, p, 1] * S[u, 1, q] + Hr[u, p, 2] * S[u, 2, q]
                        Acc2[p, q] += S[u, p, 0] * Hr[u, q, 0] + S[u, p, 1] * Hr[u, q, 1] + S[u, p, 2] * Hr[u, q, 2]
            _mm3(P, Acc, T1)
            _mm3(Acc2, P, T2)
            for p in range(3):
                for q in range(3):
                    kdw = -il * T1[p, q]
                    kwd = il * T2[p, q]
                    K_out[e, p, 6 * i + 3 + q] = -kdw
                    K_out[e, 6 + p, 6 * i + 3 + q] = kdw
                    K_out[e, 6 * i + 3 + p, q] = -kwd
                    K_out[e, 6 * i + 3 + p, 6 + q] = kwd
            for j in range(2):
                # K_ww = [j == i] sum_u [g_u]x S_u - sum_{u, v} S_u H(u, v) S_v
                for p in range(3):
                    for q in range(3):
                        Acc[p, q] = 0.0
                if j == i:
                    for u in range(2 * i, 2 * i + 2):
                        gu0, gu1, gu2 = g[u, 0], g[u, 1], g[u, 2]
                        for q in range(3):
                            Acc[0, q] += -gu2 * S[u, 1, q] + gu1 * S[u, 2, q]
                            Acc[1, q] += gu2 * S[u, 0, q] - gu0 * S[u, 2, q]
                            Acc[2, q] += -gu1 * S[u, 0, q] + gu0 * S[u, 1, q]
                for u in range(2 * i, 2 * i + 2):
                    for v in range(2 * j, 2 * j + 2):
                        if (u == 0 or u == 2) and u == v:
                            continue  # H(a_i, a_i) = 0
                        if (u % 2) != (v % 2):
                            continue  # H(a, b) = 0
                        for p in range(3):
                            for q in range(3):
                                T1[p, q] = (S[u, p, 0] * Huv[u, v, 0, q] + S[u, p, 1] * Huv[u, v, 1, q]
                                            + S[u, p, 2] * Huv[u, v, 2, q])
                        for p in range(3):
                            for q in range(3):
                                Acc[p, q] -= T1[p, 0] * S[v, 0, q] + T1[p, 1] * S[v, 1, q] + T1[p, 2] * S[v, 2, q]
                for p in range(3):
                    for q in range(3):
                        K_out[e, 6 * i + 3 + p, 6 * j + 3 + q] = Acc[p, q]
