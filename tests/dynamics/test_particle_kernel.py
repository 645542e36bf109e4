"""Compiled right-hand side of the particle system (kite_env.dynamics.kernels) against the NumPy reference path of
FlightSimulator._rhs: frame K, wing force (condensed-stiffness correction or interpolation), Eq. (10) line forces
with the tension clip, Eq. (11) line and tether drag, pair dampers, Eq. (12-13) constrained accelerations."""

import dataclasses

import numpy as np
import pytest

from kite_env import compiled
from kite_env.config import Config
from kite_env.dynamics.kernels import particle_accelerations
from kite_env.dynamics.particles import KCU, A, B, C, D, ParticleSystem
from kite_env.dynamics.simulator import FlightSimulator

pytestmark = pytest.mark.skipif(not compiled.NUMBA_AVAILABLE, reason="numba not installed")

# bridle points A, B, C, D in frame K [m]: x_k aft, y_k towards A, z_k up (away from the KCU)
Q0 = np.array([[0.0, 2.6, 0.0], [0.55, 2.5, -0.08], [0.0, -2.6, 0.0], [0.55, -2.5, -0.08]])


class ShearWind:
    """Wind that differs at every mass (shear, a cross component, time dependence) so that rows cannot be mixed up."""

    def velocity(self, t, r):
        r = np.asarray(r, dtype=float)
        out = np.empty(r.shape)
        out[..., 0] = 8.0 * (np.maximum(r[..., 2], 1.0) / 10.0) ** 0.14 + 0.5 * np.sin(0.3 * t)
        out[..., 1] = 0.05 * r[..., 0] - 1.0
        out[..., 2] = 0.3 * np.cos(0.1 * r[..., 1])
        return out


class DesignBridleOnly:
    """Stands in for the wing: FlightSimulator.__init__ reads only ``design_bridle`` from a given wing, and _rhs uses
    only the held wing force, so no aeroelastic solve is needed here."""

    design_bridle = Q0


def simulator(backend, tether_diameter=0.0):
    cfg = Config()
    cfg = dataclasses.replace(cfg, dynamics=dataclasses.replace(cfg.dynamics, tether_diameter_m=tether_diameter))
    sim = FlightSimulator(cfg, ShearWind(), wing=DesignBridleOnly(), backend=backend)
    sim.particles = ParticleSystem(cfg.dynamics, sim.tip_lengths, [500.0, 800.0, 300.0, 300.0], cfg.aero.rho_kg_m3)
    return sim


def flight_state(seed, sim, slack):
    """A kite at 80 m on the tether, its frame tilted at random, flying at ~25 m/s across the wind, slightly off the
    constraints; the bridle lines stretched by 0.1-0.3 m (0.5-1.4 kN) except line ``slack`` (1 m too long). Also
    sets the held wing force of ``sim`` (lift-dominated, in K), the wing solution's bridle points and a condensed
    wing stiffness."""
    rng = np.random.default_rng(seed)
    el, az = np.deg2rad(rng.uniform(20.0, 60.0)), np.deg2rad(rng.uniform(-40.0, 40.0))
    e_r = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    z = e_r + 0.1 * rng.normal(size=3)
    z /= np.linalg.norm(z)
    x = np.cross(z, rng.normal(size=3))
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z])
    kcu = 80.0 * e_r
    r = np.vstack([kcu + 24.86 * z + Q0 @ R.T, kcu]) + 0.01 * rng.normal(size=(5, 3))
    tangent = np.cross(e_r, [0.0, 0.0, 1.0])
    tangent /= np.linalg.norm(tangent)
    v = 25.0 * tangent + 0.5 * rng.normal(size=(5, 3))
    l = np.linalg.norm(r[:4] - r[KCU], axis=1)
    rest = l - rng.uniform(0.1, 0.3, size=4)
    rest[slack] = l[slack] + 1.0
    sim.particles.set_steering(rest[B], rest[D])
    sim.particles.rest[[A, C]] = rest[[A, C]]
    F = rng.normal(scale=40.0, size=(4, 3))
    F[:, 2] += [900.0, 350.0, 900.0, 350.0]
    sim._F_k_K = F
    sim._q_b_K = Q0 + 0.01 * rng.normal(size=(4, 3))
    K = rng.normal(scale=500.0, size=(12, 12))
    sim._K_b = K @ K.T / 12.0 + 3000.0 * np.eye(12)
    return r, v, rng


def assert_same(got, ref):
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))


