"""Breukels' LEI airfoil regression CL, CD, CM(alpha, t, kappa) with a smooth post-stall continuation.

The paper (Sect. II.B, text after Eq. 9) describes the section coefficients as correlations of camber ``kappa``,
thickness ``t`` and angle of attack ``alpha``, fitted to 2-D RANS results and "valid for -20 deg < alpha < 20 deg";
outside that range "CL and CD are described by the empirical functions proposed in [35]". The correlation is
Breukels' (2011) regression. Its structure and constants C20..C62 are transcribed from
three open TU Delft codes that agree: [S1] awegroup/Vortex-Step-Method ``AirfoilAerodynamics``, [S2]
OpenSourceAWE/VortexStepMethod.jl ``src/panel.jl``, [S3] a ``LEI_airf_coeff`` thesis helper. The polynomials take
alpha in **degrees**; this module takes radians and converts internally.

Post-stall (|alpha| > 20 deg). The open codes switch hard to the Newtonian flat-plate law ``CL = 2 cos a sin^2 a``,
``CD = 2 sin^3 a`` (the open TU Delft codes' stall law), which is discontinuous at 20 deg (CL 1.17 -> 0.22) and has the
wrong sign
for alpha < -20 deg. Here the sign-correct flat-plate law (normal-force coefficient ``C_N = 2 sin a |sin a|``)

    CL_fp = 2 cos(a) sin(a) |sin(a)|,   CD_fp = 2 |sin(a)|^3,   CM_fp = -C_N (0.5 - x_ref/c)

is reached through a C1 transition band ``ALPHA_POLY_MAX_DEG = 20 <= |alpha| <= ALPHA_FP_MIN_DEG = 30`` deg::

    C(a) = (1 - s) P_ext(a) + s C_fp(a),   s = 3 u^2 - 2 u^3,   u = (|a| - 20 deg) / (30 deg - 20 deg)

``P_ext`` is the regression polynomial for |a| <= 20 deg and its tangent line at +-20 deg beyond (value and slope of
the polynomial at the switch). Because s(0) = s'(0) = 0 and s(1) = 1, s'(1) = 0, each coefficient is C1 in alpha
at +-20 deg and at +-30 deg, equals the regression inside +-20 deg and the flat-plate law beyond +-30 deg. The
tangent line (not the polynomial itself) is continued into the band because the cubic CL polynomial turns steeply
negative beyond 20 deg (CL_poly(25 deg) = -0.47 for t = 0.1, kappa = 0.095) and would flip the sign of lift there.
CD and CM polynomials are even in alpha and so is their continuation; CL_fp is odd.

Pitching moment. The regression CM grows like -0.007 alpha_deg^2 (-2.75 at 20 deg for t = 0.1, kappa = 0.095),
and the open codes keep the polynomial beyond 20 deg. Here CM is blended like CL, CD to the flat-plate moment of a
plate whose normal force acts at mid-chord, taken about the moment reference point ``x_ref`` (measured from the
airfoil leading edge = front of the LE tube): ``CM_fp = -C_N (0.5 - x_ref/c)``; positive CM is nose-up.

Moment reference point. Breukels' thesis text was not reachable. The open code that carries this
regression states that its CM column is the "pitching moment coefficient (dimensionless, about quarter-chord)"
(awegroup/Vortex-Step-Method, docs/AirfoilAerodynamics.md, "Data Format Standards", commit 46fd9f83), and
OpenSourceAWE/VortexStepMethod.jl issue #17 moves the regression CM with ``M_x = M_quarter + L (x - 0.25)``. We
therefore take the quarter chord (``X_REF_OVER_C_DEFAULT = 0.25``) and expose the point as ``x_ref_over_c`` in
:mod:`kite_env.aero.loads`. That is the convention of those codes, not a confirmed statement of Breukels, so the
point the regression CM itself is taken about is a separate parameter ``cm_ref_over_c`` (default the quarter chord,
``CM_REGRESSION_REF_DEFAULT``; config key ``aero.cm_regression_ref_over_c``), for sensitivity studies (e.g. 0 =
about the airfoil nose). The regression moment is transferred from that point to the output reference point,
``CM_x = CM_reg + (x_ref/c - cm_ref/c) C_N`` with ``C_N = CL cos a + CD sin a`` (normal force along e_z, a force aft
of the reference point is nose-down), before the blend; the flat-plate moment is already about ``x_ref``. The
section's line of action, hence the nodal loads, then do not depend on the chosen reference point.

Negative angle of attack (``negative_alpha="bounded"``, the default). Fitted to lifting sections, the regression
gives CL = -0.80 at -5 deg and -1.54 at -10 deg (t = 0.1, kappa = 0.095) and an even, nose-down CM (-0.63 at -10
deg). Data for the TU Delft V3 LEI kite:

* 2-D CFD section polars, OpenSourceAWE/V3Kite.jl ``data/2D_polars_CFD_NF_combined/<i>.csv`` (columns alpha [deg],
  Cl, Cd, Cm; commit d8c4376d), median over the inboard profiles i = 1..16 (17-19: tip): at alpha = 0, -2, -3, -4,
  -5, -6, -8, -10 deg Cl = 0.181, -0.058, -0.165, -0.270, -0.348, -0.362, -0.434, -0.553 (profile 10: -0.31 at -5,
  -0.52 at -10 deg; profiles 1..16 range -0.63..-0.25 at -5 deg), Cd = 0.039, 0.053, 0.059, 0.072, 0.081, 0.091,
  0.107, 0.123, and Cm - Cm(0) = 0, +0.045, +0.063, +0.080, +0.090, then +0.090 (the files hold Cm constant below
  about -6 deg; quarter chord, the polar format's convention).
* Rigid 3-D wind-tunnel model, Re 5e5, awegroup/TUDELFT_V3_KITE
  ``data/aerodynamic/3D/WindTunnel_Re5e5_alpha_sweep_beta_0_Poland2025.csv`` (columns alpha, CL, CD; commit
  e021aa9): CL = -0.001, -0.214, -0.280 and CD = 0.049, 0.069, 0.098 at alpha = -2.0, -6.1, -11.6 deg (its CMy is a
  whole-wing moment about the model's reference point, not used).

The law follows the 2-D CFD, a section coefficient like the regression (itself fitted to 2-D RANS); the wind-tunnel
values are whole-wing coefficients with the finite-span loss (lift slope 0.09/deg, 2-D CFD 0.16/deg, regression
0.19/deg), which the strips of this model would otherwise get at negative alpha only. Wind tunnel / law is 0.55 and
0.50 at -6.1 and -11.6 deg, as at +5.4 deg (0.55). Beyond -10 deg the rigid CFD section keeps losing lift (-0.82 at
-15 deg); a membrane canopy cannot hold a reversed pressure difference (LE tube plus luffing canopy), so the law
saturates. With ``a`` in degrees and the regression with its tangent-line continuation ``CL_P, CD_P, CM_P``::

    w  = s((A_S - a) / (A_S - A_E))      smoothstep s, A_S = ALPHA_NEG_START_DEG = 0, A_E = ALPHA_NEG_END_DEG = -3
    CL = (1 - w) CL_P + w CL_NEG_SAT tanh((a - A_Z) / W)                 CL_NEG_SAT = 0.6, A_Z = -1 deg, W = 6.5 deg
    CD = CD_P + w CD_NEG_ADD tanh((A_S - a) / W)                         CD_NEG_ADD = 0.05
    CM = (1 - w) CM_P + w (CM_P(0) + CM_NEG_ADD tanh((A_S - a) / W_M))   CM_NEG_ADD = 0.09, W_M = 3 deg

(``A_Z`` ALPHA_NEG_ZL_DEG, ``W`` ALPHA_NEG_WIDTH_DEG, ``W_M`` ALPHA_NEG_CM_WIDTH_DEG), then the moment transfer and
the flat-plate blend above. A fixed start at 0 deg keeps alpha >= 0 bit for bit, lies just above the regression's
zero-lift angle (-0.2..-1.1 deg for kappa = 0..0.15) and needs no root of the cubic in the kernel; the data's
zero-lift angle (-1.5 deg CFD, -2 deg wind tunnel) is not reproduced (-0.7 deg here). The CL law is one curve
without t or kappa: the regression's dependence is an extrapolation there and one kite's profiles cannot support a
fitted one. The CD and CM increments ride on the regression's own (t, kappa)-dependent values. For t = 0.1, kappa
= 0.08: CL = -0.26, -0.33, -0.53, CD = 0.074, 0.082, 0.122 at -4, -5, -10 deg (CL within 0.05 of the CFD median from
-4 to -10 deg, CD within 0.007 from -2 to -10 deg), CL = -0.60 at -20 deg. w is C1 at 0 and -3 deg, so the
coefficients stay C1 over the whole range; CL is non-decreasing in alpha on [-20, 0] deg for 0.04 <= t <= 0.25,
0 <= kappa <= 0.16 (tested; the regression turns at -13..-18 deg), and returns from -0.60 at -20 deg to the flat
plate's -0.43 at -30 deg. ``negative_alpha="breukels"`` keeps the regression (the open codes' behaviour).

Cost: one small matrix product for the 8 polynomial coefficients plus ~40 element-wise array operations; no
derivatives are formed (the structural solver keeps the aerodynamic loads fixed inside its Newton loop, Sect. II.A).
"""

