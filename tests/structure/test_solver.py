"""StaticSolver: prescribed DOF and reactions, failure reporting, input checks, modified Newton, unused nodes."""

import numpy as np
import pytest

from kite_env.structure.assembly import Assembler
from kite_env.structure.beam import BeamSet
from kite_env.structure.rotations import skew
from kite_env.structure.solver import ConvergenceError, NodalState, StaticSolver


def cantilever(n=6, L=1.0, EA=1e4, EI=1.0, GJ=0.8, extra_nodes=0):
    X0 = np.zeros((n + 1 + extra_nodes, 3))
    X0[: n + 1, 0] = np.linspace(0.0, L, n + 1)
    X0[n + 1:] = [0.3, 0.7, -0.2]  # nodes that belong to no element
    conn = np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)
    bs = BeamSet(conn, X0, [0.0, 0.0, 1.0], EA=EA, EI2=EI, EI3=EI, GJ=GJ)
    return X0, Assembler(X0.shape[0], [bs])


def space_frame():
    """Three-member 3-D frame: a clamped column, a beam along y, a beam along x with a bent-down end."""
    X0 = np.array([[0, 0, 0], [0, 0, 0.5], [0, 0, 1.0], [0, 0.5, 1.0], [0, 1.0, 1.0], [0.5, 1.0, 1.0],
                   [1.0, 1.0, 1.0], [1.0, 1.0, 0.5]], dtype=float)
    conn = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 6], [6, 7]])
    up = np.array([[1, 0, 0], [1, 0, 0], [0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 1], [1, 0, 0]], dtype=float)
    bs = BeamSet(conn, X0, up, EA=500.0, EI2=2.0, EI3=3.0, GJ=1.5)
    return X0, Assembler(X0.shape[0], [bs])


def test_prescribed_displacement_reactions_balance_forces_and_moments():
    X0, asm = space_frame()
    n_dof = asm.n_dof
    fixed = np.r_[np.arange(6), 6 * 7 + np.arange(3)]  # node 0 clamped, node 7 pinned and moved
    du_fixed = np.r_[np.zeros(6), [0.05, -0.08, 0.1]]
    f_ext = np.zeros(n_dof)
    f_ext[6 * 2:6 * 2 + 6] = [0.4, -0.3, 0.2, 0.05, 0.0, -0.1]  # force + moment at node 2
    f_ext[6 * 5:6 * 5 + 3] = [0.0, 0.2, -0.5]
    f_ext[6 * 7 + 2] = 0.3  # load on a prescribed DOF: carried straight into the support
    res = StaticSolver(asm).solve(NodalState.reference(X0), f_ext, fixed_dofs=fixed, du_fixed=du_fixed)
    x = res.state.x
    assert np.allclose(x[7] - X0[7], du_fixed[6:], atol=1e-14)  # prescribed DOF reached and held
    assert np.allclose(x[0], X0[0]) and np.allclose(res.state.Rn[0], np.eye(3))
    free = np.setdiff1d(np.arange(n_dof), fixed)
    assert np.max(np.abs(res.reactions[free])) < 1e-8 * np.max(np.abs(res.reactions))
    # large enough to be a real test: the support moves by ~0.14 m on a 1 m frame
    reac = res.reactions.reshape(-1, 6)
    ext = f_ext.reshape(-1, 6)
    assert np.linalg.norm(reac[:, :3].sum(0)) > 0.1
    # force balance: reactions + external loads = 0
    assert np.allclose(reac[:, :3].sum(0) + ext[:, :3].sum(0), 0.0, atol=1e-9)
    # moment balance about the origin in the deformed configuration
    mom = np.cross(x, reac[:, :3] + ext[:, :3]).sum(0) + (reac[:, 3:] + ext[:, 3:]).sum(0)
    assert np.allclose(mom, 0.0, atol=1e-9)


def test_prescribed_tip_deflection_gives_analytic_reaction():
    """Tip of a cantilever pushed by delta (rotation free): reaction 3 EI delta / L^3, root moment L times it."""
    L, EI, delta = 1.0, 2.0, 1e-6
    X0, asm = cantilever(n=4, L=L, EI=EI)
    fixed = np.r_[np.arange(6), 6 * 4 + 1]  # root clamped, tip u_y prescribed
    res = StaticSolver(asm).solve(NodalState.reference(X0), np.zeros(asm.n_dof), fixed,
                                  du_fixed=np.r_[np.zeros(6), delta])
    P = 3.0 * EI * delta / L**3
    reac = res.reactions.reshape(-1, 6)
    assert reac[4, 1] == pytest.approx(P, rel=1e-6)  # force the support applies to the tip (+y)
    assert reac[0, 1] == pytest.approx(-P, rel=1e-6)
    assert reac[0, 5] == pytest.approx(-P * L, rel=1e-6)  # root moment about z


