"""Meshes, finite differences and reference solutions shared by ``test_shell.py`` (no tests here)."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from scipy.spatial import Delaunay

from kite_env.structure.rotations import expm


def square_mesh(n: int, a: float = 1.0):
    """``n x n`` squares on ``[0, a]^2`` (z = 0), each split by its diagonal; counter-clockwise triangles."""
    g = np.linspace(0.0, a, n + 1)
    X, Y = np.meshgrid(g, g, indexing="ij")
    X0 = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    c00, c10, c01, c11 = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel()
    conn = np.concatenate([np.stack([c00, c10, c11], 1), np.stack([c00, c11, c01], 1)])
    return X0, conn


def disk_mesh(n_r: int, a: float):
    """Delaunay mesh of a disk of radius ``a`` (z = 0), ``6 k`` nodes on ring ``k = 1..n_r``, node 0 the centre."""
    pts = [np.zeros((1, 2))]
    for k in range(1, n_r + 1):
        t = (np.arange(6 * k) + 0.25 * (k % 2)) * 2.0 * np.pi / (6 * k)
        pts.append(k * a / n_r * np.stack([np.cos(t), np.sin(t)], axis=1))
    pts = np.concatenate(pts)
    tri = Delaunay(pts).simplices
    X0 = np.c_[pts, np.zeros(len(pts))]
    e = X0[tri]
    flip = np.cross(e[:, 1] - e[:, 0], e[:, 2] - e[:, 0])[:, 2] < 0.0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    return X0, tri


def irregular_rect_mesh(rng, lx: float = 1.0, ly: float = 0.6, nx: int = 4, ny: int = 3):
    """Rectangle ``[0, lx] x [0, ly]`` with randomly displaced interior nodes (Delaunay); ccw triangles."""
    gx, gy = np.meshgrid(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1), indexing="ij")
    P = np.stack([gx.ravel(), gy.ravel()], axis=1)
    inner = (P[:, 0] > 0) & (P[:, 0] < lx) & (P[:, 1] > 0) & (P[:, 1] < ly)
    P[inner] += rng.uniform(-0.25, 0.25, size=(inner.sum(), 2)) * [lx / nx, ly / ny]
    tri = Delaunay(P).simplices
    e = P[tri]
    ar = (e[:, 1, 0] - e[:, 0, 0]) * (e[:, 2, 1] - e[:, 0, 1]) - (e[:, 1, 1] - e[:, 0, 1]) * (e[:, 2, 0] - e[:, 0, 0])
    tri[ar < 0] = tri[ar < 0][:, [0, 2, 1]]
    return np.c_[P, np.zeros(len(P))], tri


def fd_tangent(fun, x_e, R_e, h_x=1e-7, h_w=1e-7):
    """Central difference of ``fun(x_e, R_e) -> f (n, 18)``: translations additive, rotations as spatial spins."""
    n = x_e.shape[0]
    K = np.zeros((n, 18, 18))
    for a in range(3):
        for i in range(3):
            xp, xm = x_e.copy(), x_e.copy()
            xp[:, a, i] += h_x
            xm[:, a, i] -= h_x
            K[:, :, 6 * a + i] = (fun(xp, R_e) - fun(xm, R_e)) / (2 * h_x)
            e = np.zeros(3)
            e[i] = h_w
            Rp, Rm = R_e.copy(), R_e.copy()
            Rp[:, a] = expm(e) @ R_e[:, a]
            Rm[:, a] = expm(-e) @ R_e[:, a]
            K[:, :, 6 * a + 3 + i] = (fun(x_e, Rp) - fun(x_e, Rm)) / (2 * h_w)
    return K


def hencky_coefficients(nu: float):
    """Axisymmetric Foppl membrane under uniform lateral pressure, clamped edge (Hencky's problem).

    Solved by shooting on the centre stress.  Returns ``(c_w, c_n)`` with centre deflection
    ``w0 = c_w a (p a / (E h))^(1/3)`` and centre stress resultant ``N0 = c_n (E h p^2 a^2)^(1/3)``.
    """
    Eh, a, P = 1.0, 1.0, 1e-4

    def rhs(r, y):
        u, N, _ = y
        wp = -P * r / (2.0 * N)  # vertical equilibrium of the disk of radius r
        return [N * (1 - nu**2) / Eh - nu * u / r - 0.5 * wp**2, (Eh * u / r + (nu - 1.0) * N) / r, wp]

    def shoot(N0, full=False):
        r0 = 1e-7
        sol = solve_ivp(rhs, [r0, a], [N0 * (1 - nu) / Eh * r0, N0, 0.0], rtol=1e-10, atol=1e-14)
        return sol if full else sol.y[0, -1]

    N0 = brentq(shoot, 1e-5, 1.0, xtol=1e-14)
    w0 = -shoot(N0, True).y[2, -1]
    return w0 / P ** (1 / 3), N0 / P ** (2 / 3)
