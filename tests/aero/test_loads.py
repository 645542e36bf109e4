"""Section loads (Eq. 7-9), their nodal distribution and the wing totals (kite_env.aero.loads)."""

import numpy as np
import pytest

from kite_env.aero.breukels import lei_coefficients
from kite_env.aero.loads import distribute, section_loads, wing_totals

RHO = 1.225


def c_wing(n_sec=37, m=6, radius=4.0, phi_max=1.2, chord0=2.6, chord_tip=1.0, camber=0.08, seed=None, noise=0.0):
    """Symmetric C-shaped wing (right tip first), parabolic camber along the radial direction; optional random
    node perturbation (a "deformed" wing whose sections are no longer planar). Returns x, tube_d, width."""
    phi = np.linspace(phi_max, -phi_max, n_sec)
    chord = chord0 + (chord_tip - chord0) * (phi / phi_max) ** 2
    le = np.stack([0.3 * (phi / phi_max) ** 2, radius * np.sin(phi), radius * (np.cos(phi) - 1.0)], axis=1)
    radial = np.stack([np.zeros(n_sec), np.sin(phi), np.cos(phi)], axis=1)
    s = np.linspace(0.0, 1.0, m)
    x = (le[:, None, :] + (chord[:, None] * s[None, :])[:, :, None] * np.array([1.0, 0.0, 0.0])
         + (camber * 4.0 * s * (1.0 - s) * chord[:, None])[:, :, None] * radial[:, None, :])
    if noise:
        x = x + noise * np.random.default_rng(seed).normal(size=x.shape)
    return x, 0.1 * chord, np.full(n_sec, 2.0 * radius * phi_max / n_sec)


def flow(speed, alpha_deg, beta_deg=0.0):
    a, b = np.deg2rad(alpha_deg), np.deg2rad(beta_deg)
    return speed * np.array([np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)])


STATES = [  # (v_kite, omega, v_wind)
    (np.zeros(3), np.zeros(3), flow(25.0, 8.0)),
    (np.zeros(3), np.zeros(3), flow(25.0, -12.0, 10.0)),
    (np.array([-20.0, 3.0, -2.0]), np.array([0.3, -0.5, 0.8]), flow(8.0, 0.0)),
    (np.zeros(3), np.array([2.0, 0.0, 1.0]), flow(15.0, 22.0)),  # blend band and beyond at the tips
    (np.zeros(3), np.zeros(3), flow(20.0, 70.0, -20.0)),  # deep stall
    (np.zeros(3), np.zeros(3), flow(20.0, 150.0)),  # reversed flow
]


def moment_about(x, f, point):
    return np.cross(x - point[:, None, :], f).sum(axis=1)


@pytest.mark.parametrize("noise", [0.0, 0.05])
@pytest.mark.parametrize("state", range(len(STATES)))
def test_force_and_moment_reproduced(state, noise):
    x, d, w = c_wing(seed=state, noise=noise)
    L = section_loads(x, d, w, *STATES[state], RHO)
    g = L.geometry
    F = L.lift + L.drag
    scale_f = np.linalg.norm(F, axis=1)
    # the sum of nodal forces is the section force L + D (Eq. 7-8)
    np.testing.assert_array_less(np.linalg.norm(L.nodal_forces.sum(axis=1) - F, axis=1), 1e-12 * scale_f + 1e-300)
    # the moment of the nodal forces about the reference point, with the actual 3-D node positions, has the
    # e_y component M (Eq. 9); np.cross here is independent of the section-frame algebra in loads.py
    r_ref = g.r_nose + 0.25 * g.chord[:, None] * g.e_x
    mom = moment_about(x, L.nodal_forces, r_ref)
    scale_m = np.abs(L.moment) + scale_f * g.chord
    np.testing.assert_array_less(np.abs(np.einsum("ij,ij->i", mom, g.e_y) - L.moment), 1e-10 * scale_m)
    # nodal forces lie in the airfoil plane (no spanwise component)
    np.testing.assert_allclose(np.einsum("ijk,ik->ij", L.nodal_forces, g.e_y), 0.0, atol=1e-12 * scale_f.max())
    if noise == 0.0:
        # every section lies in the plane normal to its e_y (e_y is the airfoil-plane normal, also at the curved
        # tips): the whole moment vector is M e_y
        assert np.abs(np.einsum("ijk,ik->ij", x - x[:, :1], g.e_y)).max() < 1e-12
        np.testing.assert_allclose(mom, L.moment[:, None] * g.e_y, atol=1e-10 * scale_m.max())


