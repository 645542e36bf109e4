"""The compiled observation (kite_env.envs.observe) against the NumPy reference of the env's former ``_observe``."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from kite_env.config import Config
from kite_env.control import LineActuator
from kite_env.envs.figure_eight import INFO_FEATURES, KiteFigureEightEnv, observation_layout
from kite_env.envs.observe import FEATURES, N_PARTS, Observer, nearest_point
from kite_env.trajectory import Lemniscate, azimuth, elevation, heading_angle, sphere_basis, wrap_angle


def _reference(cfg, path, rec, s_hint, last_action):
    """The env's ``_observe`` as it was before the kernel (NumPy and trajectory helpers), all terms in order."""
    r_kcu = rec.state.r[4]
    R = r_kcu / np.linalg.norm(r_kcu)
    nose = -rec.R_wk[:, 0]
    psi = float(heading_angle(R, nose))
    near = path.nearest(R, s_hint)
    left = np.cross(near.point, near.e_t)
    signed = -near.distance_rad * math.copysign(1.0, float(near.e_n @ left))
    dpsi = float(wrap_angle(float(heading_angle(near.point, near.e_t)) - psi))
    x_s, y_s = sphere_basis(R)
    v_kcu = rec.state.v[4]
    w_s = (v_kcu - (v_kcu @ R) * R) / cfg.dynamics.tether_length_m
    yaw_rate = float(rec.R_wk[:, 2] @ rec.omega)
    speed = float(np.linalg.norm(rec.v_kite))
    mu = LineActuator.force_ratio(rec.line_tension)
    dl = float(rec.line_length[1] - rec.line_length[3])
    fs = cfg.env.force_scale_N
    tether = float(rec.tether_force) if math.isfinite(rec.tether_force) else float(np.sum(rec.line_tension))
    parts = np.concatenate([R, [math.sin(psi), math.cos(psi)], np.append(rec.line_tension, tether) / fs,
                            [signed, math.sin(dpsi), math.cos(dpsi), math.sin(near.s), math.cos(near.s)],
                            [w_s @ x_s, w_s @ y_s, yaw_rate, speed / 25.0],
                            [last_action, dl / cfg.control.delta_l_max_m, mu]])
    feats = [rec.t, near.distance_rad, math.degrees(near.distance_rad), near.s, tether, speed, psi, yaw_rate, mu,
             dl, math.degrees(float(elevation(R))), math.degrees(float(azimuth(R))),
             math.exp(-(near.distance_rad / math.radians(cfg.env.tracking_scale_deg)) ** 2)]
    return parts, np.array(feats)


def _random_records(path, rng, n):
    """Records at random KCU directions: near the path (incl. the crossing), far from it, and random hints."""
    recs, hints = [], []
    for k in range(n):
        kind = k % 4
        s = rng.uniform(0.0, 2.0 * math.pi) if kind != 1 else rng.choice([0.0, math.pi]) + rng.normal(0.0, 0.02)
        P = path.point(s)
        if kind == 3:  # anywhere on the upper half sphere (mostly far from the path)
            P = rng.normal(size=3)
            P[2] = abs(P[2])
            hint = rng.uniform(0.0, 2.0 * math.pi) if rng.random() < 0.7 else None
        else:
            hint = (s + rng.normal(0.0, 0.05)) % (2 * math.pi)
            P = P + rng.normal(0.0, 0.03 if kind != 2 else 0.3, 3)
        r = np.zeros((5, 3))
        r[4] = 80.0 * P / np.linalg.norm(P)
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        recs.append(SimpleNamespace(
            state=SimpleNamespace(r=r, v=rng.normal(0.0, 20.0, (5, 3))), R_wk=q * np.sign(np.linalg.det(q)),
            omega=rng.normal(0.0, 1.0, 3), v_kite=rng.normal(0.0, 20.0, 3),
            line_tension=rng.uniform(0.0, 3000.0, 4), line_length=rng.uniform(25.0, 26.0, 4),
            tether_force=float(rng.uniform(0.0, 8000.0)) if rng.random() < 0.8 else float("nan"),
            t=float(rng.uniform(0.0, 60.0))))
        hints.append(hint)
    return recs, hints


