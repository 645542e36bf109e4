"""The compiled element kernels (kite_env.structure.*_kernels) against the NumPy reference implementations.

For random large-deformation states (taut, wrinkled and slack membranes; large and tiny rotations, so that every
series / closed-form branch of the rotation functions is taken) and for the real kite mesh, the numba and numpy
backends of ``BeamSet``, ``HemSet`` and ``ShellSet`` must give the same force, tangent and energy to 1e-10 relative
(they differ only by round-off).  The finite-difference tangent and wrinkling tests of ``test_beam.py`` and
``test_shell.py`` are run again through each backend explicitly.
"""

import numpy as np
import pytest

from kite_env import compiled
from kite_env.geometry import build_kite
from kite_env.geometry.mesh import BEAM_LE, BEAM_STRUT, BEAM_TE, BEAM_TIP
from kite_env.structure import assembly_kernels, beam_kernels, rotation_kernels, shell_kernels, tube_kernels
from kite_env.structure.beam import BeamSet
from kite_env.structure.hem import HemSet
from kite_env.structure.rotations import expm
from kite_env.structure.shell import SLACK, TAUT, WRINKLED, ShellSet
from kite_env.structure.shell_bending import element_frame, local_rotations

import test_beam as _tb  # sibling test modules: re-run their checks per backend
import test_hem as _th
import test_shell as _ts

RTOL = 1e-10
E_CANOPY, NU, H_CANOPY = 1250e6, 0.3, 0.08e-3


# ---------------------------------------------------------------------------------------------- helpers
def _per_element_rel(a, b, floor=0.0):
    """Largest ``max|a_e - b_e| / max(max|b_e|, floor_e)`` over elements ``e`` (leading axis)."""
    ax = tuple(range(1, a.ndim))
    scale = np.maximum(np.max(np.abs(b), axis=ax), floor)
    return np.max(np.max(np.abs(a - b), axis=ax) / scale)


def _force_floor(K, x):
    """Force scale below which ``f`` is cancellation noise: ``K`` times a relative displacement of 1e-5.

    Near the unloaded state ``f`` is a small difference of large terms (``l - L0`` of coordinates ``|x|``), so
    both backends carry an absolute round-off of ~1e-16 ``|K| |x|``; relative agreement is asked above this floor.
    """
    return 1e-5 * np.max(np.abs(K), axis=(1, 2)) * np.max(np.abs(x), axis=(1, 2))


def _assert_energy_agree(U, U_ref, K, x):
    floor = np.max(np.abs(K)) * (1e-5 * np.max(np.abs(x))) ** 2
    assert np.allclose(U, U_ref, rtol=RTOL, atol=RTOL * max(np.max(np.abs(U_ref)), floor))


def _pair(cls, *args, **kw):
    return cls(*args, backend="numba", **kw), cls(*args, backend="numpy", **kw)


def _assert_beams_agree(conn, X0, up, stiff, x, Rn):
    bn, bp = _pair(BeamSet, conn, X0, up, **stiff)
    xe, Re = x[conn], Rn[conn]
    f1, K1 = bn.internal(xe, Re)
    f2, K2 = bp.internal(xe, Re)
    assert f1.shape == f2.shape and K1.shape == K2.shape
    f3, K3 = bn.internal(xe, Re, tangent=False)  # residual only: the same forces bit for bit
    assert K3 is None and np.array_equal(f3, f1)
    assert _per_element_rel(f1, f2, _force_floor(K2, xe)) < RTOL
    assert _per_element_rel(K1, K2) < RTOL
    # energy of the kernel (not used by BeamSet.energy, which stays NumPy)
    n = bn.n_elem
    U = np.empty(n)
    beam_kernels.beam_internal(xe, Re, bn.R0, bn.L0, bn.EA, bn._k11, bn._k12, bn._kmat, np.empty((n, 12)),
                               np.empty((n, 12, 12)), U, True)  # every argument given, as BeamSet.internal does
    _assert_energy_agree(U, bp.energy(xe, Re), K2, xe)
    return bp.local_deformation(xe, Re)


