"""Compiled (numba) section loads: geometry, inflow, Breukels coefficients and nodal distribution in one loop.

:func:`section_loads_fields` computes the same quantities as the NumPy reference
:func:`kite_env.aero.loads.section_loads` (with :func:`kite_env.aero.sections.section_geometry`,
:func:`~kite_env.aero.sections.apparent_wind`, :func:`~kite_env.aero.sections.inflow`,
:func:`kite_env.aero.breukels.lei_coefficients` and :func:`kite_env.aero.loads.distribute`), term by term and with
the same branch thresholds, as one compiled loop over the sections. The results agree with NumPy to round-off
(``tests/aero/test_aero_kernels.py``: 1e-10 relative). The formulas and their derivations are documented in the
reference modules and not repeated here; comments name the reference quantity (and the paper's equation) that each
block computes. A few expressions are regrouped (the Breukels polynomial coefficients as quadratics in ``t`` instead
of a matrix product, dot products written out), which changes only round-off.

Why: the reference is vectorised over sections, but at the size of the kite (37 sections x 6 load points) a call
is ~100 NumPy operations on tiny arrays and costs ~1 ms, almost all call overhead; it is evaluated several times
per Newton iteration of the aeroelastic wing, and :func:`kite_env.aero.loads.load_jacobian` evaluates 18 stacked
copies of the wing in one call. The kernel does the arithmetic of one section in registers.

Cost, measured on the shared 2-core development container (best of repeats, perturbed rhino16 wing, with Eq. 3):
``section_loads`` 37 x 6 ~43 us (NumPy ~720 us), of which ~11 us in the compiled kernel and the rest Python
(allocations, array views, the two frozen dataclasses, ``resolve_backend``); the 18-fold stacked call of
``load_jacobian`` (666 sections) ~190 us (NumPy ~2.0 ms). The first process after a change of this file compiles
(a few seconds); later processes load the cache from ``__pycache__``.

:func:`section_normal_rate_forces` computes Theodorsen's normal-rate load of the wing with inertia
(``WingDynamics.normal_rate_force``) from the same section
frames (:func:`_section_axes`, shared with the loads' kernel) in one loop: the force costs about 12 us per call
(with the sections gathered from the nodes and scattered back) where the NumPy path (the full loads kernel for the
frames, the 3/4-chord weights, the force) took about 64 us at every Newton iterate, 9 % of the baseline flight's
step (docs/performance.md, "Theodorsen's force compiled").

Backend selection is done by :func:`kite_env.aero.loads.section_loads` (``backend="auto" | "numba" | "numpy"``,
resolved by :func:`kite_env.compiled.resolve_backend`: environment variable ``KITE_ENV_ELEMENT_BACKEND``,
else numba when importable). Without numba the kernel below runs as plain Python (correct, very slow).

Differences from the reference outside round-off: none for valid sections. A degenerate section (LE and TE node
coincident, or a spanwise direction parallel to the chord) gives ``nan``/``inf`` in both (NumPy with a warning; the
kernel has numba's NumPy error model, below).

Implementation rules (as :mod:`kite_env.compiled`): ``cache=True``, ``fastmath=False`` (IEEE semantics);
no array views inside the section loop and only scalars passed to helpers (views cost reference-count updates);
outputs written into arrays supplied by the caller. The thresholds and Breukels' constants are literals, not
imports, because numba's cache is keyed on this file only: the test checks they equal the reference values.
"""

from __future__ import annotations

import math

import numpy as np

from kite_env.aero.sections import SectionGeometry
from kite_env.compiled import JIT, njit

# JIT (kite_env.compiled) has numba's NumPy error model, as for the structure's and the dynamics' kernels: a section of
# zero chord (its nodes collapsed in a Newton iterate) gives non-finite loads as the NumPy reference does, which the
# solver reports as a non-finite residual (a failed step, made again in halves), instead of raising ZeroDivisionError
# out of the flight

