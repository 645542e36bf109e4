"""Breukels' LEI airfoil regression with its post-stall continuation (kite_env.aero.breukels)."""

import numpy as np
import pytest

from kite_env.aero import kernels
from kite_env.aero.breukels import (
    ALPHA_FP_MIN_DEG,
    ALPHA_NEG_END_DEG,
    ALPHA_NEG_START_DEG,
    ALPHA_POLY_MAX_DEG,
    flat_plate_coefficients,
    lei_coefficients,
    poly_coefficients,
)

# Check table: Breukels' (2011) LEI regression (the paper's Sect. II.B, after Eq. 9) evaluated independently of
# kite_env.aero.breukels, with the constants C20..C62 of awegroup/Vortex-Step-Method,
# OpenSourceAWE/VortexStepMethod.jl and a LEI_airf_coeff thesis helper ([S1-S3] of kite_env/aero/breukels.py).
# t = 0.100, kappa = 0.095; columns alpha [deg], CL, CD, CM.
TABLE_T, TABLE_KAPPA = 0.100, 0.095
TABLE_LAMBDA = (-0.000322002, -0.000679965, 0.193694, 0.141663)  # lambda5..lambda8
TABLE_POLY = np.array([
    [-20, -1.4282, 0.1843, -2.7461],
    [-10, -1.5413, 0.0781, -0.6336],
    [-5, -0.8036, 0.0516, -0.1055],
    [0, 0.1417, 0.0427, 0.0705],
    [5, 1.0529, 0.0516, -0.1055],
    [10, 1.6886, 0.0781, -0.6336],
    [15, 1.8073, 0.1224, -1.5138],
    [20, 1.1675, 0.1843, -2.7461],
])
# flat-plate rows of the same table (CL = 2 cos a sin^2 a, CD = 2 sin^3 a); their CM column is the regression
# polynomial, which breukels.py deliberately replaces beyond 20 deg (checked separately below).
TABLE_FLAT = np.array([
    [25, 0.3237, 0.1510],
    [30, 0.4330, 0.2500],
    [45, 0.7071, 0.7071],
    [90, 0.0000, 2.0000],
])
# second and third parameter sets of the same evaluation: (t, kappa, lambda5..8, CL at 0,5,10,15,20 deg, CD at 0,10,20)
TABLE_OTHER = [
    (0.080, 0.080, (-0.000305742, -0.000616058, 0.188669, 0.135703),
     (0.1357, 1.0254, 1.6550, 1.7952, 1.2167), (0.0405, 0.0752, 0.1793)),
    (0.120, 0.060, (-0.000370702, -0.000578355, 0.196022, 0.107305),
     (0.1073, 1.0266, 1.6390, 1.6664, 0.8308), (0.0375, 0.0799, 0.2070)),
]
TOL_TABLE = 1.0e-4  # the table is rounded to 4 decimals (max rounding error 5e-5)


def coeffs_deg(alpha_deg, t=TABLE_T, kappa=TABLE_KAPPA, x_ref=0.25, mode="bounded"):
    return lei_coefficients(np.deg2rad(alpha_deg), t, kappa, x_ref, negative_alpha=mode)


def test_check_table_regression_range():
    # the table is the regression itself, also at negative alpha
    cl, cd, cm = coeffs_deg(TABLE_POLY[:, 0], mode="breukels")
    np.testing.assert_allclose(cl, TABLE_POLY[:, 1], atol=TOL_TABLE, rtol=0)
    np.testing.assert_allclose(cd, TABLE_POLY[:, 2], atol=TOL_TABLE, rtol=0)
    np.testing.assert_allclose(cm, TABLE_POLY[:, 3], atol=TOL_TABLE, rtol=0)