def _assert_shells_agree(s_args, x, R, **kw):
    sn, sp = _pair(ShellSet, *s_args, **kw)
    f1, K1 = sn.internal(x, R)
    f2, K2 = sp.internal(x, R)
    assert _per_element_rel(f1, f2, _force_floor(K2, x)) < RTOL
    assert _per_element_rel(K1, K2) < RTOL
    # residual-only call (modified Newton): the same forces bit for bit, no tangent
    f3, K3 = sn.internal(x, R, tangent=False)
    assert K3 is None and np.array_equal(f3, f1)
    n = sn.n_elem
    U = np.empty(n)
    # every argument given, as ShellSet.internal gives them: an omitted default is another signature that numba
    # compiles anew (about 35 s per cold cache)
    shell_kernels.shell_internal(x, R, sn.R0, sn.G, sn.A0h, sn.E, sn.nu, sn.C, sn.K_l, sn.eps_slack, sn.membrane_law,
                                 sn.bending, np.empty((n, 18)), np.empty((n, 18, 18)), U, True, sn.von_karman)
    _assert_energy_agree(U, sp.energy(x, R), K2, x)
    U3 = np.empty(n)
    shell_kernels.shell_internal(x, R, sn.R0, sn.G, sn.A0h, sn.E, sn.nu, sn.C, sn.K_l, sn.eps_slack, sn.membrane_law,
                                 sn.bending, np.empty((n, 18)), np.empty((1, 18, 18)), U3, False, sn.von_karman)
    assert np.array_equal(U3, U)
    return sp


# ---------------------------------------------------------------------------------------------- backend switch
def test_resolve_backend(monkeypatch):
    monkeypatch.delenv(compiled.ENV_VAR, raising=False)
    assert compiled.resolve_backend("auto") == "numba"
    assert compiled.resolve_backend("numpy") == "numpy"
    monkeypatch.setenv(compiled.ENV_VAR, "numpy")
    assert compiled.resolve_backend("auto") == "numpy"
    assert compiled.resolve_backend("numba") == "numba"  # an explicit choice wins over the variable
    monkeypatch.setenv(compiled.ENV_VAR, "fortran")
    with pytest.raises(ValueError):
        compiled.resolve_backend("auto")
    with pytest.raises(ValueError):
        compiled.resolve_backend("cuda")


def test_thresholds_equal_reference_modules():
    """The kernels hard-code the branch thresholds of the reference functions (numba caches on each kernel's own
    file only)."""
    import inspect

    from kite_env.structure import beam, rotations, shell_bending, shell_membrane, tube

    assert rotation_kernels._ROT_SMALL == rotations._SMALL
    assert rotation_kernels._TSMALL == beam._TSMALL
    assert shell_kernels._TAUT_TOL == shell_membrane.TAUT_TOL
    assert shell_kernels._WRINKLE_MAX_ITER == shell_membrane._WRINKLE_MAX_ITER
    assert shell_kernels._WRINKLE_MAX_STEP == shell_membrane._WRINKLE_MAX_STEP
    assert shell_kernels._WRINKLE_STEP_TOL == shell_membrane._WRINKLE_STEP_TOL
    assert "small = t < 1e-4" in inspect.getsource(rotations.tangent_inv) and rotation_kernels._TINV_SMALL == 1e-4
    src = inspect.getsource(shell_bending._log_rotation)
    assert "small = s < 1e-4" in src and rotation_kernels._LOGROT_SMALL == 1e-4
    assert "far = c < 1e-3" in src and rotation_kernels._LOGROT_FAR == 1e-3
    assert tube_kernels._FOLD_LINEAR == tube._FOLD_LINEAR


def test_outputs_are_fresh_arrays_and_shapes_checked():
    """Callers (the finite-difference tests) keep the result of one call while making the next one."""
    rng = np.random.default_rng(0)
    bs, X0, conn = _tb.random_beams(rng, 4)
    bn = BeamSet(conn, X0, rng.normal(size=(4, 3)), EA=bs.EA, EI2=bs.EI2, EI3=bs.EI3, GJ=bs.GJ, backend="numba")
    x, Rn = _tb.deformed_state(rng, X0, 0.5)
    f1, K1 = bn.internal(x[conn], Rn[conn])
    f1c, K1c = f1.copy(), K1.copy()
    f2, _ = bn.internal(X0[conn], np.broadcast_to(np.eye(3), (len(X0), 3, 3))[conn])  # unloaded
    assert np.array_equal(f1, f1c) and np.array_equal(K1, K1c)
    assert np.max(np.abs(f2)) < 1e-12 * np.max(np.abs(f1))
    with pytest.raises(ValueError):
        bn.internal(x[conn][:2], Rn[conn][:2])


