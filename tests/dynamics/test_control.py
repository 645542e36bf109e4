"""Steering-line actuator (Eq. 16-19) and the baseline heading policy (Eq. 14-15): signs, limits, blending."""

import dataclasses
import math

import numpy as np
import pytest

from kite_env.config import ConfigError, ControlConfig, config_from_dict
from kite_env.control import LineActuator
from kite_env.policies.baseline import BaselinePolicy
from kite_env.trajectory import Lemniscate, TrajectoryConfig, heading_angle, sphere_basis


def test_actuator_closes_the_steering_loop_and_the_force_loop():
    cfg = ControlConfig(line_speed_max_mps=0.0)  # the paper's Eq. 16-19 without the actuator's speed limit
    act = LineActuator(cfg, 25.2, 25.2)
    lengths = np.array([25.1, 25.3, 25.1, 25.3])
    T = np.array([1000.0, 300.0, 1000.0, 300.0])  # mu = 0.3: no force correction
    L_B, L_D, info = act.rest_lengths(0.1, lengths, T)
    assert info["mu"] == pytest.approx(0.3) and info["L3"] == pytest.approx(0.0)
    # dl* > dl = 0: the right line is lengthened and the left one shortened by K2 (dl* - dl) (Eq. 16-17)
    assert L_B - 25.2 == pytest.approx(cfg.k2 * 0.1) and 25.2 - L_D == pytest.approx(cfg.k2 * 0.1)
    # mu below mu*: both steering lines shorter by K3 (mu* - mu) (Eq. 19) plus K3i times the integral of the error
    T_low = np.array([1000.0, 200.0, 1000.0, 200.0])
    L_B2, L_D2, info2 = act.rest_lengths(0.0, lengths, T_low)
    I1 = 0.1 * cfg.control_dt_s
    assert L_B2 - 25.2 == pytest.approx(-cfg.k3_m * 0.1 - cfg.k3i_per_s * I1) and L_D2 == pytest.approx(L_B2)
    L_B3, _, _ = act.rest_lengths(0.0, lengths, T_low)  # the integral grows while the error persists
    assert L_B3 - 25.2 == pytest.approx(-cfg.k3_m * 0.1 - cfg.k3i_per_s * 2 * I1)
    # the paper's proportional loop (K3i = 0)
    p_act = LineActuator(dataclasses.replace(cfg, k3i_per_s=0.0), 25.2, 25.2)
    for _ in range(3):
        L_B4, _, _ = p_act.rest_lengths(0.0, lengths, T_low)
        assert L_B4 - 25.2 == pytest.approx(-cfg.k3_m * 0.1)
    # the desired difference is limited
    _, _, info3 = act.rest_lengths(10.0, lengths, T)
    assert info3["delta_l_star"] == cfg.delta_l_max_m


def test_force_integral_is_clamped_against_windup():
    """The integral term |K3i I| never exceeds control.force_integral_max_m, however long the error persists."""
    cfg = ControlConfig()
    act = LineActuator(cfg, 25.2, 25.2)
    lengths = np.array([25.1, 25.3, 25.1, 25.3])
    T_zero = np.array([1000.0, 0.0, 1000.0, 0.0])  # both steering lines slack: mu = 0
    for _ in range(10000):
        L_B, _, _ = act.rest_lengths(0.0, lengths, T_zero)
    assert abs(cfg.k3i_per_s * act.integral) == pytest.approx(cfg.force_integral_max_m)
    assert L_B - 25.2 == pytest.approx(-cfg.k3_m * 0.3 - cfg.force_integral_max_m)


def test_baseline_policy_signs_and_blending():
    cfg = ControlConfig()
    path = Lemniscate(TrajectoryConfig())
    pol = BaselinePolicy(cfg, path)
    pol.reset(0.0)
    R = path.point(0.0)
    e_t = path.tangent(0.0)
    # on the path, heading along it: no steering
    dl, info = pol(80.0 * R, e_t, 25.0 * e_t)
    assert abs(dl) < 1e-9 and info["beta"] == pytest.approx(1.0)
    # nose turned by +0.2 rad (towards y_s): a negative heading error -> dl* < 0 (pull the right line, turn right)
    x_s, y_s = sphere_basis(R)
    psi = float(heading_angle(R, e_t))
    nose = math.cos(psi + 0.2) * x_s + math.sin(psi + 0.2) * y_s
    dl, info = pol(80.0 * R, nose, 25.0 * e_t)
    assert info["heading_error"] == pytest.approx(-0.2, abs=1e-9)
    assert dl == pytest.approx(-0.2 * cfg.k1_m_per_rad)
    # blending: 1 on the path, 1/2 at the blending distance (at the reference speed), beta_min far away
    assert pol.blending(0.0, 25.0) == 1.0
    assert pol.blending(math.radians(cfg.beta_distance_deg), 25.0) == pytest.approx(0.5)
    assert pol.blending(1.0, 25.0) == cfg.beta_min
    # a faster kite blends over a larger distance
    d = math.radians(cfg.beta_distance_deg)
    assert pol.blending(d, 40.0) > pol.blending(d, 25.0)


