"""The trailing-edge hem as a frame-free rod element (2 nodes, 12 DOF), vectorised over elements.

The co-rotational beam (:mod:`kite_env.structure.beam`) measures each node's rotation against an element frame
built from the chord and the mean of the two nodes' section vectors, through the rotation logarithm. Both are
singular: the frame when the nodes' section vectors turn onto the chord (``D = q . r2 -> 0``, a hem bent by 90
deg at both ends in the same sense), the logarithm at a relative rotation of pi. A slack, tumbling canopy turns its
trailing-edge nodes that far: the frame flips within a step, the element's energy jumps, and the nodes' rotations
spin up (docs/model.md, "The trailing-edge hem"). This element has no frame and no logarithm. With the chord direction
``r = (x2 - x1) / l`` and each node's hem direction ``a_i = R_i e1`` (``e1`` the undeformed axis, ``R_i`` the nodal
rotation, identity unloaded), its energy is::

    U = EA / (2 L0) (l - L0)^2 + EI / L0 [4 (1 - c1) + 4 (1 - c2) + 2 (a1 . a2 - c1 c2)]
        + GJ / (2 L0) [(1 - b1 . b2)^2 + s^2],    c_i = r . a_i

For small end rotations ``phi_i`` of the nodes against the chord, ``1 - c_i = phi_i^2 / 2 + O(phi^4)`` and ``a1 . a2 -
c1 c2 = (r x a1) . (r x a2) = phi1 . phi2 + O(phi^3)``: the Euler-Bernoulli element's ``EI / L0 (2 phi1^2 + 2 phi1 .
phi2 + 2 phi2^2)`` (Hermite interpolation, as in the beam element). The energy is smooth at every configuration
with ``l > 0``, grows monotonically with each end's angle up to pi (``2 (1 - c) >= sin^2``, so the bracket is at least
``2 |s1|^2 - 2 |s1| |s2| + 2 |s2|^2 >= 0`` with ``|s_i| = sin phi_i``), and its torsion is measured by the nodes'
section vectors ``b_i = R_i e2`` (``e2`` the element's undeformed up vector, as the beam's): with ``s = r . (b1 x
b2)`` and ``c = b1 . b2``, ``(1 - c)^2 + s^2`` is ``2 (1 - cos tau)`` for a twist ``tau`` about the chord (the beam's
``(th2x - th1x)^2`` for small twists), rises monotonically to a twist of pi and vanishes only where the section
vectors agree, while a bending of one end against the other enters only at fourth order (``(1 - c)^2 + s^2 = 2 (1 -
c) - |P (b1 x b2)|^2``). ``s^2`` alone has a second minimum at a twist of pi, where a trailing-edge node flipped by
half a turn stayed in the 7 m/s flight. The torsion's negative stiffness beyond 90 deg is at most its
small-angle stiffness ``GJ / L0``, a fraction of a trailing-edge node's rotary inertia ``J / (beta dt^2)`` in a
step. Without torsion the wing's static start does not converge. Bending is isotropic (the hem's ``EI``, both
axes).

Force and tangent (``dd = dx2 - dx1``; a rotational DOF increment is a spatial spin ``dw``, ``R_new = expm(dw)
R_old``, so ``da_i = dw_i x a_i``)::

    f_d  = N r + P g_r / l,       N = EA (l - L0) / L0,  P = I - r r^T,  g_r = dU/dr
    m_i  = a_i x g_ai + b_i x g_bi,  g_u = dU/du for the directors u = a_i, b_i of node i

and the tangent ``K = df/dd`` is their exact derivative (checked against finite differences in the tests); like the
beam's it is not symmetric away from equilibrium (the spins are not additive).
"""

from __future__ import annotations

import numpy as np

from .rotations import skew

