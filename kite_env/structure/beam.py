"""Co-rotational 3-D Euler-Bernoulli beam element (2 nodes, 12 DOF), vectorised over elements.

Formulation
-----------
Battini & Pacoste (2002), "Co-rotational beam elements with warping effects in instability problems",
Comput. Methods Appl. Mech. Engrg. 191, Sect. 2-3 (the element *without* warping); Crisfield (1997),
Non-linear Finite Element Analysis of Solids and Structures, Vol. 2, ch. 17. The derivation of the
consistent tangent below is written out independently for the spatial-spin DOFs of this project.

* Element DOFs per node ``[u_x, u_y, u_z, w_x, w_y, w_z]`` in frame K; a rotational DOF increment is a
  spatial spin ``dw`` with ``R_new = expm(dw) @ R_old`` (see :mod:`kite_env.structure.rotations`).
* Reference element frame ``R0 = [e1, e2, e3]`` (columns): ``e1`` along the undeformed axis, ``e2`` the
  ``up`` vector orthogonalised against ``e1``, ``e3 = e1 x e2``.  The section triad of node ``i`` is
  ``R_i @ R0`` (``R_i`` the nodal rotation, identity when unloaded).
* Current element (co-rotated) frame ``Rr = [r1, r2, r3]``: ``r1 = (x2 - x1) / l``;
  ``q = (q1 + q2) / 2`` with ``q_i = R_i e2``; ``r3 = r1 x q / |r1 x q|``; ``r2 = r3 x r1``.
* Local deformations: ``u_bar = l - L0`` and ``theta_i = logm(Rr^T R_i R0)`` (rotation of the section
  triad relative to the element frame, components in the element frame).
* Local strain energy (linear, Euler-Bernoulli with Hermite interpolation, no transverse local
  displacements because the element frame follows the chord)::

      U = EA/(2 L0) u_bar^2 + GJ/(2 L0) (th2x - th1x)^2
          + EI2/L0 (2 th1y^2 + 2 th1y th2y + 2 th2y^2) + EI3/L0 (2 th1z^2 + 2 th1z th2z + 2 th2z^2)

  so that the element curvatures are ``kappa_y = (th2y - th1y) / L0``, ``kappa_z = (th2z - th1z) / L0``
  (exact for uniform bending) and the twist rate is ``(th2x - th1x) / L0``.

Variations (``dx21 = dx2 - dx1``)::

    d u_bar   = r1 . dx21
    d theta_i = T_s^{-1}(theta_i) Rr^T (dw_i - dw_r),      dw_r = W dd  (spin of the element frame)
    W dd      = r1 x dx21 / l + r1 (g . dd)
    g         = [ s, (q1 x r3)/(2 D), -s, (q2 x r3)/(2 D) ],  s = (q . r1) r3 / (l D),  D = q . r2

The internal force is the exact gradient ``f = dU/dd`` and the tangent ``K = df/dd`` includes every
geometric term (axial-force term, derivative of ``T_s^{-T}``, rotation of the frame, derivative of ``W``).
Because the rotational DOFs are non-additive spins, ``K`` is not symmetric away from equilibrium.
"""

from __future__ import annotations

import numpy as np

from .rotations import logm, skew, tangent_inv

_I3 = np.eye(3)
_TSMALL = 0.2  # [rad] below this the derivative coefficients of T_s^{-1} use their Taylor series