# Thresholds of the reference implementation (literals: see the module docstring; checked by the tests).
_FLAT_FRACTION = 0.02  # sections._FLAT_FRACTION: e_y blends to the LE tangent below this mean offset / chord
_PLANE_COS_FULL = 0.8660254037844386  # sections._PLANE_COS_FULL / _NONE: and where the plane normal is 30-60 deg
_PLANE_COS_NONE = 0.5  # from the LE tangent
_TINY = 1e-300  # sections.section_geometry: floor of the offset length in the plane normal
_ALPHA_POLY_MAX_DEG = 20.0  # breukels.ALPHA_POLY_MAX_DEG
_ALPHA_FP_MIN_DEG = 30.0  # breukels.ALPHA_FP_MIN_DEG
_X_REF_DEFAULT = 0.25  # breukels.X_REF_OVER_C_DEFAULT (reference point of the regression CM)
_RAD2DEG = 180.0 / math.pi  # np.rad2deg
# negative-alpha branch: breukels.ALPHA_NEG_START_DEG, ALPHA_NEG_END_DEG, CL_NEG_SAT, ALPHA_NEG_ZL_DEG,
# ALPHA_NEG_WIDTH_DEG, CD_NEG_ADD, CM_NEG_ADD, ALPHA_NEG_CM_WIDTH_DEG
_ALPHA_NEG_START_DEG = 0.0
_ALPHA_NEG_END_DEG = -3.0
_CL_NEG_SAT = 0.6
_ALPHA_NEG_ZL_DEG = -1.0
_ALPHA_NEG_WIDTH_DEG = 6.5
_CD_NEG_ADD = 0.05
_CM_NEG_ADD = 0.09
_ALPHA_NEG_CM_WIDTH_DEG = 3.0

# Breukels' constants C20..C62 (breukels.py), grouped as the eight alpha-polynomial
# coefficients, each a + b kappa + c kappa^2 with a, b, c quadratics in t (rows of breukels._COEF):
#   coef = (A0 t^2 + A1 t + A2) + kappa (B0 t^2 + B1 t + B2) + kappa^2 (D0 t^2 + D1 t + D2)
# lambda5..8 (CL), CD_2, CD_0, CM_2, CM_0; zero entries of breukels._COEF are omitted below.
_C20, _C21, _C22 = -0.008011, -0.000336, 0.000992
_C23, _C24, _C25 = 0.013936, -0.003838, -0.000161
_C26, _C27, _C28 = 0.001243, -0.009288, -0.002124
_C29, _C30, _C31 = 0.012267, -0.002398, -0.000274
_C32, _C33, _C34 = 0.0, 0.0, 0.0
_C35, _C36, _C37 = -3.371000, 0.858039, 0.141600
_C38, _C39, _C40 = 7.201140, -0.676007, 0.806629
_C41, _C42, _C43 = 0.170454, -0.390563, 0.101966
_C44, _C45, _C46, _C47, _C48, _C49 = 0.546094, 0.022247, -0.071462, -0.006527, 0.002733, 0.000686
_C50, _C51, _C52, _C53, _C54 = 0.123685, 0.143755, 0.495159, -0.105362, 0.033468
_C55, _C56, _C57, _C58 = -0.284793, -0.026199, -0.024060, 0.000559
_C59, _C60, _C61, _C62 = -1.787703, 0.352443, -0.839323, 0.137932

#: The same table as ``breukels._COEF`` (8, 9), built from the literals above; only for the consistency test.
COEF = np.array(
    [
        [_C23, _C24, _C25, _C20, _C21, _C22, 0.0, 0.0, 0.0],
        [_C29, _C30, _C31, _C26, _C27, _C28, 0.0, 0.0, 0.0],
        [_C35, _C36, _C37, _C32, _C33, _C34, 0.0, 0.0, 0.0],
        [_C41, _C42, _C43, _C38, _C39, _C40, 0.0, 0.0, 0.0],
        [0.0, _C48, _C49, 0.0, _C46, _C47, 0.0, _C44, _C45],
        [_C52, _C53, _C54, 0.0, _C50, _C51, 0.0, 0.0, 0.0],
        [0.0, _C57, _C58, 0.0, _C55, _C56, 0.0, 0.0, 0.0],
        [0.0, _C61, _C62, 0.0, _C59, _C60, 0.0, 0.0, 0.0],
    ]
)