def test_kernel_matches_numpy_reference():
    cfg = Config()
    path = Lemniscate(cfg.trajectory)
    layout = observation_layout(cfg.env.observation)
    obs = Observer(cfg, path, layout)
    rng = np.random.default_rng(3)
    recs, hints = _random_records(path, rng, 400)
    n = len(recs)
    last = rng.uniform(-1.0, 1.0, n)
    stack = lambda f: np.ascontiguousarray([f(r) for r in recs], dtype=float)  # noqa: E731
    hint0 = np.array([np.nan if h is None else h for h in hints])
    hint = hint0.copy()
    parts, feats = np.zeros((n, N_PARTS)), np.zeros((n, len(FEATURES)))
    active = np.ones(n, dtype=np.bool_)
    obs(active, stack(lambda r: r.state.r[4]), stack(lambda r: r.state.v[4]), stack(lambda r: r.R_wk),
        stack(lambda r: r.omega), stack(lambda r: r.v_kite), stack(lambda r: r.line_tension),
        stack(lambda r: r.line_length), stack(lambda r: r.tether_force), stack(lambda r: r.t), hint, last, parts,
        feats)
    far = 0
    for k, rec in enumerate(recs):
        ref_parts, ref_feats = _reference(cfg, path, rec, hints[k], last[k])
        np.testing.assert_allclose(parts[k], ref_parts, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(feats[k], ref_feats, rtol=1e-12, atol=1e-12)
        assert hint[k] == pytest.approx(ref_feats[3], abs=1e-12)  # the hint advanced to the nearest s
        far += ref_feats[1] > 0.3
    assert far > 50  # the sample covers states far from the path (refinement not bracketed)
    # inactive kites are left untouched
    parts2 = np.full((n, N_PARTS), 7.0)
    active[::2] = False
    obs(active, stack(lambda r: r.state.r[4]), stack(lambda r: r.state.v[4]), stack(lambda r: r.R_wk),
        stack(lambda r: r.omega), stack(lambda r: r.v_kite), stack(lambda r: r.line_tension),
        stack(lambda r: r.line_length), stack(lambda r: r.tether_force), stack(lambda r: r.t), hint0.copy(), last,
        parts2, feats)
    assert np.all(parts2[::2] == 7.0) and np.array_equal(parts2[1::2], parts[1::2])


def test_nearest_point_matches_lemniscate_at_the_crossing():
    """Both branches through the crossing are kept by the hint, as Lemniscate.nearest does."""
    path = Lemniscate()
    o = Observer(Config(), path, ["position"])
    c = path.point(0.0) + 1e-4 * np.array([0.0, 0.0, 1.0])
    m, w = np.empty((3, 3)), np.empty((3, 3))
    for hint in (2 * math.pi - 0.05, math.pi - 0.05, float("nan")):
        got = nearest_point(*c, hint, o.samples, o.s_samples, o.window, path.ds, path.a, path.b, path.rotation, m, w)
        ref = path.nearest(c, None if math.isnan(hint) else hint)
        assert got[0] == pytest.approx(ref.s, abs=1e-12) and got[1] == pytest.approx(ref.distance_rad, abs=1e-14)
        np.testing.assert_allclose(got[2:5], ref.point, atol=1e-14)
        np.testing.assert_allclose(got[5:8], ref.e_t, atol=1e-13)
        np.testing.assert_allclose(got[8:11], ref.e_n, atol=1e-13)


def test_env_observe_uses_kernel_with_same_keys():
    env = KiteFigureEightEnv(overrides=["env.observation=path,position"])
    rec = _random_records(env.path, np.random.default_rng(0), 1)[0][0]
    env.s_hint, env.last_action = 0.1, 0.25
    obs, feats = env._observe(rec)
    ref_parts, ref_feats = _reference(env.cfg, env.path, rec, 0.1, 0.25)
    np.testing.assert_array_equal(obs, np.concatenate([ref_parts[10:15], ref_parts[:3]]).astype(np.float32))
    assert list(feats) == list(INFO_FEATURES)
    np.testing.assert_allclose([feats[k] for k in INFO_FEATURES], ref_feats[:-1], rtol=1e-12, atol=1e-12)
    assert env.s_hint == pytest.approx(ref_feats[3], abs=1e-12)
