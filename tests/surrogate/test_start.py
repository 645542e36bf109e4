"""Start table of the reduced-order wing: the full model's reset start, tabulated over (s, w) and interpolated, for
the default model (the wing with inertia); a table of another model is refused; the shipped files."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kite_env.config import Config, ModelMismatch, fingerprint, load_config
from kite_env.dynamics import start_table as start
from kite_env.dynamics.fast import SurrogateFlightSimulator, _default_start_table
from kite_env.dynamics.simulator import SimulationError
from kite_env.dynamics.start_table import build_start_table
from kite_env.fsi import nominal_wing
from kite_env.surrogate import DATA_DIR, default_surrogate_path, load_default
from kite_env.surrogate.start import StartTable
from kite_env.wind import WindConfig, WindField

#: a 2 x 2 grid around the default flight's start (22 m/s along the path at the crossing in 5 m/s of wind:
#: s ~ 22 m/s, w ~ -4 m/s); each point is a cold FE solve of the default model's wing
S_GRID, W_GRID = (22.0, 30.0), (-7.0, -4.0)


@pytest.fixture(scope="module")
def table():
    return build_start_table(Config(), S_GRID, W_GRID)


class _Uniform:
    def __init__(self, v):
        self.v = np.asarray(v, float)

    def velocity(self, t, r):
        return np.tile(self.v, (len(np.atleast_2d(r)), 1))


def _crossing_start(s, w):
    """``(wind, R0, e_t, speed)`` of a reset whose start has tangential apparent speed ``s`` and normal apparent
    velocity ``w`` (kite at 30 deg elevation flying horizontally across a uniform wind along x)."""
    el = np.radians(30.0)
    R0 = np.array([np.cos(el), 0.0, np.sin(el)])
    V = -w / np.cos(el)  # w = -v_wind . R0 = -V cos(el)
    tang = V * np.sin(el)  # |tangential part of the wind|, perpendicular to the flight direction e_t = y
    wind = WindField(WindConfig(speed_mps=V, profile="uniform", turbulence_intensity=0.0))
    return wind, R0, np.array([0.0, 1.0, 0.0]), float(np.sqrt(s**2 - tang**2))


@pytest.mark.slow
def test_grid_node_is_the_reset_of_the_full_model(table):
    """The fast fidelity's reset from the table at a grid node (s = 22 m/s, w = -4 m/s) places the kite as its reset
    with the FE start does (the full model's start: the static wing held by its lines), without an FE solve; the
    lookup at the node returns the stored full-model result exactly. The wing with inertia has no tip dampers: its
    tip-pair stiffness is zero."""
    cfg = Config()
    assert table.converged.all() and table.meta["n_failed"] == 0
    assert table.meta["model"] == fingerprint(cfg) and table.meta["kite"] == cfg.kite.name
    assert np.all(table.k_pairs == 0.0)
    q0, F_b, k = table.lookup(np.array([-22.0, 0.0, -4.0]))
    np.testing.assert_array_equal(q0, table.q0[0, 1])
    np.testing.assert_allclose(F_b, table.F_b[0, 1], rtol=1e-13)
    np.testing.assert_array_equal(k, table.k_pairs[0, 1])
    # the loaded wing pulls towards the KCU (-z_k) and is symmetric (no sideslip)
    F = F_b.sum(axis=0)
    assert F[2] < -1000.0 and abs(F[1]) < 1e-3 * abs(F[2])
    wind, R0, e_t, speed = _crossing_start(22.0, -4.0)
    sw = load_default(cfg.kite.name)
    fe = SurrogateFlightSimulator(cfg, wind, surrogate=sw, wing=nominal_wing(cfg.kite.name, cfg), start="fe")
    tab = SurrogateFlightSimulator(cfg, wind, surrogate=sw, wing=nominal_wing(cfg.kite.name, cfg), start="table",
                                   start_table=table)
    fe.reset(R0, e_t, speed_mps=speed)
    tab.reset(R0, e_t, speed_mps=speed)
    assert (fe.fe_starts, tab.fe_starts) == (1, 0)
    np.testing.assert_allclose(tab.state.r, fe.state.r, rtol=0.0, atol=1e-6)
    np.testing.assert_array_equal(tab.state.v, fe.state.v)
    assert tab.L_B0 == pytest.approx(fe.L_B0, abs=1e-6) and tab.L_D0 == pytest.approx(fe.L_D0, abs=1e-6)
    assert np.all(tab.pair_stiffness == 0.0) and np.all(fe.pair_stiffness == 0.0)


def test_midway_is_between_the_nodes(table):
    s, w = 0.5 * (S_GRID[0] + S_GRID[1]), 0.5 * (W_GRID[0] + W_GRID[1])
    q0, F_b, k = table.lookup(np.array([-s, 0.0, w]))
    # the centre of a bilinear cell is the mean of its corners (forces: of the force over s^2 + w^2)
    np.testing.assert_allclose(q0, table.q0.mean(axis=(0, 1)), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(k, table.k_pairs.mean(axis=(0, 1)), rtol=1e-12, atol=1e-12)
    q2 = np.add.outer(np.square(S_GRID), np.square(W_GRID))
    scaled = (table.F_b / q2[:, :, None, None]).mean(axis=(0, 1))
    np.testing.assert_allclose(F_b, scaled * (s**2 + w**2), rtol=1e-12)
    lo, hi = table.F_b.sum(axis=2).min(axis=(0, 1)), table.F_b.sum(axis=2).max(axis=(0, 1))
    assert np.all(F_b.sum(axis=0) >= lo - 1e-9) and np.all(F_b.sum(axis=0) <= hi + 1e-9)


def test_outside_the_grid_or_sideslip_is_refused(table):
    for v in ([-21.5, 0.0, -5.0], [-30.5, 0.0, -5.0], [-26.0, 0.0, -3.0], [-26.0, 0.0, -7.5]):
        with pytest.raises(ValueError, match=r"outside the tabulated range \(s in \[22, 30\] m/s, w in \[-7, -4\]"):
            table.lookup(np.array(v))
    with pytest.raises(ValueError, match="sideways"):
        table.lookup(np.array([-26.0, 0.5, -5.0]))


def _fake(cfg, s, w):
    """An analytic 'full model': q0 and k linear in (s, w), forces proportional to s^2 + w^2."""
    if (s, w) == (30.0, 0.0):
        raise SimulationError("wing did not converge at the initial state", "fake")
    q0 = np.arange(12.0).reshape(4, 3) + 0.01 * s - 0.02 * w
    F_b = np.linspace(-3.0, 2.0, 12).reshape(4, 3) * (s**2 + w**2)
    return q0, F_b, np.array([1.0, 2.0, 3.0, 4.0]) * s + w


def test_non_converged_points_are_nan_and_refused_near_them(monkeypatch, tmp_path):
    monkeypatch.setattr(start, "start_state", _fake)
    t = build_start_table(Config(), [10.0, 20.0, 30.0], [-10.0, -5.0, 0.0])
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
    # save / load keeps the table, its provenance and its model
    t2 = StartTable.load(t.save(tmp_path / "start.npz"))
    np.testing.assert_array_equal(t2.F_b, t.F_b)
    assert t2.meta["kite"] == "rhino16" and t2.meta["failed"] == t.meta["failed"] and t2.meta["s_mps"][0] == 10.0
    assert t2.meta["model"] == fingerprint(Config())
    with pytest.raises(FileNotFoundError):
        StartTable.load(tmp_path / "missing.npz")
    np.savez(tmp_path / "other.npz", a=np.ones(2))
    with pytest.raises(ValueError, match="not a start table"):
        StartTable.load(tmp_path / "other.npz")


def test_a_start_table_of_another_model_is_refused(monkeypatch, tmp_path):
    """The start table next to a reduced-order wing (``<stem>_start.npz``) is checked against the configured model
    as the wing is: one built with another model raises ModelMismatch naming the keys that differ (also when the
    fast simulator is built), one that records no model is refused, one of this model is used; without a table the
    start is the FE solve."""
    monkeypatch.setattr(start, "start_state", _fake)
    cfg = Config()
    weights = load_default(cfg.kite.name).save(tmp_path / "wing.npz")
    assert _default_start_table(cfg, weights) is None  # no table next to the wing
    wind = _Uniform([5.0, 0.0, 0.0])
    cfg_w = load_config(None, [f"sim.surrogate_path={weights}"])  # (sim is not the model)
    assert SurrogateFlightSimulator(cfg_w, wind).start_mode == "fe"
    other = load_config(None, ["aero.canopy_luffing=false"])
    build_start_table(other, [10.0, 20.0], [-10.0, -5.0]).save(tmp_path / "wing_start.npz")
    for make in (lambda: _default_start_table(cfg, weights),
                 lambda: SurrogateFlightSimulator(cfg_w, wind)):
        with pytest.raises(ModelMismatch, match=r"start table '.*wing_start.npz'.*1 key\(s\) differ: "
                                                r"aero\.canopy_luffing \(False there, True here\)"):
            make()
    t = _default_start_table(other, weights)  # the table of that model
    assert t.meta["model"] == fingerprint(other)
    bare = build_start_table(cfg, [10.0, 20.0], [-10.0, -5.0])
    dataclasses.replace(bare, meta={k: v for k, v in bare.meta.items() if k != "model"}).save(
        tmp_path / "wing_start.npz")
    with pytest.raises(ModelMismatch, match="records no model"):
        _default_start_table(cfg, weights)
    bare.save(tmp_path / "wing_start.npz")
    mine = _default_start_table(cfg, weights)
    np.testing.assert_array_equal(mine.F_b, bare.F_b)
    sim = SurrogateFlightSimulator(cfg_w, wind)
    assert sim.start_mode == "table" and sim.start_table.meta["model"] == fingerprint(cfg)


#: the files shipped with the package (the reduced-order wing of each kite and, once made, its start table)
SHIPPED = sorted(DATA_DIR.glob("*.npz"))


def test_the_default_kite_ships_a_reduced_order_wing_and_no_other_file():
    """The default kite's wing ships; every shipped file is a kite's wing or that wing's start table; the data are
    small; an unknown kite gets a clear FileNotFoundError."""
    assert default_surrogate_path(Config().kite.name) in SHIPPED
    stems = {p.stem for p in SHIPPED}
    for p in SHIPPED:
        assert not p.stem.endswith("_start") or p.stem[:-len("_start")] in stems, p.name  # a table has its wing
    assert sum(p.stat().st_size for p in SHIPPED) < 1_000_000
    with pytest.raises(FileNotFoundError, match="no shipped reduced-order wing weights for kite 'nokite'"):
        load_default("nokite")


@pytest.mark.parametrize("path", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_file(path):
    """A shipped wing: float32 weights, the model it was fitted to (a named preset, and this project's model of that
    name: the wing loads for it), its kite, the latent state of the wing with inertia and held-out errors. A shipped
    start table: the model of its wing, and it covers the default flight's start (the paper's 5 m/s, 22 m/s at the
    crossing): the fast fidelity's reset there needs no FE solve."""
    from kite_env.config import check_model, preset_config
    from kite_env.surrogate.model import SurrogateWing
    from kite_env.trajectory import Lemniscate

    if not path.stem.endswith("_start"):
        with np.load(path) as z:
            assert z["W0"].dtype == np.float32
        m = SurrogateWing.load(path)
        meta = m.meta
        model = preset_config(meta["model"]["preset"])
        check_model(meta["model"], model, str(path))
        assert meta["kite"] == path.stem == model.kite.name and meta["n_sections"] == model.kite.n_sections
        assert meta["command"].startswith("kite-fit fit") and meta["git_commit"]
        assert m.inertial == model.structure.dynamic and (not m.inertial or m.taus)
        err = meta["held_out"]["force_rms_rel_traction"]
        assert np.isfinite(err) and err > 0.0 and meta["held_out"]["n_val"] > 0
        return
    t = StartTable.load(path)
    wing = SurrogateWing.load(path.with_name(path.stem[:-len("_start")] + ".npz"))
    assert t.meta["model"] == wing.meta["model"] and t.meta["kite"] == wing.meta["kite"]
    cfg = preset_config(t.meta["model"]["preset"])
    path_ = Lemniscate(cfg.trajectory)
    sim = SurrogateFlightSimulator(cfg, WindField(cfg.wind))
    sim.reset(path_.point(0.0), path_.tangent(0.0), cfg.start_speed_mps)
    assert sim.start_mode == "table" and sim.fe_starts == 0


