"""FEModel: verification problems through the public API, reactions, tube law, pressure loads, input validation."""

import numpy as np
import pytest

from kite_env.structure import tube
from kite_env.structure.model import CircularRod, CircularTube, FEModel
from kite_env.structure.solver import ConvergenceError


def line_nodes(n, L, axis=(1.0, 0.0, 0.0)):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.linspace(0.0, L, n + 1)[:, None] * axis


def chain(n):
    return np.c_[np.arange(n), np.arange(1, n + 1)]


def test_linear_cantilever_with_section_and_reactions():
    """Steel tube cantilever, small tip loads: P L^3 / (3 E I), T L / (G J); reactions balance the loads."""
    L, n = 2.0, 4
    sec = CircularTube(diameter=0.05, wall=0.002)
    E, nu = 2.1e11, 0.3
    G = E / (2 * (1 + nu))
    m = FEModel(line_nodes(n, L))
    bs = m.add_beams(chain(n), up=(0, 0, 1), section=sec, E=E, nu=nu)
    assert bs.EI2[0] == pytest.approx(E * np.pi * (0.05**4 - 0.046**4) / 64)
    m.fix(0)
    P, T = 0.01, 0.005  # [N], [N m]: deflection ~1e-6 L, geometric nonlinearity negligible
    m.add_load(n, force=(0.0, P, -2 * P), moment=(T, 0.0, 0.0))
    res = m.solve(load_steps=1)
    d = P * L**3 / (3 * E * sec.inertia)
    assert res.displacements[-1] == pytest.approx([0.0, d, -2 * d], abs=1e-5 * d)  # shortening 0.6 |u|^2/L
    assert res.rotation_vectors[-1][0] == pytest.approx(T * L / (G * sec.polar), rel=1e-6)
    # support reaction at the root: minus the load and minus its moment about the root (deformed geometry)
    F = np.array([0.0, P, -2 * P])
    # (to the round-off of the steel's axial forces, EA / L0 ~ 1e8 N/m: ~1e-7 of the load)
    assert res.reactions[0, :3] == pytest.approx(-F, abs=1e-6 * P)
    Mroot = np.cross(res.positions[-1], F) + [T, 0.0, 0.0]
    assert res.reactions[0, 3:] == pytest.approx(-Mroot, abs=1e-6 * P * L)
    assert np.all(res.reactions[1:] == 0.0)


def test_elastica_through_api():
    """P L^2 / EI = 1: tip deflection 0.3017 L (Bisshopp & Drucker 1945, Q. Appl. Math. 3, 272-275); the first
    integral of the elastica, x_tip = L sqrt(2 sin(theta_tip) / alpha), ties the tip position to the tip slope."""
    n = 32
    m = FEModel(line_nodes(n, 1.0))
    m.add_beams(chain(n), up=(0, 0, 1), EA=1e7, EI2=1.0, EI3=1.0, GJ=1.0)
    m.fix(0)
    m.add_load(n, force=(0.0, 0.0, -1.0))
    res = m.solve(load_steps=2)
    u = res.displacements[-1]
    assert -u[2] == pytest.approx(0.3017, abs=1e-4)
    theta_tip = res.rotation_vectors[-1][1]  # rotation about +y turns +x towards -z
    assert 1.0 + u[0] == pytest.approx(np.sqrt(2.0 * np.sin(theta_tip)), abs=5e-5)
    assert res.reactions[0, 2] == pytest.approx(1.0, rel=1e-9)


def test_roll_up_full_circle_through_api():
    n, L, EI = 20, 1.5, 2.0
    m = FEModel(line_nodes(n, L))
    m.add_beams(chain(n), up=(0, 0, 1), EA=1e4, EI2=EI, EI3=EI, GJ=1.0)
    m.fix(0)
    M = 2 * np.pi * EI / L
    m.add_load(n, moment=(0.0, 0.0, M))
    res = m.solve(load_steps=8)
    assert np.linalg.norm(res.positions[-1]) < 1e-9 * L  # tip back at the root
    R = EI / M
    r = np.linalg.norm(res.positions - [0.0, R, 0.0], axis=1)
    assert np.max(np.abs(r - R)) < 0.01 * R  # on the analytic circle (discretisation O(1/n^2))
    assert res.reactions[0] == pytest.approx([0, 0, 0, 0, 0, -M], abs=1e-9 * M)
    assert len(res.history) == 8 and res.iterations == sum(h["iterations"] for h in res.history)