# ---------------------------------------------------------------------------------------------- beams
@pytest.mark.parametrize("rot_scale", [1e-9, 0.05, 1.0, 2.5])
def test_random_beams_agree(rot_scale):
    """Tiny (series of logm and T_s^-1), small (series of the T_s^-T derivative), large and very large rotations."""
    rng = np.random.default_rng(20)
    n = 40
    X0 = rng.normal(size=(2 * n, 3))
    conn = np.arange(2 * n).reshape(n, 2)
    stiff = dict(EA=rng.uniform(50, 200, n), EI2=rng.uniform(1, 5, n), EI3=rng.uniform(1, 5, n),
                 GJ=rng.uniform(1, 5, n))
    x = X0 + min(0.2, 0.2 * rot_scale) * rng.normal(size=X0.shape)
    Rn = expm(rot_scale * rng.normal(size=X0.shape))
    d = _assert_beams_agree(conn, X0, rng.normal(size=(n, 3)), stiff, x, Rn)
    t = np.linalg.norm(np.concatenate([d["theta1"], d["theta2"]]), axis=1)
    if rot_scale < 1e-6:
        assert np.max(t) < 1e-6
    elif rot_scale < 0.1:
        assert np.max(t) < 0.2  # all in the Taylor branch of beam._tinv_derivative_coeffs
    else:
        assert np.max(t) > (2.0 if rot_scale > 2 else 0.5)


@pytest.mark.parametrize("rot_scale", [0.0, 0.05, 1.0, 3.0])
def test_random_hem_rods_agree(rot_scale):
    """The frame-free hem rods at no, small, large and past-a-half-turn nodal rotations."""
    rng = np.random.default_rng(22)
    n = 36
    X0 = rng.normal(size=(2 * n, 3))
    conn = np.arange(2 * n).reshape(n, 2)
    stiff = dict(EA=rng.uniform(50, 200, n), EI=rng.uniform(1, 5, n), GJ=rng.uniform(1, 5, n))
    hn, hp = _pair(HemSet, conn, X0, rng.normal(size=(n, 3)), **stiff)
    x = X0 + 0.2 * rng.normal(size=X0.shape)
    xe, Re = x[conn], expm(rot_scale * rng.normal(size=X0.shape))[conn]
    f1, K1 = hn.internal(xe, Re)
    f2, K2 = hp.internal(xe, Re)
    assert f1.shape == f2.shape == (n, 12) and K1.shape == K2.shape == (n, 12, 12)
    assert _per_element_rel(f1, f2) < RTOL and _per_element_rel(K1, K2) < RTOL
    f3, K3 = hn.internal(xe, Re, tangent=False)  # residual only: the same forces bit for bit
    assert K3 is None and np.array_equal(f3, f1)
    with pytest.raises(ValueError):
        hn.internal(xe[:2], Re[:2])


def test_unloaded_and_rigidly_rotated_beams_agree():
    rng = np.random.default_rng(21)
    bs, X0, conn = _tb.random_beams(rng, 10)
    up = rng.normal(size=(10, 3))
    stiff = dict(EA=bs.EA, EI2=bs.EI2, EI3=bs.EI3, GJ=bs.GJ)
    Q = expm(np.array([1.3, -2.1, 0.7]))
    for x, Rn in ((X0, np.broadcast_to(np.eye(3), (len(X0), 3, 3))),
                  (X0 @ Q.T + 3.0, np.broadcast_to(Q, (len(X0), 3, 3)))):
        bn, bp = _pair(BeamSet, conn, X0, up, **stiff)
        _, K1 = bn.internal(x[conn], Rn[conn])
        _, K2 = bp.internal(x[conn], Rn[conn])
        assert _per_element_rel(K1, K2) < RTOL


@pytest.fixture(scope="module")
def kite():
    return build_kite("rhino16")


