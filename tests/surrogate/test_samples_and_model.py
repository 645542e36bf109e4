"""Reduced-order wing, first step: sample layout, admissible bridle points, the flight sampler and the MLP."""

from __future__ import annotations

import numpy as np
import pytest

from kite_env.config import load_config
from kite_env.fsi import FlightState
from kite_env.surrogate.model import SurrogateWing, output_errors
from kite_env.surrogate.samples import (INPUT_NAMES, OUTPUT_NAMES, StateSampler, WingSamples, admissible, features,
                                        flight_state, targets)
from conftest import LEGACY_CONFIG  # noqa: E402

#: the model the shipped reduced-order wing and its start table were built on (configs/legacy_v0.yaml)
LEGACY = load_config(LEGACY_CONFIG)


def _rot(axis, angle):
    from kite_env.structure.rotations import expm

    return expm(angle * np.asarray(axis, float) / np.linalg.norm(axis))


def test_features_and_flight_state_round_trip():
    q_design = np.arange(12.0).reshape(4, 3)
    q_b = q_design + 0.01 * np.arange(12).reshape(4, 3)
    qdot = np.linspace(-1, 1, 12).reshape(4, 3)
    X = FlightState(v_kite=np.array([-20.0, 1.0, -3.0]), omega=np.array([0.1, -0.2, 0.3]),
                    v_wind=np.array([4.0, 0.5, 1.0]))
    x = features(q_b, qdot, X, q_design)
    assert x.shape == (len(INPUT_NAMES),) == (30,)
    np.testing.assert_allclose(x[12:24], qdot.ravel())
    q2, X2 = flight_state(x, q_design)
    np.testing.assert_allclose(q2, q_b)
    np.testing.assert_allclose(X2.v_kite - X2.v_wind, X.v_kite - X.v_wind)
    np.testing.assert_allclose(X2.omega, X.omega)


def test_admissible_restores_tip_lengths_and_frame_k():
    rng = np.random.default_rng(1)
    q = np.array([[0.0, 2.9, 0.0], [0.62, 2.75, 0.0], [0.0, -2.9, 0.0], [0.62, -2.75, 0.0]])
    lengths = (np.linalg.norm(q[0] - q[1]), np.linalg.norm(q[2] - q[3]))
    for _ in range(5):
        qp = admissible(q + rng.normal(0, 0.05, (4, 3)), lengths)
        assert np.linalg.norm(qp[0] - qp[1]) == pytest.approx(lengths[0], rel=1e-12)
        assert np.linalg.norm(qp[2] - qp[3]) == pytest.approx(lengths[1], rel=1e-12)
        # frame K: origin mid A-C, A and C on the y axis, the mid-point of B and D in the x-y plane, x towards it
        np.testing.assert_allclose(qp[0] + qp[2], 0.0, atol=1e-12)
        np.testing.assert_allclose(qp[0][[0, 2]], 0.0, atol=1e-12)
        mid = 0.5 * (qp[1] + qp[3])
        assert abs(mid[2]) < 1e-12 and mid[0] > 0
        np.testing.assert_allclose(admissible(qp, lengths), qp, atol=1e-12)  # idempotent
    # a rigid motion of admissible points changes nothing in K
    qp = admissible(q, lengths)
    moved = qp @ _rot([0.3, -1.0, 0.5], 0.7).T + np.array([3.0, -2.0, 1.0])
    np.testing.assert_allclose(admissible(moved, lengths), qp, atol=1e-12)


@pytest.fixture(scope="module")
def short_flight_samples():
    from agents.policies import make_agent
    from kite_env.envs.figure_eight import KiteFigureEightEnv

    env = KiteFigureEightEnv(config=LEGACY, overrides=["env.max_episode_s=0.06"])
    recs = []

    class Both(StateSampler):  # keep the records to compare with
        def record(self, rec, *a):
            recs.append(rec)
            super().record(rec, *a)

    sampler = Both(every=3, n_perturb=1, rng=np.random.default_rng(0), group=7)
    env.recorder = sampler
    obs, _ = env.reset(seed=0)
    agent = make_agent("constant:0.3", env)
    done = False
    while not done:
        obs, _, term, trunc, _ = env.step(agent.predict(obs)[0])
        done = term or trunc
    return env, sampler, recs


