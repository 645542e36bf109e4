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

von Karman kinematics (``structure.membrane_kinematics = "von_karman"``, the paper's, Sect. II.A)
-------------------------------------------------------------------------------------------------
In the element's reference frame ``R0 = [e1, e2, n0]`` the displacement gradient ``H = F - [e1, e2]`` has in-plane
rows ``H_ab = e_a . H_b`` and the out-of-plane row ``w_b = n0 . H_b``. The von Karman strain keeps the out-of-plane
rotations' quadratic terms only (von Karman's moderate-rotation plate strains; the paper: "a quadratic relation
between the strains and the displacements", adequate "for the expected degree of deformation")::

    E_ab = (H_ab + H_ba) / 2 + w_a w_b / 2

It is the Green-Lagrange strain less ``sum_c H_ca H_cb / 2`` over the in-plane rows ``c``: an in-plane rotation by
``theta`` strains the element by ``cos(theta) - 1`` along both axes (none with Green-Lagrange), and a tensioned
element has no geometric stiffness against in-plane motion: ``K = A0 h (B^T D B + (G S G^T) (x) n0 n0^T)`` with
``B`` of ``F_vk = [e1, e2] + n0 w^T`` in place of ``F``. Out-of-plane deformation alone (``H_ab = 0``) strains both
alike.
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
    return (*_blend(eps, taut, wrink, W_full, S_full, C, W_w, S_w, D_w), state)


def _blend(eps, taut, wrink, W_full, S_full, C, W_w, S_w, D_w):
    """Energy, stress and tangent of the relaxed laws from their taut (``W_full``, ``S_full``, ``C``) and wrinkled
    (``W_w``, ``S_w``, ``D_w``) values: taut elements take the full law, wrinkled ones the wrinkled law, every element
    keeps the fraction ``eps`` of the full law (slack elements only that)."""
    a = 1.0 - eps
    cT = a * taut.astype(float) + eps
    cW = a * wrink.astype(float)
    return (cT * W_full + cW * W_w, cT[:, None] * S_full + cW[:, None] * S_w,
            cT[:, None, None] * C + cW[:, None, None] * D_w)


def fabric_matrix(Y: np.ndarray, nu: np.ndarray, shear_ratio: float, angle: np.ndarray) -> np.ndarray:
    """Plane-stress matrix of a balanced woven fabric in the element axes; ``(n,) x 3 -> (n, 3, 3)`` [Pa].

    In the thread axes (warp 1, weft 2, equal moduli): ``C_m = [[c, nu c, 0], [nu c, c, 0], [0, 0, r G_iso]]`` with
    ``c = Y / (1 - nu^2)``, ``G_iso = Y / (2 (1 + nu))`` and ``r = shear_ratio`` (1: the isotropic law). ``angle`` is
    the warp's angle from the element's first reference axis; with the strain transformation ``T`` (Voigt, engineering
    shear) ``E_m = T E``, the energy ``E_m^T C_m E_m / 2`` gives ``C = T^T C_m T`` in the element axes.
    """
    C = plane_stress_matrix(Y, nu)
    C[..., 2, 2] *= float(shear_ratio)
    c, s = np.cos(angle), np.sin(angle)
    T = np.zeros(np.shape(angle) + (3, 3))
    T[..., 0, :] = np.stack([c * c, s * s, c * s], axis=-1)
    T[..., 1, :] = np.stack([s * s, c * c, -c * s], axis=-1)
    T[..., 2, :] = np.stack([-2.0 * c * s, 2.0 * c * s, c * c - s * s], axis=-1)
    return np.einsum("...ki,...kl,...lj->...ij", T, C, T)


def relaxed_general(Ev: np.ndarray, C: np.ndarray, eps: float):
    """Relaxed (tension-field) law of any plane-stress matrix ``C`` (an orthotropic fabric): as :func:`relaxed_svk`.

    The relaxed energy ``W_rel(E) = min_{P >= 0} W(E + P)`` (Pipkin 1986; Steigmann 1990), ``W(E) = E^T C E / 2``,
    is a convex problem over the cone of positive semi-definite wrinkle strains ``P``. Its minimiser is
    ``P = 0`` where the stress ``C E`` is positive semi-definite (taut), ``P = -E`` where the strain is negative
    semi-definite (slack: ``W = 0``), else of rank one, ``P = w m m^T`` with the wrinkle direction ``m = (cos t,
    sin t)``. For an anisotropic law ``m`` is not a principal direction of the strain or of the stress (Roddeman et
    al. 1987; Kang & Im 1997 treat the isotropic case): with ``v(t) = [cos^2 t, sin^2 t, 2 sin t cos t]`` (``m m^T``
    in Voigt strain form), ``a = C v``, ``s = a . E`` (the taut law's normal stress along ``m``) and ``d = v . a``,
    the minimum over ``w >= 0`` is ``w = -s / d`` and::

        W_rel(E) = min_t [W(E) - s(t)^2 / (2 d(t))]  (over t with s(t) < 0),     S = C E + w a   (uniaxial: S m = 0),

    found by Newton's method in ``t`` from the most compressive direction of ``C E`` (exact for an isotropic law).
    The tangent is the derivative of ``S`` with ``t`` following ``E`` (implicit function theorem):
    ``D = C - a a^T / d - g g^T / W_tt``, ``g = dS/dt = w_t a + w C v_t``, ``W_tt = d^2 W_rel / dt^2 > 0`` at the
    minimum. Regularised as :func:`relaxed_svk` (``eps`` of the full energy). For an isotropic ``C`` it equals
    :func:`relaxed_svk` to round-off (``tests/structure/test_fabric.py``).
    """
    Ev = np.asarray(Ev, dtype=float)
    S_full = np.einsum("nij,nj->ni", C, Ev)
    W_full = 0.5 * np.einsum("ni,ni->n", S_full, Ev)
    hs = 0.5 * (S_full[:, 0] - S_full[:, 1])
    s_min = 0.5 * (S_full[:, 0] + S_full[:, 1]) - np.hypot(hs, S_full[:, 2])
    scale = 0.5 * (C[:, 0, 0] + C[:, 1, 1])
    taut = s_min > -TAUT_TOL * scale
    E1 = principal_strains(Ev)[0]
    wrink = (E1 > 0.0) & ~taut
    state = np.where(taut, TAUT, np.where(wrink, WRINKLED, SLACK))
    # Newton in t on the wrinkled elements, from the most compressive direction of C E
    t = 0.5 * np.arctan2(S_full[:, 2], hs) + 0.5 * np.pi

    def terms(t):
        c2, s2 = np.cos(2.0 * t), np.sin(2.0 * t)
        v = np.stack([0.5 * (1.0 + c2), 0.5 * (1.0 - c2), s2], axis=-1)
        vt = np.stack([-s2, s2, 2.0 * c2], axis=-1)
        vtt = np.stack([-2.0 * c2, 2.0 * c2, -4.0 * s2], axis=-1)
        a = np.einsum("nij,nj->ni", C, v)
        at = np.einsum("nij,nj->ni", C, vt)
        s = np.einsum("ni,ni->n", S_full, v)
        st = np.einsum("ni,ni->n", S_full, vt)
        stt = np.einsum("ni,ni->n", S_full, vtt)
        d = np.einsum("ni,ni->n", v, a)
        dt = 2.0 * np.einsum("ni,ni->n", vt, a)
        dtt = 2.0 * (np.einsum("ni,ni->n", vt, at) + np.einsum("ni,ni->n", a, vtt))
        w = -s / d
        wt = -(st * d - s * dt) / d**2
        W_t = w * st + 0.5 * w**2 * dt
        W_tt = wt * st + w * stt + w * wt * dt + 0.5 * w**2 * dtt
        return a, at, s, d, w, wt, W_t, W_tt

    for _ in range(_WRINKLE_MAX_ITER):
        W_t, W_tt = terms(t)[6:]
        step = np.where(W_tt > 0.0, -W_t / np.where(W_tt > 0.0, W_tt, 1.0), -np.sign(W_t) * _WRINKLE_MAX_STEP)
        step = np.where(wrink, np.clip(step, -_WRINKLE_MAX_STEP, _WRINKLE_MAX_STEP), 0.0)
        t = t + step
        if np.all(np.abs(step) <= _WRINKLE_STEP_TOL):
            break
    a, at, s, d, w, wt, W_t, W_tt = terms(t)
    g = wt[:, None] * a + w[:, None] * at
    curv = np.where(W_tt > 0.0, 1.0 / np.where(W_tt > 0.0, W_tt, 1.0), 0.0)
    S_w = S_full + w[:, None] * a
    D_w = C - a[:, :, None] * a[:, None, :] / d[:, None, None] - curv[:, None, None] * g[:, :, None] * g[:, None, :]
    W_w = W_full + 0.5 * w * s
    return (*_blend(eps, taut, wrink, W_full, S_full, C, W_w, S_w, D_w), state)


#: Newton in the wrinkle angle of :func:`relaxed_general`: at most this many iterations, steps within this bound [rad],
#: converged when every step is below the tolerance [rad]
_WRINKLE_MAX_ITER = 30
_WRINKLE_MAX_STEP = 0.3
_WRINKLE_STEP_TOL = 1e-13


def membrane_law(Ev, Y, nu, C, eps, wrinkling):
    """The membrane law of ``wrinkling``: 0 (False) plain SVK, 1 (True) the isotropic relaxed law
    (:func:`relaxed_svk`), 2 the relaxed law of any ``C`` (:func:`relaxed_general`)."""
    if int(wrinkling) == 2:
        return relaxed_general(Ev, C, eps)
    return relaxed_svk(Ev, Y, nu, C, eps, bool(wrinkling))


def membrane_internal(x_e: np.ndarray, G: np.ndarray, A0h: np.ndarray, Y, nu, C, eps, wrinkling,
                      R0: np.ndarray | None = None):
    """Membrane energy, internal force and tangent w.r.t. the 9 nodal translations.

    Parameters
    ----------
    x_e : (n, 3, 3) float [m]  current node positions.
    G : (n, 3, 2) float [1/m]  reference shape-function gradients; ``A0h`` (n,) [m^3] reference volume.
    Y, nu, C, eps : material data, see :func:`relaxed_svk`; ``wrinkling`` the law of :func:`membrane_law` (0, 1, 2).
    R0 : (n, 3, 3) float  the reference element frames ``[e1, e2, n0]`` (columns): von Karman kinematics (module
        docstring); None: Green-Lagrange.

    Returns
    -------
    U : (n,) [J], f : (n, 9) [N] (node-major ``[x0, y0, z0, x1, ...]``), K : (n, 9, 9) [N/m],
    extra : dict with ``F`` (n, 3, 2), ``Ev`` (n, 3), ``S`` (n, 3), ``state`` (n,).
    """
    n = x_e.shape[0]
    F = np.einsum("nai,naI->niI", x_e, G)
    if R0 is None:
        CG = np.einsum("niI,niJ->nIJ", F, F)
        Ev = np.stack([0.5 * (CG[:, 0, 0] - 1.0), 0.5 * (CG[:, 1, 1] - 1.0), CG[:, 0, 1]], axis=-1)
        Fb = F  # the strain's derivative dE/dx is that of F
    else:
        H = np.einsum("nik,niI->nkI", R0, F)  # (n, 3, 2): rows e1, e2, n0 of the gradient
        w = H[:, 2, :]
        Ev = np.stack([H[:, 0, 0] - 1.0 + 0.5 * w[:, 0] ** 2, H[:, 1, 1] - 1.0 + 0.5 * w[:, 1] ** 2,
                       H[:, 0, 1] + H[:, 1, 0] + w[:, 0] * w[:, 1]], axis=-1)
        Fb = R0[:, :, :2] + R0[:, :, 2, None] * w[:, None, :]  # [e1, e2] + n0 w^T
    W, S, D, state = membrane_law(Ev, Y, nu, C, eps, wrinkling)
    B = _strain_operator(Fb, G)  # B[:, v, (a, i)] = dE_v / dx_ai
    f = A0h[:, None] * np.einsum("nv,nvk->nk", S, B)
    K = np.matmul(np.swapaxes(B, 1, 2), np.matmul(D, B))
    Smat = np.stack([S[:, 0], S[:, 2], S[:, 2], S[:, 1]], axis=-1).reshape(n, 2, 2)
    GSG = np.einsum("naI,nIJ,nbJ->nab", G, Smat, G)
    if R0 is None:
        for i in range(3):
            K[:, i::3, i::3] += GSG
    else:  # only the out-of-plane motion has the prestress's geometric stiffness
        nn = R0[:, :, 2, None] * R0[:, None, :, 2]
        K += (GSG[:, :, None, :, None] * nn[:, None, :, None, :]).reshape(n, 9, 9)
    K *= A0h[:, None, None]
    return A0h * W, f, K, {"F": F, "Ev": Ev, "S": S, "state": state}


def membrane_discrete_gradient(x0_e: np.ndarray, x1_e: np.ndarray, G: np.ndarray, A0h: np.ndarray, Y, nu, C, eps,
                               wrinkling, tangent: bool = False):
    """Energy-consistent membrane force of a time step from ``x0_e`` to ``x1_e`` (both (n, 3, 3) [m]).

    The discrete gradient of Gonzalez ("Exact energy and momentum conserving algorithms for general models in
    nonlinear elasticity", Comput. Methods Appl. Mech. Engrg. 190, 1763-1783, 2000), which extends the
    energy-momentum method of Simo & Tarnow (ZAMP 43, 757-792, 1992) to any stored energy::

        S_alg = S(E_mid) + [W(E1) - W(E0) - S(E_mid) : dE] / (dE : dE) dE,     E_mid = (E0 + E1) / 2, dE = E1 - E0
        f_a   = A0 h F_mid S_alg G_a,                                           F_mid = (F0 + F1) / 2

    Because ``E1 - E0 = sym(F_mid^T (F1 - F0))`` exactly, the force's work over the step is the change of the stored
    energy: ``sum_a f_a . (x1_a - x0_a) = A0 h (W(E1) - W(E0))``, whatever the law's kinks (the taut / wrinkled /
    slack switches of the relaxed energy). Averaging the end forces instead (the trapezoidal rule of
    generalized-alpha) does work that differs from the energy change at every switch; for the canopy's gram-sized
    nodes, whose membrane modes are far faster than the step, that error pumps energy into the wing (a free wing in
    vacuum gained 75 % of its kinetic energy in 0.3 s, docs/model.md, "Energy"). ``S_alg`` is
    ``S(E_mid) + O(|dE|^2)``: second order. Returns ``f`` (n, 9) [N] (node-major as :func:`membrane_internal`),
    the stored energies ``U0``, ``U1`` (n,) [J] at the two ends and, with ``tangent``, ``K`` (n, 9, 9) [N/m], the
    derivative of ``f`` with respect to ``x1``, ``A0 h (B_mid^T (dS_alg/dE1) B_1 + (G S_alg G^T) (x) I_3 / 2)``
    (else None).
    """
    n = x0_e.shape[0]
    F0 = np.einsum("nai,naI->niI", x0_e, G)
    F1 = np.einsum("nai,naI->niI", x1_e, G)

    def strain(F):
        CG = np.einsum("niI,niJ->nIJ", F, F)
        return np.stack([0.5 * (CG[:, 0, 0] - 1.0), 0.5 * (CG[:, 1, 1] - 1.0), CG[:, 0, 1]], axis=-1)

    E0, E1 = strain(F0), strain(F1)
    W0 = membrane_law(E0, Y, nu, C, eps, wrinkling)[0]
    W1, S1, _, _ = membrane_law(E1, Y, nu, C, eps, wrinkling)
    _, Sm, D, _ = membrane_law(0.5 * (E0 + E1), Y, nu, C, eps, wrinkling)
    dE = E1 - E0
    P = np.array([1.0, 1.0, 0.5])
    nE = dE * P  # the tensor dE in Voigt stress form: S_c . dE = c (dE : dE)
    dd = np.einsum("nv,nv->n", nE, dE)
    # the correction's numerator W1 - W0 - S dE is O(|dE|^3) against a round-off of eps |W|: below
    # |dE| = 1e-7 |E| it is noise (and the stress error of dropping it, O(|dE|^2), is below 1e-14 Y)
    Es = np.einsum("nv,nv->n", np.abs(E0) + np.abs(E1), np.abs(E0) + np.abs(E1))
    big = dd > 1e-14 * Es + 1e-30
    ddi = np.where(big, 1.0 / np.where(big, dd, 1.0), 0.0)
    c = (W1 - W0 - np.einsum("nv,nv->n", Sm, dE)) * ddi
    S = Sm + c[:, None] * nE
    Bm = _strain_operator(0.5 * (F0 + F1), G)
    f = A0h[:, None] * np.einsum("nv,nvk->nk", S, Bm)
    K = None
    if tangent:
        # dS_alg/dE1 = D_mid / 2 + n (S1 - S_mid - D_mid dE / 2 - 2 c n)^T / (dE : dE) + c P (n = P dE)
        g = (S1 - Sm - 0.5 * np.einsum("nuv,nv->nu", D, dE) - 2.0 * c[:, None] * nE) * ddi[:, None]
        dS = 0.5 * D + nE[:, :, None] * g[:, None, :] + (c[:, None] * P)[:, :, None] * np.eye(3)
        K = np.matmul(np.swapaxes(Bm, 1, 2), np.matmul(dS, _strain_operator(F1, G)))
        Smat = np.stack([S[:, 0], S[:, 2], S[:, 2], S[:, 1]], axis=-1).reshape(n, 2, 2)
        GSG = 0.5 * np.einsum("naI,nIJ,nbJ->nab", G, Smat, G)
        for i in range(3):
            K[:, i::3, i::3] += GSG
        K *= A0h[:, None, None]
    return f, A0h * W0, A0h * W1, K


def _strain_operator(F: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``B[:, v, (a, i)] = dE_v / dx_ai`` (n, 3, 9) at the deformation gradient ``F`` (n, 3, 2)."""
    n = F.shape[0]
    B = np.empty((n, 3, 3, 3))
    B[:, 0] = G[:, :, 0, None] * F[:, None, :, 0]
    B[:, 1] = G[:, :, 1, None] * F[:, None, :, 1]
    B[:, 2] = G[:, :, 0, None] * F[:, None, :, 1] + G[:, :, 1, None] * F[:, None, :, 0]
    return B.reshape(n, 3, 9)