def test_lambda_coefficients():
    lam = poly_coefficients(np.array([TABLE_T]), np.array([TABLE_KAPPA]))[:4, 0]
    # the table gives lambda5, lambda6 to 6 significant digits and lambda7, lambda8 to 6 decimals
    tol = np.array([5.01e-10, 5.01e-10, 5.01e-7, 5.01e-7])
    assert np.all(np.abs(lam - TABLE_LAMBDA) <= tol)
    for t, k, lam_ref, _, _ in TABLE_OTHER:
        assert np.all(np.abs(poly_coefficients(np.array([t]), np.array([k]))[:4, 0] - lam_ref) <= tol)


@pytest.mark.parametrize("t, kappa, lam, cl_ref, cd_ref", TABLE_OTHER)
def test_check_table_other_parameters(t, kappa, lam, cl_ref, cd_ref):
    cl, _, _ = coeffs_deg(np.array([0.0, 5.0, 10.0, 15.0, 20.0]), t, kappa)
    _, cd, _ = coeffs_deg(np.array([0.0, 10.0, 20.0]), t, kappa)
    np.testing.assert_allclose(cl, cl_ref, atol=TOL_TABLE, rtol=0)
    np.testing.assert_allclose(cd, cd_ref, atol=TOL_TABLE, rtol=0)


def test_check_table_flat_plate():
    # beyond 30 deg the coefficients are the flat-plate law of the table
    a = TABLE_FLAT[1:, 0]
    cl, cd, _ = coeffs_deg(a)
    np.testing.assert_allclose(cl, TABLE_FLAT[1:, 1], atol=TOL_TABLE, rtol=0)
    np.testing.assert_allclose(cd, TABLE_FLAT[1:, 2], atol=TOL_TABLE, rtol=0)
    # the 25 deg row is the open codes' hard switch; the flat-plate law itself reproduces it
    cl25, cd25, _ = flat_plate_coefficients(np.deg2rad(25.0))
    np.testing.assert_allclose([cl25, cd25], TABLE_FLAT[0, 1:], atol=TOL_TABLE, rtol=0)


def test_post_stall_moment_is_flat_plate_about_reference():
    # beyond 30 deg: normal force C_N = 2 sin a |sin a| acting at mid-chord, moment about x_ref (nose-up positive)
    a_deg = np.array([-150.0, -90.0, -45.0, -30.0, 30.0, 45.0, 90.0, 150.0])
    for x_ref in (0.0, 0.25, 0.5):
        _, _, cm = coeffs_deg(a_deg, x_ref=x_ref)
        s = np.sin(np.deg2rad(a_deg))
        np.testing.assert_allclose(cm, -2.0 * s * np.abs(s) * (0.5 - x_ref), atol=1e-14)


def test_blend_band_between_regression_tangent_and_flat_plate():
    # inside 20..30 deg the value lies between the tangent-line continuation and the flat-plate law
    a_deg = np.linspace(20.5, 29.5, 10)
    cl, cd, _ = coeffs_deg(a_deg)
    lam5, lam6, lam7, lam8 = TABLE_LAMBDA
    cl20 = ((lam5 * 20 + lam6) * 20 + lam7) * 20 + lam8
    dcl20 = (3 * lam5 * 20 + 2 * lam6) * 20 + lam7
    tangent = cl20 + dcl20 * (a_deg - 20.0)
    fp, _, _ = flat_plate_coefficients(np.deg2rad(a_deg))
    assert np.all((cl - np.minimum(tangent, fp)) >= -1e-12)
    assert np.all((np.maximum(tangent, fp) - cl) >= -1e-12)
    assert np.all(cl > 0) and np.all(cd > 0)


@pytest.mark.parametrize("mode", ["bounded", "breukels"])
@pytest.mark.parametrize("edge_deg", [-ALPHA_FP_MIN_DEG, -ALPHA_POLY_MAX_DEG, ALPHA_NEG_END_DEG, ALPHA_NEG_START_DEG,
                                      ALPHA_POLY_MAX_DEG, ALPHA_FP_MIN_DEG])
