"""The woven-fabric canopy (structure.canopy_shear_ratio): a balanced orthotropic plane-stress law with a low
in-plane shear modulus, relaxed by tension-field theory for any material matrix
(kite_env.structure.shell_membrane.fabric_matrix, relaxed_general; docs/steering.md, "Where a steering input goes")."""

import numpy as np
import pytest
from scipy.optimize import minimize

from kite_env.config import ConfigError, load_config
from kite_env.geometry import build_kite
from kite_env.structure.rotations import expm
from kite_env.structure.shell import ShellSet
from kite_env.structure.shell_membrane import (
    SLACK,
    TAUT,
    WRINKLED,
    fabric_matrix,
    plane_stress_matrix,
    relaxed_general,
    relaxed_svk,
)

from test_shell_helpers import fd_tangent

E_CANOPY, NU, H_CANOPY = 1250e6, 0.3, 0.08e-3  # paper Sect. II.A


def _strains(n, seed=0):
    return np.random.default_rng(seed).normal(size=(n, 3)) * 1e-3


def test_the_general_relaxed_law_of_an_isotropic_matrix_is_the_isotropic_law():
    """With the isotropic matrix the wrinkle direction is the minor principal strain's and the general law gives
    the classical three states (relaxed_svk) to round-off."""
    Ev = _strains(600)
    Y, nu = np.full(600, E_CANOPY), np.full(600, NU)
    C = plane_stress_matrix(Y, nu)
    ref = relaxed_svk(Ev, Y, nu, C, 1e-3, True)
    got = relaxed_general(Ev, C, 1e-3)
    assert np.array_equal(got[3], ref[3])
    assert set(np.unique(ref[3])) == {TAUT, WRINKLED, SLACK}
    for a, b in zip(got[:3], ref[:3]):
        assert np.max(np.abs(a - b)) < 1e-12 * np.max(np.abs(b))


def test_the_fabric_matrix_has_the_textbook_bias_modulus():
    """Uniaxial stress along a direction at angle t to the warp: ``1 / E_t = c^4 / E + s^4 / E + c^2 s^2 (1 / G -
    2 nu / E)`` (orthotropic plate, e.g. Jones, Mechanics of Composite Materials, Eq. 2.98); at 45 deg (the bias)
    a fabric with a tenth of the isotropic shear modulus stretches 3.4 times as much as along its threads."""
    r = 0.1
    G = r * E_CANOPY / (2 * (1 + NU))
    for warp in (0.0, 0.4, 1.3):
        for t in (0.0, np.pi / 8, np.pi / 4):
            C = fabric_matrix(np.array([E_CANOPY]), np.array([NU]), r, np.array([warp]))[0]
            Sc = np.linalg.inv(C)  # compliance in the element axes; uniaxial stress along angle warp + t
            a = warp + t
            sig = np.array([np.cos(a) ** 2, np.sin(a) ** 2, np.sin(a) * np.cos(a)])
            e = Sc @ sig
            strain_along = e[0] * np.cos(a) ** 2 + e[1] * np.sin(a) ** 2 + e[2] * np.sin(a) * np.cos(a)
            c, s = np.cos(t), np.sin(t)
            expected = c**4 / E_CANOPY + s**4 / E_CANOPY + c**2 * s**2 * (1 / G - 2 * NU / E_CANOPY)
            assert strain_along == pytest.approx(expected, rel=1e-12)
    # shear ratio 1: the isotropic matrix whatever the warp
    C1 = fabric_matrix(np.full(3, E_CANOPY), np.full(3, NU), 1.0, np.array([0.0, 0.7, 2.0]))
    assert np.allclose(C1, plane_stress_matrix(np.full(3, E_CANOPY), np.full(3, NU)), rtol=1e-13, atol=1e-3)


def _brute_force_relaxed_energy(E, C, rng):
    """``min_{P >= 0} W(E + P)`` by unconstrained minimisation over ``P = L L^T`` from several starts."""

    def W(x):
        L = np.array([[x[0], 0.0], [x[1], x[2]]])
        P = L @ L.T
        e = E + np.array([P[0, 0], P[1, 1], 2.0 * P[0, 1]])
        return 0.5 * e @ C @ e / E_CANOPY

    best = np.inf
    for _ in range(8):
        res = minimize(W, rng.normal(size=3) * np.sqrt(np.max(np.abs(E))), method="BFGS", options={"gtol": 1e-16})
        best = min(best, res.fun)
    return best * E_CANOPY


