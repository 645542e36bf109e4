from pathlib import Path

import numpy as np
import pytest
import yaml

from kite_env.config import Config, ConfigError, config_from_dict, load_config
from kite_env.frames import from_frame, kite_frame, to_frame

CONFIGS = sorted((Path(__file__).parents[1] / "configs").glob("*.yaml"))  # configs/agents/: tests/test_train_cli.py


def test_default_yaml_matches_dataclass_defaults():
    data = yaml.safe_load((Path(__file__).parents[1] / "configs" / "default.yaml").read_text())
    assert config_from_dict(data) == Config()
    assert set(data) == set(Config().to_dict())
    for sec, vals in Config().to_dict().items():
        assert set(data[sec]) == set(vals), sec


@pytest.mark.parametrize("path", CONFIGS, ids=[p.name for p in CONFIGS])
def test_every_config_file_loads(path):
    assert isinstance(load_config(path), Config)


def test_overrides_and_errors(tmp_path):
    cfg = load_config(overrides=["fsi.tol_disp_m=2e-4", "kite.name=v3", "structure.wrinkling=false"])
    assert cfg.fsi.tol_disp_m == 2e-4 and cfg.kite.name == "v3" and cfg.structure.wrinkling is False
    with pytest.raises(ConfigError, match="unknown config key 'fsi.nope'"):
        load_config(overrides=["fsi.nope=1"])
    with pytest.raises(ConfigError, match="unknown config section 'wing'"):
        load_config(overrides=["wing.x=1"])
    with pytest.raises(ConfigError, match="'structure.canopy_E_Pa' expects a number"):
        load_config(overrides=["structure.canopy_E_Pa=abc"])
    with pytest.raises(ConfigError, match="'structure.tube_pressure_Pa' must be positive"):
        load_config(overrides=["structure.tube_pressure_Pa=-1"])
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match="section.key=value"):
        load_config(overrides=["fsi"])
    assert load_config(overrides=["aero.cm_regression_ref_over_c=0"]).aero.cm_regression_ref_over_c == 0.0
    with pytest.raises(ConfigError, match="'aero.cm_regression_ref_over_c' must lie in"):
        load_config(overrides=["aero.cm_regression_ref_over_c=1.5"])
    assert load_config(overrides=["structure.tube_fold_onset_deg=0"]).structure.tube_fold_onset_deg == 0.0
    # the wing with inertia (the default) spreads part of the wing mass over its nodes: all on A-D leaves them massless
    with pytest.raises(ConfigError, match="wing_point_mass_share"):
        load_config(overrides=["dynamics.wing_point_mass_share=1"])
    assert load_config(overrides=["dynamics.wing_point_mass_share=1", "structure.dynamic=false"])
    for bad in ("180", "-5"):
        with pytest.raises(ConfigError, match="'structure.tube_fold_onset_deg' must lie in"):
            load_config(overrides=[f"structure.tube_fold_onset_deg={bad}"])
    assert load_config(overrides=["structure.membrane_kinematics=von_karman"]).structure.membrane_kinematics \
        == "von_karman"
    with pytest.raises(ConfigError, match="membrane_kinematics"):
        load_config(overrides=["structure.membrane_kinematics=foppl"])
    with pytest.raises(ConfigError, match="green_lagrange"):
        load_config(overrides=["structure.membrane_kinematics=von_karman", "structure.membrane_forces=energy_consistent"])


