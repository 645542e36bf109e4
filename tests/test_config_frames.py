from pathlib import Path

import numpy as np
import pytest
import yaml

from kite_env.config import Config, ConfigError, config_from_dict, load_config
from kite_env.frames import from_frame, kite_frame, to_frame

CONFIGS = sorted((Path(__file__).parents[1] / "configs").glob("**/*.yaml"))


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
