"""Bending part of the canopy shell: co-rotational DKT plate with a drilling penalty, vectorised.

Element frame
-------------
For node positions ``x0, x1, x2`` let ``a = x1 - x0``, ``b = x2 - x0``, ``n = a x b``.  The element frame
``Rr = [r1, r2, r3]`` (columns) has ``r1 = a/|a|``, ``r3 = n/|n|``, ``r2 = r3 x r1``; ``R0`` is the same frame
of the reference geometry.  The frame passes through the three nodes, so the local transverse nodal
displacements are zero (Rankin & Nour-Omid 1988, "The use of projectors to improve finite element
performance", Comput. Struct. 30, 257-267; Felippa & Haugen 2005, CMAME 194, 2285-2335).

Local rotations, as in :mod:`kite_env.structure.beam`: ``theta_i = logm(Rr^T R_i R0)`` (rotation of node
``i``'s triad relative to the element frame, components in the element frame), with
``d theta_i = T_s^{-1}(theta_i) Rr^T (dw_i - W dx)``.  The frame spin ``w_r = W dx`` (``W`` is 3x9, only
translations) follows from ``dr_k = w_r x r_k``::

    w_r . r1 = -r2 . dn / |n|,   w_r . r2 = r1 . dn / |n|,   w_r . r3 = r2 . da / |a|

Local energy ``U = theta^T K_l theta / 2`` with the constant 9x9 ``K_l`` (reference geometry; small local
strains):

* DKT (Batoz, Bathe & Ho 1980, "A study of three-node triangular plate bending elements", IJNME 15,
  1771-1812): the normal's tilt ``beta = (theta_y, -theta_x)`` is quadratic; at each edge mid-point
  ``beta_s = -1/4 (beta_s,i + beta_s,j)`` (Kirchhoff constraint with cubic ``w`` and zero local nodal ``w``)
  and ``beta_n = (beta_n,i + beta_n,j)/2``; curvature ``kappa = [beta_x,x, beta_y,y, beta_x,y + beta_y,x]``,
  ``U_b = 1/2 int kappa^T D_b kappa dA`` integrated exactly (3 mid-side points), ``D_b = D [[1,nu,0],
  [nu,1,0],[0,0,(1-nu)/2]]``, ``D = Y h^3 / (12 (1 - nu^2))``.  For small deflections this is exactly the
  linear DKT with transverse DOFs (its energy vanishes for the linear ``w`` that the frame removes).
* Drilling penalty ``U_d = 1/2 k_d sum_i theta_iz^2`` (rotation about the element normal), ``k_d`` set
  by :class:`kite_env.structure.shell.ShellSet`.

Force ``f = [-W^T sum_i M_i ; M_1 ; M_2 ; M_3]`` with ``M_i = Rr T_s^{-T}(theta_i) m_i``, ``m = K_l theta``.
Tangent: ``K = E^T K_th E - E^T S W_st - H`` with ``E = [-W_st | I_9]``, ``W_st = [W; W; W]``,
``K_th = Q^T K_l Q + blockdiag(Rr dT_s^{-T}m/dtheta T_s^{-1} Rr^T)``, ``Q = blockdiag(T_s^{-1} Rr^T)``,
``S = blockdiag([M_i]x)`` (rotation of the frame carrying ``M_i``) and ``H = d(W^T M)/dx`` at fixed
``M = sum M_i`` (derivative of the frame spin, written out in :func:`frame_spin_hessian`).
"""

from __future__ import annotations

import numpy as np

from .beam import _dTinvT_m
from .rotations import logm, skew, tangent_inv


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (cheaper than ``np.cross`` for small n)."""
    return np.stack([u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1], u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
                     u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]], axis=-1)


def _outer(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise outer product ``u v^T`` of (n, 3) arrays -> (n, 3, 3)."""
    return u[:, :, None] * v[:, None, :]


