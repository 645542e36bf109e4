"""The compiled section loads (kite_env.aero.kernels) against the NumPy reference (kite_env.aero.loads).

For perturbed rhino16 wing states (37 sections x 6 load points) and inflows that put sections at negative angle of
attack, in the 20-30 deg post-stall blend band and beyond it, with nearly flat sections (e_y blend), with and without
the deformation velocity of Eq. (3), per-section wind, a spanwise override and a moved moment reference point, every
field of ``SectionLoads`` from ``backend="numba"`` must equal the ``backend="numpy"`` one to 1e-10 (relative to a
per-field scale); they differ only by round-off. Also checked: the literal thresholds and Breukels' constants of the
kernel equal the reference constants, the backend dispatch, and ``load_jacobian`` through both backends.
"""

import inspect
import math

import numpy as np
import pytest

from kite_env.aero import breukels, kernels, loads, sections
from kite_env.aero.loads import load_jacobian, section_loads
from kite_env.geometry import build_kite

RTOL = 1e-10
RHO = 1.225
MESH = build_kite("rhino16", 37, 6)
X0 = MESH.nodes[MESH.sections]  # (37, 6, 3)
D, W = MESH.section_tube_d, MESH.section_width


def flow(speed, alpha_deg, beta_deg=0.0):
    """Wind vector (3,) [m/s] that a kite at rest sees at angle of attack ``alpha`` (K axes, x aft, z up)."""
    a, b = np.deg2rad(alpha_deg), np.deg2rad(beta_deg)
    return speed * np.array([np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)])


def flatten(x, idx, frac):
    """Move the nodes of sections ``idx`` towards their chord line so that the mean node offset from the chord line
    is ``frac`` times the node-to-node chord (``frac < 0.02`` puts e_y into the smoothstep blend of sections.py)."""
    x = x.copy()
    for i in idx:
        off = x[i] - x[i, 0]
        e = off[-1] / np.linalg.norm(off[-1])
        perp = off - np.outer(off @ e, e)
        h = np.linalg.norm(perp.mean(axis=0))
        x[i] = x[i, 0] + np.outer(off @ e, e) + perp * (frac * np.linalg.norm(off[-1]) / h)
    return x


def wing_state(seed, noise=0.03, flat=()):
    """Randomly perturbed design wing (node noise ``noise`` [m]); sections ``flat`` made nearly flat."""
    rng = np.random.default_rng(seed)
    x = X0 + noise * rng.normal(size=X0.shape)
    return flatten(x, flat, 0.01) if flat else x


# (name, state seed, kwargs of section_loads besides x, d, w, rho)
CASES = [
    ("negative alpha", 0, dict(v_kite=np.zeros(3), omega=np.zeros(3), v_wind=flow(25.0, -14.0, 8.0))),
    ("rotating, dt", 1, dict(v_kite=np.array([-18.0, 2.0, -1.5]), omega=np.array([0.4, -0.6, 0.9]),
                             v_wind=flow(9.0, 3.0), dt=0.05)),
    ("blend band", 2, dict(v_kite=np.zeros(3), omega=np.array([1.5, 0.0, 0.8]), v_wind=flow(15.0, 24.0))),
    ("blend band, x_ref", 3, dict(v_kite=np.zeros(3), omega=np.zeros(3), v_wind=flow(18.0, 27.0, -12.0),
                                  x_ref_over_c=0.4)),
    ("deep stall, per-section wind", 4, dict(v_kite=np.zeros(3), omega=np.zeros(3), v_wind="per_section")),
    ("reversed flow, x_ref", 5, dict(v_kite=np.zeros(3), omega=np.zeros(3), v_wind=flow(20.0, 150.0),
                                     x_ref_over_c=0.0)),
    ("spanwise override, dt", 6, dict(v_kite=np.array([-20.0, 0.0, 0.0]), omega=np.array([0.0, 0.3, 0.0]),
                                      v_wind=flow(8.0, 5.0), dt=0.02, spanwise="random")),
    ("flat sections", 7, dict(v_kite=np.zeros(3), omega=np.zeros(3), v_wind=flow(22.0, 10.0), flat=(0, 5, 18, 36))),
    ("regression CM about the nose", 8, dict(v_kite=np.zeros(3), omega=np.zeros(3), v_wind=flow(25.0, 8.0),
                                              cm_regression_ref_over_c=0.0)),
    ("rotation at 3/4 chord", 9, dict(v_kite=np.array([-22.0, 1.0, -2.0]), omega=np.array([0.3, -0.5, 1.2]),
                                      v_wind=flow(6.0, 4.0), rotation_point_over_c=0.75)),
    ("luffing band", 10, dict(v_kite=np.zeros(3), omega=np.zeros(3), v_wind=flow(25.0, -3.0, 5.0),
                                  luffing_cl=0.1)),
]