@njit(**JIT)
def _lei_coefficients(alpha, t, kappa, x_ref, cm_ref=0.25, neg=1):
    """``breukels.lei_coefficients`` of one section: (CL, CD, CM) for alpha [rad], t, kappa, x_ref / c, the
    point cm_ref / c the regression CM is taken about and ``neg`` (1: ``negative_alpha="bounded"``, 0: "breukels")."""
    t2 = t * t
    k2 = kappa * kappa
    # poly_coefficients: lambda5..8, CD_2, CD_0, CM_2, CM_0 (alpha in degrees)
    l5 = (_C23 * t2 + _C24 * t + _C25) + kappa * (_C20 * t2 + _C21 * t + _C22)
    l6 = (_C29 * t2 + _C30 * t + _C31) + kappa * (_C26 * t2 + _C27 * t + _C28)
    l7 = (_C35 * t2 + _C36 * t + _C37) + kappa * (_C32 * t2 + _C33 * t + _C34)
    l8 = (_C41 * t2 + _C42 * t + _C43) + kappa * (_C38 * t2 + _C39 * t + _C40)
    cd2 = (_C48 * t + _C49) + kappa * (_C46 * t + _C47) + k2 * (_C44 * t + _C45)
    cd0 = (_C52 * t2 + _C53 * t + _C54) + kappa * (_C50 * t + _C51)
    cm2 = (_C57 * t + _C58) + kappa * (_C55 * t + _C56)
    cm0 = (_C61 * t + _C62) + kappa * (_C59 * t + _C60)
    a = alpha * _RAD2DEG
    # regression inside +-20 deg, its tangent line at the switch beyond (P_ext)
    ac = min(max(a, -_ALPHA_POLY_MAX_DEG), _ALPHA_POLY_MAX_DEG)
    da = a - ac
    cl = ((l5 * ac + l6) * ac + l7) * ac + l8 + ((3.0 * l5 * ac + 2.0 * l6) * ac + l7) * da
    cd = cd2 * ac * ac + cd0 + 2.0 * cd2 * ac * da
    cm = cm2 * ac * ac + cm0 + 2.0 * cm2 * ac * da
    if neg != 0:
        # blend (smoothstep) below 0 deg into the bounded negative-alpha law
        u = (_ALPHA_NEG_START_DEG - a) / (_ALPHA_NEG_START_DEG - _ALPHA_NEG_END_DEG)
        u = min(max(u, 0.0), 1.0)
        w = u * u * (3.0 - 2.0 * u)
        if w > 0.0:
            cl = cl + w * (_CL_NEG_SAT * math.tanh((a - _ALPHA_NEG_ZL_DEG) / _ALPHA_NEG_WIDTH_DEG) - cl)
            cd = cd + w * (_CD_NEG_ADD * math.tanh((_ALPHA_NEG_START_DEG - a) / _ALPHA_NEG_WIDTH_DEG))
            cm = cm + w * (cm0 + _CM_NEG_ADD * math.tanh((_ALPHA_NEG_START_DEG - a) / _ALPHA_NEG_CM_WIDTH_DEG) - cm)
    if x_ref != cm_ref:
        # regression CM is about cm_ref: transfer with C_N = CL cos a + CD sin a
        cm = cm + (x_ref - cm_ref) * (cl * math.cos(alpha) + cd * math.sin(alpha))
    # C1 blend (smoothstep) to the sign-correct flat-plate law over 20..30 deg
    u = (abs(a) - _ALPHA_POLY_MAX_DEG) / (_ALPHA_FP_MIN_DEG - _ALPHA_POLY_MAX_DEG)
    u = min(max(u, 0.0), 1.0)
    s = u * u * (3.0 - 2.0 * u)
    if s > 0.0:
        sn = math.sin(alpha)
        cn = 2.0 * sn * abs(sn)  # flat-plate normal-force coefficient, acting at mid-chord
        cl = cl + s * (cn * math.cos(alpha) - cl)
        cd = cd + s * (abs(cn * sn) - cd)
        cm = cm + s * (-cn * (0.5 - x_ref) - cm)
    return cl, cd, cm


