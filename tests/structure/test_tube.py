"""Breukels' inflated-tube correlations (Breukels 2011; the paper's Sect. II.A, its ref. [9]) against a table of them
evaluated independently of kite_env.structure.tube, with the constants C1..C19 of awegroup/kite_fem and
awegroup/Billow."""

import numpy as np
import pytest

from kite_env.structure import tube

# p [bar], d [m], D=M_max, N, EI0, v_collapse, c1, c2, GJ0  (Breukels' correlations evaluated independently)
TABLE = [
    (0.15, 0.112, 23.6, 251.0, 83.7, 0.0670, 55.12, 0.485, 26.7),
    (0.30, 0.160, 58.1, 864.7, 288.2, 0.0917, 79.54, 1.148, 91.3),
    (0.50, 0.160, 98.8, 1086.1, 362.0, 0.0991, 111.20, 0.778, 86.5),
    (0.25, 0.200, 79.3, 1546.8, 515.6, 0.1140, 75.13, 2.904, 218.2),
]


@pytest.mark.parametrize("row", TABLE)
def test_correlations_reproduce_table(row):
    p_bar, d, D, N, EI0, v_col, c1, c2, GJ0 = row
    pr = tube.tube_properties(p_bar * tube.PA_PER_BAR, np.array([d]))
    assert pr.M_max[0] == pytest.approx(D, abs=0.06)
    assert pr.EI0[0] == pytest.approx(EI0, abs=0.06)
    assert pr.kappa_collapse[0] / 3.0 == pytest.approx(v_col, abs=6e-5)
    assert pr.c1[0] == pytest.approx(c1, abs=6e-3)
    assert pr.c2[0] == pytest.approx(c2, abs=6e-4)
    assert pr.GJ0[0] == pytest.approx(GJ0, abs=0.06)


def test_moment_curvature_law_limits_and_secant():
    pr = tube.tube_properties(0.3e5, np.array([0.16]))
    k = np.array([1e-12, 1e-6, 0.1, 1.0, 100.0])
    M = tube.bending_moment(pr, k)
    # initial slope EI0, saturation at M_max, secant consistent with M/kappa
    assert M[1] / k[1] == pytest.approx(pr.EI0[0], rel=1e-5)
    assert M[-1] == pytest.approx(pr.M_max[0], rel=1e-9)
    assert np.allclose(tube.secant_EI(pr, k[1:]) * k[1:], M[1:])
    assert tube.secant_EI(pr, 0.0)[()] == pytest.approx(pr.EI0[0])
    assert np.all(np.diff(tube.secant_EI(pr, k)) <= 0)  # softening
    assert tube.bending_moment(pr, -0.1) == pytest.approx(-tube.bending_moment(pr, 0.1))
    # torsion: secant times twist is the torque, initial stiffness GJ0
    phi = np.array([1e-4, 0.5, 3.0])
    assert np.allclose(tube.secant_GJ(pr, phi) * phi, tube.torque(pr, phi))
    assert tube.secant_GJ(pr, 0.0)[()] == pytest.approx(pr.GJ0[0])


def test_stiffness_grows_with_pressure_and_diameter():
    lo = tube.tube_properties(0.15e5, np.array([0.12, 0.16]))
    hi = tube.tube_properties(0.50e5, np.array([0.12, 0.16]))
    assert np.all(hi.EI0 > lo.EI0) and np.all(hi.M_max > lo.M_max)
    assert lo.EI0[1] > lo.EI0[0]


def test_collapse_flag_and_bad_input():
    pr = tube.tube_properties(0.3e5, np.array([0.16]))
    assert not tube.collapsed(pr, 0.5 * pr.kappa_collapse)[0]
    assert tube.collapsed(pr, 1.5 * pr.kappa_collapse)[0]
    with pytest.raises(ValueError, match="pressure"):
        tube.tube_properties(0.0, np.array([0.1]))
    with pytest.raises(ValueError, match="non-physical"):
        tube.tube_properties(0.3e5, np.array([0.02]))


def test_energy_densities_integrate_the_moment_and_torque_laws():
    pr = tube.tube_properties(0.3e5, np.array([0.16]))
    for k in (1e-4, 0.05, 0.3, 2.0):
        h = 1e-6 * max(k, 1e-3)
        dW = (tube.bending_energy_density(pr, k + h) - tube.bending_energy_density(pr, k - h)) / (2 * h)
        assert dW[0] == pytest.approx(tube.bending_moment(pr, k)[0], rel=1e-6)
        dT = (tube.torsion_energy_density(pr, k + h) - tube.torsion_energy_density(pr, k - h)) / (2 * h)
        assert dT[0] == pytest.approx(tube.torque(pr, k)[0], rel=1e-6)
    assert tube.bending_energy_density(pr, 0.0)[0] == 0.0 and tube.torsion_energy_density(pr, 0.0)[0] == 0.0