def element_frame(x_e: np.ndarray) -> dict:
    """Co-rotated frame of triangles ``x_e (n, 3, 3)`` [m]; returns a dict of the frame data."""
    a = x_e[:, 1] - x_e[:, 0]
    b = x_e[:, 2] - x_e[:, 0]
    nv = _cross(a, b)
    lam = np.einsum("ni,ni->n", a, a)
    nu2 = np.einsum("ni,ni->n", nv, nv)
    l, nn = np.sqrt(lam), np.sqrt(nu2)
    r1 = a / l[:, None]
    r3 = nv / nn[:, None]
    r2 = _cross(r3, r1)
    return {"a": a, "b": b, "n": nv, "lam": lam, "nu2": nu2, "l": l, "nn": nn, "r1": r1, "r2": r2, "r3": r3,
            "Rr": np.stack([r1, r2, r3], axis=-1)}


def frame_spin(fr: dict) -> np.ndarray:
    """Matrix ``W`` (n, 3, 9) with frame spin ``w_r = W dx`` (global components, node-major ``dx``)."""
    a, b, r1, r2, r3 = fr["a"], fr["b"], fr["r1"], fr["r2"], fr["r3"]
    inn = (1.0 / fr["nn"])[:, None, None]
    Wa = (-r1[:, :, None] * _cross(b, r2)[:, None, :] + r2[:, :, None] * _cross(b, r1)[:, None, :]) * inn \
        + r3[:, :, None] * r2[:, None, :] / fr["l"][:, None, None]
    Wb = r1[:, :, None] * _cross(a, r2)[:, None, :] * inn
    return np.concatenate([-Wa - Wb, Wa, Wb], axis=2)


def frame_spin_hessian(fr: dict, M: np.ndarray) -> np.ndarray:
    """``H = d(W^T M)/dx`` at fixed ``M`` (n, 3); returns (n, 9, 9), node-major.

    With ``p = n x M``, ``nu = n.n``, ``lam = a.a``::

        W^T M = [ -b x p / nu + (n.M)(n x a)/(nu lam) ,  a x p / nu ]   (w.r.t. a, b)
    """
    a, b, nv, nu2, lam = fr["a"], fr["b"], fr["n"], fr["nu2"], fr["lam"]
    n = a.shape[0]
    p = _cross(nv, M)
    dot = lambda u, v: np.einsum("ni,ni->n", u, v)  # noqa: E731
    s, Ma, Mb, ab = dot(nv, M), dot(M, a), dot(M, b), dot(a, b)
    inu, inl = 1.0 / nu2, 1.0 / (nu2 * lam)
    dnu_a = 2.0 * _cross(b, nv)  # d nu / da
    dnu_b = 2.0 * _cross(nv, a)  # d nu / db
    q = _cross(nv, a)
    # skew-symmetric and diagonal parts of the (a, b) blocks ([u]x[v]x = v u^T - (u.v) I used throughout)
    sv = np.stack([(Mb * inu)[:, None] * b + (s * inl)[:, None] * nv, (p - Ma[:, None] * b) * inu[:, None],
                   (-p - Mb[:, None] * a) * inu[:, None], (Ma * inu)[:, None] * a], axis=1)
    Sk = skew(sv)  # (n, 4, 3, 3): aa, ab, ba, bb
    for k in range(3):
        Sk[:, 0, k, k] -= s * ab * inl
        Sk[:, 1, k, k] += s * inu
    # rank-one parts
    bp = _cross(b, p) * (inu**2)[:, None]
    ap = _cross(a, p) * (inu**2)[:, None]
    qs = q * inl[:, None]
    nM = (nv * inu[:, None])[:, :, None] * M[:, None, :]
    sa = (s * inl)[:, None] * a
    Va = _cross(b, M) - s[:, None] * (dnu_a * inu[:, None] + 2.0 * a / lam[:, None])
    Vb = _cross(M, a) - (s * inu)[:, None] * dnu_b
    Haa = Sk[:, 0] + _outer(bp, dnu_a) + _outer(qs, Va) + _outer((s * inl)[:, None] * b, a)
    Hab = Sk[:, 1] + _outer(bp, dnu_b) + _outer(qs, Vb) - nM - _outer(sa, a)
    Hba = Sk[:, 2] - _outer(ap, dnu_a) + nM
    Hbb = Sk[:, 3] - _outer(ap, dnu_b)
    # chain rule to node-major x: a = x1 - x0, b = x2 - x0
    H = np.empty((n, 3, 3, 3, 3))
    Ha_, Hb_ = Haa + Hba, Hab + Hbb
    H[:, 0, :, 0] = Ha_ + Hb_
    H[:, 0, :, 1] = -Ha_
    H[:, 0, :, 2] = -Hb_
    H[:, 1, :, 0] = -(Haa + Hab)
    H[:, 1, :, 1] = Haa
    H[:, 1, :, 2] = Hab
    H[:, 2, :, 0] = -(Hba + Hbb)
    H[:, 2, :, 1] = Hba
    H[:, 2, :, 2] = Hbb
    return H.reshape(n, 9, 9)