@njit(**JIT)
def _section_axes(x, i, n, m, flip, span, has_span):
    """Section ``i``'s frame as ``section_geometry`` builds it: ``(r0, r1, r2, chord_nodes, e_x, e_y, e_z)`` (the LE
    node, the LE-TE node distance [m] and the axes' nine components, flattened), from the section nodes ``x`` (n, m,
    3); ``span``/``has_span``/``flip`` as in :func:`section_loads_kernel`."""
    r0, r1, r2 = x[i, 0, 0], x[i, 0, 1], x[i, 0, 2]
    c0, c1, c2 = x[i, m - 1, 0] - r0, x[i, m - 1, 1] - r1, x[i, m - 1, 2] - r2
    chord_nodes = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    p = 1.0 / chord_nodes
    ex0, ex1, ex2 = c0 * p, c1 * p, c2 * p
    if has_span:
        t0, t1, t2 = span[i, 0], span[i, 1], span[i, 2]
    elif n == 1:
        t0, t1, t2 = 0.0, 1.0, 0.0
    else:  # spanwise_directions: central differences of the LE nodes, one-sided at the ends
        lo = i - 1 if i > 0 else 0
        hi = i + 1 if i < n - 1 else n - 1
        t0, t1, t2 = x[hi, 0, 0] - x[lo, 0, 0], x[hi, 0, 1] - x[lo, 0, 1], x[hi, 0, 2] - x[lo, 0, 2]
        if flip:
            t0, t1, t2 = -t0, -t1, -t2
    p = t0 * ex0 + t1 * ex1 + t2 * ex2  # orthogonalised against the chord, normalised
    t0, t1, t2 = t0 - p * ex0, t1 - p * ex1, t2 - p * ex2
    p = 1.0 / math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    t0, t1, t2 = t0 * p, t1 * p, t2 * p
    # mean offset h of the nodes from the LE node, minus its chord component
    inv_m = 1.0 / m
    h0 = 0.0
    h1 = 0.0
    h2 = 0.0
    for j in range(m):
        h0 += x[i, j, 0] - r0
        h1 += x[i, j, 1] - r1
        h2 += x[i, j, 2] - r2
    h0, h1, h2 = h0 * inv_m, h1 * inv_m, h2 * inv_m
    p = h0 * ex0 + h1 * ex1 + h2 * ex2
    h0, h1, h2 = h0 - p * ex0, h1 - p * ex1, h2 - p * ex2
    h_len = math.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
    # airfoil-plane normal h × e_x, oriented like the LE line
    p = 1.0 / max(h_len, _TINY)
    n0, n1, n2 = (h1 * ex2 - h2 * ex1) * p, (h2 * ex0 - h0 * ex2) * p, (h0 * ex1 - h1 * ex0) * p
    cos_pl = n0 * t0 + n1 * t1 + n2 * t2
    if cos_pl < 0.0:
        n0, n1, n2 = -n0, -n1, -n2
    # smoothstep blend to the LE tangent for nearly flat sections and planes far from the section's
    u = min(max(h_len / (_FLAT_FRACTION * chord_nodes), 0.0), 1.0)
    v = min(max((abs(cos_pl) - _PLANE_COS_NONE) / (_PLANE_COS_FULL - _PLANE_COS_NONE), 0.0), 1.0)
    wgt = u * u * (3.0 - 2.0 * u) * v * v * (3.0 - 2.0 * v)
    ey0, ey1, ey2 = wgt * n0 + (1.0 - wgt) * t0, wgt * n1 + (1.0 - wgt) * t1, wgt * n2 + (1.0 - wgt) * t2
    p = ey0 * ex0 + ey1 * ex1 + ey2 * ex2
    ey0, ey1, ey2 = ey0 - p * ex0, ey1 - p * ex1, ey2 - p * ex2
    p = 1.0 / math.sqrt(ey0 * ey0 + ey1 * ey1 + ey2 * ey2)
    ey0, ey1, ey2 = ey0 * p, ey1 * p, ey2 * p
    ez0, ez1, ez2 = ex1 * ey2 - ex2 * ey1, ex2 * ey0 - ex0 * ey2, ex0 * ey1 - ex1 * ey0  # e_z = e_x × e_y
    return r0, r1, r2, chord_nodes, ex0, ex1, ex2, ey0, ey1, ey2, ez0, ez1, ez2