def test_element_curvature_measures():
    # uniform bending (th2 = -th1): both measures give the exact |th2 - th1| / L0; a linear curvature ramp
    # (th2 = 0) has the rms below the larger end value
    th1 = np.array([[0.0, 0.02, -0.01]])
    for measure in tube.CURVATURE_MEASURES:
        k = tube.element_curvature(th1, -th1, np.array([0.5]), measure)
        assert k[0] == pytest.approx(np.linalg.norm(2 * th1[0, 1:]) / 0.5, rel=1e-12)
    # th2 = 0: the curvature runs from -4 th1 / L0 to 2 th1 / L0; rms 2 |th1| / L0, larger end 4 |th1| / L0
    rms, end = (tube.element_curvature(th1, 0 * th1, np.array([0.5]), m)[0] for m in tube.CURVATURE_MEASURES)
    assert rms == pytest.approx(2 * np.linalg.norm(th1[0, 1:]) / 0.5, rel=1e-12)
    assert end == pytest.approx(4 * np.linalg.norm(th1[0, 1:]) / 0.5, rel=1e-12)
    with pytest.raises(ValueError, match="tube curvature measure"):
        tube.element_curvature(th1, th1, np.array([0.5]), "mean")


def _fold_props(onset=np.pi / 2):
    return tube.tube_properties(0.3e5, np.array([0.16]), np.array([0.2655]), onset)


def test_fold_contact_leaves_breukels_law_below_its_onset_and_closes_the_fold_at_pi():
    pr, bare = _fold_props(), tube.tube_properties(0.3e5, np.array([0.16]))
    L0, Mm = 0.2655, pr.M_max[0]
    k_on, k_pi = (np.pi / 2) / L0, np.pi / L0
    below = np.array([1e-3, 0.5, 2.0, 0.999 * k_on])
    np.testing.assert_array_equal(tube.bending_moment(pr, below), tube.bending_moment(bare, below))
    np.testing.assert_array_equal(tube.bending_energy_density(pr, below), tube.bending_energy_density(bare, below))
    M_c, dM_c, W_c = tube.fold_contact(pr, np.array([k_on, 0.5 * (k_on + k_pi)]))
    assert M_c[0] == 0.0 and dM_c[0] == 0.0 and W_c[0] == 0.0  # sets in with zero slope
    assert M_c[1] == pytest.approx(Mm, rel=1e-12)  # M_max half-way to the closure
    # grows without bound towards the closure, then linearly (finite for an iterate beyond pi)
    k = np.linspace(k_on, 1.2 * k_pi, 400)
    M = tube.fold_contact(pr, k)[0]
    assert np.all(np.diff(M) > 0.0) and np.all(np.isfinite(M))
    assert tube.fold_contact(pr, np.array([0.99 * k_pi]))[0][0] > 50 * Mm
    # the contact's energy integrates its moment (C1 at the onset and at the start of the linear part)
    for kk in (1.01 * k_on, 0.5 * (k_on + k_pi), k_on + 0.89 * (k_pi - k_on), k_on + 0.91 * (k_pi - k_on), 1.1 * k_pi):
        h = 1e-7 * kk
        dW = (tube.fold_contact(pr, np.array([kk + h]))[2] - tube.fold_contact(pr, np.array([kk - h]))[2]) / (2 * h)
        assert dW[0] == pytest.approx(tube.fold_contact(pr, np.array([kk]))[0][0], rel=1e-6)
        dM = (tube.fold_contact(pr, np.array([kk + h]))[0] - tube.fold_contact(pr, np.array([kk - h]))[0]) / (2 * h)
        assert dM[0] == pytest.approx(tube.fold_contact(pr, np.array([kk]))[1][0], rel=1e-6)
    with pytest.raises(ValueError, match="fold contact"):
        tube.tube_properties(0.3e5, np.array([0.16]), np.array([0.2655]), np.pi)