def test_convergence_error_when_max_iter_too_small():
    X0, asm = cantilever()
    f = np.zeros(asm.n_dof)
    f[-4] = -5.0  # P L^2 / EI = 5 in one step: needs many Newton iterations
    with pytest.raises(ConvergenceError) as info:
        StaticSolver(asm, max_iter=2).solve(NodalState.reference(X0), f, fixed_dofs=np.arange(6))
    h = info.value.history
    assert [e[0] for e in h] == [1, 2, 3]
    assert h[0][1] == pytest.approx(5.0) and h[-1][1] > 1e-6
    assert "did not converge in 2 iterations" in str(info.value)
    # the same problem converges with enough iterations
    res = StaticSolver(asm).solve(NodalState.reference(X0), f, fixed_dofs=np.arange(6))
    assert res.converged and res.iterations > 2


def test_convergence_error_for_unsupported_structure():
    """Free-floating beam with a net load: singular tangent, no equilibrium."""
    X0, asm = cantilever()
    f = np.zeros(asm.n_dof)
    f[-4] = 1.0
    with pytest.raises(ConvergenceError) as info:
        StaticSolver(asm).solve(NodalState.reference(X0), f, fixed_dofs=[])
    assert len(info.value.history) >= 1 and info.value.history[0][1] == pytest.approx(1.0)


def test_invalid_inputs_raise_value_error():
    X0, asm = cantilever()
    solver = StaticSolver(asm)
    st = NodalState.reference(X0)
    f = np.zeros(asm.n_dof)
    f[10] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        solver.solve(st, f, fixed_dofs=np.arange(6))
    with pytest.raises(ValueError, match="shape"):
        solver.solve(st, np.zeros(asm.n_dof + 1), fixed_dofs=np.arange(6))
    with pytest.raises(ValueError, match="du_fixed"):
        solver.solve(st, np.zeros(asm.n_dof), fixed_dofs=np.arange(6), du_fixed=np.zeros(3))
    with pytest.raises(ValueError, match="mode"):
        StaticSolver(asm, mode="quasi")


def test_modified_newton_matches_full_newton_and_reuses_factorisation():
    X0, asm = cantilever(n=8)
    f = np.zeros(asm.n_dof)
    f[-6:] = [0.0, 0.5, -1.5, 0.3, 0.0, 0.0]  # 3-D: two bending planes and torsion
    st0 = NodalState.reference(X0)
    full = StaticSolver(asm, mode="full").solve(st0, f, fixed_dofs=np.arange(6))
    mod_solver = StaticSolver(asm, mode="modified")
    mod = mod_solver.solve(st0, f, fixed_dofs=np.arange(6))
    assert np.allclose(mod.state.x, full.state.x, atol=1e-9)
    assert np.allclose(mod.state.Rn, full.state.Rn, atol=1e-9)
    assert mod.factorizations < full.factorizations
    # warm restart with a slightly changed load starts on the previous factorisation
    f2 = f * 1.01
    warm = mod_solver.solve(mod.state, f2, fixed_dofs=np.arange(6))
    ref = StaticSolver(asm, mode="full").solve(full.state, f2, fixed_dofs=np.arange(6))
    assert warm.factorizations < warm.iterations
    assert np.allclose(warm.state.x, ref.state.x, atol=1e-9)


def test_unused_nodes_are_fixed_automatically():
    X0, asm = cantilever(n=4, extra_nodes=2)
    solver = StaticSolver(asm)
    assert np.array_equal(asm.unused_nodes, [5, 6])
    assert np.array_equal(solver.auto_fixed, np.arange(30, 42))
    f = np.zeros(asm.n_dof)
    f[6 * 4 + 2] = -1e-3
    f[6 * 5:6 * 5 + 3] = 1.0  # load on an unused node: no stiffness there, it goes into the "reaction"
    res = solver.solve(NodalState.reference(X0), f, fixed_dofs=np.arange(6))
    assert np.array_equal(res.state.x[5:], X0[5:])
    assert np.allclose(res.state.Rn[5:], np.eye(3))
    assert np.allclose(res.reactions[30:33], -1.0)
    assert res.state.x[4, 2] == pytest.approx(-1e-3 / 3.0, rel=1e-5)  # P L^3 / (3 EI), L = EI = 1