def dkt_stiffness(xy: np.ndarray, Db: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """DKT bending stiffness with zero local nodal deflection, in local rotations.

    Parameters
    ----------
    xy : (n, 3, 2) float [m]   reference node coordinates in the element plane (counter-clockwise).
    Db : (n,) float [N m]      plate bending stiffness ``D``;  ``nu`` (n,) Poisson ratio.

    Returns
    -------
    (n, 6, 6) float [N m]   stiffness w.r.t. ``[theta_x0, theta_y0, theta_x1, theta_y1, theta_x2, theta_y2]``.
    """
    n = xy.shape[0]
    x, y = xy[..., 0], xy[..., 1]
    bb = np.stack([y[:, 1] - y[:, 2], y[:, 2] - y[:, 0], y[:, 0] - y[:, 1]], axis=1)
    cc = np.stack([x[:, 2] - x[:, 1], x[:, 0] - x[:, 2], x[:, 1] - x[:, 0]], axis=1)
    A2 = np.sum(x * bb, axis=1)  # 2 * area
    dL = np.stack([bb, cc], axis=-1) / A2[:, None, None]  # (n, 3, 2)  dL_i / d(x, y)
    edges = ((0, 1), (1, 2), (2, 0))
    Me = []
    for i, j in edges:
        s = xy[:, j] - xy[:, i]
        s = s / np.linalg.norm(s, axis=1)[:, None]
        Me.append(0.5 * np.eye(2) - 0.75 * s[:, :, None] * s[:, None, :])  # beta_mid = Me (beta_i + beta_j)
    Dm = Db[:, None, None] * np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]) \
        + (Db * nu)[:, None, None] * np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]) \
        + (Db * 0.5 * (1.0 - nu))[:, None, None] * np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    Kb = np.zeros((n, 6, 6))
    for Lgp in ([0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]):
        L = np.array(Lgp)
        # gradients (n, 2) of the quadratic shape functions at this point
        dNc = [(4.0 * L[i] - 1.0) * dL[:, i] for i in range(3)]
        dNm = [4.0 * (L[j] * dL[:, i] + L[i] * dL[:, j]) for i, j in edges]
        # dPhi_i / d(x, y): (n, 2 comps of beta, 2 beta dofs, 2 derivs)
        B = np.zeros((n, 3, 6))
        for k in range(3):
            dPhi = np.eye(2)[None, :, :, None] * dNc[k][:, None, None, :]
            for e, (i, j) in enumerate(edges):
                if k in (i, j):
                    dPhi = dPhi + Me[e][:, :, :, None] * dNm[e][:, None, None, :]
            # kappa = [bx,x, by,y, bx,y + by,x]
            B[:, 0, 2 * k:2 * k + 2] = dPhi[:, 0, :, 0]
            B[:, 1, 2 * k:2 * k + 2] = dPhi[:, 1, :, 1]
            B[:, 2, 2 * k:2 * k + 2] = dPhi[:, 0, :, 1] + dPhi[:, 1, :, 0]
        Kb += (A2 / 6.0)[:, None, None] * np.einsum("nvi,nvw,nwj->nij", B, Dm, B)
    # beta = J theta with beta_x = theta_y, beta_y = -theta_x
    J = np.kron(np.eye(3), np.array([[0.0, 1.0], [-1.0, 0.0]]))
    return np.einsum("ia,nij,jb->nab", J, Kb, J)