@njit(**JIT)
def section_loads_kernel(x, x_prev, has_prev, dt, tube_d, width, v_kite, omega, v_wind, rho, x_ref, c_pow, span,
                         has_span, scal, vec, node, zeta, axes, luff=0.0, cm_ref=0.25, rot_x=-1.0, neg=1):
    """Section loads of all sections (Eq. 2-9) written into the output arrays.

    Parameters
    ----------
    x : (n_sec, m, 3) float [m]
        Section node positions in K, LE node (j = 0) to TE node (j = m-1), sections in spanwise order.
    x_prev : (n_sec, m, 3) float [m]
        Node positions at the previous time step (Eq. 3); read only when ``has_prev``.
    has_prev : bool
        Add the deformation velocity of Eq. (3).
    dt : float [s]
        Time step of Eq. (3) (used only with ``has_prev``).
    tube_d, width : (n_sec,) float [m]
        LE tube diameter and strip width.
    v_kite, omega : (3,) float [m/s], [rad/s]
        Velocity and angular velocity of frame K.
    v_wind : (n_w, 3) float [m/s]
        Wind velocity; ``n_w = 1`` (uniform) or ``n_sec``.
    rho : float [kg/m^3]
        Air density.
    x_ref : float [-]
        Moment reference point / chord, from the airfoil leading edge.
    span : (n_sec, 3) float [m]
        Spanwise LE-line directions; read only when ``has_span``, else computed from the LE nodes as
        ``sections.spanwise_directions`` does.
    has_span : bool
    luff : float
        Luffing band (0: off): below this CL the share ``1 - smoothstep(CL/luff)`` of the section load moves to the
        LE and TE nodes (``loads.distribute`` with ``canopy_share``).
    cm_ref : float [-]
        Point / chord (from the leading edge) the regression CM is taken about (``breukels.lei_coefficients``).
    rot_x : float [-]
        Point / chord (from the airfoil nose) where the frame rotation ``omega x r`` of Eq. (2) is taken; negative:
        the LE node (the paper), ``sections.apparent_wind``.
    neg : int
        Negative-alpha branch of the coefficients: 1 bounded (measured data), 0 Breukels' regression as is.

    Outputs (written)
    -----------------
    scal : (10, n_sec) float
        Rows alpha [rad], CL, CD, CM [-], moment [N m], s_ref [m], q_dyn [Pa], chord [m], t [-], kappa [-].
    vec : (3, n_sec, 3) float
        Rows lift_local [N], drag_local [N] (section components), v_app [m/s] (K components).
    node : (2, n_sec, m, 3) float
        Rows nodal forces [N] (K components), local node coordinates (s, y, z) [m] from the LE node.
    zeta : (n_sec, m) float [-]
        Node heights above the chord line over the chord.
    axes : (n_sec, 3, 3) float [-]
        Rows e_x, e_y, e_z of each section frame (``frames = axes.transpose(0, 2, 1)``).
    """
    n = x.shape[0]
    m = x.shape[1]
    nw = v_wind.shape[0]
    inv_m = 1.0 / m
    flip = n > 1 and x[0, 0, 1] > x[n - 1, 0, 1]  # spanwise_directions: right tip first -> reverse the differences
    om0, om1, om2 = omega[0], omega[1], omega[2]
    vk0, vk1, vk2 = v_kite[0], v_kite[1], v_kite[2]
    half_rho = 0.5 * rho
    inv_2dt = 1.0 / (2.0 * dt) if has_prev else 0.0
    for i in range(n):
        # ---------------------------------------------------------------- section frame (section_geometry)
        r0, r1, r2, chord_nodes, ex0, ex1, ex2, ey0, ey1, ey2, ez0, ez1, ez2 = _section_axes(
            x, i, n, m, flip, span, has_span)
        axes[i, 0, 0], axes[i, 0, 1], axes[i, 0, 2] = ex0, ex1, ex2
        axes[i, 1, 0], axes[i, 1, 1], axes[i, 1, 2] = ey0, ey1, ey2
        axes[i, 2, 0], axes[i, 2, 1], axes[i, 2, 2] = ez0, ez1, ez2
        d = tube_d[i]
        c = chord_nodes + 0.5 * d  # Eq. (4)
        inv_c = 1.0 / c
        # local node coordinates, zeta, camber (Eq. 6) and their chordwise means (for distribute)
        kappa = -math.inf
        ms = 0.0
        mz = 0.0
        for j in range(m):
            d0, d1, d2 = x[i, j, 0] - r0, x[i, j, 1] - r1, x[i, j, 2] - r2
            ls = d0 * ex0 + d1 * ex1 + d2 * ex2
            lz = d0 * ez0 + d1 * ez1 + d2 * ez2
            node[1, i, j, 0] = ls
            node[1, i, j, 1] = d0 * ey0 + d1 * ey1 + d2 * ey2
            node[1, i, j, 2] = lz
            zj = lz * inv_c
            zeta[i, j] = zj
            kappa = max(kappa, zj)  # Eq. (6)
            ms += ls
            mz += lz
        ms *= inv_m
        mz *= inv_m
        # ---------------------------------------------------------------- apparent wind, Eq. (2)-(3)
        iw = i if nw > 1 else 0
        p0, p1, p2 = r0, r1, r2  # point of the rotation term: the LE node, or rot_x c from the nose along e_x
        if rot_x >= 0.0:
            sp = rot_x * c - 0.5 * d
            p0, p1, p2 = r0 + sp * ex0, r1 + sp * ex1, r2 + sp * ex2
        va0 = (om1 * p2 - om2 * p1) + (vk0 - v_wind[iw, 0])
        va1 = (om2 * p0 - om0 * p2) + (vk1 - v_wind[iw, 1])
        va2 = (om0 * p1 - om1 * p0) + (vk2 - v_wind[iw, 2])
        if has_prev:  # Eq. (3): mean of the LE and TE node finite-difference velocities
            va0 += ((x[i, m - 1, 0] - x_prev[i, m - 1, 0]) + (r0 - x_prev[i, 0, 0])) * inv_2dt
            va1 += ((x[i, m - 1, 1] - x_prev[i, m - 1, 1]) + (r1 - x_prev[i, 0, 1])) * inv_2dt
            va2 += ((x[i, m - 1, 2] - x_prev[i, m - 1, 2]) + (r2 - x_prev[i, 0, 2])) * inv_2dt
        vec[2, i, 0], vec[2, i, 1], vec[2, i, 2] = va0, va1, va2
        # ---------------------------------------------------------------- inflow: u = -v_a projected on the plane
        ux = -(va0 * ex0 + va1 * ex1 + va2 * ex2)
        uz = -(va0 * ez0 + va1 * ez1 + va2 * ez2)
        alpha = math.atan2(uz, ux)
        speed2 = ux * ux + uz * uz
        t_c = d * inv_c  # Eq. (5)
        cl, cd, cm = _lei_coefficients(alpha, t_c, kappa, x_ref, cm_ref, neg)
        # ---------------------------------------------------------------- section loads, Eq. (7)-(9)
        hcw = half_rho * c * width[i]
        k = hcw * math.sqrt(speed2)
        kd = k * cd
        kl = k * cl
        dr0, dr2 = kd * ux, kd * uz  # Eq. (8), along e_D = u_xz / V
        li0, li2 = -kl * uz, kl * ux  # Eq. (7), along e_L = e_D × e_y
        moment = hcw * speed2 * c ** (c_pow - 1.0) * cm  # Eq. (9), c^c_pow in all (loads module docstring)
        s_ref = x_ref * c - 0.5 * d
        vec[0, i, 0], vec[0, i, 1], vec[0, i, 2] = li0, 0.0, li2
        vec[1, i, 0], vec[1, i, 1], vec[1, i, 2] = dr0, 0.0, dr2
        scal[0, i] = alpha
        scal[1, i] = cl
        scal[2, i] = cd
        scal[3, i] = cm
        scal[4, i] = moment
        scal[5, i] = s_ref
        scal[6, i] = half_rho * speed2
        scal[7, i] = c
        scal[8, i] = t_c
        scal[9, i] = kappa
        # ---------------------------------------------------------------- distribute (minimum-norm couple)
        f0 = li0 + dr0
        f2 = li2 + dr2
        den = 0.0
        for j in range(m):
            gs = node[1, i, j, 0] - ms
            gz = node[1, i, j, 2] - mz
            den += gz * gz + gs * gs
        mu = (moment - (mz * f0 - (ms - s_ref) * f2)) / den
        fm0 = f0 * inv_m
        fm2 = f2 * inv_m
        wl = 1.0
        mu2 = ms2 = mz2 = 0.0
        if luff > 0.0:
            wl = min(max(cl / luff, 0.0), 1.0)
            wl = wl * wl * (3.0 - 2.0 * wl)  # smoothstep (loads.section_loads)
            # the same minimum-norm law on the LE and TE nodes only
            e_s0, e_z0 = node[1, i, 0, 0], node[1, i, 0, 2]
            e_s1, e_z1 = node[1, i, m - 1, 0], node[1, i, m - 1, 2]
            ms2, mz2 = 0.5 * (e_s0 + e_s1), 0.5 * (e_z0 + e_z1)
            den2 = (e_z0 - mz2) ** 2 + (e_s0 - ms2) ** 2 + (e_z1 - mz2) ** 2 + (e_s1 - ms2) ** 2
            mu2 = (moment - (mz2 * f0 - (ms2 - s_ref) * f2)) / den2
        for j in range(m):
            fs = fm0 + mu * (node[1, i, j, 2] - mz)
            fz = fm2 - mu * (node[1, i, j, 0] - ms)
            if wl < 1.0:
                fs *= wl
                fz *= wl
                if j == 0 or j == m - 1:
                    fs += (1.0 - wl) * (0.5 * f0 + mu2 * (node[1, i, j, 2] - mz2))
                    fz += (1.0 - wl) * (0.5 * f2 - mu2 * (node[1, i, j, 0] - ms2))
            node[0, i, j, 0] = fs * ex0 + fz * ez0
            node[0, i, j, 1] = fs * ex1 + fz * ez1
            node[0, i, j, 2] = fs * ex2 + fz * ez2