@pytest.mark.parametrize("tether_diameter", [0.0, 0.01])
@pytest.mark.parametrize("mode", ["correction", "interpolation"])
def test_kernel_matches_numpy_reference(mode, tether_diameter):
    ref, nb = simulator("numpy", tether_diameter), simulator("numba", tether_diameter)
    for seed in range(4):
        for sim in (ref, nb):
            r, v, rng = flight_state(seed, sim, slack=seed)
            sim._F_end_K = None if mode == "correction" else sim._F_k_K + rng.normal(scale=100.0, size=(4, 3))
        frac = rng.uniform()
        t = 0.37 * seed
        # the slack line is clipped to zero tension, the others pull (Eq. 10)
        T, l = ref.particles.line_forces(r, v)
        assert T[seed] == 0.0 and np.all(np.delete(T, seed) > 0.0)
        v_out, a_ref, lam_ref = ref._rhs(t, r, v, frac)
        v_nb, a_nb, lam_nb = nb._rhs(t, r, v, frac)
        assert v_nb is v and a_nb.shape == (5, 3) and lam_nb.shape == (3,)
        assert_same(a_nb, a_ref)
        assert_same(lam_nb, lam_ref)
        # the accelerations satisfy the stabilised constraint equations G a = -dG/dt v - 2 alpha G v - alpha^2 g
        g, G, gdot_v = nb.particles._constraints(r, v)
        al = nb.cfg.dynamics.baumgarte_1_per_s
        np.testing.assert_allclose(G @ a_nb.ravel(), -gdot_v - 2 * al * (G @ v.ravel()) - al * al * g,
                                   rtol=1e-10, atol=1e-9 * np.max(np.abs(G @ a_nb.ravel())))


def test_wing_force_modes_and_tether_drag_change_the_result():
    """The branches compared above are live: the stiffness correction, the interpolation and the tether drag each
    change the accelerations, and the tether drag acts on the KCU alone before the constraint forces."""
    sim = simulator("numba")
    r, v, _ = flight_state(7, sim, slack=B)
    params = sim.particles.kernel_parameters()
    F0, q, K = sim._F_k_K, sim._q_b_K, sim._K_b
    wind = sim.wind.velocity(0.0, r)
    a_corr, _ = particle_accelerations(r, v, wind, F0, F0, 0.0, False, q, K, *params)
    a_zero_K, _ = particle_accelerations(r, v, wind, F0, F0, 0.0, False, q, 0.0 * K, *params)
    a_held, _ = particle_accelerations(r, v, wind, F0, 2.0 * F0, 0.0, True, q, K, *params)
    a_end, _ = particle_accelerations(r, v, wind, F0, 2.0 * F0, 1.0, True, q, K, *params)
    assert np.max(np.abs(a_corr - a_zero_K)) > 1e-3
    np.testing.assert_allclose(a_held, a_zero_K, rtol=1e-13, atol=1e-12)  # frac = 0: the force at the start
    assert np.max(np.abs(a_end - a_held)) > 1.0
    # tether drag, Eq. (11) for the tether: the applied force differs on the KCU by the analytic drag only
    dt = 0.02
    on = simulator("numpy", tether_diameter=dt)
    on.particles.rest[:] = sim.particles.rest
    f_off, _ = sim.particles.forces(r, v, wind, np.zeros((4, 3)))
    f_on, _ = on.particles.forces(r, v, wind, np.zeros((4, 3)))
    lt = np.linalg.norm(r[KCU])
    vt = 0.5 * v[KCU] - wind[KCU]
    vtn = vt - (vt @ r[KCU] / lt) * r[KCU] / lt
    drag = -0.25 * on.particles.rho * on.cfg.dynamics.line_cd * dt * lt * np.linalg.norm(vtn) * vtn
    np.testing.assert_allclose(f_on[KCU] - f_off[KCU], drag, rtol=1e-9)
    np.testing.assert_array_equal(f_on[:4], f_off[:4])
    params_on = list(params)
    params_on[7] = dt
    a_on, _ = particle_accelerations(r, v, wind, F0, F0, 0.0, False, q, K, *params_on)
    assert np.max(np.abs(a_on - a_corr)) > 1e-3


def test_degenerate_geometry_gives_nan_like_numpy():
    """A and C coincident: no frame K. Both paths return non-finite accelerations (reported by the simulator as a
    non-finite state) instead of raising."""
    ref, nb = simulator("numpy"), simulator("numba")
    for sim in (ref, nb):
        r, v, _ = flight_state(3, sim, slack=D)
        sim._F_end_K = None
    r[C] = r[A]
    with np.errstate(invalid="ignore", divide="ignore"):
        _, a_ref, _ = ref._rhs(0.0, r, v)
    _, a_nb, _ = nb._rhs(0.0, r, v)
    assert not np.all(np.isfinite(a_ref)) and not np.all(np.isfinite(a_nb))