def _log_rotation(R: np.ndarray) -> np.ndarray:
    """Rotation vector of ``R`` (..., 3, 3): axis-angle formula for angles up to pi/2 (the usual case for
    rotations relative to the element frame), :func:`~kite_env.structure.rotations.logm` for the rest."""
    v = 0.5 * np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    s = np.sqrt(np.einsum("...i,...i->...", v, v))  # sin(t)
    c = 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0)  # cos(t)
    small = s < 1e-4
    th = np.where(small, 1.0 + s**2 / 6.0, np.arctan2(s, c) / np.where(small, 1.0, s))[..., None] * v
    far = c < 1e-3
    if np.any(far):
        th[far] = logm(R[far])
    return th


def local_rotations(Rr: np.ndarray, R_e: np.ndarray, R0: np.ndarray) -> np.ndarray:
    """``theta_i = logm(Rr^T R_i R0)``: (n, 3, 3) frames and (n, 3, 3, 3) nodal rotations -> (n, 3, 3)."""
    return _log_rotation(np.matmul(np.matmul(np.swapaxes(Rr, 1, 2)[:, None], R_e), R0[:, None]))


def bending_internal(x_e: np.ndarray, R_e: np.ndarray, R0: np.ndarray, K_l: np.ndarray):
    """Co-rotational bending/drilling energy, force and tangent.

    Parameters
    ----------
    x_e : (n, 3, 3) float [m];  R_e : (n, 3, 3, 3) float nodal rotations;  R0 : (n, 3, 3) reference frames;
    K_l : (n, 9, 9) float [N m] local stiffness w.r.t. ``[theta_0, theta_1, theta_2]`` (x, y, z each).

    Returns
    -------
    U : (n,) [J];  f_t : (n, 9) [N] translational force;  f_r : (n, 9) [N m] moments (global);
    K : (n, 2, 9, 2, 9) tangent blocks ``[translation/rotation rows, ., translation/rotation cols, .]``.
    """
    n = x_e.shape[0]
    fr = element_frame(x_e)
    Rr = fr["Rr"]
    th = local_rotations(Rr, R_e, R0)
    m = np.einsum("nij,nj->ni", K_l, th.reshape(n, 9)).reshape(n, 3, 3)
    U = 0.5 * np.einsum("nka,nka->n", m, th)
    Tinv = tangent_inv(th)  # (n, 3, 3, 3)
    Mi = np.einsum("nab,nkb->nka", Rr, np.einsum("nkcb,nkc->nkb", Tinv, m))  # (n, 3, 3) global moments
    M = Mi.sum(axis=1)
    W = frame_spin(fr)  # (n, 3, 9)
    f_t = -np.einsum("nak,na->nk", W, M)
    Qm = np.einsum("nkab,ncb->nkac", Tinv, Rr)  # T_s^{-1} Rr^T per node (n, 3, 3, 3)
    Q = np.zeros((n, 3, 3, 3, 3))
    for k in range(3):
        Q[:, k, :, k, :] = Qm[:, k]
    Q = Q.reshape(n, 9, 9)
    Kth = np.matmul(np.swapaxes(Q, 1, 2), np.matmul(K_l, Q))
    Gm = np.matmul(np.matmul(Rr[:, None], _dTinvT_m(th, m)), Qm)
    for k in range(3):
        Kth[:, 3 * k:3 * k + 3, 3 * k:3 * k + 3] += Gm[:, k]
    KthC = Kth[:, :, 0:3] + Kth[:, :, 3:6] + Kth[:, :, 6:9]  # K_th W_st = KthC W
    KthR = Kth[:, 0:3] + Kth[:, 3:6] + Kth[:, 6:9]  # W_st^T K_th = W^T KthR
    WT = np.swapaxes(W, 1, 2)
    K = np.empty((n, 2, 9, 2, 9))
    K[:, 0, :, 0, :] = WT @ ((KthC[:, 0:3] + KthC[:, 3:6] + KthC[:, 6:9] + skew(M)) @ W) - frame_spin_hessian(fr, M)
    K[:, 0, :, 1, :] = -(WT @ KthR)
    K[:, 1, :, 0, :] = -((KthC + skew(Mi).reshape(n, 9, 3)) @ W)
    K[:, 1, :, 1, :] = Kth
    return U, f_t, Mi.reshape(n, 9), K
