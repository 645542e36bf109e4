"""Particle-system model (Sect. II.C): line forces (Eq. 10), line drag (Eq. 11), constraints (Eq. 12-13)."""

import dataclasses

import numpy as np
import pytest

from kite_env.config import DynamicsConfig
from kite_env.dynamics.particles import KCU, A, B, C, D, ParticleSystem


def system(**kw):
    cfg = dataclasses.replace(DynamicsConfig(), **kw)
    return cfg, ParticleSystem(cfg, tip_lengths=[0.6, 0.6], pair_stiffness=[500.0, 800.0, 300.0, 300.0])


def geometry(lt=80.0, line=25.0):
    """KCU on the tether at 30 deg elevation, the wing points 'line' m further out, tips 0.6 m apart along x_k."""
    el = np.deg2rad(30.0)
    R = np.array([np.cos(el), 0.0, np.sin(el)])
    up = np.array([-np.sin(el), 0.0, np.cos(el)])
    kcu = lt * R
    y = np.array([0.0, 1.0, 0.0])
    r = np.array([kcu + line * R + 2.6 * y, kcu + line * R + 2.6 * y - 0.6 * up,
                  kcu + line * R - 2.6 * y, kcu + line * R - 2.6 * y - 0.6 * up, kcu])
    return r


def test_line_tension_eq10_pulls_only():
    cfg, ps = system()
    r = geometry()
    v = np.zeros((5, 3))
    l = np.linalg.norm(r[:4] - r[KCU], axis=1)
    ps.set_steering(l[B] - 0.01, l[D] + 0.01)  # B stretched 1 cm, D slack
    ps.rest[[A, C]] = l[[A, C]] - 0.02
    T, _ = ps.line_forces(r, v)
    k = cfg.line_stiffness_N_per_m
    np.testing.assert_allclose(T, [0.02 * k, 0.01 * k, 0.02 * k, 0.0], rtol=1e-9)
    # damping term c_c dl/dt: B moving away from the KCU at 0.1 m/s
    v[B] = 0.1 * (r[B] - r[KCU]) / l[B]
    T2, _ = ps.line_forces(r, v)
    assert T2[1] - T[1] == pytest.approx(0.1 * cfg.line_damping_Ns_per_m, rel=1e-9)
    # the forces of the lines on the wing points and the KCU cancel (internal forces)
    f, info = ps.forces(r, v * 0, np.zeros((5, 3)), np.zeros((4, 3)))
    weight = -ps.m.sum() * cfg.gravity_mps2
    np.testing.assert_allclose(f.sum(axis=0), [0.0, 0.0, weight], atol=1e-9)


def test_line_drag_eq11_half_to_each_end():
    cfg, ps = system(gravity_mps2=0.0, beta_ac=0.0, beta_bd=0.0, beta_diag=0.0)
    r = geometry()
    l = np.linalg.norm(r[:4] - r[KCU], axis=1)
    ps.set_steering(l[B] + 1.0, l[D] + 1.0)
    ps.rest[[A, C]] = l[[A, C]] + 1.0  # all lines slack: drag only
    wind = np.zeros((5, 3))
    wind[:, 1] = 10.0  # cross wind along y_w, perpendicular to every line that lies in the x-z plane ... mostly
    f, _ = ps.forces(r, np.zeros((5, 3)), wind, np.zeros((4, 3)))
    e = (r[:4] - r[KCU]) / l[:, None]
    va = -wind[:4]  # line velocity relative to the air
    van = va - np.einsum("ij,ij->i", va, e)[:, None] * e
    F = -0.5 * 1.225 * cfg.line_cd * cfg.line_diameter_m * l[:, None] * np.linalg.norm(van, axis=1)[:, None] * van
    np.testing.assert_allclose(f[:4], 0.5 * F, rtol=1e-12)
    np.testing.assert_allclose(f[KCU], 0.5 * F.sum(axis=0), rtol=1e-12)
    assert np.all(f[:4, 1] > 0)  # pushed downwind (+y)


def test_constrained_accelerations_and_projection():
    cfg, ps = system()
    rng = np.random.default_rng(2)
    r = geometry()
    v = rng.normal(size=(5, 3))
    r, v = ps.project(r, v)
    np.testing.assert_allclose(ps.constraint_violation(r), 0.0, atol=1e-10)
    _, G, gdot_v = ps._constraints(r, v)
    np.testing.assert_allclose(G @ v.ravel(), 0.0, atol=1e-10)
    f = rng.normal(size=(5, 3)) * 100
    a, lam = ps.accelerations(r, v, f)
    # exact constraint acceleration on the manifold (Baumgarte terms vanish there): G a = -dG/dt v
    np.testing.assert_allclose(G @ a.ravel(), -gdot_v, atol=1e-8)
    # the tether reaction acts on the KCU along r_KCU only
    resid = ps.m[:, None] * a - f
    np.testing.assert_allclose(np.cross(resid[KCU], r[KCU]), 0.0, atol=1e-8)
    # the tip constraints act along A-B and C-D with equal and opposite forces
    np.testing.assert_allclose(resid[A] + resid[B], 0.0, atol=1e-8)
    np.testing.assert_allclose(np.cross(resid[A], r[A] - r[B]), 0.0, atol=1e-8)


def test_pair_damping_is_a_fraction_of_critical():
    cfg, ps = system(line_cd=0.0)
    mu_ac = cfg.mass_le_kg / 2.0
    assert ps.pair_damping[0] == pytest.approx(2 * cfg.beta_ac * np.sqrt(500.0 * mu_ac))
    # a damped pair dissipates: relative velocity along A-C gives opposing forces
    r = geometry()
    v = np.zeros((5, 3))
    v[A, 1] = 1.0  # A moving away from C
    ps.rest[:] = 100.0  # lines slack
    f, _ = ps.forces(r, v, np.zeros((5, 3)), np.zeros((4, 3)))
    f0, _ = ps.forces(r, np.zeros((5, 3)), np.zeros((5, 3)), np.zeros((4, 3)))
    df = f - f0
    assert df[A, 1] < 0 and df[C, 1] > 0 and np.sum(df[:, 1]) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="steering-line"):
        ps.set_steering(-1.0, 25.0)