def case_args(seed, kw):
    """Concrete arguments of one case: (x, kwargs for section_loads)."""
    kw = dict(kw)
    rng = np.random.default_rng(100 + seed)
    x = wing_state(seed, flat=kw.pop("flat", ()))
    if isinstance(kw.get("v_wind"), str):  # per-section wind: deep stall, varying with the section
        alpha = np.linspace(35.0, 80.0, len(x))
        kw["v_wind"] = np.stack([flow(20.0, a, 10.0 * np.sin(a)) for a in alpha])
    if "dt" in kw:  # previous positions: a small rigid offset plus noise (Eq. 3 velocities ~ 0.1-1 m/s)
        kw["x_sec_prev"] = x - 0.01 * np.array([1.0, -0.5, 2.0]) + 0.003 * rng.normal(size=x.shape)
    if kw.get("spanwise") == "random":
        kw["spanwise"] = sections.spanwise_directions(x[:, 0]) + 0.3 * rng.normal(size=(len(x), 3))
    return x, kw


def assert_loads_agree(a, b, x):
    """All fields of two SectionLoads agree to RTOL with per-field scales (b is the reference)."""
    ga, gb = a.geometry, b.geometry
    c = gb.chord

    def close(name, u, v, scale):
        u, v = np.asarray(u), np.asarray(v)
        assert u.shape == v.shape, name
        assert np.all(np.abs(u - v) <= RTOL * scale), (name, np.max(np.abs(u - v) / scale))

    f_sec = np.linalg.norm(b.lift_local + b.drag_local, axis=1)  # section force magnitude [N]
    close("nodal_forces", a.nodal_forces, b.nodal_forces,
          np.max(np.abs(b.nodal_forces), axis=(1, 2))[:, None, None] + f_sec[:, None, None])
    close("alpha", a.alpha, b.alpha, 1.0)
    for name in ("CL", "CD", "CM"):
        close(name, getattr(a, name), getattr(b, name), np.maximum(np.abs(getattr(b, name)), 1.0))
    close("lift_local", a.lift_local, b.lift_local, f_sec[:, None])
    close("drag_local", a.drag_local, b.drag_local, f_sec[:, None])
    close("moment", a.moment, b.moment, np.abs(b.moment) + c * f_sec)
    close("s_ref", a.s_ref, b.s_ref, c)
    close("v_app", a.v_app, b.v_app, np.linalg.norm(b.v_app, axis=1)[:, None])
    close("q_dyn", a.q_dyn, b.q_dyn, np.abs(b.q_dyn))
    close("frames", ga.frames, gb.frames, 1.0)
    close("chord", ga.chord, gb.chord, c)
    close("t", ga.t, gb.t, np.abs(gb.t))
    close("kappa", ga.kappa, gb.kappa, np.max(np.abs(gb.zeta)))
    close("zeta", ga.zeta, gb.zeta, np.max(np.abs(gb.zeta)))
    close("local", ga.local, gb.local, c[:, None, None])
    for name in ("r_le", "tube_d"):
        np.testing.assert_array_equal(getattr(ga, name), getattr(gb, name))
    np.testing.assert_array_equal(a.positions, x)
    # derived properties go through the same frames
    close("force", a.force, b.force, f_sec[:, None])
    close("r_ref", a.r_ref, b.r_ref, c[:, None])