@njit(**JIT)
def section_normal_rate_kernel(x, v, n_start, m_a, dt, tube_d, v_wind, span, has_span, out):
    """Theodorsen's normal-rate load of every section on its nodes, written into ``out`` (n_sec, m, 3) [N]: the
    force ``F = -m_a (n' . v_rel) n`` with the section normal ``n`` (``section_geometry``'s ``e_z``) at ``x``, its rate
    ``n' = (n - n_start) / dt`` over the step, and the air-relative velocity ``v_rel`` of the section's 3/4-chord
    point, placed at that point by the least-squares weights ``W_j`` of the chordwise velocity field (``f_j = W_j F``);
    the reference is ``WingDynamics._normal_rate_section_forces`` with ``section_weights(.., "three_quarter_chord")``.
    ``x``, ``v`` (n_sec, m, 3) [m], [m/s]; ``n_start`` (n_sec, 3); ``m_a`` (n_sec,) [kg]; ``tube_d`` (n_sec,) [m];
    ``v_wind`` (1, 3) [m/s]; ``span``/``has_span`` as in :func:`section_loads_kernel`."""
    n = x.shape[0]
    m = x.shape[1]
    flip = n > 1 and x[0, 0, 1] > x[n - 1, 0, 1]
    inv_dt = 1.0 / dt
    inv_m = 1.0 / m
    for i in range(n):
        r0, r1, r2, cn, ex0, ex1, ex2, _, _, _, ez0, ez1, ez2 = _section_axes(x, i, n, m, flip, span, has_span)
        # section_weights: the chordwise coordinates s_j along the LE-TE line (held in out[i, j, 0] until the force
        # overwrites them), their deviations ds_j from the mean, the fit's slope g to the 3/4-chord point
        s_mean = 0.0
        for j in range(m):
            sj = (x[i, j, 0] - r0) * ex0 + (x[i, j, 1] - r1) * ex1 + (x[i, j, 2] - r2) * ex2
            out[i, j, 0] = sj
            s_mean += sj
        s_mean *= inv_m
        ss = 0.0
        v0 = v1 = v2 = 0.0  # sum_j v_j
        u0 = u1 = u2 = 0.0  # sum_j ds_j v_j
        for j in range(m):
            ds = out[i, j, 0] - s_mean
            out[i, j, 0] = ds
            ss += ds * ds
            v0, v1, v2 = v0 + v[i, j, 0], v1 + v[i, j, 1], v2 + v[i, j, 2]
            u0, u1, u2 = u0 + ds * v[i, j, 0], u1 + ds * v[i, j, 1], u2 + ds * v[i, j, 2]
        d = tube_d[i]
        g = ((0.75 * (cn + 0.5 * d) - 0.5 * d) - s_mean) / ss
        # the 3/4-chord point's air-relative velocity sum_j W_j v_j - v_wind (W_j = 1/m + ds_j g)
        w0 = inv_m * v0 + g * u0 - v_wind[0, 0]
        w1 = inv_m * v1 + g * u1 - v_wind[0, 1]
        w2 = inv_m * v2 + g * u2 - v_wind[0, 2]
        f = -m_a[i] * (((ez0 - n_start[i, 0]) * w0 + (ez1 - n_start[i, 1]) * w1 + (ez2 - n_start[i, 2]) * w2) * inv_dt)
        f0, f1, f2 = f * ez0, f * ez1, f * ez2
        for j in range(m):
            wj = inv_m + out[i, j, 0] * g
            out[i, j, 0] = wj * f0
            out[i, j, 1] = wj * f1
            out[i, j, 2] = wj * f2