@pytest.mark.parametrize("alpha_deg", [-25.0, 6.0, 17.0, 24.0, 45.0])
def test_reference_point_does_not_change_the_loads(alpha_deg):
    # the chosen moment reference point only changes the bookkeeping (CM, M about another point), not the line of
    # action: the nodal forces are the same, and the moment about each point is reproduced
    x, d, w = c_wing(n_sec=9, seed=4, noise=0.03)
    args = (np.zeros(3), np.zeros(3), flow(20.0, alpha_deg), RHO)
    L_qc = section_loads(x, d, w, *args)
    for x_ref in (0.0, 0.5, 0.9):
        L = section_loads(x, d, w, *args, x_ref_over_c=x_ref)
        g = L.geometry
        np.testing.assert_allclose(L.r_ref, g.r_nose + x_ref * g.chord[:, None] * g.e_x, atol=1e-14)
        f_scale = np.abs(L_qc.nodal_forces).max()
        np.testing.assert_allclose(L.nodal_forces, L_qc.nodal_forces, atol=1e-12 * f_scale)
        mom = np.einsum("ij,ij->i", moment_about(x, L.nodal_forces, L.r_ref), g.e_y)
        np.testing.assert_allclose(mom, L.moment, atol=1e-10 * np.abs(L.moment).max())
        np.testing.assert_allclose(L.CL, L_qc.CL, rtol=1e-14)
        # M_x = M_c/4 + (x_ref - 1/4) c N, N the normal force along e_z (a force aft of the point is nose-down)
        n_force = np.einsum("ij,ij->i", L.lift + L.drag, g.e_z)
        np.testing.assert_allclose(L.moment, L_qc.moment + (x_ref - 0.25) * g.chord * n_force,
                                   atol=1e-12 * np.abs(L_qc.moment).max() + 1e-12 * f_scale)


def test_pure_couple_and_zero_flow():
    # F = 0, M != 0: a pure couple; a positive (nose-up) moment pushes the LE nodes up and the TE nodes down
    s = np.tile(np.linspace(0.0, 2.0, 6), (2, 1))
    local = np.stack([s, np.zeros_like(s), 0.1 * np.sin(np.pi * s / 2.0)], axis=-1)
    f = distribute(local, np.array([0.4, 0.4]), np.zeros((2, 3)), np.array([50.0, -50.0]))
    np.testing.assert_allclose(f.sum(axis=1), 0.0, atol=1e-12)
    mom = np.einsum("ij,ij->i", local[..., 2] - 0.0, f[..., 0]) - np.einsum("ij,ij->i", s - 0.4, f[..., 2])
    np.testing.assert_allclose(mom, [50.0, -50.0], rtol=1e-13)
    assert f[0, 0, 2] > 0 > f[0, -1, 2] and f[1, 0, 2] < 0 < f[1, -1, 2]
    # no in-plane flow (pure spanwise wind): zero loads, no NaN
    x, d, w = c_wing(n_sec=5)
    L = section_loads(x, d, w, np.zeros(3), np.zeros(3), np.zeros(3), RHO)
    assert np.all(L.nodal_forces == 0.0) and np.all(np.isfinite(L.alpha))


def test_directions_and_magnitudes():
    x, d, w = c_wing(seed=11, noise=0.02)
    for v_kite, omega, v_wind in STATES:
        L = section_loads(x, d, w, v_kite, omega, v_wind, RHO)
        g = L.geometry
        # independent projected inflow: flow -v_a minus its e_y part (Eq. 2 and projection)
        r1 = x[:, 0]
        v_a = v_kite + np.cross(omega, r1) - v_wind
        u = -v_a - np.einsum("ij,ij->i", -v_a, g.e_y)[:, None] * g.e_y
        V2 = np.einsum("ij,ij->i", u, u)
        alpha = np.arctan2(np.einsum("ij,ij->i", u, g.e_z), np.einsum("ij,ij->i", u, g.e_x))
        np.testing.assert_allclose(L.alpha, alpha, atol=1e-13)
        np.testing.assert_allclose(L.v_app, v_a, atol=1e-13)
        CL, CD, CM = lei_coefficients(alpha, d / g.chord, g.kappa)
        q = 0.5 * RHO * V2
        np.testing.assert_allclose(L.q_dyn, q, rtol=1e-13)
        # Eq. (7)-(9) magnitudes
        np.testing.assert_allclose(np.linalg.norm(L.lift, axis=1), q * g.chord * w * np.abs(CL), rtol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(L.drag, axis=1), q * g.chord * w * CD, rtol=1e-12)
        np.testing.assert_allclose(L.moment, q * g.chord**2 * w * CM, rtol=1e-12)
        # drag along the projected flow, lift perpendicular to it in the airfoil plane, towards e_L = e_D x e_y
        e_d = u / np.sqrt(V2)[:, None]
        np.testing.assert_allclose(np.einsum("ij,ij->i", L.drag, e_d), q * g.chord * w * CD, rtol=1e-12)
        np.testing.assert_allclose(np.einsum("ij,ij->i", L.lift, np.cross(e_d, g.e_y)), q * g.chord * w * CL,
                                   rtol=1e-12)
        f_scale = np.linalg.norm(L.lift + L.drag, axis=1)[:, None]
        np.testing.assert_array_less(np.abs(np.einsum("ij,ij->i", L.lift, e_d)), 1e-12 * f_scale[:, 0])
        np.testing.assert_array_less(np.linalg.norm(np.cross(L.drag, e_d), axis=1), 1e-12 * f_scale[:, 0])
        np.testing.assert_array_less(np.abs(np.einsum("ij,ij->i", L.lift, g.e_y)), 1e-12 * f_scale[:, 0])