def test_sampler_stores_the_flight_solutions_and_admissible_perturbations(short_flight_samples):
    env, sampler, recs = short_flight_samples
    S = sampler.samples()
    n_visit = 1 + len(recs) // 3  # the reset state and every third of the 12 physics steps
    assert int(np.sum(S.origin == 0)) == n_visit and len(recs) == 12
    assert int(np.sum(S.origin == 1)) == n_visit - sampler.failed
    assert np.all(S.group == 7) and np.all(np.isfinite(S.inputs)) and np.all(np.isfinite(S.outputs))
    visited = S.outputs[S.origin == 0]
    np.testing.assert_array_equal(visited[1], targets(recs[2].wing))  # the third physics step's own wing solution
    q_design = env.sim.wing.design_bridle
    for x in S.inputs[S.origin == 1]:
        q, _ = flight_state(x, q_design)
        np.testing.assert_allclose(admissible(q, env.sim.tip_lengths), q, atol=1e-9)
        assert np.all(x[12:24] == 0.0)  # static solves: no deformation rate
    # outputs: bridle forces pull the wing towards the KCU (-z_k), lift > drag > 0
    F = S.outputs[:, :12].reshape(-1, 4, 3).sum(axis=1)
    assert np.all(F[:, 2] < 0) and np.all(S.outputs[:, 15] > S.outputs[:, 16]) and np.all(S.outputs[:, 16] > 0)


def test_wing_depends_on_the_apparent_velocity_only():
    """Sampling stores v_kite - v_wind: the wing's loads must not depend on v_kite and v_wind separately."""
    from kite_env.polar import nominal_wing

    wing = nominal_wing("rhino16", LEGACY)
    X1 = FlightState(v_kite=np.array([-22.0, 0.0, -4.0]), omega=np.zeros(3), v_wind=np.array([3.0, 0.0, 1.5]))
    s1 = wing.solve(None, X1, support="lines", warm=False)
    X2 = FlightState(v_kite=X1.v_kite - X1.v_wind, omega=X1.omega, v_wind=np.zeros(3))
    s2 = wing.solve(None, X2, support="lines", warm=False)
    np.testing.assert_allclose(s2.F_b, s1.F_b, rtol=1e-9, atol=1e-6)


def test_samples_save_load_and_layout_check(tmp_path):
    S = WingSamples(np.ones((3, 30)), np.zeros((3, 17)), np.array([0, 1, 0]), np.array([2, 2, 3]), {"a": 1})
    S2 = WingSamples.load(S.save(tmp_path / "s.npz"))
    np.testing.assert_array_equal(S2.inputs, S.inputs)
    assert S2.meta == {"a": 1} and list(S2.group) == [2, 2, 3]
    np.savez(tmp_path / "bad.npz", inputs=np.ones((1, 2)), outputs=np.ones((1, 2)), origin=[0], group=[0], meta="{}",
             input_names=np.array(["x", "y"]), output_names=np.array(["u", "v"]))
    with pytest.raises(ValueError, match="layout"):
        WingSamples.load(tmp_path / "bad.npz")


def test_samples_of_separate_runs_merge_with_distinct_episodes():
    """Merged sampling runs (build_surrogate --sample-seeds) keep every run's episodes apart: run 2's episode 0 is
    not run 1's episode 0 (the hold-out split is by episode)."""
    a = WingSamples(np.zeros((3, 30)), np.zeros((3, 17)), np.array([0, 1, 0]), np.array([0, 0, 1]), {"seed": 0})
    b = WingSamples(np.ones((2, 30)), np.ones((2, 17)), np.array([0, 0]), np.array([0, 2]), {"seed": 1})
    m = WingSamples.merge([a, b])
    assert list(m.group) == [0, 0, 1, 2, 4] and list(m.origin) == [0, 1, 0, 0, 0]
    np.testing.assert_array_equal(m.inputs[3:], b.inputs)
    assert m.meta["seed"] == 0 and [r["seed"] for r in m.meta["runs"]] == [0, 1]
    assert m.meta["n_samples"] == 5 and m.meta["episodes"] == 5
    with pytest.raises(ValueError, match="nothing to merge"):
        WingSamples.merge([])


