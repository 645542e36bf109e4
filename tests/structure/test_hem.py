"""Verification of the frame-free hem rod (kite_env.structure.hem).

Against independent answers: finite-difference energy gradient and tangent at large rotations, rigid-body
invariance and balance, the co-rotational beam's (and so the textbook frame element's) stiffness for small
deformations, a cantilever against Euler-Bernoulli, and the smoothness of the energy where the beam's element frame
is singular.
"""

import numpy as np
import pytest

from kite_env.structure.assembly import Assembler
from kite_env.structure.beam import BeamSet
from kite_env.structure.hem import HemSet
from kite_env.structure.rotations import expm
from kite_env.structure.solver import NodalState, StaticSolver

import test_beam as _tb  # the sibling module's finite differences


def random_rods(rng, n_e):
    X0 = rng.normal(size=(2 * n_e, 3))
    conn = np.arange(2 * n_e).reshape(n_e, 2)
    up = rng.normal(size=(n_e, 3))
    return HemSet(conn, X0, up, EA=rng.uniform(50, 200, n_e), EI=rng.uniform(1, 5, n_e),
                  GJ=rng.uniform(1, 5, n_e)), X0, conn, up


def fd_tangent_and_gradient(hs, xe, Re):
    """Central differences of the force (the tangent) and of the energy (the force), :func:`test_beam.fd_derivative`."""
    return _tb.fd_tangent(hs, xe, Re), _tb.fd_derivative(hs.energy, xe, Re)


@pytest.mark.parametrize("rot_scale", [0.05, 1.0, 2.5])
def test_force_is_the_energy_gradient_and_the_tangent_its_derivative_at_large_rotations(rot_scale):
    rng = np.random.default_rng(7)
    hs, X0, conn, _ = random_rods(rng, 6)
    x = X0 + 0.2 * rng.normal(size=X0.shape)
    Rn = expm(rot_scale * rng.normal(size=X0.shape))
    xe, Re = x[conn], Rn[conn]
    f, K = hs.internal(xe, Re)
    K_fd, g_fd = fd_tangent_and_gradient(hs, xe, Re)
    assert np.max(np.abs(f - g_fd)) <= 1e-7 * np.max(np.abs(f))
    assert np.max(np.abs(K - K_fd)) <= 1e-6 * np.max(np.abs(K))
    f_only, none = hs.internal(xe, Re, tangent=False)
    assert none is None and np.array_equal(f_only, f)


def test_a_rigid_motion_changes_no_energy_and_the_forces_balance():
    rng = np.random.default_rng(3)
    hs, X0, conn, _ = random_rods(rng, 5)
    x = X0 + 0.3 * rng.normal(size=X0.shape)
    Rn = expm(1.5 * rng.normal(size=X0.shape))
    Q = expm(np.array([0.7, -1.9, 0.4]))
    p = np.array([3.0, -1.0, 2.0])
    U = hs.energy(x[conn], Rn[conn])
    assert np.allclose(hs.energy((x @ Q.T + p)[conn], (Q @ Rn)[conn]), U, rtol=1e-12, atol=1e-12)
    f, _ = hs.internal(x[conn], Rn[conn])
    xe = x[conn]
    force = f[:, 0:3] + f[:, 6:9]
    moment = f[:, 3:6] + f[:, 9:12] + np.cross(xe[:, 0], f[:, 0:3]) + np.cross(xe[:, 1], f[:, 6:9])
    scale = np.max(np.abs(f))
    assert np.max(np.abs(force)) <= 1e-12 * scale
    assert np.max(np.abs(moment)) <= 1e-11 * scale * (1 + np.max(np.abs(xe)))


def test_for_small_deformations_it_is_the_corotational_beam():
    """Unloaded it has the beam's (the linear Euler-Bernoulli frame element's) stiffness exactly, and near it the
    beam's forces to second order in the rotations."""
    rng = np.random.default_rng(11)
    n = 4
    X0 = rng.normal(size=(2 * n, 3))
    conn = np.arange(2 * n).reshape(n, 2)
    up = rng.normal(size=(n, 3))
    EA, EI, GJ = rng.uniform(50, 200, n), rng.uniform(1, 5, n), rng.uniform(1, 5, n)
    hs = HemSet(conn, X0, up, EA, EI, GJ)
    bs = BeamSet(conn, X0, up, EA=EA, EI2=EI, EI3=EI, GJ=GJ)
    R = np.broadcast_to(np.eye(3), (2 * n, 3, 3)).copy()
    _, Kh = hs.internal(X0[conn], R[conn])
    _, Kb = bs.internal(X0[conn], R[conn])
    assert np.max(np.abs(Kh - Kb)) <= 1e-12 * np.max(np.abs(Kb))
    for eps in (1e-2, 1e-3):
        x = X0 + eps * rng.normal(size=X0.shape)
        Rn = expm(eps * rng.normal(size=X0.shape))
        fh, _ = hs.internal(x[conn], Rn[conn])
        fb, _ = bs.internal(x[conn], Rn[conn])
        # the difference is of higher order than the forces (which are of order eps)
        assert np.max(np.abs(fh - fb)) <= 20 * eps * np.max(np.abs(fb))


