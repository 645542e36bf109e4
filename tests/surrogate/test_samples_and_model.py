"""Reduced-order wing: the input layout, the MLP with its latent-state inputs and known linear part, the flights it is
fitted to (FlightTape, fly_plan, save_tape/load_tape), the effective wing force of a tape, the latent filters and
the fit (fit_mlp)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from kite_env.config import Config, ModelMismatch, fingerprint, load_config
from kite_env.fitting.fit import (
    FILTERED,
    TAUS,
    FitData,
    build_dataset,
    filter_gain,
    fit_mlp,
    history_names,
    latent_features,
    tape_samples,
)
from kite_env.fitting.trajectories import COLUMNS, EpisodePlan, FlightTape, fly_plan, load_tape, save_tape
from kite_env.frames import kite_frame
from kite_env.fsi import FlightState
from kite_env.surrogate.model import SurrogateWing, output_errors
from kite_env.surrogate.samples import INPUT_NAMES, OUTPUT_NAMES, features


def test_features_layout():
    """features: q_b - q_design, qdot_b, v_app = v_kite - v_wind, omega, in INPUT_NAMES' order."""
    q_design = np.arange(12.0).reshape(4, 3)
    q_b = q_design + 0.01 * np.arange(12).reshape(4, 3)
    qdot = np.linspace(-1, 1, 12).reshape(4, 3)
    X = FlightState(v_kite=np.array([-20.0, 1.0, -3.0]), omega=np.array([0.1, -0.2, 0.3]),
                    v_wind=np.array([4.0, 0.5, 1.0]))
    x = features(q_b, qdot, X, q_design)
    assert x.shape == (len(INPUT_NAMES),) == (30,) and len(OUTPUT_NAMES) == 17
    np.testing.assert_allclose(x[:12], (q_b - q_design).ravel(), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(x[12:24], qdot.ravel())
    np.testing.assert_array_equal(x[24:27], X.v_kite - X.v_wind)
    np.testing.assert_array_equal(x[27:30], X.omega)
    assert INPUT_NAMES[:3] == ("dq_Ax", "dq_Ay", "dq_Az") and INPUT_NAMES[24] == "v_app_x"
    assert INPUT_NAMES[27:] == ("omega_x", "omega_y", "omega_z") and OUTPUT_NAMES[15:] == ("lift", "drag")


def test_wing_depends_on_the_apparent_velocity_only():
    """The inputs carry v_kite - v_wind only: the FE wing's loads (default model) must not depend on v_kite and
    v_wind separately."""
    from kite_env.fsi import nominal_wing

    wing = nominal_wing("rhino16", Config())
    X1 = FlightState(v_kite=np.array([-22.0, 0.0, -4.0]), omega=np.zeros(3), v_wind=np.array([3.0, 0.0, 1.5]))
    s1 = wing.solve(None, X1, support="lines", warm=False)
    X2 = FlightState(v_kite=X1.v_kite - X1.v_wind, omega=X1.omega, v_wind=np.zeros(3))
    s2 = wing.solve(None, X2, support="lines", warm=False)
    assert np.abs(s1.F_b).max() > 100.0
    np.testing.assert_allclose(s2.F_b, s1.F_b, rtol=1e-9, atol=1e-6)


def _linear_model(A, c, x_mean, x_std, meta=None, K_b=None):
    """A one-layer SurrogateWing y = A x_n + c (+ K_b x[:12]) with unit output normalisation (an analytic check of
    predict)."""
    kw = {} if K_b is None else {"K_b": K_b}
    return SurrogateWing([A.T.copy()], [c.copy()], x_mean, x_std, np.zeros(17), np.ones(17), x_mean - 1.0,
                         x_mean + 1.0, meta or {}, **kw)


def test_surrogate_predict_save_load_and_envelope(tmp_path):
    rng = np.random.default_rng(0)
    A, c = rng.normal(size=(17, 30)), rng.normal(size=17)
    x_mean, x_std = rng.normal(size=30), rng.uniform(0.5, 2.0, 30)
    m = _linear_model(A, c, x_mean, x_std)
    assert m.input_names == INPUT_NAMES and m.taus == () and m.filtered == () and not m.inertial
    assert np.array_equal(m.K_b, np.zeros((12, 12)))
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


HISTORY = {"taus_s": list(TAUS), "filtered": list(FILTERED), "inertial": True}


def test_surrogate_with_history_inputs_and_known_linear_part(tmp_path):
    """A wing with memory: its inputs are INPUT_NAMES, then per time constant the filtered inputs less the current
    ones (named <input>_lag<ms>ms); predict adds K_b (q_b - q_design) to the bridle forces only; save/load keeps
    K_b, the meta and the layout; a file whose stored input names are not those its meta describes is refused, and
    a file without K_b (a memoryless wing of before) loads with K_b = 0."""
    rng = np.random.default_rng(1)
    n_in = 30 + len(TAUS) * len(FILTERED)
    A, c = rng.normal(size=(17, n_in)), rng.normal(size=17)
    x_mean, x_std = rng.normal(size=n_in), rng.uniform(0.5, 2.0, n_in)
    K_b = rng.normal(0.0, 1e3, (12, 12))
    m = _linear_model(A, c, x_mean, x_std, {"history": HISTORY, "note": "test"}, K_b)
    assert m.taus == TAUS and m.filtered == FILTERED and m.inertial
    assert len(m.input_names) == n_in and m.input_names[:30] == INPUT_NAMES
    assert m.input_names[30:] == history_names(TAUS)
    assert m.input_names[30] == "dq_Ax_lag50ms" and m.input_names[-1] == "omega_z_lag250ms"
    x = rng.normal(size=(6, n_in))
    y = m.predict(x)
    ref = ((x - x_mean) / x_std) @ A.T + c
    ref[:, :12] += x[:, :12] @ K_b.T
    np.testing.assert_allclose(y, ref, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(m.predict(x[2]), y[2], rtol=1e-14)
    # K_b acts on q_b - q_design (the first 12 inputs) and on the forces alone
    x2 = x.copy()
    x2[:, 12:] += 1.0
    d = m.predict(x2) - dataclasses.replace(m, K_b=np.zeros((12, 12))).predict(x2)
    np.testing.assert_allclose(d[:, :12], x[:, :12] @ K_b.T, rtol=1e-10, atol=1e-8)
    assert np.all(d[:, 12:] == 0.0)
    m2 = SurrogateWing.load(m.save(tmp_path / "w.npz"))
    np.testing.assert_array_equal(m2.K_b, K_b)
    assert m2.meta == m.meta and m2.input_names == m.input_names and m2.taus == TAUS and m2.inertial
    np.testing.assert_allclose(m2.predict(x), y, rtol=1e-5, atol=1e-4)
    # a file whose meta says other time constants than its stored input names
    with np.load(tmp_path / "w.npz") as z:
        arrays = {k: z[k] for k in z.files}
    bad = dict(arrays, meta=json.dumps({"history": {**HISTORY, "taus_s": [0.1, 0.25]}}))
    np.savez(tmp_path / "bad.npz", **bad)
    with pytest.raises(ValueError, match="another input/output layout"):
        SurrogateWing.load(tmp_path / "bad.npz")
    # a memoryless wing saved before K_b existed
    m0 = _linear_model(A[:, :30], c, x_mean[:30], x_std[:30])
    m0.save(tmp_path / "old.npz")
    with np.load(tmp_path / "old.npz") as z:
        arrays = {k: z[k] for k in z.files if k != "K_b"}
    np.savez(tmp_path / "old.npz", **arrays)
    old = SurrogateWing.load(tmp_path / "old.npz")
    assert np.array_equal(old.K_b, np.zeros((12, 12))) and old.input_names == INPUT_NAMES


def test_output_errors_relative_to_traction():
    y = np.zeros((4, 17))
    y[:, 2] = y[:, 8] = -1000.0  # A and C pull 1 kN each along -z: traction 2 kN
    yp = y.copy()
    yp[:, :12] += 20.0  # 20 N on every force component
    e = output_errors(y, yp)
    assert e["mean_traction_N"] == pytest.approx(2000.0)
    assert e["force_rms_N"] == pytest.approx(20.0) and e["force_rms_rel_traction"] == pytest.approx(0.01)
    assert e["rms"][OUTPUT_NAMES[0]] == pytest.approx(20.0) and e["rms"]["lift"] == 0.0


def test_latent_features_are_the_exact_discrete_filters():
    """latent_features: per time constant the filter z <- z + c (x - z), c = 1 - exp(-dt/tau) (filter_gain), started
    at the first row's inputs and updated with each row before its z - x is taken, over the FILTERED inputs."""
    rng = np.random.default_rng(2)
    X = np.cumsum(rng.normal(size=(40, 30)), axis=0)
    dt, taus = 0.005, (0.01, 0.05, 0.25)
    assert filter_gain(dt, 0.05) == pytest.approx(1.0 - np.exp(-0.1), rel=1e-15)
    H = latent_features(X, dt, taus)
    n = len(FILTERED)
    assert H.shape == (40, len(taus) * n) and FILTERED == tuple(range(12)) + tuple(range(24, 30))
    for j, tau in enumerate(taus):
        c = filter_gain(dt, tau)
        z = [X[0, i] for i in FILTERED]
        for k in range(len(X)):
            for m, i in enumerate(FILTERED):
                z[m] = z[m] + c * (X[k, i] - z[m])
                assert H[k, j * n + m] == pytest.approx(z[m] - X[k, i], rel=1e-12, abs=1e-12)
    assert np.all(H[0] == 0.0) and np.abs(H[1:]).min() > 0.0
    # a constant input is a steady state: no history
    assert np.all(latent_features(np.tile(X[:1], (10, 1)), dt, taus) == 0.0)


# ---------------------------------------------------------------------------------------------------- tapes
#: a planned episode of 0.1 s (20 physics steps, 5 control steps) of the full default model
PLAN = EpisodePlan(index=3, policy="baseline+held:0.3", wind_mps=6.0, turbulence_max=0.05, gust_mps=0.0,
                   gust_start_s=0.0, duration_s=0.1, seed=7)


class _WitnessTape(FlightTape):
    """A FlightTape that also keeps what the wing's state held at each row (its nodes' accelerations A-D, in W)."""

    def __init__(self):
        super().__init__()
        self.wing_a = []

    def _row(self, rec, L_B, L_D):
        super()._row(rec, L_B, L_D)
        dyn = self.sim.dyn
        self.wing_a.append(dyn.a[dyn.bridle] @ rec.R_wk.T)


@pytest.fixture(scope="module")
def tape():
    witness = _WitnessTape()
    arrays, meta = fly_plan(PLAN, tape=witness)
    return arrays, meta, witness


def test_a_planned_episode_is_recorded_step_by_step(tape):
    """fly_plan flies the full default model (the wing with inertia) for the planned 0.1 s: one row per physics step
    and the start, every column of COLUMNS with its shape; the accelerations of A-D are the wing's own (its nodes'
    generalized-alpha accelerations, finite in every row; not the velocity differences), the KCU's its velocity
    change over the step; the meta records the plan, the drawn conditions and the model."""
    arrays, meta, witness = tape
    cfg = Config()
    n = round(PLAN.duration_s / cfg.dynamics.dt_s) + 1
    assert type(witness.sim).__name__ == "DynamicFlightSimulator"
    assert set(arrays) == set(COLUMNS)
    for k, shape in COLUMNS.items():
        assert arrays[k].shape == (n, *shape), k
    t, v, a = arrays["t"], arrays["v"], arrays["a"]
    np.testing.assert_allclose(np.diff(t), cfg.dynamics.dt_s, rtol=1e-9)
    assert np.all(np.isfinite(a[:, :4])) and np.abs(a[:, :4]).max() > 1.0
    np.testing.assert_array_equal(a[:, :4], np.array(witness.wing_a))
    dv = (v[1:] - v[:-1]) / np.diff(t)[:, None, None]
    np.testing.assert_array_equal(a[1:, 4], dv[:, 4])
    assert np.all(np.isnan(a[0, 4]))  # no step before the start
    assert not np.allclose(a[1:, :4], dv[:, :4], rtol=0.0, atol=1.0)
    for k in ("r", "v", "rest", "tether_length", "tether_force", "tension", "wind", "alpha", "lift", "drag"):
        assert np.all(np.isfinite(arrays[k][1:])), k
    assert np.all(arrays["rest"][:, [0, 2]] == cfg.dynamics.power_line_length_m)
    assert arrays["action"][0] == 0.0 and len(set(arrays["action"][1:])) > 1  # the held noise changes the action
    np.testing.assert_allclose(np.linalg.norm(arrays["r"][:, 4], axis=1), arrays["tether_length"], rtol=1e-6)
    np.testing.assert_allclose(arrays["wind"][:, 5], 0.5 * (arrays["wind"][:, 0] + arrays["wind"][:, 2]), atol=0.5)
    assert meta["rows"] == n and meta["flown_s"] == pytest.approx(PLAN.duration_s) and meta["end"] == "time limit"
    assert meta["plan"] == dataclasses.asdict(PLAN) and meta["overrides"] == PLAN.overrides()
    assert meta["episode"]["wind_speed_mps"] == PLAN.wind_mps
    assert 0.0 <= meta["episode"]["turbulence_intensity"] <= PLAN.turbulence_max
    assert 4.0 * PLAN.wind_mps <= meta["episode"]["initial_speed_mps"] <= 4.8 * PLAN.wind_mps
    assert meta["model"] == fingerprint(cfg) and meta["model"]["preset"] == "default"


def test_tapes_save_and_load(tape, tmp_path):
    arrays, meta, _ = tape
    path = save_tape(tmp_path / "ep_0003.npz", arrays, meta)
    assert path.is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["ep_0003.npz"]  # no partial file left
    back, meta2 = load_tape(path)
    assert meta2 == json.loads(json.dumps(meta)) and set(back) == set(arrays)
    for k in arrays:
        np.testing.assert_array_equal(back[k], arrays[k], err_msg=k)  # (NaN where NaN)


def _geometry(cfg):
    from kite_env.fsi import nominal_wing

    wing = nominal_wing(cfg.kite.name, cfg)
    q0 = wing.design_bridle
    return wing, q0, (float(np.linalg.norm(q0[0] - q0[1])), float(np.linalg.norm(q0[2] - q0[3])))


@pytest.mark.parametrize("accel", ["central", "wing"])
def test_the_effective_wing_force_recovers_the_accelerations(tape, accel):
    """tape_samples: the effective wing force F_wing = m a - f_other on Table 1's point masses A-D, stored as the
    reaction F_b = -F_wing in K, gives back the accelerations: m a = F_wing + f_other, with f_other the particle
    system's forces without the wing (ParticleSystem.forces: bridle lines at the tape's rest lengths, their drag,
    gravity) at the tape's positions, velocities and wind. ``central``: the central difference of the recorded
    velocities (undefined at both ends); ``wing``: the wing's own accelerations. The inputs are the features of
    the recorded state in its frame K."""
    from kite_env.dynamics.particles import ParticleSystem

    arrays, _, _ = tape
    cfg = Config()
    _, q0, tips = _geometry(cfg)
    X, Y, ok = tape_samples(arrays, cfg, q0, tips, accel)
    t, r, v, wind = arrays["t"], arrays["r"], arrays["v"], arrays["wind"]
    n = len(t)
    assert X.shape == (n, 30) and Y.shape == (n, 17)
    if accel == "central":
        assert not ok[0] and not ok[-1] and ok[1:-1].all()
        a = np.full_like(v, np.nan)
        a[1:-1] = (v[2:] - v[:-2]) / (t[2:] - t[:-2])[:, None, None]
    else:
        assert ok.all()
        a = arrays["a"]
    ps = ParticleSystem(cfg.dynamics, tips, np.zeros(4), cfg.aero.rho_kg_m3)
    for k in np.flatnonzero(ok):
        origin, R = kite_frame(*r[k, :4])
        F_wing = -Y[k, :12].reshape(4, 3) @ R.T  # in W
        ps.set_steering(float(arrays["rest"][k, 1]), float(arrays["rest"][k, 3]))
        f, _ = ps.forces(r[k], v[k], wind[k, :5], F_wing)
        ma = ps.m[:4, None] * a[k, :4]
        np.testing.assert_allclose(f[:4], ma, rtol=0.0, atol=1e-9 * np.abs(ma).max() + 1e-6)
        # the inputs: bridle points relative to the design, the apparent velocity of the origin, in K
        np.testing.assert_allclose(X[k, :12], ((r[k, :4] - origin) @ R - q0).ravel(), atol=1e-10)
        v_app = 0.5 * (v[k, 0] + v[k, 2]) - wind[k, 5]
        np.testing.assert_allclose(X[k, 24:27], v_app @ R, atol=1e-10)
    # the pull of the wing on the lines is towards the KCU (-z_k): the reactions point the other way, summed
    assert np.all(Y[ok, :12].reshape(-1, 4, 3).sum(axis=1)[:, 2] < 0.0)
    np.testing.assert_array_equal(Y[:, 15], arrays["lift"])
    np.testing.assert_array_equal(Y[:, 12:15], np.clip(arrays["alpha"], -0.5, 0.5))


def test_build_dataset_adds_the_history_and_refuses_a_tape_of_another_model(tape, tmp_path):
    arrays, meta, _ = tape
    save_tape(tmp_path / "ep_0003.npz", arrays, meta)
    cfg = Config()
    wing, q0, tips = _geometry(cfg)
    data = build_dataset(tmp_path, cfg, wing, log=lambda m: None)
    X, Y, ok = tape_samples(arrays, cfg, q0, tips)
    H = latent_features(X, cfg.dynamics.dt_s, TAUS)
    np.testing.assert_array_equal(data.inputs, np.hstack([X, H])[ok])
    np.testing.assert_array_equal(data.outputs, Y[ok])
    assert np.all(data.group == PLAN.index) and data.meta["taus_s"] == list(TAUS)
    static = load_config(None, ["structure.dynamic=false"])  # the quasi-static wing
    with pytest.raises(ModelMismatch, match=r"tape '.*ep_0003.npz'.*structure\.dynamic"):
        build_dataset(tmp_path, static, wing, log=lambda m: None)


# ---------------------------------------------------------------------------------------------------- fit
def test_fit_mlp_fits_a_smooth_map_on_top_of_the_known_linear_part():
    """fit_mlp on synthetic data of the history layout (48 inputs): a smooth map of three of them plus a stiff linear
    part K_b x[:12] on the forces. Episodes are held out whole; the MLP fits the outputs less K_b x[:12]; the report's
    held-out errors are those of the whole model (MLP and linear part), and they are small."""
    rng = np.random.default_rng(4)
    n_ep, per = 40, 60
    n = n_ep * per
    X = rng.normal(size=(n, 48))
    D = rng.normal(size=(3, 17))
    D /= np.linalg.norm(D, axis=0)
    scale = np.array([300.0] * 12 + [0.1] * 3 + [500.0, 100.0])
    offset = np.zeros(17)
    offset[[2, 15, 16]] = -3000.0, 2000.0, 300.0
    smooth = scale * np.tanh(0.7 * X[:, 24:27] @ D) + offset
    K_b = rng.normal(0.0, 2e3, (12, 12))
    lin = np.zeros((n, 17))
    lin[:, :12] = X[:, :12] @ K_b.T
    Y = smooth + lin
    group = np.repeat(np.arange(n_ep), per)
    data = FitData(X, Y, group, {})
    W, b, (x_mean, x_std, y_mean, y_std, lo, hi), report = fit_mlp(data, hidden=(32, 32), epochs=40, batch=64,
                                                                  lr=3e-3, K_b=K_b, log=lambda m: None)
    val = group % 5 == 4
    assert report["n_val"] == int(val.sum()) == 8 * per and report["n_train"] == n - 8 * per
    assert [w.shape for w in W] == [(48, 32), (32, 32), (32, 17)]
    np.testing.assert_array_equal(lo, X[~val].min(0))
    np.testing.assert_array_equal(hi, X[~val].max(0))
    meta = {"history": {"taus_s": [0.05, 0.25], "filtered": list(range(9)), "inertial": True}}
    wing = SurrogateWing(W, b, x_mean, x_std, y_mean, y_std, lo, hi, meta, K_b)
    assert len(wing.input_names) == 48
    err = output_errors(Y[val], wing.predict(X[val]))
    # the report is the whole model's error on the held-out episodes (torch's float32 against NumPy's float64)
    assert report["force_rms_N"] == pytest.approx(err["force_rms_N"], rel=1e-3)
    assert report["rms"]["lift"] == pytest.approx(err["rms"]["lift"], rel=1e-3)
    # small against the spread of the smooth part and far below the size of the linear part
    spread = np.sqrt(np.mean(np.var(smooth[val, :12], axis=0)))
    assert err["force_rms_N"] < 0.1 * spread
    assert err["force_rms_N"] < 0.01 * np.sqrt(np.mean(np.var(lin[val, :12], axis=0)))
    assert err["rms"]["lift"] < 0.1 * np.std(smooth[val, 15])
    # the MLP alone is the map less the linear part
    mlp = dataclasses.replace(wing, K_b=np.zeros((12, 12))).predict(X[val])
    assert np.sqrt(np.mean((mlp[:, :12] - smooth[val, :12]) ** 2)) == pytest.approx(err["force_rms_N"], rel=1e-6)



def _slope_of(wing, X, direction):
    """Derivative of the wing's bridle force along ``direction`` (raw inputs) at the rows of ``X``, by central
    differences of its prediction."""
    e = 1e-4
    return (wing.predict(X + e * direction)[:, :12] - wing.predict(X - e * direction)[:, :12]) / (2 * e)


def test_the_fit_takes_the_slopes_that_the_data_cannot_tell():
    """Two inputs move together in every sample (the apparent velocity's x and z, as pitch and load move together
    under the force loop): the forces fix only the sum of their effects. Fitted with the static wing's slopes at a
    fifth of the states (kite_env.fitting.jacobians' layout: dF_b/dq_b, dF_b/dv_app, dF_b/domega), the wing's
    derivative along each is the given one, on held-out states too; fitted to the forces alone it is not. The forces
    fit as well."""
    from kite_env.fitting.fit import slope_directions

    rng = np.random.default_rng(5)
    n_ep, per = 40, 60
    n = n_ep * per
    X = rng.normal(size=(n, 48))
    X[:, 26] = X[:, 24]  # collinear in the data
    a, c = rng.normal(0.0, 300.0, 12), rng.normal(0.0, 300.0, 12)  # dF/dv_x, dF/dv_z, the truth
    Y = np.zeros((n, 17))
    Y[:, :12] = np.outer(X[:, 24], a) + np.outer(X[:, 26], c) + 200.0 * np.tanh(X[:, 25:26])
    Y[:, 12:] = rng.normal(size=(n, 5))
    group = np.repeat(np.arange(n_ep), per)
    K_b = rng.normal(0.0, 2e3, (12, 12))
    Y[:, :12] += X[:, :12] @ K_b.T
    data = FitData(X, Y, group, {})
    states = np.arange(0, n, 5)
    J = np.zeros((len(states), 12, 18))  # the map does not depend on the rotation rate
    J[:, :, :12] = K_b
    J[:, :, 12], J[:, :, 14] = a, c
    J[:, :, 13] = 200.0 / np.cosh(X[states, 25])[:, None] ** 2
    slopes = {"inputs": X[states], "J": J, "group": group[states]}
    val = group % 5 == 4
    U = slope_directions(48)
    res = {}
    for weight in (0.0, 1.0):
        W, b, norms, report = fit_mlp(data, hidden=(32, 32), epochs=40, batch=64, lr=3e-3, K_b=K_b, slopes=slopes,
                                      slope_weight=weight, log=lambda m: None)
        wing = SurrogateWing(W, b, *norms, {"history": {"taus_s": [0.05, 0.25], "filtered": list(range(9))}}, K_b)
        Xv = X[val][:50]
        res[weight] = (report, [_slope_of(wing, Xv, U[d]) for d in (6, 8)])
    for weight in (0.0, 1.0):
        report, (sx, sz) = res[weight]
        err = max(np.sqrt(np.mean((sx - a) ** 2)), np.sqrt(np.mean((sz - c) ** 2))) / np.sqrt(np.mean(a**2 + c**2))
        res[weight] = (report, err)
    assert res[1.0][1] < 0.1, res
    assert res[0.0][1] > 3 * res[1.0][1], res
    assert res[1.0][0]["force_rms_N"] < 1.2 * res[0.0][0]["force_rms_N"] + 5.0
    assert res[1.0][0]["held_out_slope_loss"] is not None and res[0.0][0]["held_out_slope_loss"] is None
    # slopes of fitted episodes only (none held out): the fit runs on the forces' held-out loss
    train = (slopes["group"] % 5) != 4
    only = {k: v[train] for k, v in slopes.items()}
    *_, report = fit_mlp(data, hidden=(8,), epochs=2, batch=256, K_b=K_b, slopes=only, slope_weight=1.0,
                         log=lambda m: None)
    assert report["held_out_slope_loss"] == 0.0 and np.isfinite(report["held_out_loss"])


def test_the_static_wings_slopes_at_a_recorded_state(tape):
    """kite-fit slopes at a recorded state of the full model: the inputs are the tape's, the derivatives in the
    apparent velocity and the rotation rate converge with the difference step, and the bridle stiffness (the solve's
    condensed tangent) is the central difference of the solve along a deformation that keeps frame K (the twist, B up
    and D down)."""
    from kite_env.fitting.jacobians import DOMEGA_RPS, DV_MPS, JAC_INPUTS, tape_jacobians
    from kite_env.fsi import nominal_wing

    arrays, meta, _ = tape
    cfg = load_config(None)
    wing = nominal_wing(cfg.kite.name, cfg)
    res = tape_jacobians(arrays, meta, cfg, wing, every=10)
    assert res["failed"] == 0 and list(res["rows"]) == [10] and res["J"].shape == (1, 12, len(JAC_INPUTS))
    _, q0, tips = _geometry(cfg)
    X, _, _ = tape_samples(arrays, cfg, q0, tips)
    np.testing.assert_allclose(res["inputs"][0, :30], X[10])
    q_b = wing.design_bridle + X[10, :12].reshape(4, 3)

    def solve(q, v, w=X[10, 27:30]):
        return np.asarray(wing.solve(q, FlightState(v_kite=v, omega=w, v_wind=np.zeros(3)), dt=None,
                                     support="prescribed", warm=True, commit=False).F_b).ravel()

    v, w = X[10, 24:27], X[10, 27:30]
    for j in range(3):
        d = np.zeros(3)
        d[j] = 0.4 * DV_MPS
        fd = (solve(q_b, v + d) - solve(q_b, v - d)) / (2 * d[j])
        np.testing.assert_allclose(res["J"][0, :, 12 + j], fd, atol=0.02 * np.abs(fd).max())
        d[j] = 0.4 * DOMEGA_RPS
        fd = (solve(q_b, v, w + d) - solve(q_b, v, w - d)) / (2 * d[j])
        np.testing.assert_allclose(res["J"][0, :, 15 + j], fd, atol=0.02 * np.abs(fd).max())
    twist = np.zeros((4, 3))
    twist[1, 2], twist[3, 2] = 1.0, -1.0
    e = 1e-4
    fd = (solve(q_b + e * twist, v) - solve(q_b - e * twist, v)) / (2 * e)
    np.testing.assert_allclose(res["J"][0, :, :12] @ twist.ravel(), fd, atol=0.02 * np.abs(fd).max())

def test_the_agent_plan_flies_a_trained_agent_alone_and_with_held_offsets():
    """agent_plan: indexed apart from the other plans, the agent alone (60 s) and with held offsets of 0.1-0.4 (40 s)
    in turn, winds of the sampling plan, the same plan for the same seed; make_sampling_policy gives the agent with a
    held offset its own action plus at most the offset, held between 0.2 and 1.5 s."""
    import gymnasium as gym

    from kite_env.fitting.trajectories import AGENT_INDEX, HeldNoise, agent_plan, make_sampling_policy, sampling_plan

    plan = agent_plan(8, 3, "ppo")
    assert plan == agent_plan(8, 3, "ppo") and plan != agent_plan(8, 4, "ppo")
    assert [p.index for p in plan] == list(range(AGENT_INDEX, AGENT_INDEX + 8))
    assert not {p.index for p in plan} & {p.index for p in sampling_plan(200, 3)}
    assert [p.policy for p in plan[::2]] == ["ppo"] * 4 and all(p.duration_s == 60.0 for p in plan[::2])
    for p in plan[1::2]:
        base, amp = p.policy.split("+held:")
        assert base == "ppo" and 0.1 <= float(amp) <= 0.4 and p.duration_s == 40.0
    assert all(4.0 <= p.wind_mps <= 10.0 and p.turbulence_max == 0.1 for p in plan)

    env = gym.make("KiteFigureEightFast-v1").unwrapped
    obs, _ = env.reset(seed=0)
    held = make_sampling_policy("ppo+held:0.3", env, seed=5)
    assert isinstance(held, HeldNoise) and held.amp == 0.3
    offsets = []
    for k in range(200):
        a_agent = float(held.base.predict(obs, None, np.array([k == 0]), True)[0].ravel()[0])
        a = float(held.predict(obs, None, np.array([k == 0]), True)[0].ravel()[0])
        offsets.append(a - a_agent)
    offsets = np.round(offsets, 6)
    assert np.abs(offsets).max() <= 0.3 + 1e-6 and len(set(offsets)) > 1
    runs = np.diff(np.flatnonzero(np.diff(offsets) != 0))  # steps an offset is held (between its changes)
    assert runs.min() >= round(0.2 / env.control_dt) - 1 and runs.max() <= round(1.5 / env.control_dt) + 1
    env.close()


@pytest.mark.parametrize("bad", [["--replay-s", "0"], ["--replay-every-s", "-1"], ["--out", "wing.txt"],
                                 ["--slope-weight", "-1"], ["--slope-directions", "v_app_x,pitch"]])
def test_kite_fit_refuses_bad_fit_options_before_reading_anything(tmp_path, capsys, bad):
    """``kite-fit fit`` with a replay of no length, a negative spacing or an output that is not .npz: exit 2 with one
    line naming the option, before a tape is read or a file written."""
    from kite_env.cli.fit import main

    args = ["fit", "--tapes", str(tmp_path / "no_tapes"), "--out", str(tmp_path / "w.npz"), *bad]
    if bad[0] == "--out":
        args[4] = str(tmp_path / bad[1])
        args = args[:5]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and any(k in err[0] for k in ("--replay", ".npz", "--slope-weight", "'pitch'"))
    assert list(tmp_path.iterdir()) == []


def test_kite_fit_slopes_and_a_fit_that_needs_them(tape, tmp_path, capsys):
    """``kite-fit fit --slope-weight`` without ``kite-fit slopes`` of the tapes: exit 2 naming the command that makes
    them, nothing written; ``kite-fit slopes --every-s 0``: exit 2."""
    from kite_env.cli.fit import main

    arrays, meta, _ = tape
    (tmp_path / "tapes").mkdir()
    save_tape(tmp_path / "tapes" / "ep_0003.npz", arrays, meta)
    assert main(["fit", "--tapes", str(tmp_path / "tapes"), "--out", str(tmp_path / "w.npz"),
                 "--slope-weight", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "kite-fit slopes --tapes" in err[0]
    assert main(["slopes", "--tapes", str(tmp_path / "tapes"), "--every-s", "0"]) == 2
    assert "--every-s" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["ep_0003.npz", "tapes"]


def test_the_depower_plan_excites_the_force_loop_with_held_offsets():
    """depower_plan: indexed apart from the other plans, 40 s flights of the controller (alone and with held steering
    offsets) with held depower offsets of 0.05-0.2 m, the same plan for the same seed; HeldDepower sets the
    actuator's common offset once per controller period, within its amplitude, each held 0.2-1.5 s."""
    from kite_env.fitting.trajectories import (
        AGENT_INDEX,
        DEPOWER_INDEX,
        HeldDepower,
        agent_plan,
        depower_plan,
        sampling_plan,
        start_plan,
    )

    plan = depower_plan(8, 3)
    assert plan == depower_plan(8, 3) and plan != depower_plan(8, 4)
    assert [p.index for p in plan] == list(range(DEPOWER_INDEX, DEPOWER_INDEX + 8))
    others = sampling_plan(200, 3) + start_plan(200, 3) + agent_plan(200, 3, "ppo")
    assert not {p.index for p in plan} & {p.index for p in others} and AGENT_INDEX < DEPOWER_INDEX
    for k, p in enumerate(plan):
        base, amp = p.policy.rsplit("+depower:", 1)
        assert 0.05 <= float(amp) <= 0.2 and p.duration_s == 40.0 and 4.0 <= p.wind_mps <= 10.0
        assert base == "baseline" if k % 2 == 0 else (base.startswith("baseline+held:")
                                                       and 0.1 <= float(base.split(":")[1]) <= 0.5)

    class Actuator:
        depower_offset_m = 0.0

    act, dt = Actuator(), 0.02
    held = HeldDepower(0.1, (0.2, 1.5), dt, np.random.default_rng(7))
    offsets = []
    for _ in range(300):
        held.update(act)
        offsets.append(act.depower_offset_m)
    offsets = np.array(offsets)
    assert np.abs(offsets).max() <= 0.1 and len(set(offsets)) > 3
    runs = np.diff(np.flatnonzero(np.diff(offsets) != 0))
    assert runs.min() >= round(0.2 / dt) - 1 and runs.max() <= round(1.5 / dt) + 1


@pytest.mark.parametrize("plans", [["--starts", "--depower"], ["--agent", "ppo", "--depower"]])
def test_kite_fit_sample_takes_one_plan(tmp_path, capsys, plans):
    """``kite-fit sample`` with two plans: exit 2 with one line, nothing flown or written."""
    from kite_env.cli.fit import main

    assert main(["sample", "--out", str(tmp_path / "tapes"), *plans]) == 2
    assert "three plans; give one" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
