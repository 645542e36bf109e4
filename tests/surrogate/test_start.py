"""Start table of the reduced-order wing: the full model's reset start, tabulated over (s, w) and interpolated."""

from __future__ import annotations

import numpy as np
import pytest

from kite_env.config import load_config
from kite_env.dynamics.simulator import FlightSimulator, SimulationError
from kite_env.surrogate import start
from kite_env.surrogate.start import StartTable, build_start_table

from conftest import LEGACY_CONFIG  # noqa: E402

#: the model the shipped reduced-order wing and its start table were built on (configs/legacy_v0.yaml)
LEGACY = load_config(LEGACY_CONFIG)

S_GRID, W_GRID = (20.0, 22.0), (-6.0, -4.0)


@pytest.fixture(scope="module")
def table():
    return build_start_table(LEGACY, S_GRID, W_GRID)


class _Uniform:
    def __init__(self, v):
        self.v = np.asarray(v, float)

    def velocity(self, t, r):
        return np.tile(self.v, (len(np.atleast_2d(r)), 1))


def test_grid_node_is_the_reset_of_the_full_model(table):
    """A flight simulator reset whose start has s = 22 m/s, w = -4 m/s (kite at 30 deg elevation, flying
    horizontally across a uniform wind along x) gives the tabulated tip-pair stiffness, and the lookup at that node
    returns the stored full-model result exactly."""
    assert table.converged.all() and table.meta["n_failed"] == 0
    el = np.radians(30.0)
    R0 = np.array([np.cos(el), 0.0, np.sin(el)])
    V = 4.0 / np.cos(el)  # w = -v_wind . R0 = -V cos(el)
    tang = V * np.sin(el)  # |tangential part of the wind|, perpendicular to the flight direction e_t = y
    speed = np.sqrt(22.0**2 - tang**2)  # s = |v0 - tangential wind|
    sim = FlightSimulator(LEGACY, _Uniform([V, 0.0, 0.0]))
    sim.reset(R0, np.array([0.0, 1.0, 0.0]), speed_mps=speed)
    q0, F_b, k = table.lookup(np.array([-22.0, 0.0, -4.0]))
    np.testing.assert_allclose(k, sim.pair_stiffness, rtol=1e-6)
    np.testing.assert_array_equal(q0, table.q0[1, 1])
    np.testing.assert_allclose(F_b, table.F_b[1, 1], rtol=1e-13)
    np.testing.assert_array_equal(k, table.k_pairs[1, 1])
    # the loaded wing pulls towards the KCU (-z_k) and is symmetric (no sideslip)
    F = F_b.sum(axis=0)
    assert F[2] < -1000.0 and abs(F[1]) < 1e-3 * abs(F[2])