@pytest.mark.parametrize("t, kappa", [(0.1, 0.095), (0.08, 0.04), (0.18, 0.12)])
def test_continuity_and_c1_at_switch_points(edge_deg, t, kappa, mode):
    a0 = np.deg2rad(edge_deg)
    h = 1e-7
    pts = np.array([a0 - h, a0, a0 + h])
    for k, c in enumerate(lei_coefficients(pts, t, kappa, negative_alpha=mode)):
        left = (c[1] - c[0]) / h
        right = (c[2] - c[1]) / h
        scale = max(1.0, abs(left))
        # a kink (C0 only) would show a jump of O(1) per rad; the one-sided difference error is O(f'' h) < 2e-4
        # (|f''| reaches ~1e3 per rad^2 in the CM blend at 30 deg for thick, cambered sections)
        assert abs(right - left) < 1e-3 * scale, (k, left, right)
        assert abs(c[2] - c[0]) < 1e-4 * scale


@pytest.mark.parametrize("mode", ["bounded", "breukels"])
def test_no_jump_over_the_whole_range(mode):
    a = np.deg2rad(np.linspace(-179.0, 179.0, 35801))
    for c in lei_coefficients(a, 0.1, 0.095, negative_alpha=mode):
        # the largest slope (|dCM/da| of the 20 deg tangent line) is below 40 per rad
        assert np.max(np.abs(np.diff(c))) < 40.0 * (a[1] - a[0])


def test_sign_correct_lift_for_large_negative_alpha():
    a_deg = np.linspace(-89.0, -5.0, 85)  # CL = 0 at exactly -90 deg (flat plate broadside)
    cl, cd, _ = coeffs_deg(a_deg)
    assert np.all(cl < 0.0)
    assert np.all(cd > 0.0)
    # beyond the blend band the law is exactly odd in CL
    big = np.linspace(30.0, 90.0, 13)
    np.testing.assert_allclose(coeffs_deg(-big)[0], -coeffs_deg(big)[0], atol=1e-15)


def test_lift_odd_part_and_symmetry_properties():
    # properties of the regression itself (negative_alpha="breukels")
    a_deg = np.linspace(0.0, 20.0, 21)
    cl_p, cd_p, cm_p = coeffs_deg(a_deg, mode="breukels")
    cl_m, cd_m, cm_m = coeffs_deg(-a_deg, mode="breukels")
    lam5, lam6, lam7, lam8 = TABLE_LAMBDA
    # inside +-20 deg: odd part = lambda5 a^3 + lambda7 a, even part = lambda6 a^2 + lambda8 (a in deg)
    np.testing.assert_allclose(0.5 * (cl_p - cl_m), lam5 * a_deg**3 + lam7 * a_deg, atol=5e-5)
    np.testing.assert_allclose(0.5 * (cl_p + cl_m), lam6 * a_deg**2 + lam8, atol=5e-5)
    np.testing.assert_allclose(cm_p, cm_m, atol=1e-15)
    assert np.all(coeffs_deg(np.linspace(5.0, 89.0, 85))[0] > 0)


def test_drag_even_and_positive_everywhere():
    a_deg = np.linspace(-175.0, 175.0, 701)
    for t, kappa in [(0.07, 0.0), (0.1, 0.095), (0.2, 0.12), (0.07, 0.12), (0.2, 0.0)]:
        _, cd, _ = coeffs_deg(a_deg, t, kappa, mode="breukels")
        _, cd_m, _ = coeffs_deg(-a_deg, t, kappa, mode="breukels")
        assert np.all(cd > 0.0)
        np.testing.assert_allclose(cd, cd_m, atol=1e-15)  # even without the negative-alpha branch
        _, cd_b, _ = coeffs_deg(a_deg, t, kappa)
        assert np.all(cd_b > 0.0)
        band = (a_deg < 0.0) & (a_deg > -ALPHA_FP_MIN_DEG)
        assert np.all(cd_b >= cd - 1e-15) and np.all(cd_b[band] > cd[band])  # the branch only adds drag


