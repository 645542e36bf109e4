"""Membrane part of the canopy shell: total-Lagrangian constant-strain triangle with a relaxed
(tension-field) St. Venant-Kirchhoff material, vectorised over elements.

Kinematics
----------
Each triangle has a reference plane (the element frame of the unloaded geometry) with local 2-D node
coordinates ``xy`` and constant shape-function gradients ``G[a, I] = dN_a/dX_I`` (``a`` node, ``I`` in-plane
axis).  The 3x2 deformation gradient of the mid-surface is ``F = sum_a x_a G_a^T`` (current positions in
frame K), the Green-Lagrange membrane strain ``E = (F^T F - I) / 2``.  Voigt notation with engineering
shear: ``E_v = [E11, E22, 2 E12]``, ``S_v = [S11, S22, S12]`` (second Piola-Kirchhoff stress [Pa]).

Material: plane-stress St. Venant-Kirchhoff, ``S = C E``, ``C = Y/(1-nu^2) [[1,nu,0],[nu,1,0],[0,0,(1-nu)/2]]``
(the paper models the ripstop as "isotropic linear material", Sect. II.A).

Wrinkling: relaxed energy (tension-field theory)
-----------------------------------------------
A fabric this thin (``h = 0.08 mm``) cannot carry compression: it wrinkles.  We use the relaxed strain
energy density of Pipkin (1986), "The relaxed energy density for isotropic elastic membranes", IMA J. Appl.
Math. 36, 85-99, and Steigmann (1990), Proc. R. Soc. Lond. A 429, 141-173:
``W_rel(E) = min_{P >= 0} W(E + P)`` (the surface may be shorter than the fabric, never longer).  For the
isotropic SVK law, with principal strains ``E1 >= E2`` (major direction ``n1``), the minimiser is coaxial
and gives the three classical states of the mixed stress-strain criterion (Kang & Im 1997, "Finite
element analysis of wrinkling membranes", J. Appl. Mech. 64, 263-269; Roddeman et al. 1987)::

    taut      E2 + nu E1 > 0   (both principal stresses > 0):  W = E_v^T C E_v / 2,  S = C E
    wrinkled  E1 > 0 >= E2 + nu E1 (uniaxial tension along n1): W = Y E1^2 / 2,     S = Y E1 n1 n1^T
    slack     E1 <= 0:                                           W = 0,               S = 0

``W_rel`` is convex and continuously differentiable (envelope theorem: the minimiser is unique), so the
stress is continuous across the state boundaries; the tangent ``dS/dE`` jumps there.  In the wrinkled
state the exact derivative of ``S = Y E1 n1 n1^T`` (derivative of eigenvalue and eigenvector) is::

    D_w = Y m1 m1^T + 2 Y E1 / (E1 - E2) m12 m12^T,   m1 = [c^2, s^2, cs],  m12 = [-cs, cs, (c^2 - s^2)/2]

with ``n1 = (c, s)``; ``E1 - E2 >= (1 + nu) E1 > 0`` so it is bounded.  To keep the tangent regular in
slack regions a fraction ``eps`` of the full SVK energy is kept:
``W_eff = (1 - eps) W_rel + eps W``, ``S = (1 - eps) S_rel + eps C E``, ``D = (1 - eps) D_rel + eps C``.
Everything returned is the exact derivative of ``W_eff`` (away from the state boundaries for ``D``).
Strains within ``TAUT_TOL = 1e-12`` of the taut region count as taut (stress error ``<= 1e-12 Y``), so a
stress-free configuration gets the linear-elastic tangent ``C`` rather than ``eps C``.

Element quantities (``A0`` reference area, ``h`` thickness): energy ``A0 h W_eff``, internal force
``f_a = A0 h F S G_a`` and tangent ``K = A0 h (B^T D B + (G S G^T) (x) I_3)`` with ``B = dE_v/dx``.
"""

from __future__ import annotations

import numpy as np

TAUT, WRINKLED, SLACK = 0, 1, 2
#: Strains this close to the taut boundary count as taut, so that a stress-free state (which round-off
#: puts at random on either side) gets the full linear-elastic tangent ``C``, the best Newton predictor.
TAUT_TOL = 1e-12