def test_table_only_start_fails_where_the_table_has_no_cell_and_the_env_redraws(table, tmp_path):
    """With ``sim.surrogate_start: table_only`` a start outside the table raises "no tabulated start" (no FE solve),
    and the environment's reset draws another start until one is tabulated (the table next to the wing given by
    ``sim.surrogate_path``)."""
    from kite_env.envs.figure_eight import KiteFigureEightEnv

    cfg = Config()
    wind, R0, e_t, _ = _crossing_start(26.0, -5.0)
    sim = SurrogateFlightSimulator(cfg, wind, start="table_only", start_table=table)
    with pytest.raises(SimulationError, match="no tabulated start"):
        sim.reset(R0, e_t, speed_mps=36.0)  # s ~ 36 m/s: beyond the 22-30 m/s grid
    assert sim.fe_starts == 0
    weights = load_default(cfg.kite.name).save(tmp_path / "wing.npz")
    table.save(tmp_path / "wing_start.npz")
    over = ["sim.surrogate_start=table_only", f"sim.surrogate_path={weights}", "env.random_start=true",
            "env.wind_speed_min_mps=5", "env.wind_speed_max_mps=9", "env.initial_speed_min_mps=18",
            "env.initial_speed_max_mps=34", "env.reset_attempts=200"]
    env = KiteFigureEightEnv(overrides=over, fidelity="surrogate")
    speeds = []
    for seed in range(6):
        _, info = env.reset(seed=seed)
        speeds.append(info["initial_speed_mps"])
    assert env.sim.start_table.meta["model"] == fingerprint(cfg) and env.sim.fe_starts == 0
    assert len(set(speeds)) == 6