def _tinv_derivative_coeffs(theta: np.ndarray):
    """Coefficients of ``T_s^{-1}(theta) = eta I + c theta theta^T - 1/2 [theta]x`` and their derivatives.

    Returns ``eta'(t)/t`` and ``c'(t)/t`` (``t = |theta|``, ``c = (1 - eta)/t^2``), which appear in
    ``d(T_s^{-T} m)/d theta``.  Series from ``(t/2) cot(t/2) = sum (-1)^n B_2n t^2n / (2n)!`` (Bernoulli
    numbers) below ``_TSMALL``.
    """
    t2 = np.einsum("...i,...i->...", theta, theta)
    t = np.sqrt(t2)
    small = t < _TSMALL
    ts = np.where(small, 1.0, t)
    half = 0.5 * ts
    eta = half / np.tan(half)
    deta = 0.5 / np.tan(half) - ts / (4.0 * np.sin(half) ** 2)  # eta'(t)
    detat_big = deta / ts
    c_big = (1.0 - eta) / ts**2
    dct_big = (-deta / ts**2 - 2.0 * c_big / ts) / ts  # c'(t)/t
    detat_small = -(1.0 / 6.0 + t2 / 180.0 + t2**2 / 5040.0 + t2**3 / 151200.0 + t2**4 / 4790016.0)
    dct_small = 1.0 / 360.0 + t2 / 7560.0 + t2**2 / 201600.0 + t2**3 / 5987520.0
    c_small = 1.0 / 12.0 + t2 / 720.0 + t2**2 / 30240.0 + t2**3 / 1209600.0 + t2**4 / 47900160.0
    return (np.where(small, c_small, c_big), np.where(small, detat_small, detat_big),
            np.where(small, dct_small, dct_big))