def test_the_relaxed_fabric_law_is_the_minimum_over_wrinkle_strains_with_its_exact_derivatives():
    """For an orthotropic fabric (threads at random angles) the relaxed energy is the minimum of the elastic energy
    over positive semi-definite wrinkle strains (checked by direct minimisation), the stress its gradient and the
    tangent the stress's derivative (central differences), and a wrinkled element carries uniaxial tension."""
    rng = np.random.default_rng(3)
    n = 300
    Ev = _strains(n, seed=4)
    C = fabric_matrix(np.full(n, E_CANOPY), np.full(n, NU), 0.05, rng.uniform(0.0, np.pi, n))
    W, S, D, state = relaxed_general(Ev, C, 0.0)
    assert set(np.unique(state)) == {TAUT, WRINKLED, SLACK}
    for i in range(30):
        W_min = _brute_force_relaxed_energy(Ev[i], C[i], rng)
        assert W[i] == pytest.approx(W_min, rel=1e-7, abs=1e-9 * E_CANOPY * 1e-6)
    h = 1e-9
    for j in range(3):
        dE = np.zeros(3)
        dE[j] = h
        Wp, Sp, _, _ = relaxed_general(Ev + dE, C, 0.0)
        Wm, Sm, _, _ = relaxed_general(Ev - dE, C, 0.0)
        assert np.max(np.abs((Wp - Wm) / (2 * h) - S[:, j])) < 1e-7 * np.max(np.abs(S))
        assert np.max(np.abs((Sp - Sm) / (2 * h) - D[:, :, j])) < 1e-6 * np.max(np.abs(D))
    wr = state == WRINKLED
    Smat = np.stack([S[wr, 0], S[wr, 2], S[wr, 2], S[wr, 1]], axis=-1).reshape(-1, 2, 2)
    lam = np.linalg.eigvalsh(Smat)
    assert np.all(lam[:, 1] > 0.0) and np.max(np.abs(lam[:, 0]) / lam[:, 1]) < 1e-10
    # the isotropic law's states differ: the low shear modulus moves elements between taut and wrinkled
    Ci = plane_stress_matrix(np.full(n, E_CANOPY), np.full(n, NU))
    assert np.any(relaxed_general(Ev, Ci, 0.0)[3] != state)


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_the_fabric_canopy_tangent_matches_finite_differences(backend):
    """The kite's canopy with a woven fabric (a twentieth of the isotropic shear modulus), deformed at random: the
    element tangent is the derivative of the element force (central differences on the translations)."""
    mesh = build_kite("rhino16", n_sections=37, n_chord=6)
    rng = np.random.default_rng(5)
    x = (mesh.nodes + 0.02 * rng.normal(size=mesh.nodes.shape))[mesh.shells][:40]
    R = expm(0.1 * rng.normal(size=(mesh.n_nodes, 3)))[mesh.shells][:40]
    sub = ShellSet(np.arange(120).reshape(40, 3), mesh.nodes[mesh.shells][:40].reshape(-1, 3), E_CANOPY, NU,
                   H_CANOPY, shear_ratio=0.05, backend=backend)  # 40 of the kite's triangles, threads along x
    assert set(np.unique(sub.stresses(x)["state"])) == {TAUT, WRINKLED, SLACK}
    f, K = sub.internal(x, R)
    cols = np.array([0, 1, 2, 6, 7, 8, 12, 13, 14])
    Kfd = fd_tangent(lambda xe, Re: sub.internal(xe, Re)[0], x, R)[:, :, cols]
    err = np.max(np.abs(K[:, :, cols] - Kfd)) / np.max(np.abs(Kfd))
    assert err < 1e-5


def test_the_warp_follows_the_chord_and_a_bad_ratio_is_one_clear_error():
    """The threads lie along frame K's x (the chord) projected onto each triangle; ``canopy_shear_ratio`` must lie
    in (0, 1] (one error naming the key)."""
    mesh = build_kite("rhino16", n_sections=37, n_chord=6)
    s = ShellSet(mesh.shells, mesh.nodes, E_CANOPY, NU, H_CANOPY, shear_ratio=0.3)
    warp_K = np.einsum("nia,na->ni", s.R0[:, :, :2], np.stack([np.cos(s.warp_angle), np.sin(s.warp_angle)], -1))
    normal = s.R0[:, :, 2]
    x_in_plane = np.array([1.0, 0.0, 0.0]) - normal[:, 0:1] * normal
    x_in_plane /= np.linalg.norm(x_in_plane, axis=1)[:, None]
    assert np.allclose(warp_K, x_in_plane, atol=1e-12)
    assert ShellSet(mesh.shells, mesh.nodes, E_CANOPY, NU, H_CANOPY).warp_angle is None  # isotropic: no threads
    for bad in ("0", "1.5", "-0.2"):
        with pytest.raises(ConfigError, match="structure.canopy_shear_ratio"):
            load_config(None, [f"structure.canopy_shear_ratio={bad}"])
