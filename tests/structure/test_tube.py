"""Breukels' inflated-tube correlations against the evaluated table of physics_facts.md 2.5."""

import numpy as np
import pytest

from kite_env.structure import tube

# p [bar], d [m], D=M_max, N, EI0, v_collapse, c1, c2, GJ0  (physics_facts.md 2.5)
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
