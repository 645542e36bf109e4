"""Section geometry (Eq. 4-6) and local inflow (Eq. 2-3) of kite_env.aero.sections."""

import numpy as np
import pytest

from kite_env.aero.sections import apparent_wind, inflow, section_geometry

MIRROR = np.diag([1.0, -1.0, 1.0])


def random_rotation(rng, keep_right_tip=True):
    """Random proper rotation; with ``keep_right_tip`` one that keeps y_k's image on the +y side."""
    while True:
        q, r = np.linalg.qr(rng.normal(size=(3, 3)))
        q = q * np.sign(np.diag(r))
        if np.linalg.det(q) < 0:
            q[:, 0] = -q[:, 0]
        if not keep_right_tip or q[1, 1] > 0.3:
            return q


def flat_wing(n_sec=5, m=6, chord=2.0, span=6.0, twist=None):
    """Flat planar wing in the x-y plane, sections ordered from the right tip (y > 0) to the left tip.

    ``twist`` (n_sec,) [rad] rotates each chord nose-up about the section's LE node (TE towards -z)."""
    y = np.linspace(span / 2, -span / 2, n_sec)
    th = np.zeros(n_sec) if twist is None else np.asarray(twist)
    ex = np.stack([np.cos(th), np.zeros(n_sec), -np.sin(th)], axis=1)
    s = np.linspace(0.0, chord, m)
    le = np.stack([np.zeros(n_sec), y, np.zeros(n_sec)], axis=1)
    return le[:, None, :] + s[None, :, None] * ex[:, None, :]


def c_wing(n_sec=37, m=6, radius=4.0, phi_max=1.2, chord0=2.6, chord_tip=1.0, camber=0.08):
    """Symmetric C-shaped wing on a circular LE arc, right tip first; parabolic camber along the radial direction.

    Returns node positions, the arc angles and the analytic section axes (x_k, tangent, radial)."""
    phi = np.linspace(phi_max, -phi_max, n_sec)
    chord = chord0 + (chord_tip - chord0) * (phi / phi_max) ** 2
    le = np.stack([0.3 * (phi / phi_max) ** 2, radius * np.sin(phi), radius * (np.cos(phi) - 1.0)], axis=1)
    radial = np.stack([np.zeros(n_sec), np.sin(phi), np.cos(phi)], axis=1)
    tangent = np.stack([np.zeros(n_sec), np.cos(phi), -np.sin(phi)], axis=1)
    s = np.linspace(0.0, 1.0, m)
    x = (le[:, None, :] + (chord[:, None] * s[None, :])[:, :, None] * np.array([1.0, 0.0, 0.0])
         + (camber * 4.0 * s * (1.0 - s) * chord[:, None])[:, :, None] * radial[:, None, :])
    return x, phi, np.tile([1.0, 0.0, 0.0], (n_sec, 1)), tangent, radial


# --------------------------------------------------------------------------- geometry (Eq. 4-6)
def test_flat_plate_rotated_arbitrarily():
    rng = np.random.default_rng(1)
    x0 = flat_wing(chord=2.0)
    d = np.full(5, 0.2)
    for _ in range(5):
        q = random_rotation(rng)
        shift = rng.normal(size=3)
        g = section_geometry(x0 @ q.T + shift, d)
        np.testing.assert_allclose(g.chord, 2.0 + 0.1, rtol=1e-14)  # Eq. (4): node distance + d/2
        np.testing.assert_allclose(g.t, 0.2 / 2.1, rtol=1e-14)  # Eq. (5)
        np.testing.assert_allclose(g.kappa, 0.0, atol=1e-14)  # Eq. (6)
        for k, e in enumerate((g.e_x, g.e_y, g.e_z)):
            np.testing.assert_allclose(e, np.tile(q[:, k], (5, 1)), atol=1e-14)
        np.testing.assert_allclose(g.frames @ g.frames.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (5, 3, 3)),
                                   atol=1e-14)
        np.testing.assert_allclose(np.linalg.det(g.frames), 1.0, rtol=1e-14)
        # nose d/2 in front of the LE node; chordwise coordinate from the nose over the chord
        np.testing.assert_allclose(g.r_nose, g.r_le - 0.1 * g.e_x, atol=1e-14)
        np.testing.assert_allclose(g.xi, np.tile(np.linspace(0.1, 2.1, 6) / 2.1, (5, 1)), atol=1e-14)


