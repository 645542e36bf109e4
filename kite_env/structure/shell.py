"""Geometrically nonlinear flat triangular shell for the kite canopy (3 nodes, 18 DOF), vectorised.

The paper (Bosch et al., Sect. II.A) discretises the canopy with "nonlinear three-node triangular flat
shell elements combining a membrane element for the in-plane forces [30, 31] and a bending element for
the out-of-plane forces [32] (DKT), 18 DOF", isotropic linear material E = 1250 MPa, nu = 0.3,
h = 0.08 mm, von Karman kinematics.  We keep membrane + DKT bending and 18 DOF but use kinematics that are
exact for large rotations (as allowed by the paper's remark that "the described procedure is general"):

* Membrane (:mod:`.shell_membrane`): total-Lagrangian constant-strain triangle, Green-Lagrange strain,
  plane-stress St. Venant-Kirchhoff law, relaxed by tension-field theory (wrinkling: taut / wrinkled /
  slack states from Pipkin's relaxed energy), with a residual fraction ``eps_slack`` of the full SVK
  energy so the tangent never becomes singular.  Rotation-free; exact gradient and Hessian.  For small
  rotations its strain reduces to the von Karman strain of the paper.
* Bending (:mod:`.shell_bending`): co-rotational DKT (Batoz, Bathe & Ho 1980) in the element frame
  through the three nodes, local rotations ``logm(Rr^T R_i R0)`` as in :mod:`.beam`, plus a drilling
  penalty ``k_d = drill_factor * E h A0`` on the rotation about the element normal (the canopy nodes
  that are not on a beam have no other stiffness about that axis).  The consistent tangent contains all
  geometric terms (rotation of the element frame, derivative of ``T_s^{-T}``).

Drilling penalty: ``k_d = drill_factor * E h A0`` [N m/rad], default ``drill_factor = 1e-6``.  Its only job is
to make the rotation about the normal of canopy-only nodes non-singular.  Because the element frame's
in-plane axis follows edge 0-1, in-plane shear leaves a drilling residual of order ``drill_factor`` relative
to the membrane forces; measured on Hencky's membrane (``tests/structure/test_shell.py``) the deformed
shape changes by 4e-8 of the deflection between ``drill_factor = 1e-8`` and ``1e-6``, and Newton still
converges at ``1e-8``.

Practical notes: a flat, stress-free membrane has no out-of-plane stiffness other than the (tiny) bending,
so a pressure load applied to a flat canopy from rest needs a bulged start, load stepping or a step limit.
Cost: with the NumPy reference (``backend="numpy"``) ``internal`` at 360 elements takes ~10 ms (best of repeats;
9-15 ms) on the shared 2-core development container, where ``BeamSet`` at 107 elements takes ~4 ms; the membrane
is ~1.5 ms of it, the rest is the exact co-rotational bending tangent (``bending=False``: ~2 ms, but then
rotations of canopy-only nodes have no stiffness and must be held fixed).  The compiled kernel
(``backend="numba"``, the default when numba is installed; :mod:`kite_env.structure.shell_kernels`) computes the same
result to round-off in ~0.6 ms (``BeamSet``: ~0.18 ms).

The DOF order per node is ``[du_x, du_y, du_z, dw_x, dw_y, dw_z]`` (spatial spins, frame K), as for
every element set; see :mod:`kite_env.structure.rotations`.
"""

from __future__ import annotations

import numpy as np

from .shell_bending import bending_internal, dkt_stiffness, element_frame, local_rotations
from .shell_membrane import (
    SLACK,
    TAUT,
    WRINKLED,
    cst_reference,
    fabric_matrix,
    membrane_internal,
    plane_stress_matrix,
    principal_strains,
)

__all__ = ["ShellSet", "pressure_load", "TAUT", "WRINKLED", "SLACK"]