from __future__ import annotations

import numpy as np

#: Upper end of the regression's validity range [deg] (paper, text after Eq. 9; the open VSM codes switch there too).
ALPHA_POLY_MAX_DEG = 20.0
#: |alpha| [deg] from which the pure flat-plate law is used (end of the C1 transition band).
ALPHA_FP_MIN_DEG = 30.0
#: Default moment reference point / chord (quarter chord, see module docstring for the source).
X_REF_OVER_C_DEFAULT = 0.25
#: Default point / chord the regression CM is taken about (quarter chord, an assumption: module docstring).
CM_REGRESSION_REF_DEFAULT = 0.25
# Negative-alpha branch (module docstring): blend band [deg], CL law, CD and CM increments.
#: Start (upper end) of the blend band to the negative-alpha law [deg].
ALPHA_NEG_START_DEG = 0.0
#: End of the blend band; below it the negative-alpha law alone [deg].
ALPHA_NEG_END_DEG = -3.0
#: Saturation |CL| of the negative-alpha law [-].
CL_NEG_SAT = 0.6
#: Zero-lift angle of the negative-alpha CL law [deg].
ALPHA_NEG_ZL_DEG = -1.0
#: Angle scale of the tanh in the CL law and the CD increment [deg].
ALPHA_NEG_WIDTH_DEG = 6.5
#: Drag increment of the luffing canopy at large negative alpha [-].
CD_NEG_ADD = 0.05
#: Nose-up CM increment at large negative alpha, over the regression CM at 0 deg [-].
CM_NEG_ADD = 0.09
#: Angle scale of the tanh in the CM increment [deg].
ALPHA_NEG_CM_WIDTH_DEG = 3.0