def _kite_beam_stiffness(mesh):
    """Order-of-magnitude section data per beam kind (only used to compare the backends)."""
    d = mesh.beam_diameter
    kind = mesh.beam_kind
    EA = np.where((kind == BEAM_LE) | (kind == BEAM_STRUT), 2e4 * np.pi * d, 1e9 * np.pi * d**2 / 4)
    EI = np.where((kind == BEAM_LE) | (kind == BEAM_STRUT), 50.0 * d, 1e9 * np.pi * d**4 / 64)
    EI = np.where(kind == BEAM_TE, 0.4, EI)
    return dict(EA=EA, EI2=EI, EI3=1.3 * EI, GJ=0.8 * EI)


@pytest.mark.parametrize("amp", [0.0, 0.02, 0.3])
def test_kite_mesh_beams_agree(kite, amp):
    """LE tube, struts, tip rods and TE wire of the rhino16 mesh (107 beams), unloaded and deformed."""
    assert {BEAM_LE, BEAM_STRUT, BEAM_TIP, BEAM_TE} <= set(kite.beam_kind.tolist())
    rng = np.random.default_rng(22)
    x = kite.nodes + amp * rng.normal(size=kite.nodes.shape)
    Rn = expm(5 * amp * rng.normal(size=kite.nodes.shape))
    _assert_beams_agree(kite.beams, kite.nodes, kite.beam_up, _kite_beam_stiffness(kite), x, Rn)


# ---------------------------------------------------------------------------------------------- shells
@pytest.mark.parametrize("wrinkling, bending", [(True, True), (False, True), (True, False)])
@pytest.mark.parametrize("rot_scale", [0.05, 0.6, 2.0])
def test_random_shells_agree_in_all_membrane_states(wrinkling, bending, rot_scale):
    rng = np.random.default_rng(30)
    Fins = [[[1.03, 0.01], [0.0, 1.02]], [[1.04, 0.02], [0.0, 0.97]], [[0.97, 0.01], [0.0, 0.96]]]
    xs, Rs, Xs = [], [], []
    for Fin in Fins:  # taut, wrinkled, slack
        X = _ts._tilted_triangles(rng, 8)
        _, x, R = _ts._deformed(rng, X, np.array(Fin), rot_scale)
        Xs.append(X)
        xs.append(x)
        Rs.append(R)
    X, x, R = np.concatenate(Xs), np.concatenate(xs), np.concatenate(Rs)
    x = x + 0.02 * rng.normal(size=x.shape)  # out-of-plane and shear on top: mixed states, frame rotation
    n = X.shape[0]
    args = (np.arange(3 * n).reshape(n, 3), X.reshape(-1, 3), E_CANOPY, NU, 0.002)
    sp = _assert_shells_agree(args, x, R, wrinkling=wrinkling, bending=bending)
    if wrinkling:
        assert set(sp.stresses(x)["state"].tolist()) == {TAUT, WRINKLED, SLACK}
    th = np.linalg.norm(local_rotations(element_frame(x)["Rr"], R, sp.R0), axis=-1)
    if rot_scale > 1.0:  # quaternion branch of shell_bending._log_rotation (cos t < 1e-3)
        assert np.max(th) > 0.5 * np.pi + 1e-3
    if rot_scale < 0.1:  # series branch of the T_s^-T derivative for some nodes
        assert np.min(th) < 0.2


def test_stress_free_shells_agree():
    """Rigid placements: round-off strains on either side of the taut boundary (TAUT_TOL), zero rotations."""
    rng = np.random.default_rng(31)
    X = _ts._tilted_triangles(rng, 12)
    n = X.shape[0]
    Q = expm(np.array([0.3, -1.2, 2.0]))
    conn = np.arange(3 * n).reshape(n, 3)
    for x, R in ((X, np.broadcast_to(np.eye(3), (n, 3, 3, 3))),
                 (X @ Q.T + 7.0, np.broadcast_to(Q, (n, 3, 3, 3)))):
        sn, sp = _pair(ShellSet, conn, X.reshape(-1, 3), E_CANOPY, NU, H_CANOPY)
        f1, K1 = sn.internal(x, R)
        f2, K2 = sp.internal(x, R)
        assert _per_element_rel(K1, K2) < RTOL
        assert np.max(np.abs(f1 - f2)) < 1e-12 * E_CANOPY * H_CANOPY
        assert np.all(sp.stresses(x)["state"] == TAUT)