def plane_stress_matrix(Y: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """Plane-stress matrix in Voigt notation with engineering shear; ``(n,), (n,) -> (n, 3, 3)`` [Pa]."""
    Y = np.asarray(Y, dtype=float)
    nu = np.asarray(nu, dtype=float)
    c = Y / (1.0 - nu**2)
    C = np.zeros(c.shape + (3, 3))
    C[..., 0, 0] = C[..., 1, 1] = c
    C[..., 0, 1] = C[..., 1, 0] = c * nu
    C[..., 2, 2] = c * 0.5 * (1.0 - nu)
    return C


def cst_reference(xy: np.ndarray):
    """Area and shape-function gradients of constant-strain triangles.

    Parameters
    ----------
    xy : (n, 3, 2) float [m]   reference node coordinates in the element plane.

    Returns
    -------
    A0 : (n,) float [m^2]      reference area (positive for counter-clockwise nodes).
    G : (n, 3, 2) float [1/m]  ``G[:, a, I] = dN_a / dX_I``.
    """
    x, y = xy[..., 0], xy[..., 1]
    b = np.stack([y[:, 1] - y[:, 2], y[:, 2] - y[:, 0], y[:, 0] - y[:, 1]], axis=1)
    c = np.stack([x[:, 2] - x[:, 1], x[:, 0] - x[:, 2], x[:, 1] - x[:, 0]], axis=1)
    A2 = np.sum(x * b, axis=1)  # twice the signed area
    G = np.stack([b, c], axis=-1) / A2[:, None, None]
    return 0.5 * A2, G


def principal_strains(Ev: np.ndarray):
    """Principal Green-Lagrange strains and direction data of Voigt strains ``(n, 3)``.

    Returns ``E1 >= E2`` (n,), ``cos 2phi``, ``sin 2phi`` (n,) with ``n1 = (cos phi, sin phi)`` the major
    principal direction in the element's reference plane.
    """
    mean = 0.5 * (Ev[:, 0] + Ev[:, 1])
    hd = 0.5 * (Ev[:, 0] - Ev[:, 1])
    e12 = 0.5 * Ev[:, 2]
    rad = np.sqrt(hd**2 + e12**2)
    safe = np.where(rad > 0.0, rad, 1.0)
    c2 = np.where(rad > 0.0, hd / safe, 1.0)
    s2 = np.where(rad > 0.0, e12 / safe, 0.0)
    return mean + rad, mean - rad, c2, s2


def relaxed_svk(Ev: np.ndarray, Y: np.ndarray, nu: np.ndarray, C: np.ndarray, eps: float, wrinkling: bool):
    """Relaxed (tension-field) SVK law: energy density, stress, tangent and state.

    Parameters
    ----------
    Ev : (n, 3) float [-]   Voigt Green-Lagrange strain ``[E11, E22, 2 E12]``.
    Y, nu : (n,) float      Young's modulus [Pa] and Poisson ratio.
    C : (n, 3, 3) float     plane-stress matrix [Pa] (:func:`plane_stress_matrix`).
    eps : float             fraction of the full SVK energy kept everywhere (slack stiffness).
    wrinkling : bool        False: plain SVK (no relaxation).

    Returns
    -------
    W : (n,) [J/m^3], S : (n, 3) [Pa], D : (n, 3, 3) [Pa], state : (n,) int (TAUT/WRINKLED/SLACK).
    """
    S_full = np.einsum("nij,nj->ni", C, Ev)
    W_full = 0.5 * np.einsum("ni,ni->n", S_full, Ev)
    if not wrinkling:
        return W_full, S_full, C.copy(), np.full(Ev.shape[0], TAUT, dtype=np.int64)
    E1, E2, c2, s2 = principal_strains(Ev)
    taut = E2 + nu * E1 > -TAUT_TOL
    wrink = (E1 > 0.0) & ~taut
    state = np.where(taut, TAUT, np.where(wrink, WRINKLED, SLACK))
    E1p = np.where(wrink, E1, 0.0)
    gap = np.where(wrink, E1 - E2, 1.0)
    m1 = np.stack([0.5 * (1.0 + c2), 0.5 * (1.0 - c2), 0.5 * s2], axis=-1)
    m12 = np.stack([-0.5 * s2, 0.5 * s2, 0.5 * c2], axis=-1)
    YE = Y * E1p
    S_w = YE[:, None] * m1
    D_w = Y[:, None, None] * m1[:, :, None] * m1[:, None, :] \
        + (2.0 * YE / gap)[:, None, None] * m12[:, :, None] * m12[:, None, :]
    W_w = 0.5 * YE * E1p
    wr = wrink.astype(float)
    ta = taut.astype(float)
    a = 1.0 - eps
    W = (a * ta + eps) * W_full + a * wr * W_w
    S = (a * ta + eps)[:, None] * S_full + (a * wr)[:, None] * S_w
    D = (a * ta + eps)[:, None, None] * C + (a * wr)[:, None, None] * D_w
    return W, S, D, state


def membrane_internal(x_e: np.ndarray, G: np.ndarray, A0h: np.ndarray, Y, nu, C, eps, wrinkling):
    """Membrane energy, internal force and tangent w.r.t. the 9 nodal translations.

    Parameters
    ----------
    x_e : (n, 3, 3) float [m]  current node positions.
    G : (n, 3, 2) float [1/m]  reference shape-function gradients; ``A0h`` (n,) [m^3] reference volume.
    Y, nu, C, eps, wrinkling : material data, see :func:`relaxed_svk`.

    Returns
    -------
    U : (n,) [J], f : (n, 9) [N] (node-major ``[x0, y0, z0, x1, ...]``), K : (n, 9, 9) [N/m],
    extra : dict with ``F`` (n, 3, 2), ``Ev`` (n, 3), ``S`` (n, 3), ``state`` (n,).
    """
    n = x_e.shape[0]
    F = np.einsum("nai,naI->niI", x_e, G)
    CG = np.einsum("niI,niJ->nIJ", F, F)
    Ev = np.stack([0.5 * (CG[:, 0, 0] - 1.0), 0.5 * (CG[:, 1, 1] - 1.0), CG[:, 0, 1]], axis=-1)
    W, S, D, state = relaxed_svk(Ev, Y, nu, C, eps, wrinkling)
    # B[:, v, (a, i)] = dE_v / dx_ai
    B = np.empty((n, 3, 3, 3))
    B[:, 0] = G[:, :, 0, None] * F[:, None, :, 0]
    B[:, 1] = G[:, :, 1, None] * F[:, None, :, 1]
    B[:, 2] = G[:, :, 0, None] * F[:, None, :, 1] + G[:, :, 1, None] * F[:, None, :, 0]
    B = B.reshape(n, 3, 9)
    f = A0h[:, None] * np.einsum("nv,nvk->nk", S, B)
    K = np.matmul(np.swapaxes(B, 1, 2), np.matmul(D, B))
    Smat = np.stack([S[:, 0], S[:, 2], S[:, 2], S[:, 1]], axis=-1).reshape(n, 2, 2)
    GSG = np.einsum("naI,nIJ,nbJ->nab", G, Smat, G)
    for i in range(3):
        K[:, i::3, i::3] += GSG
    K *= A0h[:, None, None]
    return A0h * W, f, K, {"F": F, "Ev": Ev, "S": S, "state": state}