# Breukels' LEI airfoil constants C20..C62 (awegroup/Vortex-Step-Method and OpenSourceAWE/VortexStepMethod.jl agree).
C20, C21, C22 = -0.008011, -0.000336, 0.000992
C23, C24, C25 = 0.013936, -0.003838, -0.000161
C26, C27, C28 = 0.001243, -0.009288, -0.002124
C29, C30, C31 = 0.012267, -0.002398, -0.000274
C32, C33, C34 = 0.0, 0.0, 0.0
C35, C36, C37 = -3.371000, 0.858039, 0.141600
C38, C39, C40 = 7.201140, -0.676007, 0.806629
C41, C42, C43 = 0.170454, -0.390563, 0.101966
C44, C45, C46, C47, C48, C49 = 0.546094, 0.022247, -0.071462, -0.006527, 0.002733, 0.000686
C50, C51, C52, C53, C54 = 0.123685, 0.143755, 0.495159, -0.105362, 0.033468
C55, C56, C57, C58 = -0.284793, -0.026199, -0.024060, 0.000559
C59, C60, C61, C62 = -1.787703, 0.352443, -0.839323, 0.137932

# The eight alpha-polynomial coefficients are linear in the features
#   phi = [t^2, t, 1, kappa t^2, kappa t, kappa, kappa^2 t^2, kappa^2 t, kappa^2]
# Rows: lambda5, lambda6, lambda7, lambda8 (CL = l5 a^3 + l6 a^2 + l7 a + l8), CD_2, CD_0 (CD = CD_2 a^2 + CD_0),
# CM_2, CM_0 (CM = CM_2 a^2 + CM_0), with a in degrees (Breukels 2011, as coded in the VSM codes).
_COEF = np.array(
    [
        # t^2   t     1     k t^2  k t   k     k^2 t^2  k^2 t  k^2
        [0.0, 0.0, 0.0, C20, C21, C22, 0.0, 0.0, 0.0],  # lambda5 = S9 kappa + S10 ... (kappa part)
        [0.0, 0.0, 0.0, C26, C27, C28, 0.0, 0.0, 0.0],  # lambda6
        [0.0, 0.0, 0.0, C32, C33, C34, 0.0, 0.0, 0.0],  # lambda7
        [0.0, 0.0, 0.0, C38, C39, C40, 0.0, 0.0, 0.0],  # lambda8
        [0.0, C48, C49, 0.0, C46, C47, 0.0, C44, C45],  # CD alpha^2 coefficient
        [C52, C53, C54, 0.0, C50, C51, 0.0, 0.0, 0.0],  # CD constant
        [0.0, C57, C58, 0.0, C55, C56, 0.0, 0.0, 0.0],  # CM alpha^2 coefficient
        [0.0, C61, C62, 0.0, C59, C60, 0.0, 0.0, 0.0],  # CM constant
    ]
)
# kappa-free parts of lambda5..8: S10, S12, S14, S16 (quadratics in t)
_COEF[0, 0:3] = (C23, C24, C25)
_COEF[1, 0:3] = (C29, C30, C31)
_COEF[2, 0:3] = (C35, C36, C37)
_COEF[3, 0:3] = (C41, C42, C43)