def arc_section(m, length, sagitta):
    """Nodes on a circular arc from (0, 0) to (length, 0) bulging to +z, equally spaced in arc angle."""
    radius = (length**2 / 4.0 + sagitta**2) / (2.0 * sagitta)
    half = np.arcsin(length / (2.0 * radius))
    th = np.linspace(-half, half, m)
    s = length / 2.0 + radius * np.sin(th)
    z = radius * np.cos(th) - (radius - sagitta)
    return s, z


@pytest.mark.parametrize("m", [6, 7])
def test_circular_arc_camber(m):
    length, sagitta, d = 2.4, 0.2, 0.18
    s, z = arc_section(m, length, sagitta)
    n_sec = 3
    x = np.zeros((n_sec, m, 3))
    x[:, :, 0] = s
    x[:, :, 2] = z
    x[:, :, 1] = np.array([1.0, 0.0, -1.0])[:, None]
    q = random_rotation(np.random.default_rng(7))
    g = section_geometry(x @ q.T, np.full(n_sec, d))
    c = length + d / 2
    # Eq. (6): the largest node height above the chord line; with an odd node count the mid node is the apex,
    # with m = 6 the apex is not sampled and the two middle nodes (arc angle +-half/5) are highest
    radius = (length**2 / 4 + sagitta**2) / (2 * sagitta)
    half = np.arcsin(length / (2 * radius))
    kappa_expected = sagitta / c if m % 2 else (radius * np.cos(half / 5) - (radius - sagitta)) / c
    np.testing.assert_allclose(g.kappa, kappa_expected, rtol=1e-13)
    np.testing.assert_allclose(g.chord, c, rtol=1e-14)
    np.testing.assert_allclose(g.zeta[0], z / c, atol=1e-14)


def test_negative_camber_gives_zero_kappa():
    # Eq. (6) takes the max over all nodes incl. LE and TE (height 0): a canopy bulging to -e_z gives kappa = 0
    s, z = arc_section(6, 2.0, 0.15)
    x = np.zeros((3, 6, 3))
    x[:, :, 0] = s
    x[:, :, 2] = -z
    x[:, :, 1] = np.array([1.0, 0.0, -1.0])[:, None]
    np.testing.assert_allclose(section_geometry(x, np.full(3, 0.1)).kappa, 0.0, atol=1e-15)


def test_e_y_towards_right_tip_on_c_arc():
    x, phi, ex, tangent, radial = c_wing()
    g = section_geometry(x, np.full(len(phi), 0.2))
    assert np.all(g.e_y[:, 1] > 0.0)
    # the cambered sections are radial planes of the arc: e_y is their normal = the arc tangent, at every
    # section including the tips (where a one-sided LE difference would be half an arc step off)
    np.testing.assert_allclose(g.e_y, tangent, atol=1e-13)
    np.testing.assert_allclose(g.e_x, ex, atol=1e-14)
    np.testing.assert_allclose(g.e_z, radial, atol=1e-13)
    # a flat section (no camber) has no plane of its own: e_y falls back to the LE-line direction
    xf = x.copy()
    xf[:, 1:-1] = x[:, :1] + np.linspace(0, 1, x.shape[1])[None, 1:-1, None] * (x[:, -1:] - x[:, :1])
    gf = section_geometry(xf, np.full(len(phi), 0.2))
    np.testing.assert_allclose(gf.e_y[1:-1], tangent[1:-1], atol=1e-14)
    dphi = phi[0] - phi[1]
    assert np.allclose(np.einsum("ij,ij->i", gf.e_y[[0, -1]], tangent[[0, -1]]), np.cos(dphi / 2), atol=1e-12)
    # camber measured along e_z: parabola 4 b s (1 - s) sampled at s = 0.4, 0.6 (m = 6), chord + d/2
    chord_nodes = np.linalg.norm(x[:, -1] - x[:, 0], axis=1)
    np.testing.assert_allclose(g.kappa[1:-1], (0.08 * 0.96 * chord_nodes / (chord_nodes + 0.1))[1:-1], rtol=1e-12)


