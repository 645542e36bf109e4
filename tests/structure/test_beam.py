"""Verification of the co-rotational Euler-Bernoulli beam (kite_env.structure.beam).

Every test compares with an analytic or independently computed answer:
rigid-body invariance, finite-difference tangent and energy gradient, the textbook linear frame stiffness,
linear cantilever formulas, the roll-up of a cantilever into a circle, the large-deflection elastica (reference
from scipy's BVP solver), its mesh convergence rate and the 3-D 45-degree bend of Bathe & Bolourchi (1979).
"""

import numpy as np
import pytest
from scipy.integrate import solve_bvp

from kite_env.structure.assembly import Assembler
from kite_env.structure.beam import BeamSet
from kite_env.structure.rotations import expm, logm
from kite_env.structure.solver import NodalState, StaticSolver

FIX_ROOT = np.arange(6)  # all six DOF of node 0


# --------------------------------------------------------------------------------------------- helpers
def random_beams(rng, n_e):
    """Independent 2-node beams with random geometry, ``up`` vectors and stiffnesses."""
    X0 = rng.normal(size=(2 * n_e, 3))
    conn = np.arange(2 * n_e).reshape(n_e, 2)
    up = rng.normal(size=(n_e, 3))
    bs = BeamSet(conn, X0, up, EA=rng.uniform(50, 200, n_e), EI2=rng.uniform(1, 5, n_e),
                 EI3=rng.uniform(1, 5, n_e), GJ=rng.uniform(1, 5, n_e))
    return bs, X0, conn


def deformed_state(rng, X0, rot_scale):
    """Large deformation: stretch, lateral displacement, nodal rotations (twist + bending) of ``rot_scale`` rad."""
    x = X0 + 0.2 * rng.normal(size=X0.shape)
    Rn = expm(rot_scale * rng.normal(size=X0.shape))
    return x, Rn


def fd_derivative(fun, xe, Re, h=1e-6):
    """Central FD of ``fun(x_e, R_e)`` (leading axis: elements) with respect to each element's ``[du1, dw1, du2,
    dw2]``: translations additive, rotations as spatial spins ``R <- expm(eps e_k) R``. Returns ``fun``'s shape
    plus a last axis of 12."""
    cols = []
    for a in range(2):
        for rot in (False, True):
            for k in range(3):
                e = np.zeros(3)
                e[k] = h
                xp, xm, Rp, Rm = xe.copy(), xe.copy(), Re.copy(), Re.copy()
                if rot:
                    Rp[:, a] = expm(e) @ Re[:, a]
                    Rm[:, a] = expm(-e) @ Re[:, a]
                else:
                    xp[:, a] += e
                    xm[:, a] -= e
                cols.append((fun(xp, Rp) - fun(xm, Rm)) / (2 * h))
    return np.stack(cols, axis=-1)


def fd_tangent(bs, xe, Re, h=1e-6):
    """Central FD of ``internal``'s force: the tangent (n_e, 12, 12)."""
    return fd_derivative(lambda x, R: bs.internal(x, R)[0], xe, Re, h)


def straight_cantilever(n_elem, L, axis=(1.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), **stiff):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    X0 = np.linspace(0.0, L, n_elem + 1)[:, None] * axis
    conn = np.stack([np.arange(n_elem), np.arange(1, n_elem + 1)], axis=1)
    bs = BeamSet(conn, X0, up, **stiff)
    return X0, bs


def solve_stepped(X0, sets, tip_load, n_steps, fixed=FIX_ROOT, **solver_kw):
    """Apply ``tip_load`` (6,) [N, N m] at the last node in ``n_steps`` equal increments; returns the final state."""
    asm = Assembler(X0.shape[0], sets)
    solver = StaticSolver(asm, **solver_kw)
    st = NodalState.reference(X0)
    f = np.zeros(asm.n_dof)
    for k in range(1, n_steps + 1):
        f[-6:] = np.asarray(tip_load, float) * k / n_steps
        st = solver.solve(st, f, fixed_dofs=fixed).state
    return st