def test_rotation_update_is_spatial_spin():
    """NodalState.updated applies R <- expm(dw) R (the increment is a spin about global axes)."""
    st = NodalState.reference(np.zeros((1, 3)))
    dw = np.array([0.0, 0.0, 1e-8])
    st1 = st.updated(np.r_[0.0, 0.0, 0.0, np.pi / 2, 0.0, 0.0])  # 90 deg about x
    st2 = st1.updated(np.r_[0.0, 0.0, 0.0, dw])
    dR = st2.Rn[0] @ st1.Rn[0].T
    assert np.allclose((dR - np.eye(3)) / 1e-8, skew(dw / 1e-8), atol=1e-6)


def test_stiff_members_converge_at_round_off_floor():
    """EA L^2 / EI = 1e9, P L^2 / EI = 1: the axial forces EA/L0 (l - L0) carry a round-off of ~eps |x| EA/L0
    (~1e-5 N here), above tol_force |f_ext| = 1e-8 N; the solver must accept that floor instead of failing."""
    X0, asm = cantilever(n=32, EA=1e9, EI=1.0, GJ=1.0)
    f = np.zeros(asm.n_dof)
    f[-4] = -1.0
    res = StaticSolver(asm).solve(NodalState.reference(X0), f, fixed_dofs=np.arange(6))
    assert res.converged
    assert res.history[-1][1] > 1e-8  # only the round-off criterion can have accepted this residual
    # elastica PL^2/EI = 1: tip deflection 0.30172 L (Bisshopp & Drucker 1945); 32 elements: error ~1e-5
    assert -(res.state.x[-1, 2]) == pytest.approx(0.30172, abs=5e-5)


def spring_bar(n, L, EA):
    """Straight bar of n beams along x with the tip node n as an extra block (for a configuration-dependent load)."""
    X0 = np.zeros((n + 1, 3))
    X0[:, 0] = np.linspace(0.0, L, n + 1)
    conn = np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)
    bs = BeamSet(conn, X0, [0.0, 0.0, 1.0], EA=EA, EI2=1.0, EI3=1.0, GJ=0.8)
    return X0, Assembler(n + 1, [bs], extra_blocks=np.array([[n]]))


class _TipSpringLoad:
    """Displacement-dependent tip load f_x = P - k (x_tip - x_tip0): a load with a stiffness of its own."""

    def __init__(self, asm, tip, P, k, x0, with_tangent=True):
        self.asm, self.tip, self.P, self.k, self.x0, self.with_tangent = asm, tip, P, k, x0, with_tangent
        self.calls = 0

    def force(self, st):
        self.calls += 1
        f = np.zeros(self.asm.n_dof)
        f[6 * self.tip] = self.P - self.k * (st.x[self.tip, 0] - self.x0)
        return f

    def tangent(self, st):
        block = np.zeros((1, 3, 3))
        block[0, 0, 0] = self.k if self.with_tangent else 0.0  # -d f_x / d x_tip
        return self.asm.block_data(block)


def test_configuration_dependent_load_with_its_tangent():
    n, L, EA = 6, 1.0, 1e4
    X0, asm = spring_bar(n, L, EA)
    # the extra block is part of the pattern and block_data puts its entries at (6 n + a, 6 n + b)
    dense = asm.matrix(asm.block_data(np.arange(9.0).reshape(1, 3, 3))).toarray()
    assert np.array_equal(dense[6 * n:6 * n + 3, 6 * n:6 * n + 3], np.arange(9.0).reshape(3, 3))
    assert np.count_nonzero(dense) == 8
    P, k = 50.0, 3.0 * EA / L  # load spring three times stiffer than the bar: plain load iteration diverges
    clamp = np.arange(6)
    load = _TipSpringLoad(asm, n, P, k, L)
    res = StaticSolver(asm).solve(NodalState.reference(X0), None, fixed_dofs=clamp, load=load, tol_force=1e-10)
    # springs in parallel: u = P / (EA/L + k) (axial co-rotational bar: N = EA/L0 (l - L0) exactly)
    assert res.state.x[n, 0] - L == pytest.approx(P / (EA / L + k), rel=1e-9)
    assert res.iterations <= 2
    # the reaction at the clamp carries the part of P the bar takes
    assert -res.reactions[0] == pytest.approx(P * (EA / L) / (EA / L + k), rel=1e-8)
    # without the load tangent the same Newton iteration diverges (the load stiffness is what the tangent adds)
    with pytest.raises(ConvergenceError):
        StaticSolver(asm, max_iter=20).solve(NodalState.reference(X0), None, fixed_dofs=clamp,
                                             load=_TipSpringLoad(asm, n, P, k, L, with_tangent=False))