def test_prescribed_rotation_bends_half_circle():
    """Tip rotation pi about z prescribed (tip translations free): uniform curvature pi / L, tip reaction moment
    EI pi / L (exact for the co-rotational element), tip on the inscribed polygon's circle at (0, 2 R_h, 0)."""
    n, L, EI = 16, 1.0, 3.0
    m = FEModel(line_nodes(n, L))
    m.add_beams(chain(n), up=(0, 0, 1), EA=1e4, EI2=EI, EI3=EI, GJ=1.0)
    m.fix(0)
    m.prescribe(n, "rz", np.pi)
    res = m.solve(load_steps=6)
    L0 = L / n
    R_h = L0 / (2 * np.sin(np.pi / (2 * n)))
    assert res.positions[-1] == pytest.approx([0.0, 2 * R_h, 0.0], abs=1e-9)
    assert res.rotation_vectors[-1] == pytest.approx([0.0, 0.0, np.pi], abs=1e-9)
    assert res.reactions[n, 5] == pytest.approx(EI * np.pi / L, rel=1e-9)
    assert res.reactions[n, :5] == pytest.approx(np.zeros(5), abs=1e-9)
    assert res.reactions[0, 5] == pytest.approx(-EI * np.pi / L, rel=1e-9)


def test_prescribed_displacement_reaction():
    L, EI, delta, n = 1.2, 4.0, 1e-6, 3
    m = FEModel(line_nodes(n, L, axis=(0, 1, 0)))
    # beam along y, up = x: local z = y cross x = -z, so a deflection along z bends about local y: EI2
    m.add_beams(chain(n), up=(1, 0, 0), EA=1e3, EI2=EI, EI3=10.0, GJ=1.0)
    m.fix(0)
    m.prescribe(n, "uz", delta)
    res = m.solve(load_steps=2)
    P = 3 * EI * delta / L**3
    assert res.displacements[-1] == pytest.approx([0.0, 0.0, delta], abs=1e-6 * delta)
    assert res.reactions[n, 2] == pytest.approx(P, rel=1e-6)
    assert res.reactions[0, 2] == pytest.approx(-P, rel=1e-6)
    assert res.reactions[0, 3] == pytest.approx(-P * L, rel=1e-6)  # balances the tip reaction's moment L e_y x P e_z


@pytest.mark.parametrize("m_ratio", [0.6, 0.8])
def test_inflated_tube_secant_law_under_end_moment(m_ratio):
    """Uniform bending of a Breukels tube (d = 0.16 m, 0.3 bar): M = M_max (1 - exp(-EI0 kappa / M_max)) inverted
    gives kappa = -(M_max / EI0) ln(1 - M / M_max); tip rotation kappa L. Initial law: kappa = M / EI0."""
    d, p, Et, L, n = 0.16, 0.3e5, 2e4, 1.0, 8
    props = tube.tube_properties(p, np.array([d]))
    M = m_ratio * props.M_max[0]
    results = {}
    for law in ("initial", "secant"):
        m = FEModel(line_nodes(n, L))
        m.add_inflated_tubes(chain(n), (0, 0, 1), diameter_m=d, pressure_pa=p, wall_Et=Et, tube_law=law)
        m.fix(0)
        m.add_load(n, moment=(0.0, M, 0.0))
        results[law] = m.solve(load_steps=2)
    kappa = -(props.M_max[0] / props.EI0[0]) * np.log(1.0 - m_ratio)
    assert results["secant"].rotation_vectors[-1][1] == pytest.approx(kappa * L, rel=1e-6)
    assert results["initial"].rotation_vectors[-1][1] == pytest.approx(M / props.EI0[0] * L, rel=1e-9)
    collapsed = kappa > props.kappa_collapse[0]
    assert collapsed == (m_ratio == 0.8)  # 0.6 M_max stays below Breukels' collapse curvature, 0.8 M_max not
    assert np.all(results["secant"].info["tube_collapsed"] == collapsed)
    assert results["secant"].history[-1]["outer"] > 2  # the fixed point was iterated


