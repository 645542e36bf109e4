"""Aerodynamic section loads and their nodal distribution (Bosch et al., Sect. II.B, Eq. 7-9, Fig. 4).

Per section i (geometry and inflow from :mod:`kite_env.aero.sections`, coefficients from
:mod:`kite_env.aero.breukels`), with the projected inflow speed ``V = |v_a,xz|``, chord ``c`` and strip width ``w``:

    F_L = 1/2 rho CL c w V^2                  Eq. (7)
    F_D = 1/2 rho CD c w V^2                  Eq. (8)
    M   = 1/2 rho CM c^2 w V^2                Eq. (9)

Eq. (9) as printed reads ``1/2 rho CM c w V^2``, which has the unit of a force; we use the standard 2-D moment
coefficient definition with ``c^2`` (a moment per unit span is ``q c^2 CM``). Drag acts along the projected flow
``e_D = u_xz / |u_xz|``, lift perpendicular to it in the airfoil plane, ``e_L = e_D × e_y`` (= +e_z at alpha = 0).
``M`` is the pitching moment about ``e_y`` through the reference point ``r_ref = r_nose + x_ref c e_x`` (quarter
chord by default, see :mod:`kite_env.aero.breukels`), positive nose-up: a positive rotation about ``e_y`` turns the
TE (+e_x) towards -e_z, so a lift force aft of ``r_ref`` gives a negative (nose-down) moment.

Nodal distribution. The paper distributes ``F_L`` and ``F_D`` over the m load points "such that the prescribed
airfoil moment M^i is matched" with a "varying weighted approach" of Breukels [9, 23] whose details are not
available here. We use the minimum-norm correction of a uniform distribution: the nodal forces ``f_j`` are those
closest (least squares) to ``F / m`` that reproduce exactly

    sum_j f_j = F = L + D                                       (3 equations)
    e_y · sum_j (r_j - r_ref) × f_j = M                          (1 equation, moment about e_y)

With ``g_j = e_y × (r_j - r_ref)`` (the moment row: ``e_y · (d × f) = f · (e_y × d)``) the solution of this
equality-constrained least-squares problem is closed-form:

    f_j = F / m + mu (g_j - g_mean),   mu = (M - g_mean · F) / sum_j |g_j - g_mean|^2 .

``g_j`` lies in the airfoil plane (⟂ e_y), ``e_y × (s e_x + z e_z) = -s e_z + z e_x``: the correction is a pure
couple (zero net force) whose normal (e_z) part varies affinely with the chordwise node coordinate ``s_j``, the
chordwise (e_x) part with the node height ``z_j`` above the chord line. The normal load per node is therefore the
affine "varying weight" law that puts the centre of pressure where M requires, while the denominator never vanishes
(it is the polar moment of the nodes about their centroid in the airfoil plane, > 0 for any section with a chord):
no special case at zero lift (F = 0 gives a pure couple) and no division by the normal force. All nodal forces lie
in the airfoil plane. Matched exactly: the total force vector and the e_y component of the moment about r_ref,
evaluated with the actual 3-D node positions. Not controlled: the e_x and e_z moment components that appear when a
deformed section's nodes leave the plane through r_ref normal to e_y (a 2-D airfoil model carries no such moment).

Caveat (from the regression, not from the distribution): Breukels' CM grows like -0.007 alpha_deg^2, so the centre
of pressure ``x_ref - CM/CN`` moves behind the TE above roughly 14 deg (t = 0.1, kappa = 0.095), giving nodal normal
forces of opposite sign at the LE and TE nodes (the regression's CM is implausibly large: -2.75 at 20 deg).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kite_env.aero.breukels import CM_REGRESSION_REF_DEFAULT, X_REF_OVER_C_DEFAULT, lei_coefficients
from kite_env.aero.kernels import section_loads_fields
from kite_env.aero.sections import SectionGeometry, apparent_wind, cross, inflow, section_geometry, spanwise_directions
from kite_env.compiled import resolve_backend


@dataclass(frozen=True)
class SectionLoads:
    """Aerodynamic loads of all sections, frame K, SI units.

    Attributes
    ----------
    nodal_forces : (n_sec, m, 3) float [N]
        Forces on the structural nodes of each section.
    alpha : (n_sec,) float [rad]
        Angle of attack.
    CL, CD, CM : (n_sec,) float [-]
        Section coefficients (CM about the reference point, positive nose-up).
    lift_local, drag_local : (n_sec, 3) float [N]
        Section lift and drag (Eq. 7, 8) in section-frame components (e_x, e_y, e_z); the e_y component is 0.
    moment : (n_sec,) float [N m]
        Pitching moment about ``e_y`` through ``r_ref`` (Eq. 9), positive nose-up.
    s_ref : (n_sec,) float [m]
        Moment reference point along ``e_x`` from the LE node, ``x_ref c - d/2``.
    v_app : (n_sec, 3) float [m/s]
        Apparent wind of Eq. (2) (section velocity relative to the air, not projected).
    q_dyn : (n_sec,) float [Pa]
        ``1/2 rho |v_a,xz|^2`` with the projected apparent wind.
    geometry : SectionGeometry
    positions : (n_sec, m, 3) float [m]
        The node positions the loads were computed for (points of application of ``nodal_forces``).

    Properties (frame K): ``lift``, ``drag``, ``force = lift + drag`` (n_sec, 3) [N] and the reference point
    ``r_ref = r_nose + x_ref c e_x`` (n_sec, 3) [m].
    """

    nodal_forces: np.ndarray
    alpha: np.ndarray
    CL: np.ndarray
    CD: np.ndarray
    CM: np.ndarray
    lift_local: np.ndarray
    drag_local: np.ndarray
    moment: np.ndarray
    s_ref: np.ndarray
    v_app: np.ndarray
    q_dyn: np.ndarray
    geometry: SectionGeometry
    positions: np.ndarray

    @property
    def lift(self) -> np.ndarray:
        return np.einsum("ik,ijk->ij", self.lift_local, self.geometry.frames)

    @property
    def drag(self) -> np.ndarray:
        return np.einsum("ik,ijk->ij", self.drag_local, self.geometry.frames)

    @property
    def force(self) -> np.ndarray:
        return self.lift + self.drag

    @property
    def r_ref(self) -> np.ndarray:
        return self.geometry.r_le + self.s_ref[:, None] * self.geometry.e_x


#: CL below which a section's canopy begins to luff (``aero.canopy_luffing``): the regularisation band of the blend to
#: edge-only loads, about 1 deg of alpha at the lift slope near zero lift (0.09 per deg, aero.breukels)
LUFFING_BAND_CL = 0.1

# maps section coordinates (s, y, z) of a lever arm d to g = e_y × d = (z, 0, -s), as a row vector: g = d @ _EY_CROSS
_EY_CROSS = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
# weights of the (s, y, z) components in the polar moment sum |g_j - g_mean|^2 (the y offsets do not enter)
_XZ = np.array([1.0, 0.0, 1.0])


def distribute(local: np.ndarray, s_ref: np.ndarray, force_local: np.ndarray, moment: np.ndarray,
               canopy_share: np.ndarray | None = None) -> np.ndarray:
    """Nodal forces reproducing each section's force and its moment about ``e_y`` (minimum-norm, module docstring).

    Works in section-frame components: node ``j`` at ``(s_j, y_j, z_j)`` from the LE node, reference point at
    ``(s_ref, 0, 0)``; ``g_j = e_y × (r_j - r_ref) = (z_j, 0, -(s_j - s_ref))`` does not depend on ``y_j``.

    Parameters
    ----------
    local : (n_sec, m, 3) float [m]
        Node coordinates (s, y, z) in the section frame, from the LE node.
    s_ref : (n_sec,) float [m]
        Reference point along ``e_x`` from the LE node.
    force_local : (n_sec, 3) float [N]
        Section force in section components (the e_y component, normally 0, is spread uniformly).
    moment : (n_sec,) float [N m]
        Moment about ``e_y`` through the reference point.
    canopy_share : (n_sec,) float in [0, 1], optional
        Luffing (``aero.luffing_cl``): the distribution is ``w f + (1 - w) f_edge`` with ``f_edge`` the same
        minimum-norm law restricted to the LE and TE nodes; both reproduce the force and the moment, so the blend
        does too. None or 1: ``f`` (the paper's distribution).

    Returns
    -------
    f_local : (n_sec, m, 3) float [N]
        Nodal forces in section components: ``sum_j f_j = force_local`` and
        ``sum_j (z_j f_j,x - (s_j - s_ref) f_j,z) = moment``; no e_y component is added.
    """
    m = local.shape[1]
    mean = local.sum(axis=1) * (1.0 / m)
    g_dev = (local - mean[:, None, :]) @ _EY_CROSS
    # g_mean · F with g_mean = (z_mean, 0, -(s_mean - s_ref))
    g_dot_f = mean[:, 2] * force_local[:, 0] - (mean[:, 0] - s_ref) * force_local[:, 2]
    mu = (moment - g_dot_f) / np.einsum("ijk,ijk,k->i", g_dev, g_dev, _XZ)
    f = (force_local * (1.0 / m))[:, None, :] + mu[:, None, None] * g_dev
    if canopy_share is None:
        return f
    w = np.asarray(canopy_share, dtype=float)
    ends = local[:, [0, m - 1]]
    f_edge = np.zeros_like(f)
    f_edge[:, [0, m - 1]] = distribute(ends, s_ref, force_local, moment)
    return w[:, None, None] * f + (1.0 - w)[:, None, None] * f_edge


def section_loads(
    x_sec: np.ndarray,
    tube_d: np.ndarray,
    width: np.ndarray,
    v_kite: np.ndarray,
    omega: np.ndarray,
    v_wind: np.ndarray,
    rho: float,
    x_sec_prev: np.ndarray | None = None,
    dt: float | None = None,
    x_ref_over_c: float = X_REF_OVER_C_DEFAULT,
    spanwise: np.ndarray | None = None,
    backend: str = "auto",
    moment_chord_power: float = 2.0,
    luffing_cl: float = 0.0,
    cm_regression_ref_over_c: float = CM_REGRESSION_REF_DEFAULT,
    rotation_point_over_c: float | None = None,
    negative_alpha: str = "bounded",
) -> SectionLoads:
    """Aerodynamic loads of all wing sections and their nodal distribution (Eq. 2-9).

    Parameters
    ----------
    x_sec : (n_sec, m, 3) float [m]
        Current section node positions in frame K, LE node (j = 0) to TE node (j = m-1).
    tube_d : (n_sec,) float [m]
        LE tube diameter per section.
    width : (n_sec,) float [m]
        Spanwise strip width w per section.
    v_kite : (3,) float [m/s]
        Velocity of the kite frame origin, components in K.
    omega : (3,) float [rad/s]
        Angular velocity of the kite frame, components in K.
    v_wind : (3,) or (n_sec, 3) float [m/s]
        Wind velocity, components in K.
    rho : float [kg/m^3]
        Air density.
    x_sec_prev : (n_sec, m, 3) float [m], optional
        Node positions at the previous time step (deformation velocity, Eq. 3); used only with ``dt``.
    dt : float [s], optional
        Time step for Eq. (3).
    x_ref_over_c : float [-]
        Moment reference point / chord, measured from the airfoil leading edge (front of the LE tube).
    spanwise : (n_sec, 3) float, optional
        Spanwise LE-line directions (see :func:`kite_env.aero.sections.section_geometry`); default from ``x_sec``.
    backend : {"auto", "numba", "numpy"}
        ``"numpy"``: the reference code below; ``"numba"``: the compiled kernel of :mod:`kite_env.aero.kernels`
        (same results to round-off); ``"auto"``: see :func:`kite_env.compiled.resolve_backend`.
    moment_chord_power : float
        Power of the chord in Eq. (9), ``M = 1/2 rho CM c^p w V^2``: 2 (default) is the dimensionally consistent
        moment; 1 is the formula as printed in the paper (a moment per 1 m of reference length), kept for
        sensitivity studies (module docstring).
    luffing_cl : float
        0 (default): the paper's distribution. > 0: the width of the luffing band (``aero.canopy_luffing`` uses
        ``LUFFING_BAND_CL``): a membrane cannot carry a reversed pressure difference, so as a section's lift
        coefficient falls from ``luffing_cl`` to 0 its canopy nodes give up their load: the share
        ``w = smoothstep(CL / luffing_cl)`` stays on all nodes, the rest is carried by the LE (tube) and TE (wire)
        nodes only (:func:`distribute`); at CL <= 0 all of it. Force, moment and coefficients are unchanged.
    cm_regression_ref_over_c : float [-]
        Point / chord (from the airfoil leading edge) that Breukels' regression CM is taken about (default the
        quarter chord, an assumption: :mod:`kite_env.aero.breukels`). Unlike ``x_ref_over_c`` this changes the
        section's centre of pressure, hence the nodal loads.
    rotation_point_over_c : float, optional [-]
        Where the frame rotation enters Eq. (2): None = the LE node (the paper), else that point / chord from the
        airfoil nose (:func:`kite_env.aero.sections.apparent_wind`; 0.75 = Pistolesi's 3/4-chord point).
    negative_alpha : {"bounded", "breukels"}
        Section coefficients below zero lift: bounded by measured data (default) or Breukels' regression as is
        (:func:`kite_env.aero.breukels.lei_coefficients`).

    Returns
    -------
    SectionLoads
    """
    if resolve_backend(backend) == "numba":
        return SectionLoads(*section_loads_fields(x_sec, tube_d, width, v_kite, omega, v_wind, rho, x_sec_prev, dt,
                                                  x_ref_over_c, spanwise, moment_chord_power, luffing_cl,
                                                  cm_regression_ref_over_c, rotation_point_over_c, negative_alpha))
    x_sec = np.asarray(x_sec, dtype=float)
    geom = section_geometry(x_sec, tube_d, spanwise)
    v_a = apparent_wind(x_sec, v_kite, omega, v_wind, x_sec_prev, dt, geom, rotation_point_over_c)
    c = geom.chord
    # flow u = -v_a in section components; its e_y component is dropped (projection onto the airfoil plane)
    u_loc, alpha = inflow(v_a, geom)
    u_loc[:, 1] = 0.0
    speed2 = u_loc[:, 0] ** 2 + u_loc[:, 2] ** 2
    CL, CD, CM = lei_coefficients(alpha, geom.t, geom.kappa, x_ref_over_c, cm_regression_ref_over_c,
                                  negative_alpha=negative_alpha)
    hcw = (0.5 * rho) * c * np.asarray(width, dtype=float)
    # e_D = (u_x, 0, u_z)/V and e_L = e_D × e_y = (-u_z, 0, u_x)/V; with k = q c w / V = rho c w V / 2 no division
    # by V is needed (V = 0 gives zero loads)
    k = hcw * np.sqrt(speed2)
    drag_loc = (k * CD)[:, None] * u_loc  # Eq. (8)
    lift_loc = (k * CL)[:, None] * (u_loc @ _EY_CROSS.T)  # Eq. (7): (u_x, 0, u_z) -> (-u_z, 0, u_x)
    moment = hcw * speed2 * c ** (moment_chord_power - 1.0) * CM  # Eq. (9), with c^2 by default (module docstring)
    s_ref = x_ref_over_c * c - 0.5 * geom.tube_d  # reference point along e_x from the LE node
    if luffing_cl > 0.0:
        u = np.clip(CL / luffing_cl, 0.0, 1.0)
        share = u * u * (3.0 - 2.0 * u)  # smoothstep: C1 in CL, so the Newton tangent stays continuous
    else:
        share = None
    f_loc = distribute(geom.local, s_ref, lift_loc + drag_loc, moment, share)
    nodal = f_loc @ geom.frames.transpose(0, 2, 1)  # rows e_x, e_y, e_z: f = f_s e_x + f_z e_z
    return SectionLoads(
        nodal_forces=nodal, alpha=alpha, CL=CL, CD=CD, CM=CM, lift_local=lift_loc, drag_local=drag_loc,
        moment=moment, s_ref=s_ref, v_app=v_a, q_dyn=(0.5 * rho) * speed2, geometry=geom, positions=x_sec,
    )


def load_jacobian(
    x_sec: np.ndarray,
    tube_d: np.ndarray,
    width: np.ndarray,
    v_kite: np.ndarray,
    omega: np.ndarray,
    v_wind: np.ndarray,
    rho: float,
    x_sec_prev: np.ndarray | None = None,
    dt: float | None = None,
    x_ref_over_c: float = X_REF_OVER_C_DEFAULT,
    h: float = 1e-6,
    moment_chord_power: float = 2.0,
    luffing_cl: float = 0.0,
    cm_regression_ref_over_c: float = CM_REGRESSION_REF_DEFAULT,
    rotation_point_over_c: float | None = None,
    negative_alpha: str = "bounded",
) -> tuple[np.ndarray, np.ndarray]:
    """Section-wise derivative of the nodal aerodynamic forces with respect to the node positions.

    Forward differences of :func:`section_loads` with respect to each of the ``3 m`` node coordinates of a section,
    all sections perturbed at once and all ``3 m`` perturbations evaluated in a single stacked call. A perturbation
    changes the section's geometry (Eq. 4-6) and, with ``dt``, its deformation velocity (Eq. 3), whose term
    ``1 / (2 dt)`` dominates at small time steps. Each section's loads depend on its own nodes only, except through
    the spanwise LE-line tangent used where a section is nearly flat, which is held at its unperturbed value: the
    blocks are the exact Jacobian up to that (small) coupling between neighbouring sections and the difference
    error ``O(h)``.

    Parameters are those of :func:`section_loads`; ``h`` [m] is the difference step.

    Returns
    -------
    f0 : (n_sec, m, 3) float [N]
        Nodal forces at ``x_sec``.
    J : (n_sec, 3 m, 3 m) float [N/m]
        ``J[i, 3 a + k, 3 b + l] = d f[i, a, k] / d x[i, b, l]``.
    """
    x_sec = np.asarray(x_sec, dtype=float)
    n_sec, m, _ = x_sec.shape
    p = 3 * m
    base = section_loads(x_sec, tube_d, width, v_kite, omega, v_wind, rho, x_sec_prev, dt, x_ref_over_c,
                         moment_chord_power=moment_chord_power, luffing_cl=luffing_cl,
                         cm_regression_ref_over_c=cm_regression_ref_over_c,
                         rotation_point_over_c=rotation_point_over_c, negative_alpha=negative_alpha)
    tan = spanwise_directions(x_sec[:, 0])
    # stack: copy q perturbs coordinate q (= 3 b + l) of every section
    xs = np.broadcast_to(x_sec, (p, n_sec, m, 3)).copy()
    q = np.arange(p)
    xs.reshape(p, n_sec, p)[q, :, q] += h
    def rep(a):
        return np.broadcast_to(np.asarray(a, dtype=float), (p,) + np.shape(a)).reshape((p * n_sec,) + np.shape(a)[1:])

    v_w = np.asarray(v_wind, dtype=float)
    pert = section_loads(
        xs.reshape(p * n_sec, m, 3), rep(np.broadcast_to(tube_d, (n_sec,))), rep(np.broadcast_to(width, (n_sec,))),
        v_kite, omega, rep(v_w) if v_w.ndim == 2 else v_w, rho,
        None if x_sec_prev is None else rep(x_sec_prev), dt, x_ref_over_c, spanwise=rep(tan),
        moment_chord_power=moment_chord_power, luffing_cl=luffing_cl,
        cm_regression_ref_over_c=cm_regression_ref_over_c, rotation_point_over_c=rotation_point_over_c,
        negative_alpha=negative_alpha)
    df = (pert.nodal_forces.reshape(p, n_sec, p) - base.nodal_forces.reshape(1, n_sec, p)) * (1.0 / h)
    return base.nodal_forces, df.transpose(1, 2, 0).copy()


def wing_totals(loads: SectionLoads, v_ref: np.ndarray) -> dict:
    """Total aerodynamic force of the wing and its lift/drag split about a reference apparent velocity.

    Parameters
    ----------
    loads : SectionLoads
    v_ref : (3,) float [m/s]
        Reference velocity of the kite relative to the air (e.g. ``v_kite - v_wind``); the reference flow is
        ``-v_ref``.

    Returns
    -------
    dict with
        ``force`` (3,) [N]: sum of all nodal forces;
        ``drag`` float [N]: component of ``force`` along the reference flow ``-v_ref / |v_ref|``;
        ``lift`` float [N]: magnitude of the component of ``force`` perpendicular to ``v_ref`` (>= 0);
        ``lift_vec``, ``drag_vec`` (3,) [N]: the two vector components (``lift_vec + drag_vec = force``);
        ``lift_to_drag`` float: ``lift / drag`` (inf where drag <= 0);
        ``moment`` (3,) [N m]: moment of the nodal forces about the frame origin r_k, ``sum_ij x_ij × f_ij``.
    """
    force = loads.nodal_forces.sum(axis=(0, 1))
    v_ref = np.asarray(v_ref, dtype=float)
    e_flow = -v_ref / np.linalg.norm(v_ref)
    drag = float(force @ e_flow)
    drag_vec = drag * e_flow
    lift_vec = force - drag_vec
    lift = float(np.linalg.norm(lift_vec))
    moment = cross(loads.positions, loads.nodal_forces).sum(axis=(0, 1))
    return {
        "force": force,
        "lift": lift,
        "drag": drag,
        "lift_vec": lift_vec,
        "drag_vec": drag_vec,
        "lift_to_drag": lift / drag if drag > 0.0 else float("inf"),
        "moment": moment,
    }


def section_damping(
    x_sec: np.ndarray,
    tube_d: np.ndarray,
    width: np.ndarray,
    v_kite: np.ndarray,
    omega: np.ndarray,
    v_wind: np.ndarray,
    rho: float,
    h: float = 1e-3,
    **options,
) -> np.ndarray:
    """Quasi-steady aerodynamic damping of each rigid section: ``C_i = -d F_i / d u`` (n_sec, 3, 3) [N s/m].

    ``F_i`` is the section's force (Eq. 7-8, lift + drag) and ``u`` a translation velocity of the whole section in K,
    which adds to its apparent wind (Eq. 2; Eq. 3's intent: the deformation velocity changes the inflow). Central
    differences of :func:`section_loads` in the wind (``u = +h e_k`` is the wind ``v_w - h e_k``), all six
    perturbations of all sections in one stacked call. In lift/drag axes of the section plane the exact matrix is
    ``(q c w / V) [[2 C_D, C_D' - C_L], [2 C_L, C_L' + C_D]]`` (rows and columns e_D, e_L; primes d/d alpha); the
    spanwise velocity does not enter (the inflow is projected onto the airfoil plane).

    The symmetric part is then projected onto the positive semi-definite cone (negative eigenvalues set to zero;
    they occur past the lift maximum, where ``C_L' + C_D < 0``), the skew part is kept: the damping force
    ``-C u`` then never feeds energy into the wing, ``u . C u = u . C_sym u >= 0``, and the skew (circulatory) part
    does no work.

    Parameters are those of :func:`section_loads` (``options``: its keyword arguments ``x_ref_over_c``,
    ``moment_chord_power``, ``luffing_cl``, ``cm_regression_ref_over_c``, ``rotation_point_over_c``,
    ``negative_alpha``); ``h`` [m/s]
    is the difference step. ``x_sec_prev`` / ``dt`` must not be given: the damping replaces Eq. (3).

    Returns
    -------
    C : (n_sec, 3, 3) float [N s/m]
        Section damping matrices in K components, symmetric part positive semi-definite.
    """
    if "x_sec_prev" in options or "dt" in options:
        raise TypeError("section_damping: the damping replaces Eq. (3); x_sec_prev and dt are not accepted")
    x_sec = np.asarray(x_sec, dtype=float)
    n_sec, m, _ = x_sec.shape
    v_w = np.broadcast_to(np.asarray(v_wind, dtype=float), (n_sec, 3))
    du = np.concatenate((np.eye(3), -np.eye(3))) * h  # (6, 3): +h e_k, -h e_k
    wind = (v_w[None, :, :] - du[:, None, :]).reshape(6 * n_sec, 3)
    def rep(a):
        return np.broadcast_to(np.asarray(a, dtype=float), (6,) + np.shape(a)).reshape((6 * n_sec,) + np.shape(a)[1:])

    loads = section_loads(rep(x_sec), rep(np.broadcast_to(tube_d, (n_sec,))), rep(np.broadcast_to(width, (n_sec,))),
                          v_kite, omega, wind, rho, spanwise=rep(spanwise_directions(x_sec[:, 0])), **options)
    F = loads.nodal_forces.sum(axis=1).reshape(6, n_sec, 3)
    dF_du = (F[:3] - F[3:]) / (2.0 * h)  # (k, n_sec, l): dF_l / du_k
    C = -dF_du.transpose(1, 2, 0)  # C[i, l, k] = -dF_l / du_k
    sym = 0.5 * (C + C.transpose(0, 2, 1))
    lam, V = np.linalg.eigh(sym)
    sym_psd = np.einsum("nij,nj,nkj->nik", V, np.maximum(lam, 0.0), V)
    return sym_psd + 0.5 * (C - C.transpose(0, 2, 1))


def oswald_efficiency(aspect_ratio: float) -> float:
    """Span efficiency of a straight wing of aspect ratio ``AR`` (Raymer, *Aircraft Design: A Conceptual Approach*,
    Eq. 12.48): ``e = 1.78 (1 - 0.045 AR^0.68) - 0.64`` (0.95 at the rhino16's projected AR of about 3.5)."""
    return 1.78 * (1.0 - 0.045 * aspect_ratio**0.68) - 0.64


def projected_planform(x_sec: np.ndarray) -> tuple[float, float]:
    """Span ``b`` [m] and area ``S`` [m^2] of the wing projected on its x_k-y_k plane: ``b`` between the outermost
    nodes along y_k, ``S`` the sum of the projected section strips (chord along x_k times the y_k width of each
    strip). The aspect ratio is ``b^2 / S``."""
    x_sec = np.asarray(x_sec, dtype=float)
    y_le = x_sec[:, 0, 1]
    b = float(x_sec[:, :, 1].max() - x_sec[:, :, 1].min())
    chord_x = x_sec[:, :, 0].max(axis=1) - x_sec[:, :, 0].min(axis=1)
    edges = np.concatenate(([y_le[0]], 0.5 * (y_le[1:] + y_le[:-1]), [y_le[-1]]))
    return b, float(np.sum(chord_x * np.abs(np.diff(edges))))