def test_stalled_newton_is_accepted_only_within_accept_force():
    """A tangent that is off by a constant factor converges linearly; with too few iterations the solve raises,
    unless the best iterate is within ``accept_force``, which is then returned and flagged."""
    n, L, EA = 4, 1.0, 1e4
    X0, asm = spring_bar(n, L, EA)

    class HalfTangent(_TipSpringLoad):
        def tangent(self, st):
            block = np.zeros((1, 3, 3))
            block[0, 0, 0] = 0.5 * self.k  # half the load stiffness: error factor 0.6 per iteration
            return self.asm.block_data(block)

    P, k = 50.0, 3.0 * EA / L
    clamp = np.arange(6)
    with pytest.raises(ConvergenceError):
        StaticSolver(asm, max_iter=10).solve(NodalState.reference(X0), None, fixed_dofs=clamp,
                                             load=HalfTangent(asm, n, P, k, L), tol_force=1e-10)
    res = StaticSolver(asm, max_iter=14).solve(NodalState.reference(X0), None, fixed_dofs=clamp,
                                               load=HalfTangent(asm, n, P, k, L), tol_force=1e-10, accept_force=1e-2)
    assert res.accepted and not res.converged
    u_exact = P / (EA / L + k)
    assert abs(res.state.x[n, 0] - L - u_exact) < 0.02 * u_exact
    with pytest.raises(ConvergenceError):  # 3 iterations are not within 1 %
        StaticSolver(asm, max_iter=3).solve(NodalState.reference(X0), None, fixed_dofs=clamp,
                                            load=HalfTangent(asm, n, P, k, L), tol_force=1e-10, accept_force=1e-2)


@pytest.mark.parametrize("lam0", [1e-3, 10.0])
def test_damped_newton_reaches_the_same_equilibrium(lam0):
    """Levenberg-Marquardt damping changes the path, not the solution (spring-loaded bar, analytic answer)."""
    n, L, EA = 4, 1.0, 1e4
    X0, asm = spring_bar(n, L, EA)
    P, k = 50.0, 3.0 * EA / L
    res = StaticSolver(asm).solve_damped(NodalState.reference(X0), np.arange(6), np.zeros(6),
                                         _TipSpringLoad(asm, n, P, k, L), tol_force=1e-10, tol_disp=1e-12,
                                         lam0=lam0)
    assert res.converged
    assert res.state.x[n, 0] - L == pytest.approx(P / (EA / L + k), rel=1e-8)
    if lam0 > 1:  # heavily damped start: more, shorter steps
        assert res.iterations > 2


def test_banded_and_sparse_factorisations_give_the_same_solution():
    """The LAPACK banded LU (narrow band: DOF numbered along the strip) and SuperLU solve the same Newton steps."""
    X0, asm = cantilever(n=40)
    f_ext = np.zeros(asm.n_dof)
    f_ext[6 * 40 + 2] = 2.0  # large tip load: several Newton iterations
    out = {}
    for banded in (True, False):
        solver = StaticSolver(asm, banded=banded)
        out[banded] = solver.solve(NodalState.reference(X0), f_ext, fixed_dofs=np.arange(6))
        kind = type(solver._lu).__name__
        assert (kind == "_BandedLU") == banded
    np.testing.assert_allclose(out[True].state.x, out[False].state.x, atol=1e-12)
    assert out[True].iterations == out[False].iterations


def test_a_solver_with_a_banded_factorisation_deep_copies_and_pickles():
    """Snapshots of a running simulation (copy.deepcopy, pickling for worker processes) need the kept LU to copy:
    the copy solves like the original."""
    import copy
    import pickle

    X0, asm = cantilever(n=40)
    f_ext = np.zeros(asm.n_dof)
    f_ext[6 * 40 + 2] = 2.0
    solver = StaticSolver(asm, banded=True)
    solver.solve(NodalState.reference(X0), f_ext, fixed_dofs=np.arange(6))
    assert type(solver._lu).__name__ == "_BandedLU"
    rhs = np.linspace(0.0, 1.0, len(solver._lu_free))
    for clone in (copy.deepcopy(solver), pickle.loads(pickle.dumps(solver))):
        np.testing.assert_array_equal(clone._lu.solve(rhs), solver._lu.solve(rhs))