def both(x, kw, d=D, w=W):
    return (section_loads(x, d, w, rho=RHO, backend="numba", **kw),
            section_loads(x, d, w, rho=RHO, backend="numpy", **kw))


def test_thresholds_and_constants_equal_reference():
    assert kernels._FLAT_FRACTION == sections._FLAT_FRACTION
    assert kernels._PLANE_COS_FULL == sections._PLANE_COS_FULL
    assert kernels._PLANE_COS_NONE == sections._PLANE_COS_NONE
    assert kernels._ALPHA_POLY_MAX_DEG == breukels.ALPHA_POLY_MAX_DEG
    assert kernels._ALPHA_FP_MIN_DEG == breukels.ALPHA_FP_MIN_DEG
    assert kernels._X_REF_DEFAULT == breukels.X_REF_OVER_C_DEFAULT == loads.X_REF_OVER_C_DEFAULT
    assert kernels._RAD2DEG == np.rad2deg(1.0)
    for name in ("ALPHA_NEG_START_DEG", "ALPHA_NEG_END_DEG", "CL_NEG_SAT", "ALPHA_NEG_ZL_DEG", "ALPHA_NEG_WIDTH_DEG",
                 "CD_NEG_ADD", "CM_NEG_ADD", "ALPHA_NEG_CM_WIDTH_DEG"):  # negative-alpha branch
        assert getattr(kernels, "_" + name) == getattr(breukels, name), name
    # the plane-normal floor is an inline literal of section_geometry
    assert f"np.maximum(h_len, {kernels._TINY!r})" in inspect.getsource(sections.section_geometry)
    np.testing.assert_array_equal(kernels.COEF, breukels._COEF)
    # and the kernel's polynomial coefficients are those of the table (same t, kappa, alpha in degrees)
    t, kappa = 0.11, 0.07
    lam = breukels.poly_coefficients(np.array([t]), np.array([kappa]))[:, 0]
    for a_deg in (-17.0, 4.0, 19.0):
        a = a_deg
        cl = ((lam[0] * a + lam[1]) * a + lam[2]) * a + lam[3]
        cd, cm = lam[4] * a * a + lam[5], lam[6] * a * a + lam[7]
        got = kernels._lei_coefficients(math.radians(a_deg), t, kappa, 0.25, 0.25, 0)  # neg = 0: the regression
        np.testing.assert_allclose(got, (cl, cd, cm), rtol=1e-12, atol=1e-14)
    # independent values: Breukels' regression evaluated outside this package (tests/aero/test_breukels.py's
    # TABLE_POLY: t = 0.100, kappa = 0.095, quarter chord), 4 decimals
    for a_deg, ref in ((-10.0, (-1.5413, 0.0781, -0.6336)), (0.0, (0.1417, 0.0427, 0.0705)),
                       (15.0, (1.8073, 0.1224, -1.5138))):
        np.testing.assert_allclose(kernels._lei_coefficients(math.radians(a_deg), 0.1, 0.095, 0.25, 0.25, 0), ref,
                                   rtol=0, atol=6e-5)


# kernels._lei_coefficients(..., neg=0) before the negative-alpha branch existed, repr-exact (it differs from the
# NumPy reference by round-off), at these angles [deg] for t = 0.07, kappa = 0.12, x_ref = 0.4, cm_ref = 0; rows CL,
# CD, CM
KERNEL_GOLDEN_DEG = (-150.0, -40.0, -25.0, -20.0, -12.0, -5.0, -2.0, -0.5)
KERNEL_GOLDEN = [
    [0.43301270189221874, -0.6330222215594888, -0.8558867362235325, -1.8187197562800004, -1.7219600794800003,
     -0.74152573578, -0.2003333022, 0.0780934444245],
    [0.25, 0.5311687126375895, 0.20826911188325756, 0.19265199390000004, 0.09931215338800004, 0.055923711900000006,
     0.048266928108, 0.046899645288],
    [0.04999999999999716, 0.08263518223330735, -2.201357397581296, -3.268051993927807, -1.5347689992129634,
     -0.35750891685218694, -0.0009478224253878093, 0.13586298927838442],
]


