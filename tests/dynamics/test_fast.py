"""The fast fidelity (kite_env.dynamics.fast): batched kites = single kites, inputs as sampled, wind as WindField,
agreement with the full model over a short flight, the envelope error and the fallback to the FE model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kite_env.config import Config
from kite_env.dynamics.fast import OUTSIDE, SurrogateFlightSimulator, SurrogateKites, kite_inputs
from kite_env.dynamics.simulator import FlightSimulator, SimulationError
from kite_env.frames import kite_frame
from kite_env.fsi import FlightState
from kite_env.polar import nominal_wing
from kite_env.surrogate import load_default
from kite_env.surrogate.samples import INPUT_NAMES, features
from kite_env.trajectory import Lemniscate
from kite_env.wind import WindConfig, WindField


@pytest.fixture(scope="module")
def setup(legacy_cfg):
    """The legacy model (configs/legacy_v0.yaml): the FE model the shipped reduced-order wing was fitted to."""
    cfg = legacy_cfg
    wing = nominal_wing(cfg.kite.name, cfg)
    return cfg, wing, load_default(cfg.kite.name), Lemniscate(cfg.trajectory)


def _start(sim, path, s0=0.0, v0=22.0):
    return sim.reset(path.point(s0), path.tangent(s0), v0)


def test_wind_kernel_matches_windfield():
    """The compiled wind of the batched kites is WindField.velocity (numba backend) for every profile, with
    turbulence and a gust."""
    from kite_env.dynamics.fast import _wind_at

    rng = np.random.default_rng(3)
    pos = rng.uniform([-20, -30, 5], [80, 30, 70], (6, 3))
    for profile in ("uniform", "log", "power"):
        wc = WindConfig(speed_mps=7.0, profile=profile, turbulence_intensity=0.1, gust_speed_mps=2.0,
                        gust_start_s=0.5, gust_duration_s=2.0, seed=11)
        wf = WindField(wc)
        ks = SurrogateKites.__new__(SurrogateKites)  # only the wind arrays are needed
        ks.n_modes = wc.turbulence_modes
        for name, shape in (("wind_f", (1, 9)), ("wind_i", (1, 2)), ("wavevec_t", (1, 3, 3 * ks.n_modes)),
                            ("phase0", (1, 3 * ks.n_modes)), ("omega_m", (1, 3 * ks.n_modes)),
                            ("amp", (1, 3 * ks.n_modes))):
            setattr(ks, name, np.zeros(shape, dtype=np.int64 if name == "wind_i" else float))
        SurrogateKites.set_wind(ks, 0, wf)
        for t in (0.0, 1.3):
            out = np.empty((6, 3))
            f, i = ks.wind_f[0], ks.wind_i[0]
            _wind_at(t, pos, out, f[0], i[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], i[1] != 0, ks.wavevec_t[0],
                     ks.phase0[0], ks.omega_m[0], ks.amp[0], ks.n_modes, np.empty(1))
            np.testing.assert_allclose(out, wf.velocity(t, pos), rtol=1e-12, atol=1e-12)


def test_inputs_are_the_sampled_features(setup):
    """The wing inputs the fast kernel evaluates are exactly the features the samples were made of
    (surrogate.samples.features of the bridle points, their rates relative to K, v_app and omega in K)."""
    cfg, wing, sw, path = setup
    sim = FlightSimulator(cfg, WindField(cfg.wind), wing)
    _start(sim, path)
    for _ in range(20):
        rec = sim.step(sim.L_B0 - 0.05, sim.L_D0 + 0.05)  # a turn: rotation and deformation rates
    r, v = rec.state.r, rec.state.v
    origin, R = kite_frame(r[0], r[1], r[2], r[3])
    q_b = (r[:4] - origin) @ R
    w_K = R.T @ rec.omega
    qdot = (v[:4] - rec.v_kite) @ R - np.cross(w_K, q_b)
    ref = features(q_b, qdot, FlightState(R.T @ rec.v_kite, w_K, R.T @ rec.v_wind), wing.design_bridle)
    ks = SurrogateKites(cfg, sw, wing.design_bridle, sim.tip_lengths, 1)
    ks.set_wind(0, sim.wind)
    x, w5, Rk = np.empty(30), np.empty((5, 3)), np.empty((3, 3))
    kite_inputs(rec.t, r, v, ks.q_design, ks.wind_f[0], ks.wind_i[0], ks.wavevec_t[0], ks.phase0[0], ks.omega_m[0],
                ks.amp[0], ks.n_modes, x, w5, Rk, np.empty((6, 3)), np.empty((6, 3)), np.empty(1), np.empty((6, 3)),
                False)
    assert np.abs(ref).max() > 1.0 and np.abs(ref[12:24]).max() > 1e-3  # a state that moves
    np.testing.assert_allclose(x, ref, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(Rk, R, atol=1e-14)
    np.testing.assert_allclose(w5, sim.wind.velocity(rec.t, r), atol=1e-12)


def test_batched_kites_equal_single_kites(setup):
    """Three kites in different winds, steering and starts advanced together give bit for bit the states of the
    three flown one at a time."""
    cfg, wing, sw, path = setup
    winds = [WindField(dataclasses.replace(cfg.wind, speed_mps=u, turbulence_intensity=ti, seed=s))
             for u, ti, s in ((5.0, 0.0, 0), (6.0, 0.08, 1), (4.5, 0.05, 2))]
    singles = []
    for k, (wf, s0) in enumerate(zip(winds, (0.0, 0.4, 5.9))):
        sim = SurrogateFlightSimulator(cfg, wf, surrogate=sw, wing=wing)
        _start(sim, path, s0)
        singles.append(sim)
    def kites(n):
        return SurrogateKites(cfg, sw, wing.design_bridle, singles[0].tip_lengths, n)

    ks, ones = kites(3), [kites(1) for _ in singles]
    for k, sim in enumerate(singles):
        for arr, row in ((ks, k), (ones[k], 0)):
            arr.set_wind(row, sim.wind)
            arr.set_kite(row, sim.state.r, sim.state.v, sim.t, sim.pair_stiffness, sim.L_B0, sim.L_D0)
    ks.evaluate()
    for one in ones:
        one.evaluate()
    steer = np.array([0.03, -0.02, 0.0])
    L0 = np.array([s.L_B0 for s in singles])
    for n in range(60):
        L_B, L_D = L0 - steer * np.sin(0.1 * n), L0 + steer * np.sin(0.1 * n)
        ks.step(L_B, L_D)
        for k, one in enumerate(ones):
            one.step(L_B[k:k + 1], L_D[k:k + 1])
            for name in ("r", "v", "t", "Y", "X", "tension", "tether_force", "status"):
                assert np.array_equal(getattr(one, name)[0], getattr(ks, name)[k]), (name, n, k)
    # the single simulator is the same arrays behind the FlightSimulator interface
    rec = singles[0].step(float(L0[0]), float(L0[0]))
    assert rec.line_tension.shape == (4,) and np.isfinite(rec.tether_force) and rec.wing.alpha.shape == (3,)


def test_agrees_with_full_model_over_a_short_flight(setup):
    """From the same start (FE), 0.6 s of straight flight in the model the surrogate was fitted to: tether force
    within 3 %, speed within 3 %, KCU position within 0.3 m (the bounds of issue 5; measured +1.9 %, +0.8 %,
    0.13 m)."""
    cfg, wing, sw, path = setup
    fe = FlightSimulator(cfg, WindField(cfg.wind), nominal_wing(cfg.kite.name, cfg))  # fresh wings: the FE start
    sur = SurrogateFlightSimulator(cfg, WindField(cfg.wind), surrogate=sw, wing=nominal_wing(cfg.kite.name, cfg),
                                   start="fe")
    r_fe, r_s = _start(fe, path), _start(sur, path)
    np.testing.assert_array_equal(r_fe.state.r, r_s.state.r)
    for _ in range(120):
        a, b = fe.step(fe.L_B0, fe.L_D0), sur.step(sur.L_B0, sur.L_D0)
    assert abs(b.tether_force / a.tether_force - 1.0) < 0.03
    assert abs(np.linalg.norm(b.v_kite) / np.linalg.norm(a.v_kite) - 1.0) < 0.03
    assert np.linalg.norm(b.state.r[4] - a.state.r[4]) < 0.3  # of 17 m flown


def test_the_ground_station_reels_out_as_in_the_full_model(setup):
    """dynamics.winch = "force" in the fast fidelity: above the set force each kite's reel-out speed follows
    (F_t - F_set) / c_w with its lag, as :meth:`FlightSimulator._winch`; the tether length grows by each step's
    reel-out, the KCU stays on the tether, its radial speed is the reel speed, and the records carry length and speed.
    With "fixed" (configs/legacy_v0.yaml) the tether keeps its 80 m."""
    cfg, wing, sw, path = setup
    fixed = SurrogateFlightSimulator(cfg, WindField(cfg.wind), surrogate=sw, wing=wing)
    _start(fixed, path)
    recs = [fixed.step(fixed.L_B0, fixed.L_D0) for _ in range(40)]
    assert all(r.tether_length == 80.0 and r.reel_speed == 0.0 for r in recs)
    cfg = dataclasses.replace(cfg, dynamics=dataclasses.replace(cfg.dynamics, winch="force", winch_force_N=1000.0,
                                                                winch_time_constant_s=0.05))
    sim = SurrogateFlightSimulator(cfg, WindField(cfg.wind), surrogate=sw, wing=wing)
    _start(sim, path)
    d = cfg.dynamics
    l_t, v_r = 80.0, 0.0
    for _ in range(40):
        rec = sim.step(sim.L_B0, sim.L_D0)
        l_t += d.dt_s * v_r  # the step reels out at the speed set after the previous one
        v_step = v_r
        v_set = min(max((rec.tether_force - d.winch_force_N) / d.winch_damping_Ns_per_m, 0.0), d.winch_speed_max_mps)
        v_r = v_set + (v_r - v_set) * np.exp(-d.dt_s / d.winch_time_constant_s)
        assert rec.tether_length == pytest.approx(l_t, abs=1e-12) and rec.reel_speed == pytest.approx(v_r, abs=1e-12)
        assert np.linalg.norm(rec.state.r[4]) == pytest.approx(l_t, abs=1e-9)
    assert rec.tether_length > 80.1 and 1.0 < rec.reel_speed < 6.0
    r, v = rec.state.r[4], rec.state.v[4]
    assert r @ v / np.linalg.norm(r) == pytest.approx(v_step, rel=1e-6)  # the KCU moves out at the step's reel speed
    assert rec.tether_force < 0.9 * recs[-1].tether_force  # reeling out lowers the traction


def test_outside_the_envelope_raises_or_falls_back(setup):
    """A kite pushed beyond the sampled inputs ends with 'outside surrogate envelope' naming the inputs; with the
    fallback it continues in the FE model."""
    cfg, wing, sw, path = setup
    sim = SurrogateFlightSimulator(cfg, WindField(cfg.wind), surrogate=sw, wing=wing)
    _start(sim, path)
    sim.kites.v[0, 4] += 80.0  # the KCU suddenly 80 m/s faster: tip and bridle rates far beyond any sample
    with pytest.raises(SimulationError) as err:
        for _ in range(5):
            sim.step(sim.L_B0, sim.L_D0)
    names = err.value.detail.split(", ")
    assert err.value.reason == "outside surrogate envelope" and names[0] and set(names) <= set(INPUT_NAMES)
    assert sim.kites.status[0] == OUTSIDE
    fb = SurrogateFlightSimulator(cfg, WindField(cfg.wind), surrogate=sw, wing=wing, on_outside="fe")
    _start(fb, path)
    x_max = fb.kites._hi.copy()
    fb.kites._hi[24] = fb.kites.X[0, 24] - 1.0  # the current apparent speed becomes 'outside'
    rec = fb.step(fb.L_B0, fb.L_D0)
    assert fb.fidelity_now == "fe" and fb.fallback_t == pytest.approx(rec.t)
    fb.kites._hi = x_max
    rec2 = fb.step(fb.L_B0, fb.L_D0)
    assert rec2.wing.nodes.shape == wing.mesh.nodes.shape and not np.array_equal(rec2.wing.nodes, wing.mesh.nodes)


def test_compiled_tanh_is_accurate():
    """The rational tanh of the compiled MLP is tanh to 3e-10 on the whole real line (clamped beyond |x| = 12) and
    keeps NaN."""
    from kite_env.dynamics.fast import tanh_inplace

    x = np.concatenate([np.linspace(-30.0, 30.0, 200_001), [0.0, 1e-300, -1e-300, np.inf, -np.inf]])
    h = x.copy()
    tanh_inplace(h)
    assert np.abs(h - np.tanh(x)).max() < 3e-10
    assert np.all(np.sign(h) == np.sign(x)) and np.all(np.abs(h) <= 1.0 + 3e-10)
    nan = np.array([np.nan, 0.5])
    tanh_inplace(nan)
    assert np.isnan(nan[0]) and abs(nan[1] - np.tanh(0.5)) < 3e-10


def test_compiled_mlp_is_the_surrogate(setup):
    """The compiled float32 MLP with the normalisations folded in gives SurrogateWing.predict (float64 NumPy) to
    float32 round-off, over inputs spread across the sampled envelope."""
    from kite_env.dynamics.fast import mlp_row

    cfg, wing, sw, _ = setup
    ks = SurrogateKites(cfg, sw, wing.design_bridle, np.ones(2), 1)
    rng = np.random.default_rng(5)
    X = sw.x_min + rng.uniform(0.0, 1.0, (200, sw.x_min.size)) * (sw.x_max - sw.x_min)
    ref = sw.predict(X)
    h = [np.empty(w.shape[1], dtype=np.float32) for w in ks._W]
    got = np.empty_like(ref)
    for i in range(len(X)):
        mlp_row(X[i], *ks._weights, *h, got[i])
    scale = np.maximum(np.abs(ref).max(axis=0), sw.y_std)
    assert np.abs(got - ref).max(axis=0).max() > 0.0  # float32: not bit-identical
    np.testing.assert_array_less(np.abs(got - ref) / scale, 2e-5)