def test_midway_is_between_the_nodes(table):
    q0, F_b, k = table.lookup(np.array([-21.0, 0.0, -5.0]))
    # the centre of a bilinear cell is the mean of its corners (forces: of the force over s^2 + w^2)
    np.testing.assert_allclose(q0, table.q0.mean(axis=(0, 1)), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(k, table.k_pairs.mean(axis=(0, 1)), rtol=1e-12)
    q2 = np.add.outer(np.square(S_GRID), np.square(W_GRID))
    scaled = (table.F_b / q2[:, :, None, None]).mean(axis=(0, 1))
    np.testing.assert_allclose(F_b, scaled * (21.0**2 + 5.0**2), rtol=1e-12)
    lo, hi = table.F_b.sum(axis=2).min(axis=(0, 1)), table.F_b.sum(axis=2).max(axis=(0, 1))
    assert np.all(F_b.sum(axis=0) >= lo - 1e-9) and np.all(F_b.sum(axis=0) <= hi + 1e-9)


def test_outside_the_grid_or_sideslip_is_refused(table):
    for v in ([-19.5, 0.0, -5.0], [-22.5, 0.0, -5.0], [-21.0, 0.0, -3.0], [-21.0, 0.0, -6.5]):
        with pytest.raises(ValueError, match=r"outside the tabulated range \(s in \[20, 22\] m/s, w in \[-6, -4\]"):
            table.lookup(np.array(v))
    with pytest.raises(ValueError, match="sideways"):
        table.lookup(np.array([-21.0, 0.5, -5.0]))


def _fake(cfg, s, w):
    """An analytic 'full model': q0 and k linear in (s, w), forces proportional to s^2 + w^2."""
    if (s, w) == (30.0, 0.0):
        raise SimulationError("wing did not converge at the initial state", "fake")
    q0 = np.arange(12.0).reshape(4, 3) + 0.01 * s - 0.02 * w
    F_b = np.linspace(-3.0, 2.0, 12).reshape(4, 3) * (s**2 + w**2)
    return q0, F_b, np.array([1.0, 2.0, 3.0, 4.0]) * s + w


def test_non_converged_points_are_nan_and_refused_near_them(monkeypatch, tmp_path):
    monkeypatch.setattr(start, "start_state", _fake)
    t = build_start_table(LEGACY, [10.0, 20.0, 30.0], [-10.0, -5.0, 0.0])
    assert t.meta["n_failed"] == 1 and t.meta["failed"][0]["s"] == 30.0 and t.meta["failed"][0]["w"] == 0.0
    assert np.isnan(t.q0[2, 2]).all() and t.converged.sum() == 8
    # bilinear interpolation is exact for these functions anywhere in the converged cells
    for s, w in ((12.5, -7.0), (20.0, -2.0), (27.0, -9.0), (10.0, -10.0)):
        q0, F_b, k = t.lookup(np.array([-s, 0.0, w]))
        q_ref, F_ref, k_ref = _fake(None, s, w)
        np.testing.assert_allclose(q0, q_ref, rtol=1e-12)
        np.testing.assert_allclose(F_b, F_ref, rtol=1e-12)
        np.testing.assert_allclose(k, k_ref, rtol=1e-12)
    # the node next to the failed one is usable; the cell with the failed corner is not
    assert np.isfinite(t.lookup(np.array([-30.0, 0.0, -5.0]))[1]).all()
    with pytest.raises(ValueError, match=r"s = 25.000 m/s, w = -2.000 m/s .*\(30.0, 0.0\).*did not converge"):
        t.lookup(np.array([-25.0, 0.0, -2.0]))
    # save / load keeps the table and its provenance
    t2 = StartTable.load(t.save(tmp_path / "start.npz"))
    np.testing.assert_array_equal(t2.F_b, t.F_b)
    assert t2.meta["kite"] == "rhino16" and t2.meta["failed"] == t.meta["failed"] and t2.meta["s_mps"][0] == 10.0
    with pytest.raises(FileNotFoundError):
        StartTable.load(tmp_path / "missing.npz")
    np.savez(tmp_path / "other.npz", a=np.ones(2))
    with pytest.raises(ValueError, match="not a start table"):
        StartTable.load(tmp_path / "other.npz")


def test_shipped_files_of_rhino16():
    """The package ships the reduced-order wing of the default kite: small, float32 weights, provenance and held-out
    errors meeting the requirement (bridle-force RMS < 3 % of the mean traction), a start table covering the
    reset's usual starts; an unknown kite gets a clear FileNotFoundError."""
    from kite_env.surrogate import DATA_DIR, default_surrogate_path, load_default, load_default_start

    path = default_surrogate_path("rhino16")
    assert path.parent == DATA_DIR and sum(p.stat().st_size for p in DATA_DIR.glob("*.npz")) < 1_000_000
    with np.load(path) as z:
        assert z["W0"].dtype == np.float32
    m = load_default("rhino16")
    meta = m.meta
    assert meta["kite"] == "rhino16" and meta["n_dof"] == 1332 and meta["n_sections"] == 37
    assert meta["samples"]["git_commit"] and meta["samples"]["n_samples"] > 10_000
    assert meta["build_command"].startswith("python scripts/build_surrogate.py")
    assert meta["heldout_errors"]["force_rms_rel_traction"] < 0.03
    t = load_default_start("rhino16")
    assert t.meta["kite"] == "rhino16" and t.meta["build_command"] == meta["build_command"]
    q0, F_b, k = t.lookup(np.array([-22.0, 0.0, -6.0]))
    assert np.all(np.isfinite(q0)) and F_b.sum(axis=0)[2] < 0
    with pytest.raises(FileNotFoundError, match="no shipped reduced-order wing weights for kite 'nokite'"):
        load_default("nokite")


def test_table_only_start_fails_where_the_table_has_no_cell_and_the_env_redraws(table):
    """With ``sim.surrogate_start: table_only`` a start outside the table raises "no tabulated start" (no FE solve),
    and the environment's reset draws another start until one is tabulated."""
    from kite_env.dynamics.fast import SurrogateFlightSimulator
    from kite_env.envs.figure_eight import KiteFigureEightEnv

    el = np.radians(30.0)
    R0 = np.array([np.cos(el), 0.0, np.sin(el)])
    sim = SurrogateFlightSimulator(LEGACY, _Uniform([4.0 / np.cos(el), 0.0, 0.0]), start="table_only",
                                   start_table=table)
    with pytest.raises(SimulationError, match="no tabulated start"):
        sim.reset(R0, np.array([0.0, 1.0, 0.0]), speed_mps=30.0)  # s ~ 30 m/s: beyond the 20-22 m/s grid
    assert sim.fe_starts == 0
    over = ["sim.surrogate_start=table_only", "env.random_start=true", "env.wind_speed_min_mps=4",
            "env.wind_speed_max_mps=10", "env.initial_speed_min_mps=10", "env.initial_speed_max_mps=40",
            "env.reset_attempts=200"]
    env = KiteFigureEightEnv(overrides=over, fidelity="surrogate")
    speeds = []
    for seed in range(6):
        _, info = env.reset(seed=seed)
        speeds.append(info["initial_speed_mps"])
    assert env.sim.fe_starts == 0
    assert len(set(speeds)) == 6