def test_lei_coefficients_kernel_breukels_mode_unchanged():
    got = [kernels._lei_coefficients(math.radians(a), 0.07, 0.12, 0.4, 0.0, 0) for a in KERNEL_GOLDEN_DEG]
    np.testing.assert_array_equal(np.array(got).T, np.array(KERNEL_GOLDEN))
    # default neg = 1 is the bounded branch
    assert kernels._lei_coefficients(math.radians(-10.0), 0.1, 0.08, 0.25)[0] > -0.6


@pytest.mark.parametrize("mode,neg", [("bounded", 1), ("breukels", 0)])
def test_lei_coefficients_kernel_equals_reference(mode, neg):
    # the scalar compiled twin against breukels.lei_coefficients on a fine grid over all angles and branches
    a = np.deg2rad(np.linspace(-180.0, 180.0, 7201))
    for t, kappa, x_ref, cm_ref in [(0.1, 0.08, 0.25, 0.25), (0.07, 0.12, 0.4, 0.0), (0.2, 0.0, 0.0, 0.25),
                                    (0.12, 0.16, 0.6, 0.1)]:
        ref = np.array(breukels.lei_coefficients(a, t, kappa, x_ref, cm_ref, negative_alpha=mode))
        got = np.array([kernels._lei_coefficients(v, t, kappa, x_ref, cm_ref, neg) for v in a]).T
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name,seed,kw", CASES, ids=[c[0] for c in CASES])
def test_numba_matches_numpy(name, seed, kw):
    x, kw = case_args(seed, kw)
    a, b = both(x, kw)
    assert_loads_agree(a, b, x)


def test_cases_cover_the_branches():
    # the cases above reach every branch of the reference: negative alpha, the 20-30 deg blend band, the flat-plate
    # law beyond, the moved reference point, and e_y in its flat-section blend (0 < u < 1)
    alpha, u_flat = [], []
    for _, seed, kw in CASES:
        x, kw2 = case_args(seed, kw)
        b = section_loads(x, D, W, rho=RHO, backend="numpy", **kw2)
        alpha.append(np.rad2deg(b.alpha))
        off = x - x[:, :1]
        e = off[:, -1] / np.linalg.norm(off[:, -1], axis=1)[:, None]
        h = off.mean(axis=1)
        h -= np.einsum("ij,ij->i", h, e)[:, None] * e
        u_flat.append(np.linalg.norm(h, axis=1) / (0.02 * np.linalg.norm(off[:, -1], axis=1)))
    a, u = np.abs(np.concatenate(alpha)), np.concatenate(u_flat)
    assert np.sum(np.concatenate(alpha) < -1.0) >= 20
    assert np.sum((a > 20.5) & (a < 29.5)) >= 20
    assert np.sum((a > 30.0) & (a < 90.0)) >= 20 and np.sum(a > 90.0) >= 20
    assert np.sum((u > 0.05) & (u < 0.95)) >= 4


def test_small_wings_and_broadcast_inputs():
    # one section (spanwise default y_k), two sections (one-sided differences only), scalar tube diameter/width
    kw = dict(v_kite=[0.0, 0.0, 0.0], omega=[0.1, 0.2, 0.0], v_wind=list(flow(20.0, 12.0)))
    for sel in ([18], [17, 18], [36, 20, 3]):
        x = wing_state(9)[sel]
        a, b = both(x, kw, d=0.2, w=1.5)
        assert_loads_agree(a, b, x)
    # left tip first (reversed spanwise order: the LE tangents are not flipped)
    x = wing_state(10)[::-1]
    a, b = both(x, kw, d=D[::-1], w=W[::-1])
    assert_loads_agree(a, b, x)


