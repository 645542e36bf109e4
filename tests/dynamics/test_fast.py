"""The fast fidelity (kite_env.dynamics.fast) on the default model (the wing with inertia): batched kites = single
kites, inputs as the features, the latent filters of the reduced-order wing, wind as WindField, the compiled MLP with
its known linear part, the baseline's flight, the ground station and the envelope error,
and the refusal of a reduced-order wing fitted to another model."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from kite_env.config import Config, ConfigError, ModelMismatch, fingerprint, load_config
from kite_env.dynamics.factory import make_simulator
from kite_env.dynamics.fast import OK, OUTSIDE, SurrogateFlightSimulator, SurrogateKites, kite_inputs
from kite_env.dynamics.simulator import SimulationError
from kite_env.fitting.fit import FILTERED, filter_gain, latent_features
from kite_env.frames import kite_frame
from kite_env.fsi import FlightState, nominal_wing
from kite_env.surrogate import default_surrogate_path, load_default, surrogate_for
from kite_env.surrogate.samples import features
from kite_env.trajectory import Lemniscate
from kite_env.wind import WindConfig, WindField

PAPER = Path(__file__).resolve().parents[2] / "configs" / "paper.yaml"


@pytest.fixture(scope="module")
def setup():
    """The default model (the wing with inertia) and the reduced-order wing shipped for it."""
    cfg = Config()
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
    """The wing inputs the fast kernel evaluates are exactly the features the reduced-order wing is fitted to
    (surrogate.samples.features of the bridle points, their rates relative to K, v_app and omega in K), here along a
    turn of the full model of the default configuration (the wing with inertia)."""
    cfg, wing, sw, path = setup
    sim = make_simulator(cfg, WindField(cfg.wind), nominal_wing(cfg.kite.name, cfg))
    assert type(sim).__name__ == "DynamicFlightSimulator"
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
    """Three kites in different winds, steering and starts advanced together give bit for bit the states (and the
    latent filters of the reduced-order wing) of the three flown one at a time."""
    cfg, wing, sw, path = setup
    winds = [WindField(dataclasses.replace(cfg.wind, speed_mps=u, turbulence_intensity=ti, seed=s))
             for u, ti, s in ((5.0, 0.0, 0), (6.0, 0.08, 1), (4.5, 0.05, 2))]
    singles = []
    for wf, s0 in zip(winds, (0.0, 0.4, 5.9)):
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
            for name in ("r", "v", "t", "Y", "X", "Z", "tension", "tether_force", "tether_length", "reel_speed",
                         "status"):
                assert np.array_equal(getattr(one, name)[0], getattr(ks, name)[k]), (name, n, k)
    assert np.all(ks.status == OK)
    assert np.abs(ks.X[:, 30:]).max() > 0.0  # the latent state moved with the flights
    # the single simulator is the same arrays behind the FlightSimulator interface
    rec = singles[0].step(float(L0[0]), float(L0[0]))
    assert rec.line_tension.shape == (4,) and np.isfinite(rec.tether_force) and rec.wing.alpha.shape == (3,)


def test_blocks_of_kites_with_inactive_ones_equal_single_kites(setup):
    """More kites than a block (:data:`BLOCK` + 3, so the last block is short), some of them inactive in some steps
    (the blocks gather the active ones): every kite's state, inputs, wing outputs and status are bit for bit those of
    the same kite flown alone (n = 1, one row per MLP call), and an inactive kite does not move."""
    from kite_env.dynamics.fast import BLOCK

    cfg, wing, sw, path = setup
    n = BLOCK + 3
    singles = []
    for k, s0 in enumerate((0.0, 0.4, 5.9)):
        wf = WindField(dataclasses.replace(cfg.wind, speed_mps=5.0 + 0.5 * k, turbulence_intensity=0.04 * k, seed=k))
        sim = SurrogateFlightSimulator(cfg, wf, surrogate=sw, wing=wing)
        _start(sim, path, s0)
        singles.append(sim)
    ks = SurrogateKites(cfg, sw, wing.design_bridle, singles[0].tip_lengths, n)
    ones = [SurrogateKites(cfg, sw, wing.design_bridle, singles[0].tip_lengths, 1) for _ in range(n)]
    for k in range(n):
        sim = singles[k % 3]
        for arr, row in ((ks, k), (ones[k], 0)):
            arr.set_wind(row, sim.wind)
            arr.set_kite(row, sim.state.r, sim.state.v, sim.t, sim.pair_stiffness, sim.L_B0, sim.L_D0)
    ks.evaluate()
    for one in ones:
        one.evaluate()
    steer = np.linspace(-0.04, 0.04, n)
    L0 = np.array([singles[k % 3].L_B0 for k in range(n)])
    names = ("r", "v", "t", "Y", "X", "Z", "R", "wind", "tension", "length", "tether_force", "tether_length",
             "reel_speed", "status")
    for step in range(12):
        L_B, L_D = L0 - steer * np.sin(0.3 * step), L0 + steer * np.sin(0.3 * step)
        active = np.ones(n, dtype=bool) if step % 3 == 0 else (np.arange(n) % (2 + step % 3)) != 0
        before = ks.r.copy()
        ks.step(L_B, L_D, active)
        assert np.array_equal(ks.r[~active], before[~active])
        for k in np.flatnonzero(active):
            ones[k].step(L_B[k:k + 1], L_D[k:k + 1])
        for k, one in enumerate(ones):
            for name in names:
                assert np.array_equal(getattr(one, name)[0], getattr(ks, name)[k], equal_nan=True), (name, step, k)
    assert np.all(ks.status == OK)


def test_the_latent_filters_follow_the_inputs_as_in_the_fit(setup):
    """The reduced-order wing's latent state in the kernel: ``evaluate`` starts the filters at the current inputs
    (a steady start: history inputs zero, ``Z`` the filtered inputs); each step updates them with the step's end
    inputs, ``z <- z + (1 - exp(-dt/tau)) (x[sel] - z)``, and feeds ``z - x[sel]`` to the MLP: along the kernel's own
    inputs this is :func:`kite_env.fitting.fit.latent_features`, the history the wing was fitted with."""
    cfg, wing, sw, path = setup
    assert sw.taus and sw.filtered == FILTERED and sw.inertial  # a wing with memory, fitted by kite_env.fitting.fit
    sel = np.asarray(sw.filtered)
    n_sel = len(sel)
    assert len(sw.input_names) == 30 + len(sw.taus) * n_sel
    sim = SurrogateFlightSimulator(cfg, WindField(dataclasses.replace(cfg.wind, turbulence_intensity=0.1, seed=3)),
                                   surrogate=sw, wing=wing)
    _start(sim, path)
    ks = sim.kites
    assert ks.X.shape == (1, len(sw.input_names)) and ks.Z.shape == (1, len(sw.taus), n_sel)
    np.testing.assert_array_equal(ks._gain, [filter_gain(cfg.sim.surrogate_dt_s, tau) for tau in sw.taus])
    assert np.all(ks.X[0, 30:] == 0.0)
    for j in range(len(sw.taus)):
        np.testing.assert_array_equal(ks.Z[0, j], ks.X[0, sel])
    X = [ks.X[0].copy()]
    for n in range(80):  # a steering oscillation in turbulence: inputs that change from step to step
        d = 0.05 * math.sin(0.15 * n)
        sim.step(sim.L_B0 - d, sim.L_D0 + d)
        X.append(ks.X[0].copy())
        z = ks.Z[0]
        for j in range(len(sw.taus)):
            np.testing.assert_array_equal(X[-1][30 + j * n_sel:30 + (j + 1) * n_sel], z[j] - X[-1][sel])
    X = np.array(X)
    H = latent_features(X[:, :30], cfg.sim.surrogate_dt_s, sw.taus)
    assert np.abs(X[:, 30:]).max() > 1e-3  # a history that is not the steady one
    np.testing.assert_allclose(X[:, 30:], H, rtol=0.0, atol=1e-12 * np.abs(X[:, :30]).max())
    # the filters lag: the slow one further behind the inputs than the fast one
    lag = np.abs(X[:, 30:]).reshape(len(X), len(sw.taus), n_sel).mean(axis=(0, 2))
    assert sw.taus[0] < sw.taus[1] and lag[0] < lag[1]


def test_the_default_fast_model_flies_the_baseline_figure_eight():
    """The fast fidelity of the default model (KiteFigureEightFast-v1's) flown by the paper's controller through
    kite_env.flight.fly: 20 s at 5 m/s from the crossing without leaving the envelope of the reduced-order wing (a
    state beyond it ends the flight) and at least one whole figure-eight."""
    from kite_env.flight import fly

    cfg = load_config(None, ["sim.fidelity=surrogate"])
    assert cfg.wind.speed_mps == 5.0
    log = fly(cfg, duration_s=20.0)
    assert log.meta["termination_reason"] == "completed", log.meta["termination_reason"]
    assert log.series["t"][-1] == pytest.approx(20.0)
    path_s = log.series["path_s"]
    assert (path_s[-1] - path_s[0]) / (2.0 * math.pi) >= 1.0  # one figure-eight is 2 pi of the path parameter
    assert np.all(np.isfinite(log.series["tether_force"][1:])) and np.mean(log.series["tether_force"][1:]) > 1000.0


def test_the_ground_station_reels_out_as_in_the_full_model(setup):
    """dynamics.winch = "force" in the fast fidelity: above the set force each kite's reel-out speed follows
    (F_t - F_set) / c_w with its lag, as :meth:`FlightSimulator._winch`; the tether length grows by each step's
    reel-out, the KCU stays on the tether, its radial speed is the reel speed, and the records carry length and speed.
    With "fixed" (the paper's constant tether) the tether keeps its 80 m."""
    cfg0, wing, sw, path = setup
    cfg = dataclasses.replace(cfg0, dynamics=dataclasses.replace(cfg0.dynamics, winch="fixed"))
    fixed = SurrogateFlightSimulator(cfg, WindField(cfg.wind), surrogate=sw, wing=wing, start="fe")
    _start(fixed, path)
    recs = [fixed.step(fixed.L_B0, fixed.L_D0) for _ in range(40)]
    assert all(r.tether_length == 80.0 and r.reel_speed == 0.0 for r in recs)
    cfg = dataclasses.replace(cfg0, dynamics=dataclasses.replace(cfg0.dynamics, winch="force", winch_force_N=1000.0,
                                                                 winch_time_constant_s=0.05))
    sim = SurrogateFlightSimulator(cfg, WindField(cfg.wind), surrogate=sw, wing=wing, start="fe")
    _start(sim, path)
    d, dt = cfg.dynamics, cfg.sim.surrogate_dt_s  # the fast fidelity's step
    l_t, v_r = 80.0, 0.0
    for _ in range(40):
        rec = sim.step(sim.L_B0, sim.L_D0)
        l_t += dt * v_r  # the step reels out at the speed set after the previous one
        v_step = v_r
        v_set = min(max((rec.tether_force - d.winch_force_N) / d.winch_damping_Ns_per_m, 0.0), d.winch_speed_max_mps)
        v_r = v_set + (v_r - v_set) * np.exp(-dt / d.winch_time_constant_s)
        assert rec.tether_length == pytest.approx(l_t, abs=1e-12) and rec.reel_speed == pytest.approx(v_r, abs=1e-12)
        assert np.linalg.norm(rec.state.r[4]) == pytest.approx(l_t, abs=1e-9)
    assert rec.tether_length > 80.1 and 1.0 < rec.reel_speed < d.winch_speed_max_mps
    r, v = rec.state.r[4], rec.state.v[4]
    assert r @ v / np.linalg.norm(r) == pytest.approx(v_step, rel=1e-6)  # the KCU moves out at the step's reel speed
    # the default ground station (15 kN) does not reel out at the start of the paper's flight
    default = SurrogateFlightSimulator(cfg0, WindField(cfg0.wind), surrogate=sw, wing=wing, start="fe")
    _start(default, path)
    recs = [default.step(default.L_B0, default.L_D0) for _ in range(40)]
    assert all(r.tether_force < cfg0.dynamics.winch_force_N and r.tether_length == 80.0 for r in recs)


def test_outside_the_envelope_raises(setup):
    """A kite pushed beyond the sampled inputs ends with 'outside surrogate envelope' naming the inputs."""
    cfg, wing, sw, path = setup
    sim = SurrogateFlightSimulator(cfg, WindField(cfg.wind), surrogate=sw, wing=wing)
    _start(sim, path)
    v = sim.kites.v[0]
    v += 200.0 * v.mean(axis=0) / np.linalg.norm(v.mean(axis=0))  # the whole kite suddenly 200 m/s faster along
    with pytest.raises(SimulationError) as err:                 # its flight: an apparent speed beyond any sample
        sim.step(sim.L_B0, sim.L_D0)
    names = err.value.detail.split(", ")
    assert err.value.reason == "outside surrogate envelope" and "v_app_x" in names
    assert set(names) <= set(sw.input_names)
    assert sim.kites.status[0] == OUTSIDE and sim.kites.X[0, 24] < sw.envelope()[0][24]


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


@pytest.mark.parametrize("weights", ["shipped", "odd"])
def test_mlp_rows_is_mlp_row_row_by_row(setup, weights):
    """The engine's block MLP (:func:`mlp_rows`, rows in groups of four, inputs in groups of four) gives each row's
    outputs bit for bit as :func:`mlp_row` on that row alone, for blocks that do not divide the number of rows (the
    last block short; rows left over from the groups of four; work arrays longer than the block), inputs far outside
    the envelope and a NaN input. ``odd``: random layers whose widths are no multiple of 4 (inputs left over)."""
    from kite_env.dynamics.fast import BLOCK, mlp_row, mlp_rows

    cfg, wing, sw, path = setup
    rng = np.random.default_rng(7)
    if weights == "shipped":
        ks = SurrogateKites(cfg, sw, wing.design_bridle, np.ones(2), 1)
        wts = ks._weights
        lo, hi = sw.x_min, sw.x_max
    else:
        sizes = (31, 13, 10, 17)
        wts = tuple(a for n_i, n_o in zip(sizes[:-1], sizes[1:])
                    for a in (rng.normal(0.0, 0.6, (n_i, n_o)).astype(np.float32),
                              rng.normal(0.0, 0.3, n_o).astype(np.float32)))
        lo, hi = -np.ones(31), np.ones(31)
    n_in, n_out = wts[0].shape[0], wts[4].shape[1]
    X = lo + rng.uniform(-0.2, 1.2, (23, n_in)) * (hi - lo)
    X[3] *= 40.0  # saturated units
    X[11, n_in - 1] = np.nan
    h = [np.empty(w.shape[1], dtype=np.float32) for w in wts[::2]]
    ref = np.empty((len(X), n_out))
    for k, x in enumerate(X):
        mlp_row(x, *wts, *h, ref[k])
    assert np.isnan(ref[11]).all() and np.isfinite(np.delete(ref, 11, axis=0)).all()
    for block in sorted({1, 3, 4, 5, 6, BLOCK, 16}):
        hb = [np.empty((block + 2, w.shape[1]), dtype=np.float32) for w in wts[::2]]
        got = np.full((len(X), n_out), -1.0)
        for s in range(0, len(X), block):
            nb = min(block, len(X) - s)
            mlp_rows(X[s:s + nb], nb, *wts, *hb, got[s:s + nb])
        np.testing.assert_array_equal(got, ref, err_msg=f"block {block}")


def _compiled(ks, x):
    """The kernel's wing outputs for one extended input ``x``: the float32 MLP, then the known linear part."""
    from kite_env.dynamics.fast import add_stiffness, mlp_row

    h = [np.empty(w.shape[1], dtype=np.float32) for w in ks._W]
    y = np.empty(17)
    mlp_row(x, *ks._weights, *h, y)
    add_stiffness(x, ks._K_b, y)
    return y


@pytest.mark.parametrize("K_b", ["shipped", "random"])
def test_compiled_mlp_is_the_surrogate(setup, K_b):
    """The compiled float32 MLP with the normalisations folded in, plus the known linear part ``K_b (q_b -
    q_design)``, gives SurrogateWing.predict (float64 NumPy) to float32 round-off: over extended inputs spread across
    the sampled envelope, built as the kernel builds them (the current inputs, then the filters less the filtered
    inputs, :func:`history_inputs`), and at the kite's own inputs along a flight. ``random``: the shipped MLP with
    another K_b (the linear part is applied as given)."""
    from kite_env.dynamics.fast import history_inputs

    cfg, wing, sw, path = setup
    rng = np.random.default_rng(5)
    if K_b == "random":
        sw = dataclasses.replace(sw, K_b=rng.normal(0.0, 2e4, (12, 12)))
    assert np.abs(sw.K_b).max() > 0.0
    ks = SurrogateKites(cfg, sw, wing.design_bridle, np.ones(2), 1)
    sel = np.asarray(sw.filtered)
    n_in, n_sel = len(sw.input_names), len(sel)
    target = sw.x_min + rng.uniform(0.0, 1.0, (200, n_in)) * (sw.x_max - sw.x_min)
    X = np.empty_like(target)
    for i, t in enumerate(target):
        z = t[sel][None, :] + t[30:].reshape(len(sw.taus), n_sel)  # filters whose history inputs are t[30:]
        X[i, :30] = t[:30]
        X[i, 30:] = np.nan
        history_inputs(X[i], z, sel)
    np.testing.assert_allclose(X, target, rtol=0.0, atol=1e-12 * np.abs(target).max())
    ref = sw.predict(X)
    got = np.array([_compiled(ks, x) for x in X])
    scale = np.maximum(np.abs(ref).max(axis=0), sw.y_std)
    assert np.abs(got - ref).max(axis=0).max() > 0.0  # float32: not bit-identical
    np.testing.assert_array_less(np.abs(got - ref) / scale, 2e-5)
    # the linear part is K_b (q_b - q_design), on the forces only
    lin = sw.predict(X) - dataclasses.replace(sw, K_b=np.zeros((12, 12))).predict(X)
    np.testing.assert_allclose(lin[:, :12], X[:, :12] @ sw.K_b.T, rtol=1e-9, atol=1e-6)
    assert np.all(lin[:, 12:] == 0.0)
    # the kernel's outputs along a flight are those of its own inputs (the kite placed by the fast fidelity's start)
    sim = SurrogateFlightSimulator(cfg, WindField(cfg.wind), surrogate=load_default(cfg.kite.name), wing=wing)
    _start(sim, path)
    # 20 steps of the fitted tapes' 5 ms: with the random K_b the wing is not the fitted one and leaves the envelope
    # later, so the comparison stays at states of the sampled size (float32 round-off grows with the inputs)
    ks = SurrogateKites(cfg, sw, wing.design_bridle, sim.tip_lengths, 1, dt=cfg.dynamics.dt_s)
    ks.set_wind(0, sim.wind)
    ks.set_kite(0, sim.state.r, sim.state.v, sim.t, sim.pair_stiffness, sim.L_B0, sim.L_D0)
    ks.evaluate()
    for _ in range(20):
        ks.step(np.array([sim.L_B0 - 0.03]), np.array([sim.L_D0 + 0.03]))
        assert np.all(np.isfinite(ks.X[0])) and np.all(np.isfinite(ks.Y[0]))
        np.testing.assert_array_less(np.abs(ks.Y[0] - sw.predict(ks.X[0])) / scale, 2e-5)


def _with_model(tmp_path, sw, record, name="other.npz"):
    meta = {k: v for k, v in sw.meta.items() if k != "model"}
    if record is not None:
        meta["model"] = record
    return dataclasses.replace(sw, meta=meta).save(tmp_path / name)


def test_a_wing_fitted_to_another_model_is_refused(setup, tmp_path):
    """surrogate_for (and make_simulator, the env's constructor of the fast fidelity) loads the reduced-order wing
    of the configured model and refuses one fitted to another model with ModelMismatch naming the keys that differ,
    and one that records no model; the shipped wing is the default model's (the task, wind and run length are not
    the model)."""
    cfg, wing, sw, path = setup
    got, p = surrogate_for(load_config(None, ["sim.fidelity=surrogate", "wind.speed_mps=8", "env.max_episode_s=5",
                                              "wind.turbulence_intensity=0.1"]))
    assert p == default_surrogate_path(cfg.kite.name) and got.meta["model"] == fingerprint(cfg)
    # the shipped wing for the paper's model (the quasi-static wing) is refused, naming what differs
    paper = load_config(PAPER, ["sim.fidelity=surrogate"])
    with pytest.raises(ModelMismatch, match=r"'default'.*not this one 'paper'.*structure\.dynamic \(True there, False "
                                            r"here\)"):
        surrogate_for(paper)
    # a wing fitted to a model with another ground station, asked for the default model
    other = load_config(None, ["dynamics.winch_force_N=10000"])
    fitted = _with_model(tmp_path, sw, fingerprint(other))
    cfg_s = load_config(None, ["sim.fidelity=surrogate", f"sim.surrogate_path={fitted}"])
    for make in (lambda: surrogate_for(cfg_s), lambda: make_simulator(cfg_s, WindField(cfg_s.wind))):
        with pytest.raises(ModelMismatch) as err:
            make()
        msg = str(err.value)
        assert str(fitted) in msg and "1 key(s) differ: dynamics.winch_force_N (10000.0 there, 15000.0 here)" in msg
        assert isinstance(err.value, ConfigError)
    # the same file is the wing of that model
    assert surrogate_for(load_config(None, ["dynamics.winch_force_N=10000", f"sim.surrogate_path={fitted}"]))[1] \
        == fitted
    # a wing that records no model
    bare = _with_model(tmp_path, sw, None, "bare.npz")
    cfg_b = load_config(None, ["sim.fidelity=surrogate", f"sim.surrogate_path={bare}"])
    for make in (lambda: surrogate_for(cfg_b), lambda: make_simulator(cfg_b, WindField(cfg_b.wind))):
        with pytest.raises(ModelMismatch, match="records no model"):
            make()


@pytest.mark.slow  # 15 s of the full model: ~20-40 s
def test_the_fast_fidelity_agrees_with_the_full_model_over_a_turbulent_flight():
    """The paper's controller 15 s at 8 m/s with turbulence 0.1 (the same realisation) in both fidelities: the mean
    traction within 3 % and the tracking error within 1 deg (kite_env.fitting.agreement's targets; the README's
    agreement table has the long flights, where 4-5 m/s do not hold)."""
    from kite_env.fitting.agreement import TRACKING_DEG, TRACTION_REL, fly_case

    base = ["wind.speed_mps=8.0", "wind.turbulence_intensity=0.1", "wind.seed=0"]
    full = fly_case((base, 15.0))
    fast = fly_case((["sim.fidelity=surrogate", *base], 15.0))
    assert full["end"] == fast["end"] == "completed"
    assert abs(fast["traction_mean_N"] / full["traction_mean_N"] - 1.0) < TRACTION_REL
    assert abs(fast["tracking_rms_deg"] - full["tracking_rms_deg"]) < TRACKING_DEG


def test_the_agreement_reads_back_its_full_model_results(tmp_path):
    """kite-fit agreement keeps the full model's flights (``OUT/fe``) and reads them back on the next comparison: a
    result kept for this model is returned without flying (its record holds the retired keys at their one value),
    one kept for another model is refused naming the key."""
    import json

    from kite_env.fitting.agreement import _cached

    model = fingerprint(load_config(None, []))
    assert _cached(tmp_path, "flight", model, lambda: {"traction": 1.0}) == {"traction": 1.0}
    assert _cached(tmp_path, "flight", model, lambda: pytest.fail("flown again")) == {"traction": 1.0}
    other = fingerprint(load_config(None, ["wind.speed_mps=4.0", "kite.n_sections=25"]))
    (tmp_path / "other.json").write_text(json.dumps({"model": other, "result": {}}))
    with pytest.raises(ModelMismatch, match="kite.n_sections"):
        _cached(tmp_path, "other", model, lambda: pytest.fail("flown"))