def test_force_loop_holds_while_the_power_lines_are_unloaded():
    """mu of Eq. 18 is 0/0 on an unloaded wing: the loop holds (no 1e10 m rest lengths from 1 N / 1e-9 N)."""
    from kite_env.control import POWER_LINES_MIN_N, force_ratio_error

    cfg = ControlConfig()
    act = LineActuator(cfg, 25.2, 25.2)
    lengths = np.array([25.1, 25.3, 25.1, 25.3])
    for T in ([1e-9, 1.0, 0.0, 0.0], [0.4 * POWER_LINES_MIN_N, 200.0, 0.5 * POWER_LINES_MIN_N, 0.0]):
        L_B, L_D, info = act.rest_lengths(0.0, lengths, np.array(T))
        assert info["mu"] == cfg.mu_target and info["L3"] == 0.0 and act.integral == 0.0
        assert L_B == pytest.approx(25.2) and L_D == pytest.approx(25.2)
    # at the threshold it acts again, and the array form (batched env) agrees
    T = np.array([[60.0, 30.0, 40.0, 0.0], [10.0, 30.0, 20.0, 0.0]])
    mu, err = force_ratio_error(T, 0.3)
    assert mu == pytest.approx([0.3, 0.3]) and err == pytest.approx([0.0, 0.0])
    mu, err = force_ratio_error(np.array([700.0, 150.0, 300.0, 150.0]), 0.3)
    assert float(mu) == pytest.approx(0.3) and float(err) == pytest.approx(0.0)
    mu, _ = force_ratio_error(np.array([700.0, 50.0, 300.0, 150.0]), 0.3)
    assert float(mu) == pytest.approx(0.2)


def test_actuator_speed_limit():
    """control.line_speed_max_mps bounds the rest-length change per controller period; 0 is Eq. 16-17 as printed."""
    lengths = np.array([25.1, 25.2, 25.1, 25.2])
    T = np.array([1000.0, 300.0, 1000.0, 300.0])
    free = LineActuator(ControlConfig(line_speed_max_mps=0.0), 25.2, 25.2)
    L_B, L_D, _ = free.rest_lengths(1.5, lengths, T)
    assert L_B - 25.2 == pytest.approx(3.0 * 1.5)  # K2 (dl* - dl): 4.5 m within one period
    cfg = ControlConfig(line_speed_max_mps=2.0)
    act = LineActuator(cfg, 25.2, 25.2)
    for k in range(1, 4):  # from the initial rest lengths, then from the last period's
        L_B, L_D, _ = act.rest_lengths(1.5, lengths, T)
        assert L_B - 25.2 == pytest.approx(k * 2.0 * cfg.control_dt_s)
        assert 25.2 - L_D == pytest.approx(k * 2.0 * cfg.control_dt_s)


def test_kcu_steering_and_depower_motors_have_their_own_speed():
    """The actuator is the KCU's two motors: half the difference and the mean of the two rest lengths each move at
    most line_speed_max_mps; a saturated steering command leaves the force loop's common change its speed."""
    from kite_env.control import actuate

    step = 2.0 * 0.02
    lengths = np.array([25.1, 25.2, 25.1, 25.2])
    T = np.array([1000.0, 0.0, 1000.0, 0.0])  # both steering lines slack: mu = 0, the force loop shortens both
    act = LineActuator(ControlConfig(line_speed_max_mps=2.0), 25.2, 25.2)
    L_B, L_D, info = act.rest_lengths(1.5, lengths, T)  # dl* - dl = 1.5 m: K2 e = 4.5 m, far beyond the limit
    assert info["L3"] < 0.0
    assert 0.5 * (L_B - L_D) == pytest.approx(step) and 0.5 * (L_B + L_D) == pytest.approx(25.2 - step)
    # within both limits the command passes unchanged; arrays (the batched env) are limited element-wise
    cfg = ControlConfig(line_speed_max_mps=2.0)
    assert actuate(25.21, 25.19, 25.2, 25.2, cfg) == pytest.approx((25.21, 25.19))
    B, D = actuate(np.array([30.0, 25.2]), np.array([20.4, 25.18]), np.full(2, 25.2), np.full(2, 25.2), cfg)
    assert B == pytest.approx([25.24, 25.2]) and D == pytest.approx([25.16, 25.18])
    with pytest.raises(ConfigError, match="config key 'control.actuator_axes' is retired"):
        config_from_dict({"control": {"actuator_axes": "per_line"}})