_I3 = np.eye(3)


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (np.cross's overhead dominates at the hem's 36 elements)."""
    u0, u1, u2 = u[:, 0], u[:, 1], u[:, 2]
    v0, v1, v2 = v[:, 0], v[:, 1], v[:, 2]
    return np.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], axis=1)


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return (u * v).sum(axis=1)


class HemSet:
    """Frame-free hem rods (module docstring) on the node pairs ``conn`` (n_e, 2).

    Parameters
    ----------
    conn : (n_e, 2) int
    X0 : (n_nodes, 3) float [m]
        Undeformed node positions.
    up : (n_e, 3) float
        Each element's up vector (orthogonalised against its axis: ``e2``).
    EA, EI, GJ : (n_e,) float [N, N m^2, N m^2]
        Axial, isotropic bending and torsional stiffness.
    backend : {"auto", "numba", "numpy"}
        Implementation of :meth:`internal`: the compiled kernel :func:`kite_env.structure.hem_kernels.hem_internal` or
        the NumPy reference below (``"auto"``: :func:`kite_env.compiled.resolve_backend`). The NumPy
        reference costs about 0.3 ms per call at the wing's 36 elements, mostly NumPy's overhead on small arrays: a
        tenth of a flight's time.
    """

    def __init__(self, conn, X0, up, EA, EI, GJ, backend="auto"):
        from kite_env.compiled import resolve_backend  # imports numba (once per process)

        self.backend = resolve_backend(backend)
        self.conn = np.asarray(conn, dtype=np.int64).reshape(-1, 2)
        X0 = np.asarray(X0, dtype=float)
        d = X0[self.conn[:, 1]] - X0[self.conn[:, 0]]
        self.L0 = np.linalg.norm(d, axis=1)
        if np.any(self.L0 <= 0.0):
            raise ValueError("HemSet: an element has zero length")
        self.e1 = d / self.L0[:, None]  # undeformed axis; the hem direction a_i = R_i e1 at each node
        e2 = np.asarray(up, dtype=float).reshape(-1, 3)
        e2 = e2 - np.einsum("ni,ni->n", e2, self.e1)[:, None] * self.e1
        self.e2 = e2 / np.linalg.norm(e2, axis=1, keepdims=True)  # the section vector b_i = R_i e2
        shape = self.L0.shape
        self.EA, self.EI, self.GJ = (np.broadcast_to(np.asarray(v, dtype=float), shape).copy() for v in (EA, EI, GJ))

    @property
    def n_elem(self) -> int:
        return self.conn.shape[0]

    def _kinematics(self, x_e, R_e):
        d = x_e[:, 1] - x_e[:, 0]
        l = np.sqrt(_dot(d, d))
        r = d / l[:, None]
        # the directors of both nodes at once: (n, 2, 3) = R (n, 2, 3, 3) @ e (n, 3)
        a = np.matmul(R_e, self.e1[:, None, :, None])[..., 0]
        b = np.matmul(R_e, self.e2[:, None, :, None])[..., 0]
        a1, a2, b1, b2 = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
        c1 = _dot(r, a1)
        c2 = _dot(r, a2)
        b12 = _cross(b1, b2)
        s = _dot(r, b12)
        return l, r, a1, a2, b1, b2, c1, c2, b12, s

    def energy(self, x_e: np.ndarray, R_e: np.ndarray) -> np.ndarray:
        """Strain energy of each element (n_e,) [J] at the element nodes' positions ``x_e`` (n_e, 2, 3) and
        rotations ``R_e`` (n_e, 2, 3, 3)."""
        l, r, a1, a2, b1, b2, c1, c2, b12, s = self._kinematics(x_e, R_e)
        a12 = _dot(a1, a2)
        return (0.5 * self.EA / self.L0 * (l - self.L0) ** 2
                + self.EI / self.L0 * (8.0 - 4.0 * c1 - 4.0 * c2 + 2.0 * (a12 - c1 * c2))
                + 0.5 * self.GJ / self.L0 * ((1.0 - _dot(b1, b2)) ** 2 + s**2))

    def internal(self, x_e: np.ndarray, R_e: np.ndarray, tangent: bool = True):
        """Internal forces ``f_e`` (n_e, 12) [N, N m] and tangent ``K_e`` (n_e, 12, 12) (None without ``tangent``),
        node-major ``[u1, w1, u2, w2]``; new arrays on every call, whatever the backend."""
        if self.backend == "numba":
            from .hem_kernels import hem_internal

            x_e = np.ascontiguousarray(x_e, dtype=float)
            R_e = np.ascontiguousarray(R_e, dtype=float)
            n = self.n_elem
            if x_e.shape != (n, 2, 3) or R_e.shape != (n, 2, 3, 3):
                raise ValueError(f"HemSet.internal: expected x_e (n_e, 2, 3) and R_e (n_e, 2, 3, 3) with n_e = {n}, "
                                 f"got {x_e.shape} and {R_e.shape}")
            f = np.empty((n, 12))
            K = np.empty((n, 12, 12) if tangent else (1, 12, 12))
            hem_internal(x_e, R_e, self.e1, self.e2, self.L0, self.EA, self.EI, self.GJ, f, K, bool(tangent))
            return f, (K if tangent else None)
        return self._internal_numpy(x_e, R_e, tangent)

    def _internal_numpy(self, x_e: np.ndarray, R_e: np.ndarray, tangent: bool = True):
        """:meth:`internal`, the vectorised NumPy reference."""
        x_e = np.asarray(x_e, dtype=float)
        R_e = np.asarray(R_e, dtype=float)
        l, r, a1, a2, b1, b2, c1, c2, b12, s = self._kinematics(x_e, R_e)
        k = (self.EI / self.L0)[:, None]
        G = (self.GJ / self.L0)[:, None]
        N = self.EA * (l - self.L0) / self.L0
        # the twist's sine s = r . (b1 x b2), the cosine c = b1 . b2 of the section vectors' angle, and their
        # gradients
        s_r, s_b1, s_b2 = b12, _cross(b2, r), _cross(r, b1)
        Gs = G * s[:, None]
        oc = 1.0 - _dot(b1, b2)  # 1 - c
        Goc = G * oc[:, None]
        g = {"r": k * (-(4.0 + 2.0 * c2)[:, None] * a1 - (4.0 + 2.0 * c1)[:, None] * a2) + Gs * s_r,
             "a1": k * (2.0 * a2 - (4.0 + 2.0 * c2)[:, None] * r),
             "a2": k * (2.0 * a1 - (4.0 + 2.0 * c1)[:, None] * r),
             "b1": Gs * s_b1 - Goc * b2, "b2": Gs * s_b2 - Goc * b1}
        rg = _dot(r, g["r"])
        Pg = g["r"] - rg[:, None] * r
        f_d = N[:, None] * r + Pg / l[:, None]
        m1 = _cross(a1, g["a1"]) + _cross(b1, g["b1"])
        m2 = _cross(a2, g["a2"]) + _cross(b2, g["b2"])
        f = np.concatenate([-f_d, m1, f_d, m2], axis=1)
        if not tangent:
            return f, None
        n = len(l)
        rr = r[:, :, None] * r[:, None, :]
        P = _I3[None] - rr
        il = (1.0 / l)[:, None, None]
        kk, GG, Gs3 = k[:, :, None], G[:, :, None], Gs[:, :, None]

        def outer(u, v):
            return u[:, :, None] * v[:, None, :]

        # the energy's second derivatives in the chord direction r and the directors (bending, then torsion)
        H = {("r", "r"): -2.0 * kk * (outer(a1, a2) + outer(a2, a1)) + GG * outer(s_r, s_r),
             ("r", "a1"): kk * (-(4.0 + 2.0 * c2)[:, None, None] * _I3 - 2.0 * outer(a2, r)),
             ("r", "a2"): kk * (-(4.0 + 2.0 * c1)[:, None, None] * _I3 - 2.0 * outer(a1, r)),
             ("a1", "a2"): 2.0 * kk * P,
             ("r", "b1"): GG * outer(s_r, s_b1) - Gs3 * skew(b2),
             ("r", "b2"): GG * outer(s_r, s_b2) + Gs3 * skew(b1),
             ("b1", "b1"): GG * (outer(s_b1, s_b1) + outer(b2, b2)),
             ("b2", "b2"): GG * (outer(s_b2, s_b2) + outer(b1, b1)),
             ("b1", "b2"): GG * (outer(s_b1, s_b2) + outer(b2, b1)) - Gs3 * skew(r) - Goc[:, :, None] * _I3}

        def h(u, v):
            if (u, v) in H:
                return H[(u, v)]
            if (v, u) in H:
                return H[(v, u)].transpose(0, 2, 1)
            return None

        # variations: dr = P dd / l, du = -[u]x dw_i for the directors u of node i
        S = {"a1": skew(a1), "a2": skew(a2), "b1": skew(b1), "b2": skew(b2)}
        node = {1: ("a1", "b1"), 2: ("a2", "b2")}
        K_dd = ((self.EA / self.L0)[:, None, None] * rr + (N / l)[:, None, None] * P
                - il * il * (rg[:, None, None] * P + outer(r, Pg) + outer(Pg, r)) + il * il * P @ h("r", "r") @ P)
        K = np.zeros((n, 12, 12))
        u_ = {1: slice(0, 3), 2: slice(6, 9)}
        w_ = {1: slice(3, 6), 2: slice(9, 12)}
        K[:, u_[1], u_[1]] = K[:, u_[2], u_[2]] = K_dd
        K[:, u_[1], u_[2]] = K[:, u_[2], u_[1]] = -K_dd
        for i in (1, 2):
            # d f_d / d w_i and d m_i / d dd
            K_dw = -il * P @ sum(h("r", u) @ S[u] for u in node[i])
            K_wd = il * sum(S[u] @ h(u, "r") for u in node[i]) @ P
            K[:, u_[1], w_[i]], K[:, u_[2], w_[i]] = -K_dw, K_dw
            K[:, w_[i], u_[1]], K[:, w_[i], u_[2]] = -K_wd, K_wd
            for j in (1, 2):
                # d m_i / d w_j: the directors' own turn (j = i) and the change of their gradients
                K_ww = np.zeros((n, 3, 3))
                for u in node[i]:
                    if j == i:
                        K_ww += skew(g[u]) @ S[u]
                    for v in node[j]:
                        Huv = h(u, v)
                        if Huv is not None:
                            K_ww -= S[u] @ Huv @ S[v]
                K[:, w_[i], w_[j]] = K_ww
        return f, K