def test_kite_frame_orthonormal_right_handed_and_definition():
    rng = np.random.default_rng(3)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    # points in K: A right front, C left front, B/D rear
    pk = np.array([[0.0, 2.9, 0.0], [0.6, 2.8, 0.05], [0.0, -2.9, 0.0], [0.6, -2.8, -0.05]])
    shift = rng.normal(size=3)
    pw = pk @ Q.T + shift
    origin, R = kite_frame(*pw)
    assert np.allclose(origin, shift)
    assert np.allclose(R.T @ R, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(R, Q)  # recovers the rotation that placed the kite
    v = rng.normal(size=3)
    assert np.allclose(from_frame(to_frame(v, R), R), v)


def test_kite_frame_rates_match_finite_differences():
    from kite_env.frames import kite_frame, kite_frame_rates
    from kite_env.structure.rotations import expm, logm

    rng = np.random.default_rng(7)
    pos = np.array([[0.0, 2.6, 0.0], [0.6, 2.5, 0.1], [0.0, -2.6, 0.0], [0.6, -2.5, -0.1]]) + 0.05 * rng.normal(
        size=(4, 3))
    vel = 3.0 * rng.normal(size=(4, 3))
    o, R, v_k, omega = kite_frame_rates(pos, vel)
    h = 1e-6
    o2, R2 = kite_frame(*(pos + h * vel))
    o1, R1 = kite_frame(*(pos - h * vel))
    np.testing.assert_allclose(v_k, (o2 - o1) / (2 * h), atol=1e-7)
    # dR/dt = skew(omega) R
    np.testing.assert_allclose(logm(R2 @ R1.T) / (2 * h), omega, atol=1e-6)
    # a rigid rotation of the four points with omega0 gives omega0
    omega0 = np.array([0.3, -1.2, 0.7])
    vel_rigid = np.cross(omega0, pos - o) + np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(kite_frame_rates(pos, vel_rigid)[3], omega0, atol=1e-12)
    assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) > 0 and np.allclose(expm(np.zeros(3)), np.eye(3))


def test_kite_frame_rates_in_floats_equal_the_array_formulas():
    """The plain-float implementation used per time step gives the array implementation's frame and rates."""
    from kite_env.frames import _kite_frame_rates_arrays, kite_frame_rates

    rng = np.random.default_rng(5)
    base = np.array([[0.5, 4.0, 0.0], [1.5, 3.9, 0.2], [0.5, -4.0, 0.0], [1.5, -3.9, 0.1]])
    for _ in range(50):
        pos = base + 0.3 * rng.normal(size=(4, 3))
        vel = 10.0 * rng.normal(size=(4, 3))
        for a, b in zip(kite_frame_rates(pos, vel), _kite_frame_rates_arrays(pos, vel)):
            np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-12)
    with pytest.raises(ValueError, match=r"\(4, 3\)"):
        kite_frame_rates(base[:3], base[:3])


def test_agent_recipes_pin_the_legacy_model_the_fast_fidelity_was_fitted_to():
    """configs/agents/*.yaml fly the fast fidelity on configs/legacy_v0.yaml's model: every key of that file is
    pinned by each recipe's env entry, with the same value."""
    import yaml

    from kite_env.cli.train import FAST_ENV_ID, load_hyperparameters

    root = Path(__file__).resolve().parents[1] / "configs"
    legacy = yaml.safe_load((root / "legacy_v0.yaml").read_text())
    flat = {f"{sec}.{k}": v for sec, vals in legacy.items() for k, v in vals.items() if k != "induced_drag"}
    for algo in ("ppo", "sac"):
        env = load_hyperparameters(root / "agents" / f"{algo}.yaml", algo, FAST_ENV_ID)["env"]
        assert {k: env[k] for k in flat} == flat


def test_start_speed_can_follow_the_wind():
    from kite_env.config import load_config

    assert load_config(None, []).start_speed_mps == 22.0  # 4.4 times the paper's 5 m/s
    assert load_config(None, ["wind.speed_mps=7"]).start_speed_mps == pytest.approx(30.8)
    assert load_config(None, ["wind.speed_mps=10"]).start_speed_mps == pytest.approx(44.0)
    # a speed set in m/s wins over the multiple of the wind
    assert load_config(None, ["wind.speed_mps=10", "sim.initial_speed_mps=22"]).start_speed_mps == 22.0
    with pytest.raises(ConfigError, match="sim.initial_speed_per_wind"):
        load_config(None, ["sim.initial_speed_per_wind=-1"])
    with pytest.raises(ConfigError, match="both 0"):
        load_config(None, ["sim.initial_speed_per_wind=0"])