class ShellSet:
    """A set of co-rotational flat shell triangles (membrane with wrinkling + DKT bending + drilling).

    Parameters
    ----------
    conn : (n_e, 3) int
        Node indices of each triangle.
    X0 : (n_nodes, 3) float [m]
        Reference (unloaded, stress-free) node coordinates.
    E : float or (n_e,) float [Pa]
        Young's modulus of the fabric.
    nu : float or (n_e,) float [-]
        Poisson ratio.
    h : float or (n_e,) float [m]
        Thickness (membrane stiffness ``E h`` [N/m], bending stiffness ``E h^3 / (12 (1 - nu^2))`` [N m]).
    wrinkling : bool
        Use the relaxed (tension-field) membrane energy; False: plain SVK (carries compression).
    eps_slack : float [-]
        Fraction of the full SVK energy kept in wrinkled/slack states (regularisation, 0 <= eps < 1).
    drill_factor : float [-]
        Drilling stiffness ``k_d = drill_factor * E h A0`` [N m/rad] per node and element.
    bending : bool
        Include the DKT bending and drilling part (False: pure membrane, rotations get no stiffness).
    shear_ratio : float [-]
        In-plane shear modulus of the fabric as a fraction of the isotropic ``E / (2 (1 + nu))`` (1: the isotropic
        law of the paper). Any other value makes the membrane a balanced woven fabric
        (:func:`.shell_membrane.fabric_matrix`) with its threads along ``warp`` and the relaxed law of any material
        matrix (:func:`.shell_membrane.relaxed_general`); the bending part stays isotropic.
    warp : (3,) float
        Direction of the warp threads in the frame of ``X0``, projected onto each triangle's plane (the weft is
        perpendicular in the plane); used with ``shear_ratio != 1``.
    backend : {"auto", "numba", "numpy"}
        Implementation of :meth:`internal`: the compiled kernel :func:`kite_env.structure.shell_kernels.shell_internal`
        or the vectorised NumPy reference (same result to round-off); ``"auto"`` resolves with
        :func:`kite_env.compiled.resolve_backend` (numba when importable).  :meth:`energy` and
        :meth:`stresses` always use NumPy.
    kinematics : {"green_lagrange", "von_karman"}
        The membrane's strain: Green-Lagrange (exact for any rotation), or von Karman's moderate-rotation strain in
        each element's reference frame, the paper's (Sect. II.A), whose tensioned elements have no geometric
        stiffness against in-plane motion (:mod:`.shell_membrane`). The bending part is the same.
    """

    n_en = 3  # nodes per element

    def __init__(self, conn, X0, E, nu, h, wrinkling=True, eps_slack=1e-3, drill_factor=1e-6, bending=True,
                 shear_ratio=1.0, warp=(1.0, 0.0, 0.0), backend="auto", kinematics="green_lagrange"):
        from kite_env.compiled import resolve_backend  # imports numba (once per process)

        self.backend = resolve_backend(backend)
        self.conn = np.asarray(conn, dtype=np.int64).reshape(-1, 3)
        X0 = np.asarray(X0, dtype=float)
        n_e = self.conn.shape[0]
        bc = lambda v: np.array(np.broadcast_to(np.asarray(v, dtype=float), (n_e,)))  # noqa: E731
        self.E, self.nu, self.h = bc(E), bc(nu), bc(h)
        if np.any(self.E <= 0) or np.any(self.h <= 0) or np.any((self.nu <= -1.0) | (self.nu >= 0.5)):
            raise ValueError("ShellSet: need E > 0, h > 0 and -1 < nu < 0.5")
        if not 0.0 <= eps_slack < 1.0:
            raise ValueError("ShellSet: eps_slack must be in [0, 1)")
        if kinematics not in ("green_lagrange", "von_karman"):
            raise ValueError(f"ShellSet: kinematics must be 'green_lagrange' or 'von_karman', got {kinematics!r}")
        self.von_karman = kinematics == "von_karman"  # the membrane's strain (shell_membrane: von Karman kinematics)
        self.wrinkling = bool(wrinkling)
        self.eps_slack = float(eps_slack)
        self.drill_factor = float(drill_factor)
        self.bending = bool(bending)
        Xe = X0[self.conn]
        fr = element_frame(Xe)
        bad = np.flatnonzero(fr["nn"] <= 1e-12 * fr["lam"])
        if bad.size:
            raise ValueError(f"ShellSet: degenerate triangle(s) at rows {bad[:10]}")
        self.R0 = fr["Rr"]  # (n_e, 3, 3) reference element frames
        self.xy = np.einsum("nia,nki->nka", self.R0, Xe - Xe[:, :1])[:, :, :2]  # (n_e, 3, 2) local coords
        self.A0, self.G = cst_reference(self.xy)
        if not shear_ratio > 0.0:
            raise ValueError("ShellSet: need shear_ratio > 0")
        self.shear_ratio = float(shear_ratio)
        # membrane law of the kernels: 0 plain SVK, 1 isotropic relaxed, 2 relaxed law of any C
        self.membrane_law = int(self.wrinkling)
        if self.shear_ratio == 1.0:
            self.C = plane_stress_matrix(self.E, self.nu)
            self.warp_angle = None
        else:
            wv = np.asarray(warp, dtype=float)
            wl = np.einsum("nia,i->na", self.R0[:, :, :2], wv)  # the warp in each element's reference axes
            if np.any(np.hypot(wl[:, 0], wl[:, 1]) < 1e-3 * np.linalg.norm(wv)):
                raise ValueError("ShellSet: the warp direction is normal to a triangle")
            self.warp_angle = np.arctan2(wl[:, 1], wl[:, 0])
            self.C = fabric_matrix(self.E, self.nu, self.shear_ratio, self.warp_angle)
            self.membrane_law = 2 if self.wrinkling else 0
        self.A0h = self.A0 * self.h
        self.D_bend = self.E * self.h**3 / (12.0 * (1.0 - self.nu**2))
        self.k_drill = self.drill_factor * self.E * self.h * self.A0
        K_l = np.zeros((n_e, 3, 3, 3, 3))
        Kb = dkt_stiffness(self.xy, self.D_bend, self.nu).reshape(n_e, 3, 2, 3, 2)
        K_l[:, :, :2, :, :2] = Kb
        for k in range(3):
            K_l[:, k, 2, k, 2] = self.k_drill
        self.K_l = K_l.reshape(n_e, 9, 9)

    @property
    def n_elem(self) -> int:
        return self.conn.shape[0]

    # ------------------------------------------------------------------------------------------ evaluation
    def _membrane(self, x_e):
        return membrane_internal(np.asarray(x_e, dtype=float), self.G, self.A0h, self.E, self.nu, self.C,
                                 self.eps_slack, self.membrane_law, self.R0 if self.von_karman else None)

    def energy(self, x_e, R_e) -> np.ndarray:
        """Strain energy of each element, ``(n_e,)`` [J] (membrane + bending + drilling)."""
        U = self._membrane(x_e)[0]
        if self.bending:
            fr = element_frame(np.asarray(x_e, dtype=float))
            th = local_rotations(fr["Rr"], np.asarray(R_e, dtype=float), self.R0).reshape(-1, 9)
            U = U + 0.5 * np.einsum("ni,nij,nj->n", th, self.K_l, th)
        return U

    def internal(self, x_e, R_e, tangent: bool = True):
        """Internal force and consistent tangent of every element.

        Parameters
        ----------
        x_e : (n_e, 3, 3) float [m]   current node positions ``x[conn]``.
        R_e : (n_e, 3, 3, 3) float    nodal rotation matrices ``Rn[conn]``.
        tangent : bool                False: ``K_e`` is None and the compiled kernel skips its tangent (the forces
                                      are the same); the NumPy reference computes both either way.

        Returns
        -------
        f_e : (n_e, 18) float [N, N m]   gradient of the strain energy w.r.t. ``[du_a, dw_a]`` per node a.
        K_e : (n_e, 18, 18) float        exact derivative of ``f_e`` (spatial spins; not symmetric away
                                         from equilibrium because of the non-additive rotations).

        Both are new arrays on every call (whatever the backend).
        """
        if self.backend == "numba":
            return self._internal_numba(x_e, R_e, tangent)
        f, K = self._internal_numpy(x_e, R_e)
        return f, (K if tangent else None)

    def _internal_numba(self, x_e, R_e, tangent: bool = True):
        """:meth:`internal` through the compiled kernel :func:`kite_env.structure.shell_kernels.shell_internal`."""
        from .shell_kernels import shell_internal

        x_e = np.ascontiguousarray(x_e, dtype=float)
        R_e = np.ascontiguousarray(R_e, dtype=float)
        n = self.n_elem
        if x_e.shape != (n, 3, 3) or R_e.shape != (n, 3, 3, 3):
            raise ValueError(f"ShellSet.internal: expected x_e (n_e, 3, 3) and R_e (n_e, 3, 3, 3) with n_e = {n}, "
                             f"got {x_e.shape} and {R_e.shape}")
        f = np.empty((n, 18))
        K = np.empty((n, 18, 18) if tangent else (1, 18, 18))
        shell_internal(x_e, R_e, self.R0, self.G, self.A0h, self.E, self.nu, self.C, self.K_l, self.eps_slack,
                       self.membrane_law, self.bending, f, K, np.empty(n), bool(tangent), self.von_karman)
        return f, (K if tangent else None)

    def _internal_numpy(self, x_e, R_e):
        """:meth:`internal`, vectorised NumPy reference implementation."""
        x_e = np.asarray(x_e, dtype=float)
        n = x_e.shape[0]
        _, fm, Km, _ = self._membrane(x_e)
        f = np.empty((n, 3, 2, 3))
        K = np.empty((n, 3, 6, 3, 6))
        if self.bending:
            _, ft, fr_, Kb = bending_internal(x_e, np.asarray(R_e, dtype=float), self.R0, self.K_l)
            f[:, :, 0] = (fm + ft).reshape(n, 3, 3)
            f[:, :, 1] = fr_.reshape(n, 3, 3)
            Kb[:, 0, :, 0, :] += Km
            K[:, :, :3, :, :3] = Kb[:, 0, :, 0, :].reshape(n, 3, 3, 3, 3)
            K[:, :, :3, :, 3:] = Kb[:, 0, :, 1, :].reshape(n, 3, 3, 3, 3)
            K[:, :, 3:, :, :3] = Kb[:, 1, :, 0, :].reshape(n, 3, 3, 3, 3)
            K[:, :, 3:, :, 3:] = Kb[:, 1, :, 1, :].reshape(n, 3, 3, 3, 3)
        else:
            f[:, :, 0] = fm.reshape(n, 3, 3)
            f[:, :, 1] = 0.0
            K[...] = 0.0
            K[:, :, :3, :, :3] = Km.reshape(n, 3, 3, 3, 3)
        return f.reshape(n, 18), K.reshape(n, 18, 18)

    def stresses(self, x_e, R_e=None) -> dict:
        """Membrane stress/strain state of every element.

        Returns
        -------
        dict with
            ``S1``, ``S2`` (n_e,) [Pa]: principal second Piola-Kirchhoff stresses (``S1 >= S2``) of the
            returned (relaxed) stress; ``N1``, ``N2`` (n_e,) [N/m]: the same times ``h``;
            ``E1``, ``E2`` (n_e,) [-]: principal Green-Lagrange strains of the surface;
            ``state`` (n_e,) int: ``TAUT`` (0), ``WRINKLED`` (1), ``SLACK`` (2);
            ``dir1`` (n_e, 3): unit current direction (frame K) of the major principal strain axis;
            ``S`` (n_e, 3) [Pa]: Voigt stress ``[S11, S22, S12]`` in the reference element axes.
        """
        _, _, _, ex = self._membrane(x_e)
        S = ex["S"]
        Sv = np.stack([S[:, 0], S[:, 1], 2.0 * S[:, 2]], axis=-1)  # principal_strains expects engineering shear
        S1, S2, _, _ = principal_strains(Sv)
        E1, E2, c2, s2 = principal_strains(ex["Ev"])
        phi = 0.5 * np.arctan2(s2, c2)
        d1 = np.einsum("niI,nI->ni", ex["F"], np.stack([np.cos(phi), np.sin(phi)], axis=-1))
        d1 /= np.linalg.norm(d1, axis=1)[:, None]
        return {"S1": S1, "S2": S2, "N1": S1 * self.h, "N2": S2 * self.h, "E1": E1, "E2": E2,
                "state": ex["state"], "dir1": d1, "S": S}


def pressure_load(x: np.ndarray, conn: np.ndarray, p) -> np.ndarray:
    """Nodal loads of a follower pressure on the current surface.

    Parameters
    ----------
    x : (n_nodes, 3) float [m]   current node positions.
    conn : (n_e, 3) int          triangles; the load acts along ``n = (x1 - x0) x (x2 - x0)``.
    p : float or (n_e,) float [Pa]  pressure, positive along ``n``.

    Returns
    -------
    (n_nodes * 6,) float [N]: ``p A n_hat / 3`` added to the translational DOFs of each node of each triangle.
    """
    x = np.asarray(x, dtype=float)
    conn = np.asarray(conn, dtype=np.int64).reshape(-1, 3)
    xe = x[conn]
    nv = np.cross(xe[:, 1] - xe[:, 0], xe[:, 2] - xe[:, 0])  # |nv| = 2 A
    fe = (np.broadcast_to(np.asarray(p, dtype=float), (conn.shape[0],)) / 6.0)[:, None] * nv
    f = np.zeros((x.shape[0], 6))
    for k in range(3):
        f[:, k] = np.bincount(conn.ravel(), weights=np.repeat(fe[:, k], 3), minlength=x.shape[0])
    return f.ravel()