def test_vectorised_shapes_and_broadcasting():
    alpha = np.deg2rad(np.linspace(-40, 40, 20)).reshape(4, 5)
    t = np.linspace(0.08, 0.12, 5)
    kappa = 0.09
    cl, cd, cm = lei_coefficients(alpha, t, kappa)
    assert cl.shape == cd.shape == cm.shape == (4, 5)
    # element-wise equality with scalar calls
    for i, j in [(0, 0), (1, 3), (3, 4), (2, 2)]:
        ref = lei_coefficients(alpha[i, j], t[j], kappa)
        np.testing.assert_allclose([cl[i, j], cd[i, j], cm[i, j]], [float(r) for r in ref], rtol=1e-14, atol=1e-15)
    assert np.shape(lei_coefficients(0.1, 0.1, 0.1)[0]) == ()


def test_moment_transfer_to_other_reference_points():
    # CM about x_ref = CM about c/4 + (x_ref - 1/4) C_N with C_N = CL cos a + CD sin a, over the whole range
    a = np.deg2rad(np.linspace(-170.0, 170.0, 341))
    cl, cd, cm_qc = lei_coefficients(a, 0.1, 0.095)
    cn = cl * np.cos(a) + cd * np.sin(a)
    for x_ref in (0.0, 0.5, np.full(a.shape, 0.7)):
        cl_x, cd_x, cm_x = lei_coefficients(a, 0.1, 0.095, x_ref)
        np.testing.assert_allclose(cl_x, cl, rtol=1e-15)
        np.testing.assert_allclose(cd_x, cd, rtol=1e-15)
        np.testing.assert_allclose(cm_x, cm_qc + (x_ref - 0.25) * cn, atol=1e-13)


def test_regression_moment_point_moves_the_centre_of_pressure():
    # the regression CM taken about cm_ref instead of c/4: for any output point x_ref the
    # centre of pressure x_cp = x_ref - CM_x / C_N moves by (cm_ref - 1/4) c; CL and CD are unchanged
    a = np.deg2rad(np.linspace(-19.0, 19.0, 39))
    cl, cd, cm_qc = lei_coefficients(a, 0.1, 0.095)
    cn = cl * np.cos(a) + cd * np.sin(a)
    for cm_ref in (0.0, 0.1, 0.25):
        for x_ref in (0.0, 0.25, 0.6):
            cl_x, cd_x, cm_x = lei_coefficients(a, 0.1, 0.095, x_ref, cm_ref)
            np.testing.assert_allclose(cl_x, cl, rtol=1e-15)
            np.testing.assert_allclose(cd_x, cd, rtol=1e-15)
            np.testing.assert_allclose(x_ref - cm_x / cn, (0.25 - cm_qc / cn) + (cm_ref - 0.25), atol=1e-12)


# ---------------------------------------------------------------------------------------------------------------
# Negative-alpha branch (negative_alpha="bounded", module docstring of breukels.py)

# Values of lei_coefficients before the branch existed (same code path as negative_alpha="breukels"), repr-exact,
# at these angles [deg] for (t, kappa, x_ref, cm_ref); rows CL, CD, CM.
GOLDEN_DEG = np.array([-150.0, -40.0, -25.0, -20.0, -12.0, -5.0, -2.0, -0.5])
GOLDEN = {
    (0.1, 0.08, 0.25, 0.25): [
        [0.4330127018922205, -0.633022221559489, -0.36236750748353264, -1.3167100240000003, -1.7069916560000002,
         -0.8129339740000001, -0.25774640800000004, 0.032533773200000005],
        [0.25, 0.5311687126375895, 0.20286636273325748, 0.18330325399999997, 0.09182806424, 0.049306394,
         0.041802569840000005, 0.04046260124],
        [0.125, 0.20658795558326748, -1.787780893210818, -2.4206120840000005, -0.8279685000000003,
         -0.08763808400000003, 0.043008459999999984, 0.06633819999999999],
    ],
    (0.07, 0.12, 0.4, 0.0): [
        [0.43301270189221874, -0.6330222215594888, -0.8558867362235323, -1.81871975628, -1.7219600794800003,
         -0.74152573578, -0.2003333022, 0.0780934444245],
        [0.25, 0.5311687126375895, 0.2082691118832575, 0.19265199389999998, 0.09931215338800002, 0.0559237119,
         0.048266928108, 0.046899645288],
        [0.04999999999999716, 0.08263518223330735, -2.2013573975812957, -3.2680519939278065, -1.5347689992129634,
         -0.35750891685218694, -0.0009478224253878093, 0.13586298927838442],
    ],
}