def elastica_reference(alpha):
    """Cantilever elastica under a dead tip load, ``alpha = P L^2 / EI``, by scipy's collocation BVP solver.

    Unit length; theta(s) is the slope angle (towards the load), theta'' = -alpha cos(theta), theta(0) = 0,
    theta'(1) = 0 (no tip moment). Returns (horizontal shortening, deflection along the load, tip slope) / L.
    """
    s = np.linspace(0.0, 1.0, 101)

    def rhs(_s, y):  # y = [theta, theta', x, v]
        return np.vstack([y[1], -alpha * np.cos(y[0]), np.cos(y[0]), np.sin(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    y0 = np.zeros((4, s.size))
    y0[2] = s
    sol = solve_bvp(rhs, bc, s, y0, tol=1e-10, max_nodes=100000)
    assert sol.success
    th_tip = sol.y[0, -1]
    # first integral of the ODE gives x_tip = sqrt(2 sin(theta_tip) / alpha) (independent check of the BVP)
    assert sol.y[2, -1] == pytest.approx(np.sqrt(2.0 * np.sin(th_tip) / alpha), abs=1e-8)
    return 1.0 - sol.y[2, -1], sol.y[3, -1], th_tip


def elastica_fe(alpha, n_elem):
    """FE tip (shortening, deflection) / L of the elastica: beam along +x, dead load along -z, L = EI = 1."""
    X0, bs = straight_cantilever(n_elem, 1.0, EA=1e8, EI2=1.0, EI3=1.0, GJ=1.0)
    st = solve_stepped(X0, [bs], [0, 0, -alpha, 0, 0, 0], n_steps=int(np.ceil(alpha)))
    u = st.x[-1] - X0[-1]
    return -u[0], -u[2]


# --------------------------------------------------------------------------------------------- element level
def test_rigid_body_motion_gives_zero_force_and_objectivity():
    rng = np.random.default_rng(10)
    bs, X0, conn = random_beams(rng, 20)
    Q = expm(np.array([1.3, -2.1, 0.7]))  # |theta| ~ 2.6 rad
    t = np.array([30.0, -10.0, 20.0])
    # rigid motion of the unloaded state: nodes and nodal triads
    x = X0 @ Q.T + t
    Rn = np.broadcast_to(Q, (X0.shape[0], 3, 3))
    f, _ = bs.internal(x[conn], Rn[conn])
    f0, _ = bs.internal(X0[conn], np.broadcast_to(np.eye(3), (X0.shape[0], 3, 3))[conn])
    assert np.max(np.abs(f0)) < 1e-12
    assert np.max(np.abs(f)) < 1e-10 * np.max(bs.EA)
    assert np.max(np.abs(bs.energy(x[conn], Rn[conn]))) < 1e-20 * np.max(bs.EA)
    # rigid motion superposed on a deformed state: energy unchanged, forces and moments rotate with Q
    xd, Rd = deformed_state(rng, X0, 1.0)
    fd, _ = bs.internal(xd[conn], Rd[conn])
    fq, _ = bs.internal((xd @ Q.T + t)[conn], (Q @ Rd)[conn])
    assert np.allclose(bs.energy((xd @ Q.T + t)[conn], (Q @ Rd)[conn]), bs.energy(xd[conn], Rd[conn]), rtol=1e-10)
    rot = np.einsum("ij,nkj->nki", Q, fd.reshape(-1, 4, 3)).reshape(-1, 12)
    assert np.allclose(fq, rot, atol=1e-9 * np.max(np.abs(fd)))


def test_internal_force_is_self_equilibrated():
    """Sum of forces and of moments (about the origin, deformed configuration) vanish at any state."""
    rng = np.random.default_rng(11)
    bs, X0, conn = random_beams(rng, 15)
    x, Rn = deformed_state(rng, X0, 1.2)
    f, _ = bs.internal(x[conn], Rn[conn])
    f4 = f.reshape(-1, 4, 3)  # [f1, m1, f2, m2]
    xe = x[conn]
    scale = np.max(np.abs(f))
    assert np.allclose(f4[:, 0] + f4[:, 2], 0.0, atol=1e-12 * scale)
    mom = np.cross(xe[:, 0], f4[:, 0]) + f4[:, 1] + np.cross(xe[:, 1], f4[:, 2]) + f4[:, 3]
    assert np.allclose(mom, 0.0, atol=1e-11 * scale)


@pytest.mark.parametrize("rot_scale", [0.05, 1.0])  # 0.05: series branch of T_s^-1 derivatives, 1.0: closed form
def test_tangent_matches_central_difference(rot_scale):
    rng = np.random.default_rng(12)
    bs, X0, conn = random_beams(rng, 12)
    x, Rn = deformed_state(rng, X0, rot_scale)
    xe, Re = x[conn], Rn[conn]
    d = bs.local_deformation(xe, Re)
    assert np.all(np.abs(d["u_bar"]) > 1e-3)  # nonzero axial force in every element
    if rot_scale > 0.5:  # large local twist and bending rotations (> 0.2 rad in some components)
        assert np.max(np.abs(np.concatenate([d["theta1"], d["theta2"]]))) > 1.0
    _, K = bs.internal(xe, Re)
    K_fd = fd_tangent(bs, xe, Re)
    err = np.max(np.abs(K - K_fd), axis=(1, 2)) / np.max(np.abs(K), axis=(1, 2))
    assert np.all(err < 1e-6), err


def test_internal_force_is_gradient_of_energy():
    rng = np.random.default_rng(13)
    bs, X0, conn = random_beams(rng, 12)
    x, Rn = deformed_state(rng, X0, 1.0)
    xe, Re = x[conn], Rn[conn]
    f, _ = bs.internal(xe, Re)
    g = fd_derivative(bs.energy, xe, Re)
    assert np.max(np.abs(f - g)) < 1e-7 * np.max(np.abs(f))


def test_reference_tangent_is_textbook_linear_frame_stiffness():
    """At the unloaded state K equals the classical 12x12 Euler-Bernoulli frame matrix (Przemieniecki 1968)."""
    L, EA, EI2, EI3, GJ = 1.7, 300.0, 4.0, 9.0, 2.5
    e1 = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    up = np.array([0.3, -0.2, 1.0])
    X0 = np.stack([np.zeros(3), L * e1])
    bs = BeamSet([[0, 1]], X0, up, EA=EA, EI2=EI2, EI3=EI3, GJ=GJ)
    _, K = bs.internal(X0[None], np.broadcast_to(np.eye(3), (1, 2, 3, 3)))
    # local axes: x along the beam, y = up (orthogonalised), z = x cross y; local DOF [u, v, w, rx, ry, rz] x 2
    Kl = np.zeros((12, 12))
    for (i, j), k in {(0, 0): EA / L, (3, 3): GJ / L}.items():
        Kl[np.ix_([i, i + 6], [j, j + 6])] = k * np.array([[1, -1], [-1, 1]])
    # bending in the local x-y plane (v, rz): stiffness about the local z axis = EI3
    # bending in the local x-z plane (w, ry): stiffness about the local y axis = EI2
    for (t, r, EI, s) in ((1, 5, EI3, 1.0), (2, 4, EI2, -1.0)):
        idx = [t, r, t + 6, r + 6]
        k = EI / L**3 * np.array([[12, 6 * L, -12, 6 * L], [6 * L, 4 * L**2, -6 * L, 2 * L**2],
                                  [-12, -6 * L, 12, -6 * L], [6 * L, 2 * L**2, -6 * L, 4 * L**2]])
        sgn = np.array([1.0, s, 1.0, s])
        Kl[np.ix_(idx, idx)] = k * np.outer(sgn, sgn)
    T = np.zeros((12, 12))
    R0 = bs.R0[0]
    for b in range(4):
        T[3 * b:3 * b + 3, 3 * b:3 * b + 3] = R0.T
    assert np.allclose(K[0], T.T @ Kl @ T, atol=1e-12 * np.max(np.abs(Kl)))


# --------------------------------------------------------------------------------------------- linear cantilever
def test_linear_cantilever_both_planes_torsion_axial():
    """Small tip loads on an oblique cantilever: P L^3/(3 EI), P L^2/(2 EI), T L/GJ, P L/EA (exact for cubics)."""
    L, EA, EI2, EI3, GJ = 2.0, 500.0, 3.0, 7.0, 1.5
    axis = np.array([1.0, 1.0, 0.5])
    up = np.array([-1.0, 1.0, 0.0])  # already perpendicular to axis
    X0, bs = straight_cantilever(4, L, axis=axis, up=up, EA=EA, EI2=EI2, EI3=EI3, GJ=GJ)
    e1, e2, e3 = bs.R0[0].T
    eps = 1e-6  # [N]: tip deflection ~1e-7 L; the axial shortening 0.6 delta^2 / L is ~1e-7 relative
    cases = [  # (tip load (6,), expected tip displacement, expected tip rotation vector)
        (np.r_[eps * e2, 0, 0, 0], eps * L**3 / (3 * EI3) * e2, eps * L**2 / (2 * EI3) * e3),
        (np.r_[eps * e3, 0, 0, 0], eps * L**3 / (3 * EI2) * e3, -eps * L**2 / (2 * EI2) * e2),
        (np.r_[0, 0, 0, eps * e1], np.zeros(3), eps * L / GJ * e1),
        (np.r_[eps * e1, 0, 0, 0], eps * L / EA * e1, np.zeros(3)),
    ]
    for load, u_ref, w_ref in cases:
        st = solve_stepped(X0, [bs], load, 1)
        u = st.x[-1] - X0[-1]
        w = logm(st.Rn[-1])
        scale = max(np.linalg.norm(u_ref), np.linalg.norm(w_ref))
        assert np.allclose(u, u_ref, rtol=0, atol=1e-6 * scale), (u, u_ref)
        assert np.allclose(w, w_ref, rtol=0, atol=1e-6 * scale), (w, w_ref)


# --------------------------------------------------------------------------------------------- large rotations
@pytest.mark.parametrize("turns, n_steps", [(1.0, 8), (0.5, 4)])
def test_cantilever_rolls_up_into_circle(turns, n_steps):
    """End moment M = 2 pi EI / L (full circle) and pi EI / L (half circle): curvature M / EI everywhere.

    With N = 0 and no shear, each co-rotational element keeps its chord L0 and turns by phi = M L0 / EI, so the
    discrete solution is the regular polygon inscribed in the circle of radius R_h = L0 / (2 sin(phi / 2)) (exact,
    checked to round-off) which tends to the analytic circle R = EI / M as O(1 / n^2).
    """
    n, L, EI = 20, 2.0, 3.0
    X0, bs = straight_cantilever(n, L, EA=1e4, EI2=EI, EI3=50.0, GJ=1.0)  # moment about z uses EI2 (up = z)
    M = 2.0 * np.pi * turns * EI / L
    st = solve_stepped(X0, [bs], [0, 0, 0, 0, 0, M], n_steps)
    R = EI / M
    # analytic circle through the root, tangent to +x, centre (0, R, 0)
    r = np.linalg.norm(st.x - np.array([0.0, R, 0.0]), axis=1)
    assert np.max(np.abs(r - R)) < 0.01 * R
    assert np.allclose(st.x[:, 2], 0.0, atol=1e-12)
    # exact discrete answer
    phi = M * (L / n) / EI
    R_h = (L / n) / (2.0 * np.sin(phi / 2.0))
    # the polygon's circumscribed circle is tangent to +x at the root (chords at phi/2, 3 phi/2, ...)
    assert np.allclose(np.linalg.norm(st.x - np.array([0.0, R_h, 0.0]), axis=1), R_h, rtol=0, atol=1e-9 * R)
    # nodal triads: rotation k phi about z at node k
    ang = phi * np.arange(n + 1)
    Rz = np.zeros((n + 1, 3, 3))
    Rz[:, 0, 0] = Rz[:, 1, 1] = np.cos(ang)
    Rz[:, 1, 0] = np.sin(ang)
    Rz[:, 0, 1] = -np.sin(ang)
    Rz[:, 2, 2] = 1.0
    assert np.allclose(st.Rn, Rz, atol=1e-9)
    if turns == 1.0:
        assert np.linalg.norm(st.x[-1]) < 1e-9 * L  # the tip returns to the root
    else:
        assert st.x[-1] == pytest.approx([0.0, 2.0 * R_h, 0.0], abs=1e-9)
        assert abs(2.0 * R_h - 2.0 * R) < 2.5e-3 * R  # analytic tip position (0, 2R, 0)


@pytest.mark.parametrize("alpha", [1.0, 2.0, 5.0])
def test_elastica_tip_load(alpha):
    """Large-deflection cantilever under a dead tip load vs the elastica solved by scipy's BVP solver."""
    dh_ref, dv_ref, _ = elastica_reference(alpha)
    if alpha == 1.0:
        # Bisshopp & Drucker (1945), Q. Appl. Math. 3, 272-275, PL^2/EI = 1: tip deflection 0.3017 L
        assert dv_ref == pytest.approx(0.3017, abs=1e-4)
    dh, dv = elastica_fe(alpha, 32)
    assert dh == pytest.approx(dh_ref, abs=2e-4)
    assert dv == pytest.approx(dv_ref, abs=2e-4)


def test_elastica_mesh_convergence_rate():
    """Tip error of the elastica (PL^2/EI = 2) falls as h^2 (measured rate 2.0; straight elements, linear
    local theory: the chord approximation of the arc is O(h^2))."""
    dh_ref, dv_ref, _ = elastica_reference(2.0)
    ns = np.array([4, 8, 16, 32])
    err = []
    for n in ns:
        dh, dv = elastica_fe(2.0, n)
        err.append(np.hypot(dh - dh_ref, dv - dv_ref))
    rate = -np.polyfit(np.log(ns), np.log(err), 1)[0]
    assert rate > 1.8, (rate, err)
    assert err[-1] < 5e-5


def test_bathe_bolourchi_45_degree_bend():
    """3-D coupled bending and torsion: 45-degree bend cantilever, tip load 600 out of its plane.

    Data (Bathe & Bolourchi 1979, IJNME 14, 961-986; as restated in the Kynema verification docs,
    https://kynema.github.io/kynema/_sources/testing/curved.rst.txt): radius 100 in, 45-degree arc, 1 x 1 in square
    section, E = 1e7 psi, nu = 0 -> EA = 1e7, EI = 8.333e5, GJ = 8.333e5; tip force 600 lb normal to the plane.
    Reference tip displacement (Bathe & Bolourchi, 8 elements): 23.5 along the initial tangent (towards the
    root), 13.4 in-plane away from the centre, 53.4 along the load. The same docs give a converged Timoshenko
    (shear-flexible) solution 23.65 / 13.72 / 53.58.
    """
    n = 16
    phi = np.linspace(0.0, np.pi / 4.0, n + 1)
    X0 = np.stack([100.0 * np.sin(phi), 100.0 * (1.0 - np.cos(phi)), np.zeros_like(phi)], axis=1)  # centre (0,100,0)
    conn = np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)
    EI = 1e7 / 12.0
    bs = BeamSet(conn, X0, [0.0, 0.0, 1.0], EA=1e7, EI2=EI, EI3=EI, GJ=EI)
    st = solve_stepped(X0, [bs], [0, 0, 600.0, 0, 0, 0], n_steps=6)
    u = st.x[-1] - X0[-1]
    # measured: (-23.55, -13.60, 53.48)
    assert u == pytest.approx([-23.5, -13.4, 53.4], abs=0.3)


# --------------------------------------------------------------------------------------------- dynamics
def test_cantilever_first_natural_frequency_with_lumped_masses():
    """The discretisation of the wing with inertia (kite_env/dynamics/wing_dynamics.py): lumped translational masses
    on the nodes, massless rotations condensed out. A clamped cantilever's first bending frequency against
    Euler-Bernoulli's ``omega_1 = 1.8751^2 sqrt(EI / (mu L^4))`` (Blevins, Formulas for Natural Frequency and Mode
    Shape, Table 8-1), within 1 %, converging under refinement."""
    L, EI, mu = 2.0, 3.0, 0.4  # [m], [N m^2], [kg/m]
    exact = 1.8751**2 * np.sqrt(EI / (mu * L**4))
    errs = []
    for n in (8, 16, 32):
        X0, bs = straight_cantilever(n, L, EA=1e5, EI2=EI, EI3=EI, GJ=EI)
        asm = Assembler(X0.shape[0], [bs])
        _, K = asm.assemble(X0, np.broadcast_to(np.eye(3), (n + 1, 3, 3)).copy())
        K = K.toarray()[6:, 6:]  # root clamped
        m = np.full(n, mu * L / n)
        m[-1] *= 0.5
        dof = np.arange(K.shape[0])
        # bending in z (up = z): the transverse translations; axial and in-plane DOF do not couple with it in the
        # straight, unstressed reference state
        t = dof[(dof % 6) == 2]
        r = dof[(dof % 6) >= 3]
        Ks = K[np.ix_(t, t)] - K[np.ix_(t, r)] @ np.linalg.solve(K[np.ix_(r, r)], K[np.ix_(r, t)])
        w2 = np.linalg.eigvalsh(Ks / np.sqrt(np.outer(m, m)))
        errs.append(abs(np.sqrt(w2.min()) - exact) / exact)
    assert errs[-1] < 0.01
    assert errs[0] > errs[1] > errs[2]


def test_nodal_rotation_limit_reaches_the_same_equilibrium():
    """StaticSolver(nodal_rot_limit=True) clamps only the nodes whose rotation increment exceeds max_rot_rad: the
    same equilibrium as the global scaling (a cantilever rolled by a tip moment to a half circle in one load step)."""
    L, EI, n = 1.0, 2.0, 16
    X0, bs = straight_cantilever(n, L, EA=1e4, EI2=EI, EI3=EI, GJ=EI)
    load = np.r_[0.0, 0.0, 0.0, 0.0, np.pi * EI / L, 0.0]  # a half turn about y
    results = {}
    for nodal in (False, True):
        asm = Assembler(X0.shape[0], [bs])
        solver = StaticSolver(asm, max_iter=200, nodal_rot_limit=nodal)
        f = np.zeros(asm.n_dof)
        f[-6:] = load
        results[nodal] = solver.solve(NodalState.reference(X0), f, fixed_dofs=FIX_ROOT)
    assert np.allclose(results[True].state.x, results[False].state.x, atol=1e-6)
    # the circle of radius L / pi: the tip back over the root at height 2 L / pi
    assert results[True].state.x[-1] == pytest.approx([0.0, 0.0, -2.0 * L / np.pi], abs=2e-3)