def test_e_y_is_continuous_when_the_mean_offset_turns_into_the_span():
    # A section of a slack canopy whose nodes are displaced sideways: its mean offset from the chord line turns
    # from the camber direction (e_z) into the span (e_y). The "plane" of chord and offset then contains the span,
    # and its normal crosses 90 deg from the LE tangent, where its orientation flips. e_y and the angle of attack
    # must not jump there (a 12 deg jump of alpha made Newton cycle between the two sides; docs/model.md,
    # "Section frame, fold contact, rotary inertia").
    from kite_env.aero.loads import section_loads
    m, chord, mag = 6, 2.0, 0.01  # mean offset 0.5 % of the chord: a quarter into the flat-section blend
    s = np.linspace(0.0, chord, m)
    bump = np.sin(np.pi * s / chord)
    bump *= mag / bump.mean()

    def section(phi):
        x = np.zeros((1, m, 3))
        x[0, :, 0] = s
        x[0, :, 1] = np.sin(phi) * bump
        x[0, :, 2] = np.cos(phi) * bump
        return x

    phis = np.radians(np.linspace(0.0, 180.0, 721))
    span = np.array([[0.0, 1.0, 0.0]])
    ey = np.array([section_geometry(section(p), np.full(1, 0.1), spanwise=span).e_y[0] for p in phis])
    step = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", ey[1:], ey[:-1]), -1.0, 1.0)))
    assert step.max() < 0.5  # 0.25 deg steps of the offset's direction; before: a 21 deg jump at 90 deg
    # an offset in the camber direction keeps the plane normal (the tips of a C wing), one along the span gives
    # the LE tangent, the blend only between 30 and 60 deg
    near = phis <= np.radians(30.0)
    n_pl = np.stack([np.zeros(near.sum()), np.cos(phis[near]), -np.sin(phis[near])], axis=1)  # offset x chord
    w = 0.25**2 * (3.0 - 2.0 * 0.25)  # the flat-section weight of a 0.5 % offset (threshold 2 %)
    expect = w * n_pl + (1.0 - w) * span
    np.testing.assert_allclose(ey[near], expect / np.linalg.norm(expect, axis=1)[:, None], atol=1e-13)
    side = (phis >= np.radians(60.0)) & (phis <= np.radians(120.0))
    np.testing.assert_allclose(ey[side], np.tile([0.0, 1.0, 0.0], (int(side.sum()), 1)), atol=1e-14)
    # the compiled kernel and the reference agree, and alpha has no jump either
    wind = np.array([[20.0, 0.0, 3.0]])
    alpha = {b: np.array([section_loads(section(p), np.full(1, 0.1), np.full(1, 0.5), np.zeros(3), np.zeros(3),
                                        wind, 1.225, backend=b).alpha[0] for p in phis]) for b in ("numba", "numpy")}
    np.testing.assert_allclose(alpha["numba"], alpha["numpy"], atol=1e-12)
    assert np.max(np.abs(np.diff(np.degrees(alpha["numpy"])))) < 0.5


def test_section_order_does_not_change_frames():
    x, *_ = c_wing(n_sec=9)
    d = np.linspace(0.1, 0.2, 9)
    g = section_geometry(x, d)
    g_rev = section_geometry(x[::-1], d[::-1])
    for a, b in ((g.e_x, g_rev.e_x), (g.e_y, g_rev.e_y), (g.e_z, g_rev.e_z), (g.kappa, g_rev.kappa), (g.t, g_rev.t)):
        np.testing.assert_allclose(a, b[::-1], atol=1e-15)


