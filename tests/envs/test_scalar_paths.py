"""The single env's float arithmetic against the NumPy forms it stands in for, bit for bit: the actuator
(``LineActuator.rest_lengths`` against ``force_ratio_error``, ``force_integral`` and ``actuate``, the batched env's
forms), NumPy's clip rules, the action's conversion and the one-kite observation kernel against the batch's."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from kite_env.config import ControlConfig
from kite_env.control import POWER_LINES_MIN_N, LineActuator, _clip, actuate, force_integral, force_ratio_error
from kite_env.envs.figure_eight import KiteFigureEightEnv
from kite_env.envs.observe import FEATURES, N_PARTS

_EDGES = [-0.0, 0.0, 1.0, -1.0, 0.5, math.nan, math.inf, -math.inf, 2.0, -2.0]


def _same(x: float, y: float) -> bool:
    """Equal bit for bit (NaN equals NaN; the sign of a zero counts)."""
    return (math.isnan(x) and math.isnan(y)) or (x == y and math.copysign(1.0, x) == math.copysign(1.0, y))


def test_clip_of_floats_is_numpys_clip():
    for x, lo, hi in itertools.product(_EDGES, repeat=3):
        assert _same(_clip(x, lo, hi), float(np.clip(x, lo, hi))), (x, lo, hi)


@pytest.mark.parametrize("changes", [{}, {"line_speed_max_mps": 0.0}, {"k3i_per_s": 0.0},
                                     {"force_integral_max_m": 0.0}])
def test_actuator_is_the_array_forms_bit_for_bit(changes):
    """Random lengths and tensions (power lines loaded and unloaded, NaN) over many periods: the rest lengths,
    the integral and the reported values equal those of the array forms of the batched env."""
    cfg = dataclasses.replace(ControlConfig(), **changes)
    act = LineActuator(cfg, 25.2, 25.3)
    integral, last = 0.0, (25.2, 25.3)
    rng = np.random.default_rng(1)
    for i in range(3000):
        lengths = 25.2 + rng.normal(0.0, 0.3, 4)
        T = rng.uniform(0.0, 3000.0, 4) * rng.choice([0.01, 1.0], 4)
        if i >= 2990:  # NaN stays in the integral: the last periods
            T[rng.integers(4)] = np.nan
        dls = float(rng.uniform(-2.0, 2.0)) if i % 3 else float(rng.choice([-1.5, 1.5, 0.0, -0.0]))
        L_B, L_D, info = act.rest_lengths(dls, lengths, T)
        # the reference: the NumPy forms, as rest_lengths composed them
        dls_ref = float(np.clip(dls, -cfg.delta_l_max_m, cfg.delta_l_max_m))
        dl = float(lengths[1] - lengths[3])
        mu, err = force_ratio_error(T, cfg.mu_target)
        integral = force_integral(integral, float(err), cfg)
        L3 = -cfg.k3_m * float(err) - cfg.k3i_per_s * integral
        e = dls_ref - dl
        ref = actuate(25.2 + cfg.k2 * e + L3, 25.3 - cfg.k2 * e + L3, last[0], last[1], cfg)
        last = tuple(float(v) for v in ref)
        assert _same(L_B, last[0]) and _same(L_D, last[1]), i
        assert _same(float(act.integral), float(integral)), i
        for key, value in (("delta_l", dl), ("delta_l_star", dls_ref), ("mu", float(mu)), ("L3", L3)):
            assert _same(info[key], value), (i, key)


def test_actions_of_any_float_type_give_the_same_step():
    """A float, a float32 or float64 array of any size-1 shape and a list step the env identically."""
    rollouts = []
    for kind in ("float", "f32", "f64", "f32_0d", "list"):
        env = KiteFigureEightEnv(fidelity="surrogate")
        env.reset(seed=3)
        out = []
        for i in range(20):
            v = float(np.float32(0.7 * math.sin(0.3 * i)))
            a = {"float": v, "f32": np.array([v], np.float32), "f64": np.array([[v]]),
                 "f32_0d": np.array(v, np.float32), "list": [v]}[kind]
            obs, reward, terminated, truncated, info = env.step(a)
            out.append((obs.tobytes(), reward, terminated, truncated, sorted(info.items())))
        rollouts.append(out)
    assert all(r == rollouts[0] for r in rollouts[1:])


def test_one_kite_observation_kernel_is_the_batch_of_one():
    """The single env's observation kernel (observe_one) gives the batch kernel's (observe_kites) parts, features
    and hint for the same record, and gathers the observation's terms."""
    env = KiteFigureEightEnv(fidelity="surrogate", overrides=["env.observation=path,rates,position"])
    env.reset(seed=0)
    for _ in range(30):
        env.step(np.array([0.3], np.float32))
    rec = env.rec
    assert rec is not None
    hint = env.s_hint
    parts, feats = np.zeros((1, N_PARTS)), np.zeros((1, len(FEATURES)))
    s = np.array([hint])
    env.observer(np.ones(1, dtype=np.bool_), rec.state.r[4:5], rec.state.v[4:5], rec.R_wk[None], rec.omega[None],
                  rec.v_kite[None], rec.line_tension[None], rec.line_length[None], np.array([rec.tether_force]),
                  np.array([rec.t]), s, np.array([env.last_action]), parts, feats)
    obs, info = env._observe(rec)
    assert env.s_hint == s[0]
    np.testing.assert_array_equal(env._parts, parts[0])
    np.testing.assert_array_equal(env._feats, feats[0])
    np.testing.assert_array_equal(obs, parts[0, env.observer.index].astype(np.float32))
    assert list(info.values()) == feats[0, :-1].tolist()