def test_a_cantilever_of_rods_bends_as_euler_bernoulli():
    n_el, L, EI = 8, 2.0, 3.0
    X0 = np.linspace(0.0, L, n_el + 1)[:, None] * np.array([1.0, 0.0, 0.0])
    conn = np.stack([np.arange(n_el), np.arange(1, n_el + 1)], axis=1)
    hs = HemSet(conn, X0, np.tile([0.0, 0.0, 1.0], (n_el, 1)), EA=1e6, EI=EI, GJ=2.0)
    solver = StaticSolver(Assembler(n_el + 1, [hs]), tol_force=1e-10, tol_disp=1e-12)
    P, T = 1e-3, 2e-3  # a small tip force along z and a tip torque about the axis
    f_ext = np.zeros(6 * (n_el + 1))
    f_ext[6 * n_el + 2] = P
    f_ext[6 * n_el + 3] = T
    res = solver.solve(NodalState.reference(X0), f_ext, np.arange(6))
    w_tip = res.state.x[-1, 2]
    # cubic Hermite elements are exact for a tip load: P L^3 / (3 EI)
    assert w_tip == pytest.approx(P * L**3 / (3 * EI), rel=1e-4)
    twist = np.arcsin(np.clip(res.state.Rn[-1] @ np.array([0.0, 0.0, 1.0]), -1, 1))  # e3 turned about x: -y part
    assert -twist[1] == pytest.approx(T * L / 2.0, rel=1e-4)


def test_its_energy_is_smooth_where_the_corotational_frame_is_singular():
    """Both nodes turned about the same axis normal to the chord, together, from 0 to 180 deg (a hem bent at both
    ends in the same sense): the beam's element frame degenerates at 90 deg and its energy jumps; the rod's grows
    smoothly with the angle and has its slope at every step."""
    X0 = np.array([[0.0, 0.0, 0.0], [0.4, 0.0, 0.0]])
    conn = np.array([[0, 1]])
    up = np.array([[0.0, 0.0, 1.0]])
    hs = HemSet(conn, X0, up, 1e3, 0.4, 0.3)
    bs = BeamSet(conn, X0, up, EA=np.array([1e3]), EI2=np.array([0.4]), EI3=np.array([0.4]), GJ=np.array([0.3]))
    angles = np.linspace(0.0, np.pi, 720)  # (not through 90 deg exactly, where the beam's frame is undefined)
    axis = np.array([0.0, 1.0, 0.0])  # turns the nodes' e2 = z onto the chord x
    U_h, U_b, dU_h = [], [], []
    for a in angles:
        R = np.stack([expm(a * axis)] * 2)[None]
        U_h.append(hs.energy(X0[None], R)[0])
        with np.errstate(divide="ignore", invalid="ignore"):  # (the beam's rotation logarithm near its branch)
            U_b.append(bs.energy(X0[None], R)[0])
        f, _ = hs.internal(X0[None], R, tangent=False)
        dU_h.append(f[0, 4] + f[0, 10])  # dU / d(angle): the moments about the axis
    U_h, U_b, dU_h = map(np.asarray, (U_h, U_b, dU_h))
    da = angles[1] - angles[0]
    assert np.max(np.abs(np.diff(U_h) - 0.5 * da * (dU_h[1:] + dU_h[:-1]))) <= 1e-6 * np.max(U_h)
    assert np.all(np.diff(U_h) > 0.0)
    # the beam: a jump of the energy between two samples 0.25 deg apart, far above its smooth change there
    assert np.max(np.abs(np.diff(U_b))) > 100 * np.max(np.abs(np.diff(U_h)))


def test_its_torsion_rises_to_a_half_turn_and_bending_one_end_barely_enters_it():
    """One node turned about the chord by tau: the torsion energy is ``GJ / L0 (1 - cos tau)``, rising to a half turn
    (the sine of the twist alone would have a second minimum there, where a flipped trailing-edge node stayed, stop
    43); one node bent by delta about an axis normal to the chord and its section vector changes it only at fourth
    order (no bending energy from GJ)."""
    L0, GJ = 0.4, 0.3
    X0 = np.array([[0.0, 0.0, 0.0], [L0, 0.0, 0.0]])
    conn = np.array([[0, 1]])
    hs = HemSet(conn, X0, np.array([[0.0, 0.0, 1.0]]), 1e3, 0.0, GJ)
    for tau in np.linspace(0.0, np.pi, 13):
        R = np.stack([np.eye(3), expm(tau * np.array([1.0, 0.0, 0.0]))])[None]
        assert hs.energy(X0[None], R)[0] == pytest.approx(GJ / L0 * (1.0 - np.cos(tau)), rel=1e-12, abs=1e-15)
    for delta in (1e-2, 1e-1):
        R = np.stack([np.eye(3), expm(delta * np.array([0.0, 1.0, 0.0]))])[None]
        assert hs.energy(X0[None], R)[0] <= GJ / L0 * delta**4