def test_load_jacobian_through_both_backends(monkeypatch):
    # the 18x stacked call (spanwise held, x_sec_prev and per-section wind tiled) goes through the dispatch
    x, kw = case_args(1, CASES[1][2])
    kw["v_wind"] = kw["v_wind"] + np.linspace(-1.0, 1.0, len(x))[:, None] * np.array([0.0, 1.0, 0.5])
    out = {}
    for be in ("numba", "numpy"):
        monkeypatch.setenv("KITE_ENV_ELEMENT_BACKEND", be)
        out[be] = load_jacobian(x, D, W, rho=RHO, h=1e-6, **kw)
    (f1, J1), (f2, J2) = out["numba"], out["numpy"]
    scale_f = np.max(np.abs(f2))
    assert np.max(np.abs(f1 - f2)) <= RTOL * scale_f
    # forward differences amplify the round-off of f (~1e-15 |f|) by 1/h: compare to that level
    assert np.max(np.abs(J1 - J2)) <= 1e-13 * scale_f / 1e-6
    assert np.max(np.abs(J2)) > 1e3 * 1e-13 * scale_f / 1e-6  # the bound is far below the entries themselves


def test_auto_backend_follows_environment(monkeypatch):
    calls = []

    def spy(*args):
        calls.append(args)
        return kernels.section_loads_fields(*args)

    monkeypatch.setattr(loads, "section_loads_fields", spy)
    x, kw = case_args(0, CASES[0][2])
    monkeypatch.setenv("KITE_ENV_ELEMENT_BACKEND", "numpy")
    section_loads(x, D, W, rho=RHO, **kw)
    assert not calls
    monkeypatch.setenv("KITE_ENV_ELEMENT_BACKEND", "numba")
    section_loads(x, D, W, rho=RHO, **kw)
    assert len(calls) == 1


def test_inconsistent_shapes_are_rejected():
    # the compiled loop does not check bounds; the wrapper rejects what NumPy broadcasting would reject
    x = wing_state(11)
    with pytest.raises(ValueError):
        section_loads(x, D, W, np.zeros(3), np.zeros(3), np.zeros((5, 3)), RHO, backend="numba")
    with pytest.raises(ValueError):
        section_loads(x, D, W, np.zeros(3), np.zeros(3), np.zeros(3), RHO, x_sec_prev=x[:5], dt=0.1,
                      backend="numba")
    with pytest.raises(ValueError):
        section_loads(x, D, W, np.zeros(3), np.zeros(3), np.zeros(3), RHO, spanwise=np.ones((4, 3)),
                      backend="numba")