def test_inflated_tube_axial_stiffness_is_wall_membrane():
    d, Et, L, P = 0.2, 3e4, 2.0, 5.0
    m = FEModel(line_nodes(2, L))
    m.add_inflated_tubes(chain(2), (0, 0, 1), diameter_m=d, pressure_pa=0.25e5, wall_Et=Et)
    m.fix(0)
    m.add_load(2, force=(P, 0.0, 0.0))
    res = m.solve(load_steps=1)
    assert res.displacements[-1, 0] == pytest.approx(P * L / (Et * np.pi * d), rel=1e-9)


def test_pressure_resultants():
    nodes = np.array([[0, 0, 0], [2, 0, 0], [0, 3, 0], [0, 0, 1.5]], dtype=float)
    m = FEModel(nodes)
    m.add_pressure([[0, 1, 2]], p=10.0)
    f = m.pressure_loads()
    assert f[:, :3].sum(0) == pytest.approx([0.0, 0.0, 10.0 * 3.0])  # p A n, n = (x1 - x0) x (x2 - x0) / |.|
    assert np.all(f[3] == 0.0) and np.all(f[:, 3:] == 0.0)
    # closed surface (tetrahedron, consistently oriented): no net force
    m2 = FEModel(nodes)
    m2.add_pressure([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], p=7.0)
    assert np.allclose(m2.pressure_loads()[:, :3].sum(0), 0.0, atol=1e-12)


@pytest.mark.parametrize("follower", [True, False])
def test_follower_versus_dead_pressure_on_torsion_flags(follower):
    """A shaft (GJ = 1, L = 1) twisted by pressure on two stiff flags at its tip, one on each side, pushing in
    opposite directions: a pure torque T0 = (4/3) p c w^2 at the reference geometry.

    Follower pressure turns with the flags: T = T0, so the twist is T0 L / GJ = 1 rad. Dead loads keep their
    direction: T = T0 cos(phi), so phi = cos(phi) -> phi = 0.7390851332 (the fixed point of cos).
    """
    c, w, L, GJ = 0.1, 0.3, 1.0, 1.0
    n = 4
    tip = n
    nodes = np.vstack([line_nodes(n, L), [[L + c, w, 0], [L - c, w, 0], [L - c, -w, 0], [L + c, -w, 0]]])
    a1, b1, a2, b2 = n + 1, n + 2, n + 3, n + 4
    m = FEModel(nodes)
    m.add_beams(chain(n), up=(0, 0, 1), EA=1e3, EI2=1e2, EI3=1e2, GJ=GJ)
    arms = [[tip, a1], [tip, b1], [a1, b1], [tip, a2], [tip, b2], [a2, b2]]
    m.add_beams(arms, up=(0, 0, 1), EA=1e5, EI2=1e4, EI3=1e4, GJ=1e4)  # stiff flag frames
    m.fix(0)
    p = 1.0 / ((4.0 / 3.0) * c * w**2)  # T0 L / GJ = 1
    m.add_pressure([[tip, a1, b1], [tip, b2, a2]], p=p, follower=follower)
    res = m.solve(load_steps=4)
    phi = res.rotation_vectors[tip]
    expected = 1.0 if follower else 0.7390851332151607
    assert phi[0] == pytest.approx(expected, abs=1e-5)
    assert np.abs(phi[1:]).max() < 1e-5
    assert np.linalg.norm(res.displacements[tip]) < 1e-6  # pure torque: the shaft does not bend


def test_shell_patch_equibiaxial_tension():
    """Two membrane triangles stretched equibiaxially by delta (taut, so wrinkling plays no part): St. Venant-
    Kirchhoff plane stress, Green strain e = delta + delta^2 / 2, S = E e / (1 - nu), edge force (1 + delta) S h W."""
    W, delta, E, nu, h = 1.0, 1e-3, 1e6, 0.3, 1e-3
    m = FEModel([[0, 0, 0], [W, 0, 0], [W, W, 0], [0, W, 0]])
    m.add_shells([[0, 1, 2], [0, 2, 3]], E=E, nu=nu, h=h, wrinkling=True)
    m.fix([0, 1, 2, 3], ["uz", "rx", "ry", "rz"])
    m.fix([0, 3], "ux")
    m.fix([0, 1], "uy")
    for nd in (1, 2):
        m.prescribe(nd, "ux", delta)
    for nd in (2, 3):
        m.prescribe(nd, "uy", delta)
    res = m.solve(load_steps=1)
    e = delta + delta**2 / 2
    F = (1 + delta) * E * e / (1 - nu) * h * W
    assert res.reactions[[1, 2], 0].sum() == pytest.approx(F, rel=1e-9)
    assert res.reactions[[2, 3], 1].sum() == pytest.approx(F, rel=1e-9)
    assert res.reactions[:, :3].sum(0) == pytest.approx(np.zeros(3), abs=1e-12)