@pytest.mark.parametrize("changes", [{}, {"line_speed_max_mps": 0.0}, {"k3i_per_s": 0.0},
                                     {"force_integral_max_m": 0.0}])
def test_compiled_actuator_is_line_actuator_bit_for_bit(changes):
    """The compiled step's actuator (fast_step.rest_lengths) against LineActuator.rest_lengths over many periods,
    with unloaded power lines, NaN tensions and clipped commands."""
    from kite_env.envs import fast_step as fs

    cfg = dataclasses.replace(ControlConfig(), **changes)
    act = LineActuator(cfg, 25.2, 25.3)
    ctrl = np.zeros(10)
    ctrl[[fs.C_DL_MAX, fs.C_K2, fs.C_K3, fs.C_K3I, fs.C_MU_TARGET, fs.C_INTEGRAL_MAX, fs.C_CONTROL_DT,
          fs.C_LINE_SPEED_MAX, fs.C_POWER_MIN]] = (cfg.delta_l_max_m, cfg.k2, cfg.k3_m, cfg.k3i_per_s, cfg.mu_target,
                                                  cfg.force_integral_max_m, cfg.control_dt_s, cfg.line_speed_max_mps,
                                                  POWER_LINES_MIN_N)
    integral, last = 0.0, (25.2, 25.3)
    rng = np.random.default_rng(2)
    for i in range(3000):
        lengths = 25.2 + rng.normal(0.0, 0.3, 4)
        T = rng.uniform(0.0, 3000.0, 4) * rng.choice([0.01, 1.0], 4)
        if i >= 2990:
            T[rng.integers(4)] = np.nan
        dls = float(rng.uniform(-2.0, 2.0)) if i % 3 else float(rng.choice([-1.5, 1.5, 0.0, -0.0]))
        L_B, L_D, info = act.rest_lengths(dls, lengths, T)
        c_B, c_D, c_dls, integral = fs.rest_lengths(dls, ctrl, 25.2, 25.3, integral, last[0], last[1], *T.tolist(),
                                                    float(lengths[1]), float(lengths[3]))
        last = (c_B, c_D)
        assert _same(L_B, c_B) and _same(L_D, c_D) and _same(info["delta_l_star"], c_dls), i
        assert _same(float(act.integral), integral), i


def test_compiled_omega_is_the_fma_order_of_numpys_product():
    """kite_omega: each row fma(R[i, 2], w2, fma(R[i, 0], w0, R[i, 1] w1)), rounded once per FMA (exact rational
    reference); on this x86-64 OpenBLAS it is NumPy's ``R @ w`` (the record's omega, the observations recorded)."""
    from fractions import Fraction

    from kite_env.envs.fast_step import kite_omega, kite_omega_rows

    def fma(a, b, c):
        return float(Fraction(a) * Fraction(b) + Fraction(c))

    rng = np.random.default_rng(3)
    R = rng.normal(size=(400, 3, 3))
    X = rng.normal(size=(400, 30)) * 10.0 ** rng.integers(-3, 3, size=(400, 1))
    rows = np.empty((400, 3))
    kite_omega_rows(R, X, rows)
    one = np.empty(3)
    for k in range(400):
        kite_omega(R[k], X[k, 27:30], one)
        w = X[k, 27:30].tolist()
        ref = [fma(R[k, i, 2], w[2], fma(R[k, i, 0], w[0], R[k, i, 1] * w[1])) for i in range(3)]
        assert one.tolist() == ref and rows[k].tolist() == ref, k
    if not np.array_equal(rows, np.matmul(R, X[:, 27:30, None])[..., 0]):
        pytest.skip("this machine's BLAS sums a 3 x 3 product in another order than the one the flights were "
                    "recorded with (the compiled form is the same on every machine)")