def section_normal_rate_forces(x_sec, v_sec, n_start, m_a, dt, tube_d, v_wind, spanwise=None):
    """The compiled :func:`section_normal_rate_kernel`: forces (n_sec, m, 3) [N] on the nodes of sections ``x_sec``
    moving with ``v_sec`` (n_sec, m, 3), normals ``n_start`` (n_sec, 3) at the step's start, added masses ``m_a``
    (n_sec,) [kg], step ``dt`` [s], LE tube diameters ``tube_d`` (n_sec,) [m], uniform wind ``v_wind`` (3,) [m/s];
    ``spanwise`` (n_sec, 3) held LE-line tangents (default: from the LE nodes)."""
    x = np.ascontiguousarray(x_sec, dtype=float)
    n, m, _ = x.shape
    has_span = spanwise is not None
    v_w = np.ascontiguousarray(v_wind, dtype=float).reshape(1, 3)
    span = np.ascontiguousarray(spanwise, dtype=float) if has_span else v_w
    if has_span and span.shape != (n, 3):
        raise ValueError("section_normal_rate_forces: spanwise must be (n_sec, 3)")
    out = np.empty((n, m, 3))
    section_normal_rate_kernel(x, np.ascontiguousarray(v_sec, dtype=float), np.ascontiguousarray(n_start, dtype=float),
                               np.ascontiguousarray(m_a, dtype=float), float(dt),
                               np.ascontiguousarray(tube_d, dtype=float), v_w, span, has_span, out)
    return out