def test_input_validation():
    with pytest.raises(ValueError, match="shape"):
        FEModel(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="non-finite"):
        FEModel([[0, 0, 0], [np.nan, 0, 0]])
    m = FEModel(line_nodes(3, 1.0))
    with pytest.raises(ValueError, match="outside 0..3"):
        m.add_beams([[0, 1], [1, 4]], (0, 0, 1), EA=1, EI2=1, EI3=1, GJ=1)
    with pytest.raises(ValueError, match="integers"):
        m.add_beams([[0.0, 1.0]], (0, 0, 1), EA=1, EI2=1, EI3=1, GJ=1)
    with pytest.raises(ValueError, match=r"shape \(n_elem >= 1, 2\)"):
        m.add_beams([0, 1, 2], (0, 0, 1), EA=1, EI2=1, EI3=1, GJ=1)
    with pytest.raises(ValueError, match="repeat a node"):
        m.add_beams([[1, 1]], (0, 0, 1), EA=1, EI2=1, EI3=1, GJ=1)
    with pytest.raises(ValueError, match="EI2 must be finite and positive"):
        m.add_beams(chain(3), (0, 0, 1), EA=1, EI2=-1, EI3=1, GJ=1)
    with pytest.raises(ValueError, match="all required"):
        m.add_beams(chain(3), (0, 0, 1), EA=1, EI2=1, EI3=1)
    with pytest.raises(ValueError, match="not both"):
        m.add_beams(chain(3), (0, 0, 1), EA=1, section=CircularRod(0.01), E=1e9, nu=0.3)
    with pytest.raises(ValueError, match="nu"):
        m.add_beams(chain(3), (0, 0, 1), section=CircularRod(0.01), E=1e9, nu=0.7)
    with pytest.raises(ValueError, match=r"up: expected shape"):
        m.add_beams(chain(3), (0, 1), EA=1, EI2=1, EI3=1, GJ=1)
    with pytest.raises(ValueError, match="parallel"):
        m.add_beams(chain(3), (1, 0, 0), EA=1, EI2=1, EI3=1, GJ=1)
    with pytest.raises(ValueError, match="pressure_pa"):
        m.add_inflated_tubes(chain(3), (0, 0, 1), 0.16, -1.0, 1e4)
    with pytest.raises(ValueError, match="unknown DOF"):
        m.fix(0, "uw")
    with pytest.raises(ValueError, match="one DOF"):
        m.prescribe(1, "xyz", 0.1)
    with pytest.raises(ValueError, match="non-finite"):
        m.add_load(2, force=(0, np.nan, 0))
    with pytest.raises(ValueError, match="outside"):
        m.add_load(7, force=(0, 1, 0))
    with pytest.raises(ValueError, match="shells"):
        m.add_pressure("all", 1.0)
    with pytest.raises(ValueError, match="no elements"):
        m.solve()
    m.add_beams(chain(2), (0, 0, 1), EA=1, EI2=1, EI3=1, GJ=1)  # node 3 belongs to no element
    with pytest.raises(ValueError, match="free-floating"):
        m.solve()
    m.fix(0)
    m.add_load(3, force=(0, 1, 0))
    with pytest.raises(ValueError, match="belong to no element"):
        m.solve()
    with pytest.raises(ValueError, match="load_steps"):
        m.solve(load_steps=0)


def test_failure_reports_load_step():
    n = 8
    m = FEModel(line_nodes(n, 1.0))
    m.add_beams(chain(n), (0, 0, 1), EA=1e4, EI2=1.0, EI3=1.0, GJ=1.0)
    m.fix(0)
    m.add_load(n, force=(0.0, 0.0, -20.0))
    with pytest.raises(ConvergenceError, match="load step 1/1") as info:
        m.solve(load_steps=1, max_iter=3)
    assert len(info.value.history) == 4