def test_moment_as_printed_in_the_paper_scales_by_the_chord():
    """Eq. (9) as printed (c^1) against the consistent c^2: same coefficients, moment divided by the chord, both
    backends alike."""
    x, kw = case_args(*CASES[0][1:])
    a2 = section_loads(x, D, W, rho=RHO, backend="numpy", **kw)
    a1, b1 = (section_loads(x, D, W, rho=RHO, backend=be, moment_chord_power=1.0, **kw) for be in ("numpy", "numba"))
    np.testing.assert_allclose(a1.moment, a2.moment / a2.geometry.chord, rtol=1e-12)
    np.testing.assert_allclose(b1.moment, a1.moment, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(b1.nodal_forces, a1.nodal_forces, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(a1.nodal_forces.sum(axis=1), a2.nodal_forces.sum(axis=1), rtol=1e-12, atol=1e-9)


def test_luffing_option_moves_the_load_of_low_lift_sections_to_the_edges():
    """aero.luffing_cl: both backends alike; per section the force and moment are those of the paper's distribution;
    sections with CL >= luffing_cl keep it node for node, CL <= 0 loads only the LE and TE nodes, in between a blend."""
    x, kw = case_args(*CASES[0][1:])
    # per-section wind from -12 to +12 deg: sections below CL = 0, between 0 and 0.6, and above 0.6
    kw = dict(kw, v_wind=np.stack([flow(25.0, a) for a in np.linspace(-12.0, 12.0, len(x))]))
    ref = section_loads(x, D, W, rho=RHO, backend="numpy", **kw)
    a, b = (section_loads(x, D, W, rho=RHO, backend=be, luffing_cl=0.6, **kw) for be in ("numpy", "numba"))
    np.testing.assert_allclose(b.nodal_forces, a.nodal_forces, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(a.CL, ref.CL)
    np.testing.assert_allclose(a.nodal_forces.sum(axis=1), ref.nodal_forces.sum(axis=1), rtol=1e-12, atol=1e-9)
    arm = x - (x[:, :1] + a.s_ref[:, None, None] * a.geometry.frames[:, None, :, 0])  # from the reference point
    m_a = np.einsum("ijk,ik->i", np.cross(arm, a.nodal_forces), a.geometry.frames[:, :, 1])
    m_ref = np.einsum("ijk,ik->i", np.cross(arm, ref.nodal_forces), a.geometry.frames[:, :, 1])
    np.testing.assert_allclose(m_a, m_ref, rtol=1e-9, atol=1e-9 * np.abs(m_ref).max())
    full, off = a.CL >= 0.6, a.CL <= 0.0
    assert full.any() and off.any() and ((~full) & (~off)).any()
    np.testing.assert_array_equal(a.nodal_forces[full], ref.nodal_forces[full])
    assert np.all(a.nodal_forces[off][:, 1:-1] == 0.0)
    blend = ~full & ~off
    assert np.all(np.abs(a.nodal_forces[blend][:, 1:-1]) <= np.abs(ref.nodal_forces[blend][:, 1:-1]) + 1e-12)


def test_rotation_point_moves_the_rotation_term_along_the_chord():
    """aero.rotation_point: the frame rotation of Eq. (2) is taken at x_p c behind the nose; against the LE node the
    apparent wind differs by exactly omega x (x_p c - d/2) e_x per section (both backends)."""
    x, _ = case_args(9, {})
    omega = np.array([0.2, -0.4, 1.1])
    kw = dict(v_kite=np.array([-20.0, 0.0, -1.0]), omega=omega, v_wind=flow(5.0, 3.0))
    for be in ("numpy", "numba"):
        le = section_loads(x, D, W, rho=RHO, backend=be, **kw)
        q = section_loads(x, D, W, rho=RHO, backend=be, rotation_point_over_c=0.75, **kw)
        arm = (0.75 * le.geometry.chord - 0.5 * le.geometry.tube_d)[:, None] * le.geometry.e_x
        np.testing.assert_allclose(q.v_app - le.v_app, np.cross(omega, arm), atol=1e-12)
        assert np.abs(q.alpha - le.alpha).max() > 1e-3  # a yaw rate changes the sections' angles of attack



def test_a_collapsed_section_gives_non_finite_loads_in_both_backends_instead_of_raising():
    """A Newton iterate can collapse a section's nodes onto its LE node (zero chord). The compiled kernel then divides
    by zero as the NumPy reference does and returns non-finite loads, which the solver reports as a non-finite residual
    (a failed step, made again in halves); with numba's Python error model it raised ZeroDivisionError."""
    x = X0.copy()
    x[18] = x[18, 0]
    for backend in ("numba", "numpy"):
        with np.errstate(all="ignore"):
            out = section_loads(x, D, W, np.zeros(3), np.zeros(3), flow(25.0, 8.0), RHO, backend=backend)
        assert not np.all(np.isfinite(out.nodal_forces[18])), backend
        assert np.all(np.isfinite(out.nodal_forces[:18])), backend