def section_loads_fields(x_sec, tube_d, width, v_kite, omega, v_wind, rho, x_sec_prev=None, dt=None,
                         x_ref_over_c=0.25, spanwise=None, moment_chord_power=2.0, luffing_cl=0.0,
                         cm_ref_over_c=0.25, rotation_point_over_c=None, negative_alpha="bounded"):
    """Fields of :class:`kite_env.aero.loads.SectionLoads` from the compiled kernel (same arguments as
    :func:`kite_env.aero.loads.section_loads`, Eq. 2-9).

    Parameters
    ----------
    x_sec : (n_sec, m, 3) float [m]
    tube_d, width : (n_sec,) float [m] (or broadcastable to it)
    v_kite, omega : (3,) float [m/s], [rad/s]
    v_wind : (3,) or (n_sec, 3) float [m/s]
    rho : float [kg/m^3]
    x_sec_prev : (n_sec, m, 3) float [m], optional
    dt : float [s], optional
    x_ref_over_c : float [-]
    spanwise : (n_sec, 3) float, optional
    moment_chord_power, luffing_cl, cm_ref_over_c : float
    rotation_point_over_c : float or None
    negative_alpha : {"bounded", "breukels"}

    Returns
    -------
    tuple
        ``(nodal_forces, alpha, CL, CD, CM, lift_local, drag_local, moment, s_ref, v_app, q_dyn, geometry,
        positions)`` in the field order of ``SectionLoads``.
    """
    x_sec = np.asarray(x_sec, dtype=float)
    x = np.ascontiguousarray(x_sec)
    n, m, _ = x.shape
    d = np.asarray(tube_d, dtype=float)
    if d.shape != (n,):
        d = np.broadcast_to(d, (n,)).copy()
    w = np.asarray(width, dtype=float)
    if w.shape != (n,):
        w = np.broadcast_to(w, (n,)).copy()
    v_w = np.asarray(v_wind, dtype=float)
    v_w = v_w.reshape(1, 3) if v_w.ndim == 1 else np.ascontiguousarray(v_w)
    has_prev = x_sec_prev is not None and bool(dt)
    prev = np.ascontiguousarray(x_sec_prev, dtype=float) if has_prev else x
    has_span = spanwise is not None
    span = np.ascontiguousarray(spanwise, dtype=float) if has_span else v_w
    # the kernel does not check bounds: shapes the reference would reject by broadcasting are rejected here
    if x.ndim != 3 or x.shape[2] != 3 or v_w.shape[1:] != (3,) or v_w.shape[0] not in (1, n) or (
            has_prev and prev.shape != x.shape) or (has_span and span.shape != (n, 3)):
        raise ValueError("section_loads: inconsistent shapes of x_sec, v_wind, x_sec_prev or spanwise")
    scal = np.empty((10, n))
    vec = np.empty((3, n, 3))
    node = np.empty((2, n, m, 3))
    zeta = np.empty((n, m))
    axes = np.empty((n, 3, 3))
    section_loads_kernel(x, prev, has_prev, float(dt) if has_prev else 0.0, np.ascontiguousarray(d),
                         np.ascontiguousarray(w), np.ascontiguousarray(v_kite, dtype=float),
                         np.ascontiguousarray(omega, dtype=float), v_w, float(rho), float(x_ref_over_c),
                         float(moment_chord_power), span,
                         has_span, scal, vec, node, zeta, axes, float(luffing_cl), float(cm_ref_over_c),
                         -1.0 if rotation_point_over_c is None else float(rotation_point_over_c),
                         1 if negative_alpha == "bounded" else 0)
    alpha, cl, cd, cm, moment, s_ref, q_dyn, chord, t, kappa = scal
    lift, drag, v_app = vec
    nodal, local = node
    geom = SectionGeometry(frames=axes.transpose(0, 2, 1), chord=chord, t=t, kappa=kappa, r_le=x_sec[:, 0],
                           zeta=zeta, tube_d=d, local=local)
    return nodal, alpha, cl, cd, cm, lift, drag, moment, s_ref, v_app, q_dyn, geom, x_sec