@pytest.mark.parametrize("shear_ratio", [1.0, 0.05])
@pytest.mark.parametrize("amp", [0.0, 0.01, 0.1])
def test_kite_mesh_shells_agree(kite, amp, shear_ratio):
    """The 360 canopy triangles of the rhino16 mesh, unloaded and deformed (mixed membrane states); isotropic and
    a woven fabric (the relaxed law of any material matrix, shell_membrane.relaxed_general)."""
    rng = np.random.default_rng(32)
    x = kite.nodes + amp * rng.normal(size=kite.nodes.shape)
    Rn = expm(5 * amp * rng.normal(size=kite.nodes.shape))
    conn = kite.shells
    sp = _assert_shells_agree((conn, kite.nodes, E_CANOPY, NU, H_CANOPY), x[conn], Rn[conn],
                              shear_ratio=shear_ratio)
    assert sp.membrane_law == (1 if shear_ratio == 1.0 else 2)
    if amp > 0.05:
        assert len(set(sp.stresses(x[conn])["state"].tolist())) == 3


# ------------------------------------------------------------------------------------- existing tests per backend
@pytest.fixture(params=["numba", "numpy"])
def backend(request, monkeypatch):
    """Route ``backend="auto"`` of every element set built inside a test to one backend."""
    monkeypatch.setenv(compiled.ENV_VAR, request.param)
    assert BeamSet([[0, 1]], np.eye(3)[:2], [0.0, 0.0, 1.0], 1.0, 1.0, 1.0, 1.0).backend == request.param
    assert ShellSet([[0, 1, 2]], np.eye(3), 1.0, 0.3, 1.0).backend == request.param
    assert HemSet([[0, 1]], np.eye(3)[:2], [0.0, 0.0, 1.0], 1.0, 1.0, 1.0).backend == request.param
    return request.param


@pytest.mark.parametrize("rot_scale", [0.05, 1.0])
def test_beam_fd_tangent_per_backend(backend, rot_scale):
    _tb.test_tangent_matches_central_difference(rot_scale)
    _tb.test_internal_force_is_self_equilibrated()


@pytest.mark.parametrize("rot_scale", [0.05, 2.5])
def test_hem_fd_tangent_per_backend(backend, rot_scale):
    _th.test_force_is_the_energy_gradient_and_the_tangent_its_derivative_at_large_rotations(rot_scale)


@pytest.mark.parametrize("regime, Fin", [
    ("taut", [[1.03, 0.01], [0.0, 1.02]]),
    ("wrinkled", [[1.04, 0.02], [0.0, 0.97]]),
    ("slack", [[0.97, 0.01], [0.0, 0.96]]),
])
def test_shell_fd_tangent_per_backend(backend, regime, Fin):
    _ts.test_tangent_matches_finite_difference(regime, Fin)


def test_shell_wrinkling_per_backend(backend):
    _ts.test_wrinkling_force_continuous_across_state_boundaries()
    _ts.test_stress_free_state_has_linear_elastic_cst_tangent()
    _ts.test_rigid_body_motion_gives_zero_force()


def test_rotate_nodes_matches_rodrigues():
    from kite_env.structure.rotation_kernels import rotate_nodes
    from kite_env.structure.rotations import expm

    rng = np.random.default_rng(5)
    R = expm(rng.normal(size=(50, 3)))
    dw = rng.normal(size=(50, 3)) * np.logspace(-9, 0.5, 50)[:, None]  # through the series branch
    out = np.empty_like(R)
    rotate_nodes(R, dw, out)
    np.testing.assert_allclose(out, np.einsum("nij,njk->nik", expm(dw), R), atol=1e-14)


def test_residual_only_assembly_gives_the_same_internal_forces(kite):
    """Assembler.assemble_data(tangent=False) (shells through the residual-only kernel, beams as before): the same
    internal force vector bit for bit as with the tangent, and no tangent data."""
    from kite_env.structure.assembly import Assembler

    rng = np.random.default_rng(4)
    x = kite.nodes + 0.02 * rng.normal(size=kite.nodes.shape)
    Rn = expm(0.1 * rng.normal(size=kite.nodes.shape))
    shells = ShellSet(kite.shells, kite.nodes, E_CANOPY, NU, H_CANOPY, backend="numba")
    beams = BeamSet(kite.beams, kite.nodes, np.tile([0.0, 0.0, 1.0], (len(kite.beams), 1)), EA=1e5, EI2=50.0,
                    EI3=50.0, GJ=20.0, backend="numba")
    asm = Assembler(kite.nodes.shape[0], [shells, beams])
    f_full, data = asm.assemble_data(x, Rn, tangent=True)
    f_res, none = asm.assemble_data(x, Rn, tangent=False)
    assert data is not None and none is None
    assert np.array_equal(f_full, f_res) and np.any(f_full != 0.0)