def test_lift_towards_e_z_and_center_of_pressure_of_flat_plate():
    # flat rectangular wing (kappa = 0) at 10 deg: the normal-force line of action follows from CL, CD, CM
    n, m, c_n, d = 3, 6, 2.0, 0.2
    x = np.zeros((n, m, 3))
    x[:, :, 0] = np.linspace(0.0, c_n, m)
    x[:, :, 1] = np.array([1.0, 0.0, -1.0])[:, None]
    a = np.deg2rad(10.0)
    L = section_loads(x, np.full(n, d), np.ones(n), np.zeros(3), np.zeros(3), flow(20.0, 10.0), RHO)
    assert np.all(L.lift[:, 2] > 0) and np.all(L.lift[:, 0] < 0)  # lift tilted forward at positive alpha
    c = c_n + d / 2
    CL, CD, CM = lei_coefficients(a, d / c, 0.0)
    cn = CL * np.cos(a) + CD * np.sin(a)  # normal-force coefficient (along e_z)
    x_cp = 0.25 * c - CM * c / cn  # from the nose: M = -(x_cp - x_ref) N (lift aft of x_ref is nose-down)
    fz = L.nodal_forces[..., 2]
    s_nose = x[..., 0] + d / 2
    np.testing.assert_allclose((fz * s_nose).sum(axis=1) / fz.sum(axis=1), x_cp, rtol=1e-12)
    assert CM < 0 and np.all(x_cp > 0.25 * c)  # negative (nose-down) CM puts the centre of pressure aft


def test_geometric_scaling_moment_has_chord_squared():
    x, d, w = c_wing(n_sec=9, seed=2, noise=0.02)
    args = (np.zeros(3), np.zeros(3), flow(20.0, 6.0), RHO)
    L1 = section_loads(x, d, w, *args)
    L2 = section_loads(2.0 * x, 2.0 * d, 2.0 * w, *args)
    np.testing.assert_allclose(L2.alpha, L1.alpha, atol=1e-14)
    np.testing.assert_allclose(L2.nodal_forces, 4.0 * L1.nodal_forces, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(L2.moment, 8.0 * L1.moment, rtol=1e-12)


def test_rigid_rotation_covariance():
    rng = np.random.default_rng(5)
    x, d, w = c_wing(n_sec=11, seed=9, noise=0.02)
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r)) * np.sign(np.linalg.det(q * np.sign(np.diag(r))))
    if q[1, 1] < 0:  # keep the right tip on the +y side
        q = q @ np.diag([-1.0, -1.0, 1.0])
    v_k, om, v_w = np.array([-5.0, 1.0, 0.5]), np.array([0.2, -0.1, 0.4]), flow(18.0, 7.0, 5.0)
    L0 = section_loads(x, d, w, v_k, om, v_w, RHO)
    L1 = section_loads(x @ q.T, d, w, q @ v_k, q @ om, q @ v_w, RHO)
    np.testing.assert_allclose(L1.alpha, L0.alpha, atol=1e-13)
    np.testing.assert_allclose(L1.nodal_forces, L0.nodal_forces @ q.T, atol=1e-10)


def test_deformation_velocity_reaches_loads():
    x, d, w = c_wing(n_sec=7)
    args = (np.zeros(3), np.zeros(3), flow(20.0, 5.0), RHO)
    L0 = section_loads(x, d, w, *args)
    np.testing.assert_allclose(section_loads(x, d, w, *args, x_sec_prev=x, dt=0.1).nodal_forces, L0.nodal_forces,
                               rtol=1e-14)
    # moving down relative to K (plunge) raises alpha and lift everywhere (aerodynamic damping)
    L1 = section_loads(x, d, w, *args, x_sec_prev=x + np.array([0.0, 0.0, 0.05]), dt=0.1)
    assert np.all(L1.alpha > L0.alpha)