def poly_coefficients(t, kappa):
    """The eight alpha-polynomial coefficients of Breukels' regression.

    Parameters
    ----------
    t : (n,) float [-]
        Thickness, LE tube diameter / chord (Eq. 5).
    kappa : (n,) float [-]
        Camber, maximum canopy height / chord (Eq. 6).

    Returns
    -------
    coef : (8, n) float
        Rows lambda5, lambda6, lambda7, lambda8, CD_2, CD_0, CM_2, CM_0 (alpha in degrees, see ``_COEF``).
    """
    t = np.asarray(t, dtype=float)
    k = np.asarray(kappa, dtype=float)
    t2 = t * t
    base = np.stack((t2, t, np.ones_like(t)))
    phi = np.concatenate((base, k * base, (k * k) * base))
    return _COEF @ phi


def _smoothstep(u):
    """Cubic smoothstep 3u^2 - 2u^3 on u clipped to [0, 1] (C1 at both ends)."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def flat_plate_coefficients(alpha, x_ref_over_c=X_REF_OVER_C_DEFAULT):
    """Sign-correct Newtonian flat-plate law (C_N = 2 sin^2 alpha, as in the VSM codes) with its moment about ``x_ref``.

    Parameters
    ----------
    alpha : array float [rad]
        Angle of attack.
    x_ref_over_c : float or array [-]
        Moment reference point / chord, from the airfoil leading edge.

    Returns
    -------
    CL, CD, CM : arrays like ``alpha``
        ``CL = 2 cos a sin a |sin a|``, ``CD = 2 |sin a|^3``, ``CM = -2 sin a |sin a| (0.5 - x_ref/c)``.
    """
    s = np.sin(alpha)
    cn = 2.0 * s * np.abs(s)  # normal-force coefficient, acts at mid-chord
    return cn * np.cos(alpha), np.abs(cn * s), -cn * (0.5 - x_ref_over_c)


def lei_coefficients(alpha, t, kappa, x_ref_over_c=X_REF_OVER_C_DEFAULT, cm_ref_over_c=CM_REGRESSION_REF_DEFAULT,
                     negative_alpha="bounded"):
    """Section lift, drag and pitching-moment coefficients of an LEI airfoil.

    Breukels' regression for |alpha| <= 20 deg (below 0 deg blended into the bounded negative-alpha law unless
    ``negative_alpha="breukels"``), C1 blend to the sign-correct flat-plate law over 20 deg < |alpha| < 30 deg,
    flat-plate law beyond (see the module docstring).

    Parameters
    ----------
    alpha : array float [rad]
        Angle of attack (any shape; broadcast with ``t`` and ``kappa``), positive when the flow comes from the
        -e_z (pressure) side.
    t : array float [-]
        Thickness ratio, tube diameter / chord (Eq. 5).
    kappa : array float [-]
        Camber ratio, maximum canopy height / chord (Eq. 6).
    x_ref_over_c : float or array [-]
        Moment reference point / chord, from the airfoil leading edge. The regression CM is transferred from
        ``cm_ref_over_c`` to this point (module docstring).
    cm_ref_over_c : float [-]
        Point / chord (from the leading edge) the regression CM is taken about; default the quarter chord.
    negative_alpha : {"bounded", "breukels"}
        ``"bounded"``: below ``ALPHA_NEG_START_DEG`` blend into the negative-alpha law fitted to V3 data (module
        docstring); ``"breukels"``: the regression at negative alpha as well (the former behaviour, bit for bit).

    Returns
    -------
    CL, CD, CM : arrays of the broadcast shape [-]
        CM positive nose-up.
    """
    if negative_alpha not in ("bounded", "breukels"):
        raise ValueError(f"negative_alpha must be 'bounded' or 'breukels', not {negative_alpha!r}")
    cm_ref = float(cm_ref_over_c)
    at_quarter_chord = np.ndim(x_ref_over_c) == 0 and float(x_ref_over_c) == cm_ref
    alpha, t, kappa, x_ref = np.broadcast_arrays(
        np.asarray(alpha, float), np.asarray(t, float), np.asarray(kappa, float), np.asarray(x_ref_over_c, float)
    )
    shape = alpha.shape
    a_rad = alpha.ravel()
    coef = poly_coefficients(t.ravel(), kappa.ravel())
    a = np.rad2deg(a_rad)
    # Regression inside +-20 deg, its tangent line at the switch beyond (P_ext in the module docstring).
    ac = np.clip(a, -ALPHA_POLY_MAX_DEG, ALPHA_POLY_MAX_DEG)
    da = a - ac
    l5, l6, l7, l8, cd2, cd0, cm2, cm0 = coef
    cl = ((l5 * ac + l6) * ac + l7) * ac + l8 + ((3.0 * l5 * ac + 2.0 * l6) * ac + l7) * da
    cd = cd2 * ac * ac + cd0 + 2.0 * cd2 * ac * da
    cm = cm2 * ac * ac + cm0 + 2.0 * cm2 * ac * da
    if negative_alpha == "bounded":
        # blend below ALPHA_NEG_START_DEG into the negative-alpha law (w = 0 above: cl + 0 * (...) == cl)
        w = _smoothstep((ALPHA_NEG_START_DEG - a) / (ALPHA_NEG_START_DEG - ALPHA_NEG_END_DEG))
        if np.any(w > 0.0):
            cl = cl + w * (CL_NEG_SAT * np.tanh((a - ALPHA_NEG_ZL_DEG) / ALPHA_NEG_WIDTH_DEG) - cl)
            cd = cd + w * (CD_NEG_ADD * np.tanh((ALPHA_NEG_START_DEG - a) / ALPHA_NEG_WIDTH_DEG))
            cm = cm + w * (cm0 + CM_NEG_ADD * np.tanh((ALPHA_NEG_START_DEG - a) / ALPHA_NEG_CM_WIDTH_DEG) - cm)
    if not at_quarter_chord:
        # regression CM is about cm_ref: move it to x_ref with the normal force C_N = CL cos a + CD sin a
        cm = cm + (x_ref.ravel() - cm_ref) * (cl * np.cos(a_rad) + cd * np.sin(a_rad))
    s = _smoothstep((np.abs(a) - ALPHA_POLY_MAX_DEG) / (ALPHA_FP_MIN_DEG - ALPHA_POLY_MAX_DEG))
    if np.any(s > 0.0):
        cl_fp, cd_fp, cm_fp = flat_plate_coefficients(a_rad, x_ref.ravel())
        cl = cl + s * (cl_fp - cl)
        cd = cd + s * (cd_fp - cd)
        cm = cm + s * (cm_fp - cm)
    return cl.reshape(shape), cd.reshape(shape), cm.reshape(shape)