# 2-D CFD section polars of the V3 kite, OpenSourceAWE/V3Kite.jl data/2D_polars_CFD_NF_combined/<i>.csv (commit
# d8c4376d), over the inboard profiles i = 1..16 at alpha [deg]: median, minimum and maximum of Cl and Cd, and the
# median of Cm - Cm(0 deg) (module docstring of breukels.py).
V3_DEG = np.array([-2.0, -3.0, -4.0, -5.0, -6.0, -8.0, -10.0])
V3_CL = np.array([
    [-0.0582, -0.1648, -0.2704, -0.3475, -0.3623, -0.4341, -0.5529],  # median
    [-0.2998, -0.4396, -0.5477, -0.6284, -0.6863, -0.7509, -0.7766],  # min
    [0.0305, -0.1063, -0.1830, -0.2451, -0.2696, -0.3637, -0.4927],  # max
])
V3_CD = np.array([
    [0.0529, 0.0594, 0.0720, 0.0814, 0.0905, 0.1067, 0.1233],
    [0.0480, 0.0559, 0.0601, 0.0633, 0.0664, 0.0727, 0.0790],
    [0.0620, 0.0703, 0.0790, 0.0884, 0.0979, 0.1272, 0.1671],
])
V3_DCM = np.array([0.0445, 0.0630, 0.0795, 0.0904, 0.0904, 0.0904, 0.0904])
V3_T, V3_KAPPA = 0.1, 0.08  # representative V3 section (the data files give no t, kappa)
TOL_V3_CL = 0.05  # from -4 to -10 deg; at -2 and -3 deg within the profiles' range (the regression dominates there)
TOL_V3_CD = 0.007
TOL_V3_DCM = 0.015


def kernel_coefficients(alpha, t, kappa, x_ref=0.25, cm_ref=0.25, neg=1):
    """The compiled twin ``kernels._lei_coefficients`` on an array of angles [rad]: (3, n)."""
    return np.array([kernels._lei_coefficients(float(a), t, kappa, x_ref, cm_ref, neg) for a in alpha]).T


@pytest.mark.parametrize("key", list(GOLDEN))
def test_breukels_mode_reproduces_former_values_bit_for_bit(key):
    t, kappa, x_ref, cm_ref = key
    got = lei_coefficients(np.deg2rad(GOLDEN_DEG), t, kappa, x_ref, cm_ref, negative_alpha="breukels")
    np.testing.assert_array_equal(np.array(got), np.array(GOLDEN[key]))


@pytest.mark.parametrize("t, kappa, x_ref, cm_ref", [(0.1, 0.08, 0.25, 0.25), (0.07, 0.12, 0.4, 0.0),
                                                     (0.2, 0.0, 0.0, 0.25), (0.12, 0.16, 0.6, 0.1)])
def test_positive_alpha_unchanged_bit_for_bit(t, kappa, x_ref, cm_ref):
    a = np.deg2rad(np.linspace(0.0, 180.0, 9001))  # all of alpha >= 0, whatever the band constants
    bounded = np.array(lei_coefficients(a, t, kappa, x_ref, cm_ref))
    np.testing.assert_array_equal(bounded, np.array(lei_coefficients(a, t, kappa, x_ref, cm_ref,
                                                                     negative_alpha="breukels")))
    # and the branch does act just below the start of the band
    below = np.array(lei_coefficients(np.deg2rad(-0.1), t, kappa, x_ref, cm_ref))
    assert np.all(below != np.array(lei_coefficients(np.deg2rad(-0.1), t, kappa, x_ref, cm_ref,
                                                     negative_alpha="breukels")))


