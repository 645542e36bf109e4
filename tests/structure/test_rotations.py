import numpy as np

from kite_env.structure.rotations import expm, logm, skew, tangent_inv, unskew


def test_exp_log_roundtrip_and_orthonormal():
    rng = np.random.default_rng(0)
    th = rng.normal(size=(200, 3))
    th *= (rng.uniform(0, np.pi * 0.999, size=200) / np.linalg.norm(th, axis=1))[:, None]
    th[:5] *= 1e-9  # near-zero rotations
    R = expm(th)
    assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(logm(R), th, atol=1e-10)


def test_skew_is_cross_product():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(2, 10, 3))
    assert np.allclose(np.einsum("nij,nj->ni", skew(a), b), np.cross(a, b))
    assert np.allclose(unskew(skew(a)), a)


def test_tangent_inv_matches_finite_difference():
    rng = np.random.default_rng(2)
    for theta in [rng.normal(size=3), 1e-7 * rng.normal(size=3), 2.5 * np.array([0.0, 0.6, 0.8])]:
        Ti = tangent_inv(theta)
        h = 1e-7
        fd = np.zeros((3, 3))
        for k in range(3):
            dw = np.zeros(3)
            dw[k] = h
            fd[:, k] = (logm(expm(dw) @ expm(theta)) - logm(expm(-dw) @ expm(theta))) / (2 * h)
        assert np.allclose(Ti, fd, atol=1e-6)


def test_compiled_relative_rotation_vectors_match_logm():
    # the wing's rotations over a time step (kite_env.dynamics.wing_dynamics): the compiled loop against
    # logm(R1 R0^T), from round-off-sized rotations to nearly half a turn, on every branch of Shepperd's quaternion
    from kite_env.structure.rotation_kernels import relative_rotation_vectors

    rng = np.random.default_rng(3)
    R0 = expm(rng.normal(size=(300, 3)))
    th = rng.normal(size=(300, 3))
    th *= (np.geomspace(1e-12, 0.999 * np.pi, 300) / np.linalg.norm(th, axis=1))[:, None]
    R1 = expm(th) @ R0
    out = relative_rotation_vectors(R1, R0, np.empty((300, 3)))
    assert np.allclose(out, logm(np.einsum("nij,nkj->nik", R1, R0)), rtol=0, atol=1e-13)
    assert np.allclose(out, th, rtol=0, atol=1e-9)