def _linear_model(A, c, x_mean, x_std):
    """A one-layer SurrogateWing y = A x_n + c with unit output normalisation (an analytic check of predict)."""
    return SurrogateWing([A.T.copy()], [c.copy()], x_mean, x_std, np.zeros(17), np.ones(17),
                         x_mean - 1.0, x_mean + 1.0)


def test_surrogate_predict_save_load_and_envelope(tmp_path):
    rng = np.random.default_rng(0)
    A, c = rng.normal(size=(17, 30)), rng.normal(size=17)
    x_mean, x_std = rng.normal(size=30), rng.uniform(0.5, 2.0, 30)
    m = _linear_model(A, c, x_mean, x_std)
    x = rng.normal(size=(5, 30))
    np.testing.assert_allclose(m.predict(x), ((x - x_mean) / x_std) @ A.T + c, rtol=1e-12)
    assert m.predict(x[0]).shape == (17,)
    m2 = SurrogateWing.load(m.save(tmp_path / "w.npz"))
    np.testing.assert_allclose(m2.predict(x), m.predict(x), rtol=1e-5, atol=1e-5)  # weights stored as float32
    assert m.outside(x_mean) == []
    far = x_mean.copy()
    far[[3, 25]] += 5.0
    assert m.outside(far) == [INPUT_NAMES[3], INPUT_NAMES[25]]
    # an input that vanishes by construction (A and C in their own frame K) has a range of round-off only: a
    # query's round-off stays inside, a physical deviation (1 mm/s) does not
    m.x_min[12], m.x_max[12] = -1e-14, 1e-14
    roundoff = x_mean.copy()
    roundoff[12] = 3e-13
    assert m.outside(roundoff) == []
    roundoff[12] = 1e-3
    assert m.outside(roundoff) == [INPUT_NAMES[12]]
    (tmp_path / "bad.npz").write_text("not an npz")
    with pytest.raises(ValueError, match="not a readable"):
        SurrogateWing.load(tmp_path / "bad.npz")
    with pytest.raises(FileNotFoundError):
        SurrogateWing.load(tmp_path / "missing.npz")
    with pytest.raises(ValueError, match="inputs"):
        SurrogateWing([np.ones((3, 17))], [np.ones(17)], *[np.zeros(3)] * 2, np.zeros(17), np.ones(17),
                      np.zeros(3), np.ones(3))


def test_output_errors_relative_to_traction():
    y = np.zeros((4, 17))
    y[:, 2] = y[:, 8] = -1000.0  # A and C pull 1 kN each along -z: traction 2 kN
    yp = y.copy()
    yp[:, :12] += 20.0  # 20 N on every force component
    e = output_errors(y, yp)
    assert e["mean_traction_N"] == pytest.approx(2000.0)
    assert e["force_rms_N"] == pytest.approx(20.0) and e["force_rms_rel_traction"] == pytest.approx(0.01)
    assert e["rms"][OUTPUT_NAMES[0]] == pytest.approx(20.0) and e["rms"]["lift"] == 0.0


def test_training_script_fits_a_smooth_function(tmp_path):
    """train_surrogate.py on synthetic samples of a smooth map: the held-out error is small and stored."""
    import subprocess
    import sys
    from pathlib import Path

    rng = np.random.default_rng(3)
    n = 1200
    X = rng.normal(size=(n, 30))
    Y = np.tanh(X[:, :17] * 0.5) * 100.0 + 0.3 * X[:, 13:30] ** 2
    Y[:, 2] -= 2000.0
    WingSamples(X, Y, np.zeros(n, int), np.arange(n) % 10, {"git_commit": "test"}).save(tmp_path / "s.npz")
    script = Path(__file__).parents[2] / "scripts" / "train_surrogate.py"
    r = subprocess.run([sys.executable, str(script), "--samples", str(tmp_path / "s.npz"), "--out",
                        str(tmp_path / "w.npz"), "--epochs", "300", "--hidden", "64"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    m = SurrogateWing.load(tmp_path / "w.npz")
    assert m.meta["samples"]["git_commit"] == "test" and m.meta["n_heldout"] == 240
    val = (np.arange(n) % 10) % 5 == 4
    rel = np.sqrt(np.mean((m.predict(X[val]) - Y[val]) ** 2)) / np.std(Y[val])
    assert rel < 0.1
    assert m.meta["heldout_errors"]["force_rms_rel_traction"] < 0.05