def test_bounded_branch_reproduces_v3_section_data():
    cl, cd, cm = coeffs_deg(V3_DEG, V3_T, V3_KAPPA)
    _, _, cm0 = coeffs_deg(0.0, V3_T, V3_KAPPA)
    assert np.all((cl >= V3_CL[1]) & (cl <= V3_CL[2]))
    far = V3_DEG <= -4.0
    np.testing.assert_allclose(cl[far], V3_CL[0, far], atol=TOL_V3_CL, rtol=0)
    assert np.all((cd >= V3_CD[1]) & (cd <= V3_CD[2]))
    np.testing.assert_allclose(cd, V3_CD[0], atol=TOL_V3_CD, rtol=0)
    np.testing.assert_allclose(cm - cm0, V3_DCM, atol=TOL_V3_DCM, rtol=0)
    # saturation: weak negative lift down to -20 deg, CD keeps rising
    cl20, cd20, _ = coeffs_deg(np.array([-20.0, -10.0]), V3_T, V3_KAPPA)
    assert -0.65 < cl20[0] < cl20[1] and cd20[0] > cd20[1]


def test_bounded_lift_monotone_from_blend_start_to_minus_20_deg():
    a_deg = np.linspace(-ALPHA_POLY_MAX_DEG, ALPHA_NEG_START_DEG, 4001)
    grid = [(t, k) for t in (0.04, 0.07, 0.1, 0.15, 0.2, 0.25) for k in (0.0, 0.04, 0.08, 0.12, 0.16)]
    for t, k in grid:
        cl = coeffs_deg(a_deg, t, k)[0]
        assert np.all(np.diff(cl) >= 0.0), (t, k)  # non-decreasing in alpha: more negative lift as alpha falls
    # the regression itself turns (dCL/da < 0 below about -14 deg), which this check detects
    assert not np.all(np.diff(coeffs_deg(a_deg, 0.1, 0.08, mode="breukels")[0]) >= 0.0)


def max_slope_jump(c, h):
    """Largest change of the finite-difference slope between neighbouring intervals of a uniform grid (step h)."""
    return np.max(np.abs(np.diff(np.diff(c) / h)))


@pytest.mark.parametrize("impl", ["numpy", "kernel"])
def test_c1_over_the_full_range_on_a_fine_grid(impl):
    # C0 and C1 on -90..90 deg: a jump J shows as a slope spike J / h, a kink as a slope step; for a C1 function with
    # |f''| <= M the slope changes by at most M h between intervals (M ~ 1e3 per rad^2 in the 20..30 deg CM blend)
    a = np.deg2rad(np.linspace(-90.0, 90.0, 36001))
    h = a[1] - a[0]
    tol = 0.5  # per rad; h = 8.7e-5 rad
    for t, kappa, x_ref in [(0.1, 0.08, 0.25), (0.07, 0.0, 0.25), (0.2, 0.16, 0.4), (0.12, 0.1, 0.0)]:
        if impl == "numpy":
            coeffs = lei_coefficients(a, t, kappa, x_ref)
        else:
            coeffs = kernel_coefficients(a, t, kappa, x_ref)
        for k, c in enumerate(coeffs):
            assert max_slope_jump(c, h) < tol, (t, kappa, k, max_slope_jump(c, h))
    # the check flags a hard switch to the negative-alpha law at the end of the band
    bounded, breukels = (lei_coefficients(a, 0.1, 0.08, negative_alpha=m)[0] for m in ("bounded", "breukels"))
    hard = np.where(a < np.deg2rad(ALPHA_NEG_END_DEG), bounded, breukels)
    assert max_slope_jump(hard, h) > 100.0 * tol


def test_negative_alpha_option_is_checked():
    with pytest.raises(ValueError, match="negative_alpha"):
        lei_coefficients(-0.1, 0.1, 0.08, negative_alpha="clipped")