# --------------------------------------------------------------------------- inflow (Eq. 2-3)
def alpha_of(x, v_kite=None, omega=None, v_wind=None, x_prev=None, dt=None, d=0.2):
    v_kite, omega, v_wind = (np.zeros(3) if a is None else a for a in (v_kite, omega, v_wind))
    g = section_geometry(x, np.full(x.shape[0], d))
    u_loc, alpha = inflow(apparent_wind(x, v_kite, omega, v_wind, x_prev, dt), g)
    return alpha, u_loc


def test_alpha_equals_set_up_angle():
    twist = np.deg2rad([-4.0, 2.0, 0.0, 7.0, 12.0])
    x = flat_wing(twist=twist)
    for a0 in np.deg2rad([-30.0, -5.0, 0.0, 3.0, 10.0, 60.0]):
        for beta in np.deg2rad([0.0, 25.0]):  # sideslip along the span does not change alpha (projection)
            flow = 20.0 * np.array([np.cos(a0) * np.cos(beta), np.sin(beta), np.sin(a0) * np.cos(beta)])
            alpha, u_loc = alpha_of(x, v_wind=flow)  # kite at rest, wind = flow seen by the wing
            np.testing.assert_allclose(alpha, a0 + twist, atol=1e-13)
            np.testing.assert_allclose(u_loc[:, 0] ** 2 + u_loc[:, 2] ** 2, (20.0 * np.cos(beta)) ** 2, rtol=1e-13)
            # same flow from flying at -flow through still air (Eq. 2: v_k - v_w)
            np.testing.assert_allclose(alpha_of(x, v_kite=-flow)[0], a0 + twist, atol=1e-13)


def test_alpha_invariant_under_rigid_rotation():
    rng = np.random.default_rng(3)
    x, *_ = c_wing(n_sec=11)
    wind = np.array([18.0, 2.0, 3.0])
    alpha0, _ = alpha_of(x, v_wind=wind)
    q = random_rotation(rng)
    alpha1, _ = alpha_of(x @ q.T, v_wind=q @ wind)
    np.testing.assert_allclose(alpha1, alpha0, atol=1e-13)


def test_rotation_term_of_eq2_roll_and_yaw():
    x = flat_wing(n_sec=7, span=8.0)
    y = x[:, 0, 1]
    V, p = 20.0, 1.5
    wind = np.array([V, 0.0, 0.0])
    # roll about x_k: the right wing (y > 0) moves up (+z), sees flow from above -> smaller alpha
    alpha, _ = alpha_of(x, omega=np.array([p, 0.0, 0.0]), v_wind=wind)
    np.testing.assert_allclose(alpha, np.arctan2(-p * y, V), atol=1e-14)
    assert alpha[0] < 0 < alpha[-1]
    # yaw about z_k: no alpha change, in-plane speed V + r y (right wing moves backwards, into less flow)
    r = 0.7
    alpha, u_loc = alpha_of(x, omega=np.array([0.0, 0.0, r]), v_wind=wind)
    np.testing.assert_allclose(alpha, 0.0, atol=1e-15)
    np.testing.assert_allclose(u_loc[:, 0], V + r * y, rtol=1e-14)
    # the rotation term uses the LE node r_i1: a pitch rate about y_k with the LE nodes at x = 0 changes nothing
    alpha, _ = alpha_of(x, omega=np.array([0.0, 0.9, 0.0]), v_wind=wind)
    np.testing.assert_allclose(alpha, 0.0, atol=1e-15)