def test_wing_totals():
    x, d, w = c_wing(seed=1, noise=0.02)
    v_kite, omega, v_wind = np.array([-15.0, 2.0, 1.0]), np.array([0.1, 0.2, -0.3]), flow(10.0, 3.0)
    L = section_loads(x, d, w, v_kite, omega, v_wind, RHO)
    v_ref = v_kite - v_wind
    tot = wing_totals(L, v_ref)
    F = L.nodal_forces.reshape(-1, 3).sum(axis=0)
    np.testing.assert_allclose(tot["force"], F, rtol=1e-13)
    np.testing.assert_allclose(tot["force"], (L.lift + L.drag).sum(axis=0), rtol=1e-12)
    e_flow = -v_ref / np.linalg.norm(v_ref)
    np.testing.assert_allclose(tot["drag"], F @ e_flow, rtol=1e-13)
    np.testing.assert_allclose(tot["lift"], np.linalg.norm(np.cross(F, e_flow)), rtol=1e-13)
    np.testing.assert_allclose(tot["lift_vec"] + tot["drag_vec"], F, rtol=1e-13)
    assert abs(tot["lift_vec"] @ v_ref) < 1e-10 * np.linalg.norm(F) * np.linalg.norm(v_ref)
    np.testing.assert_allclose(tot["lift_to_drag"], tot["lift"] / tot["drag"], rtol=1e-14)
    np.testing.assert_allclose(tot["moment"], np.cross(x.reshape(-1, 3), L.nodal_forces.reshape(-1, 3)).sum(0),
                               rtol=1e-12, atol=1e-9)


def test_wing_totals_flat_wing_matches_section_sums_and_symmetry():
    # identical flat sections in a uniform flow: all lifts / drags parallel, totals are the sums of magnitudes
    n, m = 5, 6
    x = np.zeros((n, m, 3))
    x[:, :, 0] = np.linspace(0.0, 2.0, m)
    x[:, :, 1] = np.linspace(2.0, -2.0, n)[:, None]
    v_wind = flow(20.0, 6.0)
    L = section_loads(x, np.full(n, 0.2), np.full(n, 1.0), np.zeros(3), np.zeros(3), v_wind, RHO)
    tot = wing_totals(L, -v_wind)
    np.testing.assert_allclose(tot["lift"], np.linalg.norm(L.lift, axis=1).sum(), rtol=1e-13)
    np.testing.assert_allclose(tot["drag"], np.linalg.norm(L.drag, axis=1).sum(), rtol=1e-13)
    # symmetric C wing in symmetric flow: no side force, no roll or yaw moment
    xc, d, w = c_wing()
    tot = wing_totals(section_loads(xc, d, w, np.zeros(3), np.zeros(3), v_wind, RHO), -v_wind)
    f = np.linalg.norm(tot["force"])
    assert abs(tot["force"][1]) < 1e-12 * f
    assert np.all(np.abs(tot["moment"][[0, 2]]) < 1e-12 * f)
    assert tot["force"][2] > 0 and tot["lift_to_drag"] > 1.0


@pytest.mark.parametrize("with_dt", [False, True])
def test_load_jacobian_matches_central_differences(with_dt):
    """Section blocks of d(nodal forces)/d(node positions), against central differences of section_loads on one
    section at a time (the spanwise LE tangent then moves with the perturbation, as it does in the wing)."""
    from kite_env.aero.loads import load_jacobian

    x, d, w = c_wing(n_sec=9, m=5, seed=3, noise=0.01)
    prev = x - 0.002 * np.random.default_rng(4).normal(size=x.shape) if with_dt else None
    dt = 5.3e-3 if with_dt else None
    args = (d, w, np.array([1.0, -2.0, 0.5]), np.array([0.1, 0.2, -0.3]), flow(25.0, 10.0, 5.0), RHO, prev, dt)
    f0, J = load_jacobian(x, *args)
    np.testing.assert_allclose(f0, section_loads(x, *args).nodal_forces, rtol=0, atol=1e-12)
    h = 1e-6
    for i in (0, 4, 8):
        Jc = np.zeros((15, 15))
        for q in range(15):
            xp, xm = x.copy(), x.copy()
            xp[i].reshape(-1)[q] += h
            xm[i].reshape(-1)[q] -= h
            Jc[:, q] = (section_loads(xp, *args).nodal_forces[i] - section_loads(xm, *args).nodal_forces[i]).ravel()
        Jc /= 2 * h
        scale = np.abs(Jc).max()
        assert np.abs(J[i] - Jc).max() < 1e-3 * scale
        if with_dt:  # the deformation-velocity term 1/(2 dt) of Eq. (3) is a large part of the block
            assert np.abs(J[i] - load_jacobian(x, *args[:6])[1][i]).max() > 0.2 * scale