def test_backend_selection(monkeypatch):
    assert simulator("numpy").backend == "numpy"
    assert simulator("numba").backend == "numba"
    monkeypatch.setenv(compiled.ENV_VAR, "numpy")
    assert simulator("auto").backend == "numpy"
    monkeypatch.setenv(compiled.ENV_VAR, "numba")
    assert simulator("auto").backend == "numba"
    with pytest.raises(ValueError):
        simulator("cuda")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_constraint_projection_matches_numpy_reference(seed):
    """project_constraints = ParticleSystem.project (3 position passes, then velocities) to round-off, and the
    projected state satisfies the constraints and their time derivatives."""
    from kite_env.dynamics.kernels import project_constraints

    sim = simulator("numpy")
    p = sim.particles
    rng = np.random.default_rng(seed)
    r = np.vstack([Q0 + [0.0, 0.0, 105.0], [0.0, 0.0, 80.0]]) + 0.02 * rng.normal(size=(5, 3))  # off by ~cm
    v = 20.0 * rng.normal(size=(5, 3))
    r_in, v_in = r.copy(), v.copy()
    r_ref, v_ref = p.project(r, v)
    r_nb, v_nb = project_constraints(r, v, p.m, float(p.cfg.tether_length_m), p.tip_lengths, 3, 0.0)
    np.testing.assert_allclose(r_nb, r_ref, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(v_nb, v_ref, rtol=1e-13, atol=1e-10)
    assert np.max(np.abs(p.constraint_violation(r_nb))) < 1e-9
    g_dot = [r_nb[KCU] @ v_nb[KCU], (r_nb[A] - r_nb[B]) @ (v_nb[A] - v_nb[B]),
             (r_nb[C] - r_nb[D]) @ (v_nb[C] - v_nb[D])]
    np.testing.assert_allclose(g_dot, 0.0, atol=1e-9)
    np.testing.assert_array_equal(r, r_in)  # the inputs are not modified
    np.testing.assert_array_equal(v, v_in)


@pytest.mark.parametrize("seed", [0, 1])
def test_reeling_tether_kernel_matches_numpy_and_its_constraint(seed):
    """With the winch reeling out (l_t(t) = l_0 + v_r (t - t_0)) the compiled and NumPy right-hand sides agree, and
    the accelerations satisfy the reeling tether's constraint equation: g = 1/2 (|r|^2 - l_t^2),
    G a = -(|v|^2 - v_r^2) - 2 alpha (r . v - l_t v_r) - alpha^2 g."""
    ref, nb = simulator("numpy"), simulator("numba")
    t = 0.8
    for sim in (ref, nb):
        r, v, _ = flight_state(seed, sim, slack=seed)
        sim.tether_length, sim.reel_speed, sim._t_step = 80.2, 3.0, t - 0.002
    _, a_ref, lam_ref = ref._rhs(t, r, v)
    _, a_nb, lam_nb = nb._rhs(t, r, v)
    assert_same(a_nb, a_ref)
    assert_same(lam_nb, lam_ref)
    l_t, v_r = 80.2 + 0.002 * 3.0, 3.0
    assert nb.particles.tether_length == pytest.approx(l_t, abs=1e-12)
    al = nb.cfg.dynamics.baumgarte_1_per_s
    rk, vk = r[KCU], v[KCU]
    g = 0.5 * (rk @ rk - l_t**2)
    np.testing.assert_allclose(rk @ a_nb[KCU], -(vk @ vk - v_r**2) - 2 * al * (rk @ vk - l_t * v_r) - al * al * g,
                               rtol=1e-10)
    # the reel speed changes the tether force: the same state with the constant tether gives another multiplier
    nb.reel_speed = 0.0
    _, _, lam_fixed = nb._rhs(t, r, v)
    assert abs(lam_fixed[0] - lam_nb[0]) > 1e-3 * abs(lam_nb[0])


@pytest.mark.parametrize("seed", [0, 1])
def test_projection_onto_a_reeling_tether(seed):
    """Both projections put the KCU at |r_KCU| = l_t with the radial speed r . v / l_t = v_r (the winch)."""
    from kite_env.dynamics.kernels import project_constraints

    sim = simulator("numpy")
    p = sim.particles
    p.tether_length, p.reel_speed = 83.0, 2.5
    rng = np.random.default_rng(seed)
    r = np.vstack([Q0 + [0.0, 0.0, 108.0], [0.0, 0.0, 83.0]]) + 0.02 * rng.normal(size=(5, 3))
    v = 20.0 * rng.normal(size=(5, 3))
    r_ref, v_ref = p.project(r, v)
    r_nb, v_nb = project_constraints(r, v, p.m, p.tether_length, p.tip_lengths, 3, p.reel_speed)
    np.testing.assert_allclose(r_nb, r_ref, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(v_nb, v_ref, rtol=1e-13, atol=1e-10)
    assert np.linalg.norm(r_nb[KCU]) == pytest.approx(83.0, abs=1e-9)
    assert r_nb[KCU] @ v_nb[KCU] / 83.0 == pytest.approx(2.5, abs=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kcu_line_force_matches_the_numpy_lines(seed):
    """kcu_line_force (the full model's KCU step) = the smoothed pull-only tension of Eq. (10) along each bridle line
    plus half of Eq. (11)'s drag, as DynamicFlightSimulator computes them with NumPy (line_tension, line_drag), to
    round-off; one line slack (its tension the smoothing's few newtons) and one stretched so that both branches of
    the law are taken."""
    from kite_env.dynamics.kernels import kcu_line_force
    from kite_env.dynamics.lines import LINE_SMOOTHING_N, line_drag, line_tension

    rng = np.random.default_rng(seed)
    r_k = np.array([60.0, 5.0, 70.0]) + rng.normal(size=3)
    r_b = r_k + np.array([0.0, 0.0, 11.0]) + Q0 + 0.05 * rng.normal(size=(4, 3))
    v_k = rng.normal(scale=20.0, size=3)
    v_b = v_k + rng.normal(scale=2.0, size=(4, 3))
    wind = np.array([8.0, 0.0, 0.0]) + rng.normal(size=(5, 3))
    l0 = np.linalg.norm(r_b - r_k, axis=1)
    rest = l0 - np.array([0.2, -1.0, 0.1, 0.0])  # line B 1 m too long: slack
    k_c, c_c, coef = 6e4, 1e2, -0.5 * 1.225 * 1.1 * 2.5e-3
    out = np.full(3, np.nan)
    kcu_line_force(r_b, v_b, r_k, v_k, wind, rest, k_c, c_c, coef, LINE_SMOOTHING_N, out)
    dl = r_b - r_k
    l = np.linalg.norm(dl, axis=1)
    e = dl / l[:, None]
    T, _ = line_tension(k_c * (l - rest) + c_c * np.einsum("ij,ij->i", e, v_b - v_k))
    assert T[1] < LINE_SMOOTHING_N and T[0] > 1e3
    ref = T @ e + 0.5 * line_drag(coef, 0.5 * (v_b + v_k) - 0.5 * (wind[:4] + wind[4]), e, l).sum(axis=0)
    assert np.allclose(out, ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_wing_bridle_lines_match_the_numpy_lines(seed):
    """wing_bridle_lines (the wing with inertia's lines at every Newton iterate) = the NumPy path of
    ``StepLoad._lines``: unit vectors, lengths, the smoothed pull-only tension of Eq. (10) and its derivative, and
    the wing end's half of Eq. (11)'s drag with the lines' mean velocity, to round-off; one line slack and one
    stretched, so that both branches of the tension law are taken."""
    from kite_env.dynamics.kernels import wing_bridle_lines
    from kite_env.dynamics.lines import LINE_SMOOTHING_N, line_drag, line_tension

    rng = np.random.default_rng(seed)
    r_k = rng.normal(size=3)
    x_b = r_k + np.array([0.0, 0.0, 11.0]) + Q0 + 0.05 * rng.normal(size=(4, 3))
    v_k = rng.normal(scale=2.0, size=3)
    v_b = v_k + rng.normal(scale=2.0, size=(4, 3))
    wind = np.array([-25.0, 0.0, 3.0]) + rng.normal(size=3)
    l0 = np.linalg.norm(x_b - r_k, axis=1)
    rest = l0 - np.array([0.2, -1.0, 0.1, 0.0])  # line B 1 m too long: slack
    k_c, c_c, coef = 6e4, 1e2, -0.5 * 1.225 * 1.1 * 2.5e-3
    e, l, T, dT, drag = (np.full(s, np.nan) for s in ((4, 3), 4, 4, 4, (4, 3)))
    wing_bridle_lines(x_b, v_b, r_k, v_k, wind, rest, k_c, c_c, coef, LINE_SMOOTHING_N, e, l, T, dT, drag)
    d = x_b - r_k
    l_ref = np.linalg.norm(d, axis=1)
    e_ref = d / l_ref[:, None]
    T_ref, dT_ref = line_tension(k_c * (l_ref - rest) + c_c * np.einsum("ij,ij->i", e_ref, v_b - v_k))
    assert T_ref[1] < LINE_SMOOTHING_N and T_ref[0] > 1e3
    drag_ref = 0.5 * line_drag(coef, 0.5 * (v_b + v_k) - wind, e_ref, l_ref)
    for got, ref in ((e, e_ref), (l, l_ref), (T, T_ref), (dT, dT_ref), (drag, drag_ref)):
        assert np.allclose(got, ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))