def _tube_chain(measure, fold_onset=None):
    """Four tube elements of a bent, twisted inflated tube (0.3 bar, 0.16-0.2 m) at a strongly deformed state,
    the secant law evaluated there: ``(beams, props, x_e, R_e, update)`` with ``update(x_e, R_e)`` setting the
    secant stiffness (and, for ``element_energy``, its material tangent terms) of a state. ``fold_onset`` [rad]:
    with the fold contact from that element fold angle."""
    from kite_env.structure.beam import BeamSet
    from kite_env.structure.rotations import expm

    rng = np.random.default_rng(4)
    s = np.linspace(0.0, 1.6, 5)
    X = np.stack([s, 0.3 * np.sin(s), 0.1 * s**2], axis=1)
    conn = np.stack([np.arange(4), np.arange(1, 5)], axis=1)
    L0 = np.linalg.norm(X[1:] - X[:-1], axis=1)
    props = tube.tube_properties(0.3e5, np.linspace(0.16, 0.2, 4), None if fold_onset is None else L0, fold_onset)
    bs = BeamSet(conn, X, [0.0, 0.0, 1.0], 3e4, props.EI0, props.EI0, props.GJ0, backend="numpy")
    x = X + 0.03 * rng.normal(size=X.shape)
    R = expm(0.25 * rng.normal(size=X.shape))  # curvatures up to ~1/m: secants well below EI0

    def update(x_e, R_e):
        loc = bs.local_deformation(x_e, R_e)
        k = tube.element_curvature(loc["theta1"], loc["theta2"], bs.L0, measure)
        phi = np.abs(loc["theta2"][:, 0] - loc["theta1"][:, 0]) / bs.L0
        g = tube.secant_material_terms(props, k, phi, bs.L0) if measure == "element_energy" else (None, None)
        bs.set_bending_torsion(np.arange(4), tube.secant_EI(props, k), tube.secant_GJ(props, phi), *g)
        return k, phi

    return bs, props, x[conn], R[conn], update


def _perturbed(x_e, R_e, j, h):
    from kite_env.structure.rotations import expm

    x2, R2 = x_e.copy(), R_e.copy()
    a, i = divmod(j, 6)
    if i < 3:
        x2[:, a, i] += h
    else:
        e = np.zeros(3)
        e[i - 3] = h
        R2[:, a] = expm(np.broadcast_to(e, (len(x2), 3))) @ R2[:, a]
    return x2, R2


def _tube_energy(bs, props, update, x_e, R_e):
    k, phi = update(x_e, R_e)
    l = np.linalg.norm(x_e[:, 1] - x_e[:, 0], axis=1)
    return bs.L0 * (tube.bending_energy_density(props, k) + tube.torsion_energy_density(props, phi)) \
        + 0.5 * bs.EA / bs.L0 * (l - bs.L0) ** 2


@pytest.mark.parametrize("measure", tube.CURVATURE_MEASURES)
def test_secant_tube_forces_are_the_gradient_of_a_stored_energy_only_with_the_element_energy_curvature(measure):
    # f = dU/dd with U = L0 (W(kappa) + W_t(phi)) + EA/2L0 (l - L0)^2: the element is elastic (conservative). The
    # larger-end curvature (max_end) is no function of the element's energy: its forces are not a
    # gradient, and a free wing integrated with it gained energy from nothing
    bs, props, x_e, R_e, update = _tube_chain(measure)
    update(x_e, R_e)
    f = bs.internal(x_e, R_e)[0]
    h = 1e-6
    g = np.stack([(_tube_energy(bs, props, update, *_perturbed(x_e, R_e, j, h))
                   - _tube_energy(bs, props, update, *_perturbed(x_e, R_e, j, -h))) / (2 * h) for j in range(12)],
                 axis=1)
    err = np.abs(f - g).max() / np.abs(f).max()
    if measure == "element_energy":
        assert err < 1e-7
    else:
        assert err > 1e-3


@pytest.mark.parametrize("fold", [False, True])
@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_secant_tube_tangent_is_consistent(backend, fold):
    # with the material terms g m m^T the element tangent is the exact derivative of its forces (the secant alone
    # missed 4 % of the rotational columns at a flight state); with the fold contact set in at 0.1 rad here, so
    # that elements of this chain are in it, the contact stiffens them (g_b > 0) and the tangent stays exact
    pytest.importorskip("numba") if backend == "numba" else None
    bs, props, x_e, R_e, update = _tube_chain("element_energy", 0.1 if fold else None)
    bs.backend = backend
    k = update(x_e, R_e)[0]
    f, K = bs.internal(x_e, R_e)
    if fold:
        assert np.any(tube.fold_contact(props, k)[0] > 0.0) and np.any(bs._kmat[:, 0] > 0.0)
    else:
        assert np.all(bs._kmat[:, 0] < 0.0) and np.all(bs._kmat[:, 1] < 0.0)
    h = 1e-6
    Kfd = np.empty_like(K)
    for j in range(12):
        fp = (update(*_perturbed(x_e, R_e, j, h)), bs.internal(*_perturbed(x_e, R_e, j, h))[0])[1]
        fm = (update(*_perturbed(x_e, R_e, j, -h)), bs.internal(*_perturbed(x_e, R_e, j, -h))[0])[1]
        Kfd[:, :, j] = (fp - fm) / (2 * h)
    assert np.abs(K - Kfd).max() < 1e-7 * np.abs(K).max()
    # the secant stiffness is well below the initial one here: the law is in its nonlinear range
    assert np.min(bs.EI2 / props.EI0) < 0.8