def test_deformation_velocity_eq3():
    x = flat_wing(n_sec=5, chord=2.0)
    V, dt, h = 20.0, 0.05, 0.1
    wind = np.array([V, 0.0, 0.0])
    # plunge: the wing moved down by h during dt -> flow from below -> alpha = atan(h/dt / V)
    x_prev = x + np.array([0.0, 0.0, h])
    alpha, _ = alpha_of(x, v_wind=wind, x_prev=x_prev, dt=dt)
    np.testing.assert_allclose(alpha, np.arctan2(h / dt, V), atol=1e-14)
    # without dt (or without previous positions) no deformation velocity
    np.testing.assert_allclose(alpha_of(x, v_wind=wind, x_prev=x_prev)[0], 0.0, atol=1e-15)
    # pitch about the chord midpoint: LE and TE displacements cancel in the average of Eq. (3)
    th = 0.1
    rot = np.array([[np.cos(th), 0.0, np.sin(th)], [0.0, 1.0, 0.0], [-np.sin(th), 0.0, np.cos(th)]])
    mid = np.array([1.0, 0.0, 0.0])
    x_prev = (x - mid) @ rot.T + mid
    alpha, _ = alpha_of(x, v_wind=wind, x_prev=x_prev, dt=dt)
    np.testing.assert_allclose(alpha, 0.0, atol=1e-14)
    # pitch about the LE node: only the TE node moved, Eq. (3) takes half its velocity
    x_prev = x @ rot.T
    u_te = (x[:, -1] - x_prev[:, -1]) / dt
    alpha, _ = alpha_of(x, v_wind=wind, x_prev=x_prev, dt=dt)
    flow = wind - 0.5 * u_te  # flow seen by the wing: -(u_i - v_w)
    np.testing.assert_allclose(alpha, np.arctan2(flow[:, 2], flow[:, 0]), atol=1e-14)


def test_mirror_symmetry():
    x, *_ = c_wing(n_sec=13)
    d = np.linspace(0.15, 0.25, 13)
    d = 0.5 * (d + d[::-1])
    xm = x @ MIRROR  # mirror image about the x-z plane (right and left swap)
    assert np.allclose(xm[::-1], x, atol=1e-14)  # the wing is symmetric
    g = section_geometry(x, d)
    np.testing.assert_allclose(g.e_x, g.e_x[::-1] @ MIRROR, atol=1e-14)
    np.testing.assert_allclose(g.e_z, g.e_z[::-1] @ MIRROR, atol=1e-14)
    np.testing.assert_allclose(g.e_y, -g.e_y[::-1] @ MIRROR, atol=1e-14)  # both point towards the right tip
    np.testing.assert_allclose(g.kappa, g.kappa[::-1], atol=1e-15)
    # symmetric flow (no sideslip, pitch rate only): mirrored alpha
    wind = np.array([20.0, 0.0, 4.0])
    alpha, _ = alpha_of(x, omega=np.array([0.0, 0.4, 0.0]), v_wind=wind)
    np.testing.assert_allclose(alpha, alpha[::-1], atol=1e-14)
    # asymmetric flow: sideslip + roll + yaw; the mirrored state (v_y, omega_x, omega_z reversed) mirrors alpha
    v = np.array([20.0, 5.0, 4.0])
    om = np.array([0.8, 0.4, -0.6])
    alpha, _ = alpha_of(x, omega=om, v_wind=v)
    alpha_m, _ = alpha_of(x, omega=om * np.array([-1.0, 1.0, -1.0]), v_wind=MIRROR @ v)
    np.testing.assert_allclose(alpha, alpha_m[::-1], atol=1e-14)
    assert np.ptp(alpha - alpha[::-1]) > 1e-3  # the asymmetric state is really asymmetric


def test_per_section_wind_and_shapes():
    x, *_ = c_wing(n_sec=7)
    winds = np.column_stack([np.linspace(10, 20, 7), np.zeros(7), np.linspace(0, 3, 7)])
    alpha, _ = alpha_of(x, v_wind=winds)
    for i in (0, 3, 6):
        np.testing.assert_allclose(alpha[i], alpha_of(x, v_wind=winds[i])[0][i], atol=1e-15)
    assert alpha.shape == (7,)