def _dTinvT_m(theta: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``d(T_s^{-T}(theta) m)/d theta`` at fixed ``m``; ``(..., 3), (..., 3) -> (..., 3, 3)``.

    ``T_s^{-T} m = eta m + c theta (theta . m) + 1/2 theta x m``.
    """
    c, detat, dct = _tinv_derivative_coeffs(theta)
    tm = np.einsum("...i,...i->...", theta, m)
    out = detat[..., None, None] * m[..., :, None] * theta[..., None, :]
    out += (tm * dct)[..., None, None] * theta[..., :, None] * theta[..., None, :]
    out += c[..., None, None] * (tm[..., None, None] * _I3 + theta[..., :, None] * m[..., None, :])
    out -= 0.5 * skew(m)
    return out


class BeamSet:
    """A set of co-rotational Euler-Bernoulli beams sharing one vectorised evaluation.

    Parameters
    ----------
    conn : (n_e, 2) int
        Node indices of each beam.
    X0 : (n_nodes, 3) float [m]
        Reference (unloaded) node coordinates in frame K.
    up : (n_e, 3) float
        Vector fixing the local y axis (orthogonalised against the beam axis; need not be unit).
    EA : (n_e,) float [N]
        Axial stiffness.
    EI2, EI3 : (n_e,) float [N m^2]
        Bending stiffness about the local y axis (``up``) and about the local z axis.
    GJ : (n_e,) float [N m^2]
        Torsional stiffness.
    backend : {"auto", "numba", "numpy"}
        Implementation of :meth:`internal`: the compiled kernel :func:`kite_env.structure.beam_kernels.beam_internal`
        or the vectorised NumPy reference below (same result to round-off); ``"auto"`` resolves with
        :func:`kite_env.compiled.resolve_backend` (numba when importable).

    Scalars are broadcast to ``(n_e,)``.
    """

    n_en = 2  # nodes per element

    def __init__(self, conn, X0, up, EA, EI2, EI3, GJ, backend="auto"):
        from kite_env.compiled import resolve_backend  # imports numba (once per process)

        self.backend = resolve_backend(backend)
        self.conn = np.asarray(conn, dtype=np.int64).reshape(-1, 2)
        X0 = np.asarray(X0, dtype=float)
        n_e = self.conn.shape[0]
        d = X0[self.conn[:, 1]] - X0[self.conn[:, 0]]
        self.L0 = np.linalg.norm(d, axis=1)
        if np.any(self.L0 <= 0.0):
            raise ValueError(f"BeamSet: zero-length beam(s) at rows {np.flatnonzero(self.L0 <= 0.0)[:10]}")
        e1 = d / self.L0[:, None]
        up = np.broadcast_to(np.asarray(up, dtype=float), (n_e, 3))
        e2 = up - np.einsum("ni,ni->n", up, e1)[:, None] * e1
        n2 = np.linalg.norm(e2, axis=1)
        if np.any(n2 < 1e-8 * np.maximum(np.linalg.norm(up, axis=1), 1e-300)):
            raise ValueError(f"BeamSet: `up` is parallel to the beam axis for rows {np.flatnonzero(n2 < 1e-8)[:10]}")
        e2 /= n2[:, None]
        e3 = np.cross(e1, e2)
        self.R0 = np.stack([e1, e2, e3], axis=-1)  # (n_e, 3, 3), columns e1, e2, e3
        self.EA = self.EI2 = self.EI3 = self.GJ = None
        self.set_stiffness(EA=EA, EI2=EI2, EI3=EI3, GJ=GJ)

    @property
    def n_elem(self) -> int:
        return self.conn.shape[0]

    def set_stiffness(self, EA=None, EI2=None, EI3=None, GJ=None) -> None:
        """Replace section stiffness arrays (``None`` keeps the current one); scalars broadcast to ``(n_e,)``."""
        n_e = self.n_elem
        for name, val in (("EA", EA), ("EI2", EI2), ("EI3", EI3), ("GJ", GJ)):
            if val is None:
                continue
            arr = np.array(np.broadcast_to(np.asarray(val, dtype=float), (n_e,)))
            if not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
                raise ValueError(f"BeamSet.set_stiffness: {name} must be finite and >= 0")
            setattr(self, name, arr)
        L0 = self.L0
        # diagonal local stiffness blocks (element frame), K_l[theta_i, theta_j] = diag(k_ij)
        self._k11 = np.stack([self.GJ, 4.0 * self.EI2, 4.0 * self.EI3], axis=-1) / L0[:, None]
        self._k12 = np.stack([-self.GJ, 2.0 * self.EI2, 2.0 * self.EI3], axis=-1) / L0[:, None]
        # rank-one material terms of a nonlinear moment law (set_bending_torsion): dm/dtheta = K_l + g m m^T
        self._kmat = np.zeros((n_e, 2))

    def set_bending_torsion(self, rows: np.ndarray, EI: np.ndarray, GJ: np.ndarray, g_bend=None, g_twist=None) -> None:
        """Fast in-place update of ``EI2 = EI3 = EI`` and ``GJ`` for the beams ``rows`` (index array), for a
        stiffness law evaluated every iteration (inflated tubes); values must be finite and >= 0 (not checked).

        ``g_bend``, ``g_twist`` (len(rows),) [1/(N m)]: the material part of the tangent of a secant law whose
        stiffness depends on the deformation, ``dm/dtheta = K_l + g m m^T`` over the bending (y, z of both ends) and
        the twist components of the local moments ``m``; None = 0 (the secant alone)."""
        if self.backend == "numba":
            from .beam_kernels import beam_set_bending_torsion

            empty = np.zeros(0)
            beam_set_bending_torsion(rows, EI, GJ, empty if g_bend is None else g_bend,
                                     empty if g_twist is None else g_twist, self.L0, self.EI2, self.EI3, self.GJ,
                                     self._k11, self._k12, self._kmat)
            return
        self.EI2[rows] = EI
        self.EI3[rows] = EI
        self.GJ[rows] = GJ
        iL = 1.0 / self.L0[rows]
        self._k11[rows, 0] = GJ * iL
        self._k11[rows, 1] = self._k11[rows, 2] = 4.0 * EI * iL
        self._k12[rows, 0] = -GJ * iL
        self._k12[rows, 1] = self._k12[rows, 2] = 2.0 * EI * iL
        self._kmat[rows, 0] = 0.0 if g_bend is None else g_bend
        self._kmat[rows, 1] = 0.0 if g_twist is None else g_twist

    # ------------------------------------------------------------------------------------------ kinematics
    def _frame(self, x_e, R_e):
        """Co-rotated frame and local deformations (see module docstring)."""
        x_e = np.asarray(x_e, dtype=float)
        R_e = np.asarray(R_e, dtype=float)
        d = x_e[:, 1] - x_e[:, 0]
        l = np.sqrt(np.einsum("ni,ni->n", d, d))
        r1 = d / l[:, None]
        qn = np.einsum("nkij,nj->nki", R_e, self.R0[:, :, 1])  # (n, 2, 3)  q_i = R_i e2
        q = 0.5 * (qn[:, 0] + qn[:, 1])
        n3 = np.cross(r1, q)
        r3 = n3 / np.sqrt(np.einsum("ni,ni->n", n3, n3))[:, None]
        r2 = np.cross(r3, r1)
        Rr = np.stack([r1, r2, r3], axis=-1)
        Rbar = np.einsum("nji,nkjl,nlm->nkim", Rr, R_e, self.R0)
        theta = logm(Rbar)  # (n, 2, 3)
        return l, r1, r2, r3, q, qn, Rr, theta

    def local_rotations(self, x_e, R_e) -> tuple[np.ndarray, np.ndarray]:
        """Current chord length ``l`` (n_e,) [m] and local end rotations ``theta`` (n_e, 2, 3) [rad] (element frame;
        x: twist, y/z: bending), the cheap part of :meth:`local_deformation` (compiled with the numba backend)."""
        if self.backend == "numba":
            from .beam_kernels import beam_local_rotations

            n = self.n_elem
            l, th = np.empty(n), np.empty((n, 2, 3))
            beam_local_rotations(np.ascontiguousarray(x_e, dtype=float), np.ascontiguousarray(R_e, dtype=float),
                                 self.R0, l, th)
            return l, th
        l, _, _, _, _, _, _, theta = self._frame(x_e, R_e)
        return l, theta

    def local_deformation(self, x_e, R_e) -> dict:
        """Local (co-rotated) deformation measures for a tube law.

        Parameters
        ----------
        x_e : (n_e, 2, 3) float [m]   current node positions ``x[conn]``.
        R_e : (n_e, 2, 3, 3) float    nodal rotation matrices ``Rn[conn]``.

        Returns
        -------
        dict with
            ``u_bar`` (n_e,) [m] axial extension ``l - L0``; ``length`` (n_e,) [m] current chord length;
            ``L0`` (n_e,) [m]; ``theta1``, ``theta2`` (n_e, 3) [rad] local rotation vectors of the end
            sections in the element frame (x: twist, y/z: bending about local y/z);
            ``kappa`` (n_e, 3) [1/m] mean twist rate and curvatures ``(theta2 - theta1) / L0``;
            ``frame`` (n_e, 3, 3) current element frame ``Rr`` (columns r1, r2, r3 in frame K).
        """
        l, _, _, _, _, _, Rr, theta = self._frame(x_e, R_e)
        return {"u_bar": l - self.L0, "length": l, "L0": self.L0.copy(), "theta1": theta[:, 0],
                "theta2": theta[:, 1], "kappa": (theta[:, 1] - theta[:, 0]) / self.L0[:, None], "frame": Rr}

    def energy(self, x_e, R_e) -> np.ndarray:
        """Strain energy of each element, ``(n_e,)`` [J]."""
        l, _, _, _, _, _, _, th = self._frame(x_e, R_e)
        m1, m2 = self._local_moments(th)
        return 0.5 * self.EA / self.L0 * (l - self.L0) ** 2 + 0.5 * (
            np.einsum("ni,ni->n", m1, th[:, 0]) + np.einsum("ni,ni->n", m2, th[:, 1]))

    def _local_moments(self, th):
        m1 = self._k11 * th[:, 0] + self._k12 * th[:, 1]
        m2 = self._k12 * th[:, 0] + self._k11 * th[:, 1]
        return m1, m2

    # ------------------------------------------------------------------------------------------ forces
    def internal(self, x_e, R_e, tangent: bool = True):
        """Internal force and consistent tangent of every element.

        Parameters
        ----------
        x_e : (n_e, 2, 3) float [m]   current node positions.
        R_e : (n_e, 2, 3, 3) float    nodal rotation matrices.
        tangent : bool                False: ``K_e`` is None and the compiled kernel skips its tangent (the forces
                                      are the same); the NumPy reference computes both either way.

        Returns
        -------
        f_e : (n_e, 12) float [N, N m]   gradient of the strain energy w.r.t. ``[du1, dw1, du2, dw2]``.
        K_e : (n_e, 12, 12) float        ``d f_e / d[du1, dw1, du2, dw2]`` (exact, all geometric terms).

        Both are new arrays on every call (whatever the backend).
        """
        if self.backend == "numba":
            return self._internal_numba(x_e, R_e, tangent)
        f, K = self._internal_numpy(x_e, R_e)
        return f, (K if tangent else None)

    def _internal_numba(self, x_e, R_e, tangent: bool = True):
        """:meth:`internal` through the compiled kernel :func:`kite_env.structure.beam_kernels.beam_internal`."""
        from .beam_kernels import beam_internal

        x_e = np.ascontiguousarray(x_e, dtype=float)
        R_e = np.ascontiguousarray(R_e, dtype=float)
        n = self.n_elem
        if x_e.shape != (n, 2, 3) or R_e.shape != (n, 2, 3, 3):
            raise ValueError(f"BeamSet.internal: expected x_e (n_e, 2, 3) and R_e (n_e, 2, 3, 3) with n_e = {n}, "
                             f"got {x_e.shape} and {R_e.shape}")
        f = np.empty((n, 12))
        K = np.empty((n, 12, 12) if tangent else (1, 12, 12))
        beam_internal(x_e, R_e, self.R0, self.L0, self.EA, self._k11, self._k12, self._kmat, f, K, np.empty(n),
                      bool(tangent))
        return f, (K if tangent else None)

    def _internal_numpy(self, x_e, R_e):
        """:meth:`internal`, vectorised NumPy reference implementation."""
        l, r1, r2, r3, q, qn, Rr, th = self._frame(x_e, R_e)
        n = l.shape[0]
        L0 = self.L0
        N = self.EA / L0 * (l - L0)  # axial force [N]
        m = np.stack(self._local_moments(th), axis=1)  # (n, 2, 3) local moments
        Tinv = tangent_inv(th)  # (n, 2, 3, 3)
        Mi = np.einsum("nab,nkcb,nkc->nka", Rr, Tinv, m)  # (n, 2, 3)  Rr T^{-T} m_i (global)

        # ---- spin of the element frame: dw_r = W dd
        Dd = np.einsum("ni,ni->n", q, r2)
        gam = np.einsum("ni,ni->n", q, r1)
        s = (gam / (l * Dd))[:, None] * r3
        gw = np.cross(qn, r3[:, None, :]) / (2.0 * Dd)[:, None, None]  # (n, 2, 3)
        g = np.concatenate([s, gw[:, 0], -s, gw[:, 1]], axis=1)  # (n, 12)
        Sk = skew(r1) / l[:, None, None]
        W = r1[:, :, None] * g[:, None, :]
        W[:, :, 0:3] -= Sk
        W[:, :, 6:9] += Sk

        # E_i = P_i - W  (n, 2, 3, 12)
        E = np.broadcast_to(-W[:, None], (n, 2, 3, 12)).copy()
        E[:, 0, :, 3:6] += _I3
        E[:, 1, :, 9:12] += _I3

        # ---- internal force
        bu = np.concatenate([-r1, np.zeros((n, 3)), r1, np.zeros((n, 3))], axis=1)
        f = N[:, None] * bu + np.einsum("nkai,nka->ni", E, Mi)

        # ---- tangent
        RrT_E = np.einsum("nba,nkbj->nkaj", Rr, E)
        Bth = np.einsum("nkab,nkbj->nkaj", Tinv, RrT_E)  # d theta_i / dd
        KlB = np.empty_like(Bth)
        KlB[:, 0] = self._k11[:, :, None] * Bth[:, 0] + self._k12[:, :, None] * Bth[:, 1]
        KlB[:, 1] = self._k12[:, :, None] * Bth[:, 0] + self._k11[:, :, None] * Bth[:, 1]
        if np.any(self._kmat):  # material terms of a nonlinear moment law: (dm/dtheta) B = K_l B + g m (m^T B)
            sb = np.einsum("nka,nkaj->nj", m[:, :, 1:], Bth[:, :, 1:])  # bending y, z
            st = np.einsum("nk,nkj->nj", m[:, :, 0], Bth[:, :, 0])  # twist x
            KlB[:, :, 1:] += self._kmat[:, 0, None, None, None] * m[:, :, 1:, None] * sb[:, None, None, :]
            KlB[:, :, 0] += self._kmat[:, 1, None, None] * m[:, :, 0, None] * st[:, None, :]
        Y = np.einsum("nkba,nkbj->nkaj", Tinv, KlB) + np.einsum("nkab,nkbj->nkaj", _dTinvT_m(th, m), Bth)
        Z = np.einsum("nab,nkbj->nkaj", Rr, Y) - np.einsum("nkab,nbj->nkaj", skew(Mi), W)
        K = np.einsum("nkai,nkaj->nij", E, Z)
        K += (self.EA / L0)[:, None, None] * bu[:, :, None] * bu[:, None, :]
        A = (_I3 - r1[:, :, None] * r1[:, None, :]) / l[:, None, None]
        NA = N[:, None, None] * A
        K[:, 0:3, 0:3] += NA
        K[:, 0:3, 6:9] -= NA
        K[:, 6:9, 0:3] -= NA
        K[:, 6:9, 6:9] += NA

        # ---- variation of W^T M at fixed M (M = M1 + M2): K -= d(W^T M)
        M = Mi[:, 0] + Mi[:, 1]
        H = np.einsum("nab,nbc->nac", skew(M), A) / l[:, None, None] \
            - np.cross(M, r1)[:, :, None] * r1[:, None, :] / (l**2)[:, None, None]
        K[:, 0:3, 0:3] -= H
        K[:, 0:3, 6:9] += H
        K[:, 6:9, 0:3] += H
        K[:, 6:9, 6:9] -= H
        AM = np.einsum("nab,nb->na", A, M)
        AM12 = np.concatenate([-AM, np.zeros((n, 3)), AM, np.zeros((n, 3))], axis=1)
        K -= g[:, :, None] * AM12[:, None, :]
        alpha = np.einsum("ni,ni->n", r1, M)
        Aq = np.einsum("nab,nb->na", A, q)
        qr1 = 0.5 * np.cross(qn, r1[:, None, :])
        qr2 = 0.5 * np.cross(qn, r2[:, None, :])
        dgam = np.concatenate([-Aq, qr1[:, 0], Aq, qr1[:, 1]], axis=1)
        gr2 = (gam / l)[:, None] * r2
        dD = np.concatenate([gr2, qr2[:, 0], -gr2, qr2[:, 1]], axis=1)
        dr3 = -np.einsum("nab,nbj->naj", skew(r3), W)
        ds = (r3[:, :, None] * dgam[:, None, :] + gam[:, None, None] * dr3) / (l * Dd)[:, None, None] \
            - s[:, :, None] * bu[:, None, :] / l[:, None, None] - s[:, :, None] * dD[:, None, :] / Dd[:, None, None]
        qr3 = np.einsum("nki,ni->nk", qn, r3)  # (n, 2)
        dgw = np.einsum("nkab,nbj->nkaj", qr3[:, :, None, None] * _I3 - r3[:, None, :, None] * qn[:, :, None, :], W)
        dgw[:, 0, :, 3:6] += qn[:, 0, :, None] * r3[:, None, :] - qr3[:, 0, None, None] * _I3
        dgw[:, 1, :, 9:12] += qn[:, 1, :, None] * r3[:, None, :] - qr3[:, 1, None, None] * _I3
        dgw = dgw / (2.0 * Dd)[:, None, None, None] - gw[:, :, :, None] * (dD / Dd[:, None])[:, None, None, :]
        dg = np.concatenate([ds, dgw[:, 0], -ds, dgw[:, 1]], axis=1)  # (n, 12, 12)
        K -= alpha[:, None, None] * dg
        return f, K