def _fast_and_python_steps(overrides, actions, seed, monkeypatch):
    """The same episode stepped by the compiled step and by the Python step (the compiled step unbound)."""
    out = []
    for compiled in (True, False):
        env = KiteFigureEightEnv(fidelity="surrogate", overrides=overrides)
        if not compiled:
            monkeypatch.setattr(env, "_bind_fast", lambda sim: None)
        env.reset(seed=seed)
        env.step(np.array([0.0], np.float32))
        assert (env._fast_head is not None) == compiled
        steps: list = []
        ended = False
        for a in actions:
            obs, reward, terminated, truncated, info = env.step(np.array([a], np.float32))
            rec = env.rec
            assert rec is not None and env.sim is not None
            steps.append((obs.tobytes(), reward, terminated, truncated, sorted((k, repr(v)) for k, v in info.items()),
                          env.s_hint, env.actuator.integral, env.actuator.last, env.L_B, env.L_D, env._kcu,
                          env._trail[-1], rec.t, rec.state.r.tobytes(), rec.state.v.tobytes(), rec.omega.tobytes(),
                          rec.R_wk.tobytes(), rec.line_tension.tobytes(), rec.line_length.tobytes(), rec.tether_force,
                          rec.tether_length, rec.reel_speed, rec.wing.F_b.tobytes(), env.sim.t,
                          env.sim.state.r.tobytes()))
            if ended:  # one step after the end (Gymnasium leaves it undefined; the env steps on)
                break
            ended = terminated or truncated
        out.append(steps)
    return out


@pytest.mark.parametrize("case", ["steer", "ground", "outside"])
def test_compiled_step_is_the_python_step(case, monkeypatch):
    """The compiled control step (kite_env.envs.fast_step) and the env's Python step give the same observations,
    rewards, ends, info, records and actuator states, bit for bit: in flight, on the ground, beyond the surrogate's
    envelope (the failed physics step: the last good state observed), and in the step after the end."""
    if case == "steer":
        rng = np.random.default_rng(4)
        actions = (0.4 * np.sin(0.05 * np.arange(200)) + rng.uniform(-0.3, 0.3, 200)).tolist()
        seed, over = 0, ["wind.turbulence_intensity=0.1"]
    elif case == "ground":  # on the ground after some 270 steps
        actions, seed, over = [0.15] * 400, 0, []
    else:  # beyond the envelope after some 125 steps
        actions, seed, over = [1.0] * 300, 40, []
    fast, python = _fast_and_python_steps(over, actions, seed, monkeypatch)
    assert len(fast) == len(python)
    for i, (f, p) in enumerate(zip(fast, python)):
        assert f == p, i
    if case != "steer":
        info_end = dict(fast[-2][4])
        assert fast[-2][2], "the episode ends"
        assert info_end["termination_reason"] == repr({"ground": "ground", "outside": "outside surrogate envelope"}[
            case])


def test_the_depower_offset_moves_both_lines_in_both_step_paths(monkeypatch):
    """``LineActuator.depower_offset_m`` (an exogenous common offset of the steering lines): the compiled step of the
    fast env and the Python step apply it alike, bit for bit; zero is the paper's actuator; an offset moves both rest
    lengths by the same amount, at most the actuator's speed limit per controller period, and the force loop answers
    it only in part."""
    def fly(offset, compiled):
        env = KiteFigureEightEnv(fidelity="surrogate")
        if not compiled:
            monkeypatch.setattr(env, "_bind_fast", lambda sim: None)
        env.reset(seed=3)
        rows = []
        for k in range(60):
            env.actuator.depower_offset_m = offset if k >= 10 else 0.0
            obs, reward, term, trunc, info = env.step(np.array([0.2], dtype=np.float32))
            rows.append((info["L_B_m"], info["L_D_m"], reward, *obs.tolist()))
            assert not term
        assert (env._fast_head is not None) == compiled
        return np.array(rows), env.cfg.control

    (base, cfg), (base_py, _) = fly(0.0, True), fly(0.0, False)
    (off, _), (off_py, _) = fly(0.05, True), fly(0.05, False)
    assert np.array_equal(base, base_py) and np.array_equal(off, off_py)
    assert np.array_equal(base[:10], off[:10])
    common = 0.5 * (off[:, 0] + off[:, 1]) - 0.5 * (base[:, 0] + base[:, 1])
    assert common[10] > 0 and np.all(np.abs(np.diff(common)) <= 2 * cfg.line_speed_max_mps * cfg.control_dt_s)
    assert 0.005 < np.mean(common[30:]) < 0.05