def test_condensed_tangent_of_a_cantilever_tip_is_the_analytic_tip_stiffness():
    """Tip translations prescribed, tip rotations free: the condensed stiffness of a clamped beam is
    diag(EA/L, 3EI/L^3, 3EI/L^3) (linear range: a 1 nm prescribed move); twice (the cached block positions)."""
    n, L, EA, EI = 20, 1.0, 1e4, 1.0
    X0, asm = cantilever(n=n, L=L, EA=EA, EI=EI)
    tip = 6 * n + np.arange(3)
    solver = StaticSolver(asm)
    for _ in range(2):
        solver.solve(NodalState.reference(X0), np.zeros(asm.n_dof), fixed_dofs=np.r_[np.arange(6), tip],
                     du_fixed=np.r_[np.zeros(6), 0.0, -1e-9, 1e-9])  # linear range
        K = solver.condensed_tangent(tip)
        np.testing.assert_allclose(K, np.diag([EA / L, 3 * EI / L**3, 3 * EI / L**3]), rtol=1e-6, atol=1e-4)


def test_error_estimate_stops_modified_newton_one_correction_earlier_within_the_tolerance():
    """``error_estimate`` (Hairer & Wanner's rule): the iterate's error estimated from the contraction of the last
    correction, ``theta / (1 - theta) |du|``, certifies it against ``tol_disp``; the last increment alone certifies
    only the iterate before it. On a warm restart of the modified iteration (5 % more load) the estimate stops one
    correction earlier (4 against 5), at a state within ``tol_disp`` of the exact solution (8.8e-5 m against
    3.5e-5 m)."""
    X0, asm = cantilever(n=8)
    f = np.zeros(asm.n_dof)
    f[-6:] = [0.0, 0.5, -1.5, 0.3, 0.0, 0.0]
    clamp = np.arange(6)
    st0 = NodalState.reference(X0)
    exact = StaticSolver(asm, mode="full", tol_force=1e-12, tol_disp=1e-12).solve(st0, 1.05 * f, fixed_dofs=clamp)
    runs = {}
    for est in (False, True):
        s = StaticSolver(asm, mode="modified", contraction=0.9, tol_force=1e-3, tol_disp=1e-4, error_estimate=est)
        warm = s.solve(st0, f, fixed_dofs=clamp).state  # leaves its factorisation for the next solve
        runs[est] = s.solve(warm, 1.05 * f, fixed_dofs=clamp)
    assert runs[True].iterations == runs[False].iterations - 1
    for res in runs.values():
        assert np.max(np.abs(res.state.x - exact.state.x)) < 1e-4


def test_a_load_may_hand_over_the_structure_it_assembled():
    """``load.assembled(state)``: the solver takes ``(f_int, tangent data)`` a load assembled at that very iterate
    instead of assembling again (the wing with inertia assembles its structural damping's tangent at the step's
    first iterate); the solution is the same."""
    n, L, EA = 6, 1.0, 1e4
    X0, asm = spring_bar(n, L, EA)
    P, k = 50.0, 3.0 * EA / L
    clamp = np.arange(6)
    calls = []

    class Handing(_TipSpringLoad):
        def force(self, st):
            self._pre = (st, *asm.assemble_data(st.x, st.Rn, tangent=True))
            return super().force(st)

        def assembled(self, st):
            calls.append(self._pre[0] is st)
            return self._pre[1:] if self._pre[0] is st else None

    counted = []
    orig = asm.assemble_data

    def counting(*a, **kw):
        counted.append(1)
        return orig(*a, **kw)

    ref = StaticSolver(asm).solve(NodalState.reference(X0), None, fixed_dofs=clamp,
                                  load=_TipSpringLoad(asm, n, P, k, L), tol_force=1e-10)
    asm.assemble_data = counting
    res = StaticSolver(asm).solve(NodalState.reference(X0), None, fixed_dofs=clamp, load=Handing(asm, n, P, k, L),
                                  tol_force=1e-10)
    assert calls and all(calls)
    assert len(counted) == len(calls)  # the load's own assemblies only: the solver used each of them
    assert np.allclose(res.state.x, ref.state.x, rtol=0, atol=1e-12)