def test_gathered_csc_product_is_scipys_product_of_the_gathered_matrix():
    """csc_gather_matvec (the Rayleigh damping's product on the translations) equals scipy's product of the matrix
    built from the gathered values, to the last bit (same order of operations), and a zero scale gives zero."""
    import scipy.sparse as sp

    rng = np.random.default_rng(5)
    n_big, n = 400, 60
    A = sp.random(n, n, density=0.2, random_state=6, format="csc")
    entries = rng.choice(n_big, size=A.nnz, replace=True)
    data = rng.normal(size=n_big)
    x = rng.normal(size=n)
    out = np.full(n, np.nan)
    assembly_kernels.csc_gather_matvec(data, entries, A.indices, A.indptr, 0.37, x, out)
    ref = sp.csc_matrix((0.37 * data[entries], A.indices, A.indptr), shape=(n, n)) @ x
    assert np.array_equal(out, ref)
    assembly_kernels.csc_gather_matvec(data, entries, A.indices, A.indptr, 0.0, x, out)
    assert np.array_equal(out, np.zeros(n))


@pytest.mark.parametrize("material_terms", [False, True])
def test_set_bending_torsion_is_the_same_per_backend(material_terms):
    """The compiled BeamSet.set_bending_torsion (the tubes' secant stiffness at every iterate) writes the same
    stiffness arrays, local blocks and material terms as the NumPy one, bit for bit, on the rows given only."""
    rng = np.random.default_rng(11)
    n = 6
    X0 = np.cumsum(rng.uniform(0.2, 0.5, size=(n + 1, 3)), axis=0)
    conn = np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)
    bn, bp = _pair(BeamSet, conn, X0, [0.0, 0.0, 1.0], EA=3e4, EI2=50.0, EI3=60.0, GJ=20.0)
    rows = np.array([1, 4, 5])
    EI, GJ = rng.uniform(10.0, 40.0, 3), rng.uniform(5.0, 15.0, 3)
    g = (rng.uniform(0.0, 1e-3, 3), rng.uniform(0.0, 1e-3, 3)) if material_terms else (None, None)
    for b in (bn, bp):
        b._kmat[:] = 7.0  # (overwritten on the rows, kept elsewhere)
        b.set_bending_torsion(rows, EI, GJ, *g)
    for name in ("EI2", "EI3", "GJ", "_k11", "_k12", "_kmat"):
        assert np.array_equal(getattr(bn, name), getattr(bp, name)), name
    assert np.array_equal(bn.EI2[rows], EI) and bn.EI2[0] == 50.0 and bn._kmat[0, 0] == 7.0


@pytest.mark.parametrize("kinematics", ["green_lagrange", "von_karman"])
def test_a_degenerate_triangle_gives_non_finite_forces_in_both_backends_instead_of_raising(kinematics):
    """A Newton iterate can fold a canopy triangle onto a line. The compiled kernel then divides by zero as the NumPy
    reference does and returns non-finite forces, which the solver reports as a non-finite residual (a failed step,
    made again in halves); with numba's Python error model it raised ZeroDivisionError out of the flight."""
    X = np.array([[0.0, 0.0, 0.0], [0.4, 0.0, 0.0], [0.15, 0.3, 0.0]])
    x = np.array([[[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.4, 0.0, 0.0]]])  # on one line: no normal
    R = np.broadcast_to(np.eye(3), (1, 3, 3, 3)).copy()
    for backend in ("numba", "numpy"):
        s = ShellSet([[0, 1, 2]], X, 1.25e9, 0.3, 8e-5, backend=backend, kinematics=kinematics)
        with np.errstate(all="ignore"):
            f, _ = s.internal(x, R)
        assert not np.all(np.isfinite(f)), backend
