from pathlib import Path

import numpy as np
import pytest
import yaml

from kite_env.config import Config, ConfigError, config_from_dict, load_config
from kite_env.frames import from_frame, kite_frame, to_frame

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = sorted((ROOT / "configs").glob("*.yaml"))  # the training recipes (agents/recipes): tests/test_train_cli.py


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
        load_config(overrides=["structure.membrane_kinematics=von_karman",
                               "structure.membrane_forces=energy_consistent"])


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


def test_default_yaml_lists_the_turbulence_range():
    """configs/default.yaml lists env.turbulence_intensity_min (with its max: the range drawn per episode); a range
    whose min exceeds its max is refused."""
    data = yaml.safe_load((ROOT / "configs" / "default.yaml").read_text())
    assert data["env"]["turbulence_intensity_min"] == Config().env.turbulence_intensity_min == 0.0
    assert data["env"]["turbulence_intensity_max"] == Config().env.turbulence_intensity_max
    cfg = load_config(None, ["env.turbulence_intensity_min=0.05", "env.turbulence_intensity_max=0.1"])
    assert (cfg.env.turbulence_intensity_min, cfg.env.turbulence_intensity_max) == (0.05, 0.1)
    with pytest.raises(ConfigError,
                       match="'env.turbulence_intensity_min' must not exceed 'env.turbulence_intensity_max'"):
        load_config(None, ["env.turbulence_intensity_min=0.2", "env.turbulence_intensity_max=0.1"])


# ---------------------------------------------------------------------------------------------------- model identity
def test_presets_are_recognised_and_paper_yaml_is_the_paper_preset():
    """preset_name: the default configuration is 'default', configs/paper.yaml is 'paper' (and holds exactly
    PRESETS['paper']), any other model is 'custom'; what is not the model (wind, task, run, solver, figure) does not
    change the name."""
    from kite_env.config import PRESETS, preset_config, preset_name

    assert set(PRESETS) == {"default", "paper"} and PRESETS["default"] == {}
    assert preset_name(Config()) == preset_name(load_config(ROOT / "configs" / "default.yaml")) == "default"
    paper = load_config(ROOT / "configs" / "paper.yaml")
    assert preset_name(paper) == "paper" and paper == preset_config("paper")
    assert yaml.safe_load((ROOT / "configs" / "paper.yaml").read_text()) == PRESETS["paper"]
    assert preset_config("default") == Config()
    task = ["wind.speed_mps=8", "wind.turbulence_intensity=0.1", "env.max_episode_s=5", "sim.fidelity=surrogate",
            "fsi.tol_disp_m=2e-4", "trajectory.width_deg=90"]
    assert preset_name(load_config(None, task)) == "default"
    assert preset_name(load_config(ROOT / "configs" / "paper.yaml", task)) == "paper"
    assert preset_name(load_config(None, ["aero.canopy_luffing=false"])) == "custom"
    assert preset_name(load_config(ROOT / "configs" / "paper.yaml", ["structure.dynamic=true",
                                                                    "dynamics.tether=rope"])) == "custom"
    with pytest.raises(ConfigError, match="unknown model preset 'nope'"):
        preset_config("nope")


def test_fingerprint_covers_the_model_sections_only():
    import json

    from kite_env.config import MODEL_SECTIONS, RETIRED, fingerprint, model_keys

    cfg = Config()
    fp = fingerprint(cfg)
    assert set(fp) == {"preset", "fingerprint", "keys"} and fp["preset"] == "default"
    assert len(fp["fingerprint"]) == 16 and int(fp["fingerprint"], 16) >= 0
    d = cfg.to_dict()
    assert model_keys(cfg) == {f"{s}.{k}": v for s in MODEL_SECTIONS for k, v in d[s].items()}
    # the retired keys of the model's sections stay in the record at their one value (fsi is not the model)
    retired = {k: v for k, v in RETIRED.items() if k.split(".")[0] in MODEL_SECTIONS}
    assert retired and "fsi.extrapolate" in RETIRED and "fsi.extrapolate" not in fp["keys"]
    assert fp["keys"] == model_keys(cfg) | retired
    assert set(MODEL_SECTIONS) == {"kite", "structure", "aero", "dynamics", "control"}
    same = load_config(None, ["wind.speed_mps=8", "env.max_episode_s=5", "sim.fidelity=surrogate",
                              "fsi.max_newton_iter=40", "trajectory.elevation_deg=30"])
    assert fingerprint(same) == fp
    for key in ("dynamics.winch_force_N=10000", "kite.n_sections=21", "control.k2=2", "aero.damping=eq3",
                "structure.rho_inf=0.5"):
        other = fingerprint(load_config(None, [key]))
        assert other["fingerprint"] != fp["fingerprint"] and other["preset"] == "custom", key
    assert fingerprint(load_config(ROOT / "configs" / "paper.yaml"))["preset"] == "paper"
    assert json.loads(json.dumps(fp)) == fp  # stored as JSON with every artefact


def test_check_model_names_the_keys_that_differ():
    import json

    from kite_env.config import ModelMismatch, check_model, fingerprint

    cfg = Config()
    check_model(json.loads(json.dumps(fingerprint(cfg))), cfg, "wing 'w.npz'")  # the same model: no error
    check_model(fingerprint(cfg), load_config(None, ["wind.speed_mps=9", "sim.fidelity=surrogate"]), "w")
    other = load_config(None, ["dynamics.winch_force_N=10000"])
    with pytest.raises(ModelMismatch) as err:
        check_model(fingerprint(cfg), other, "wing 'w.npz'")
    msg = str(err.value)
    assert msg.startswith("wing 'w.npz' was made with model 'default'") and "not this one 'custom'" in msg
    assert "1 key(s) differ: dynamics.winch_force_N (15000.0 there, 10000.0 here)" in msg
    assert isinstance(err.value, ConfigError)
    paper = load_config(ROOT / "configs" / "paper.yaml")
    with pytest.raises(ModelMismatch, match=r"9 key\(s\) differ: aero\.canopy_luffing \(True there, False here\), "
                                            r".*structure\.dynamic \(True there, False here\) and 1 more"):
        check_model(fingerprint(cfg), paper, "agent")
    # a key that one side does not have (a record of an older key set)
    rec = fingerprint(cfg)
    rec["keys"] = {k: v for k, v in rec["keys"].items() if k != "control.k2"} | {"control.old_gain": 1.0}
    with pytest.raises(ModelMismatch, match=r"control\.k2 \('<absent>' there, 3\.0 here\), control\.old_gain "
                                            r"\(1\.0 there, '<absent>' here\)"):
        check_model(rec, cfg, "agent")
    for record in (None, {}, {"preset": "default", "fingerprint": fingerprint(cfg)["fingerprint"]}):
        with pytest.raises(ModelMismatch, match="agent records no model"):
            check_model(record, cfg, "agent")


def test_a_record_made_at_another_value_of_a_retired_key_is_refused():
    """A retired key (kite_env.config.RETIRED) stays in a model's record at its one value: a record made before it
    was retired, at that value, is this model (the shipped agent's and reduced-order wing's records, the
    fingerprint unchanged); one made at another value (the larger-end tube law) is refused, naming the key."""
    import json

    from kite_env.config import ModelMismatch, check_model, fingerprint
    from kite_env.surrogate import default_surrogate_path
    from kite_env.surrogate.model import SurrogateWing

    cfg = Config()
    agent = json.loads((ROOT / "agents" / "models" / "ppo" / "model.json").read_text())
    wing = SurrogateWing.load(default_surrogate_path(cfg.kite.name)).meta["model"]
    for record in (agent, wing):
        assert record["keys"]["structure.tube_curvature"] == "element_energy"  # made with the retired key
        assert record["fingerprint"] == fingerprint(cfg)["fingerprint"]
        check_model(record, cfg, "shipped artefact")
    rec = fingerprint(cfg)
    rec["keys"] = rec["keys"] | {"structure.tube_curvature": "max_end"}
    with pytest.raises(ModelMismatch, match=r"1 key\(s\) differ: structure\.tube_curvature \('max_end' there, "
                                            r"'element_energy' here\)"):
        check_model(rec, cfg, "agent")


@pytest.mark.parametrize("key", ["structure.tube_curvature", "structure.te_hem_element",
                                 "structure.added_mass_force", "fsi.extrapolate", "control.actuator_axes"])
def test_a_retired_key_is_refused_with_what_every_model_now_does(key, tmp_path):
    """A configuration that gives a retired key, even at the value every model now has, is refused with one
    message: the key is retired, its one value, what the model does; the same from a file and from --set."""
    from kite_env.config import RETIRED, RETIRED_NOW

    value = RETIRED[key]
    section, name = key.split(".")
    path = tmp_path / "old.yaml"
    path.write_text(yaml.safe_dump({section: {name: value}}))
    for kwargs in ({"path": path}, {"overrides": [f"{key}={str(value).lower()}"]}):
        with pytest.raises(ConfigError) as err:
            load_config(**kwargs)
        msg = str(err.value)
        assert msg.startswith(f"config key '{key}' is retired, always {str(value).lower()} now: ")
        assert RETIRED_NOW[key] in msg and msg.endswith("remove it from the configuration")
        assert "\n" not in msg
    with pytest.raises(ConfigError, match=f"config key '{key}' is retired"):
        config_from_dict({section: {name: "anything"}})


def test_a_config_recorded_before_the_keys_were_retired_loads_without_them():
    """kite_env.config.without_retired: a complete configuration written before keys were retired (a kite-train
    run's config.yml, agents/models/ppo/config.yml) loads once its retired keys at their one value are dropped; one
    recorded at another value is still refused, naming the key."""
    from kite_env.config import without_retired

    data = yaml.safe_load((ROOT / "agents" / "models" / "ppo" / "config.yml").read_text())
    assert data["structure"]["tube_curvature"] == "element_energy" and data["fsi"]["extrapolate"] is True
    with pytest.raises(ConfigError, match="is retired"):
        config_from_dict(data)
    cfg = config_from_dict(without_retired(data))
    assert cfg.structure == Config().structure and cfg.control == Config().control
    assert data["structure"]["tube_curvature"] == "element_energy"  # (the record itself left as it is)
    data["control"]["actuator_axes"] = "per_line"
    with pytest.raises(ConfigError, match="config key 'control.actuator_axes' is retired"):
        config_from_dict(without_retired(data))



def test_the_shipped_recipes_train_on_the_default_model():
    """agents/recipes/*.yaml set the task (conditions, starts) and no model key: the fast fidelity they train flies
    the default model, the one the shipped reduced-order wing belongs to."""
    from kite_env.cli.train import FAST_ENV_ID, default_recipe, load_hyperparameters, recipe_overrides
    from kite_env.config import fingerprint

    for algo in ("ppo", "sac"):
        over = recipe_overrides(load_hyperparameters(default_recipe(algo), algo, FAST_ENV_ID))
        assert over and fingerprint(load_config(None, over)) == fingerprint(Config()), algo

# ---------------------------------------------------------------------------------------------------- randomised
#: a value of each randomised quantity and the ranges it pins when given alone
PINS = {
    "wind.speed_mps": (8.0, {"env.wind_speed_min_mps": 8.0, "env.wind_speed_max_mps": 8.0}),
    "wind.turbulence_intensity": (0.1, {"env.turbulence_intensity_min": 0.1, "env.turbulence_intensity_max": 0.1}),
    "sim.initial_speed_mps": (25.0, {"env.initial_speed_min_mps": 25.0, "env.initial_speed_max_mps": 25.0,
                                     "env.initial_speed_per_wind_min": 0.0, "env.initial_speed_per_wind_max": 0.0}),
    "sim.initial_speed_per_wind": (4.2, {"env.initial_speed_per_wind_min": 4.2, "env.initial_speed_per_wind_max": 4.2}),
}


def _get(cfg, key):
    s, k = key.split(".")
    return getattr(getattr(cfg, s), k)


def _nested(flat):
    out = {}
    for key, v in flat.items():
        s, k = key.split(".")
        out.setdefault(s, {})[k] = v
    return out


def test_every_randomised_quantity_is_listed_with_its_ranges():
    from kite_env.config import RANDOMISED

    assert set(RANDOMISED) == set(PINS)
    for key, ranges in RANDOMISED.items():
        assert set(ranges) == set(PINS[key][1]), key


@pytest.mark.parametrize("key", sorted(PINS))
def test_a_randomised_quantity_given_alone_pins_its_range(key, tmp_path):
    """Given without its range in one layer (a dict, the overrides, a config file) the value is flown: its range is
    pinned to it (the start speed in m/s also clears the range per m/s of wind)."""
    value, pinned = PINS[key]
    f = tmp_path / "c.yaml"
    f.write_text(yaml.safe_dump(_nested({key: value})))
    for cfg in (config_from_dict(_nested({key: value})), load_config(None, [f"{key}={value}"]), load_config(f)):
        assert _get(cfg, key) == value
        for r, v in pinned.items():
            assert _get(cfg, r) == v, (key, r)
    # the default ranges are not those values: the pin did something
    assert any(_get(Config(), r) != v for r, v in pinned.items())


#: a range of each randomised quantity, given with it
RANGES = {
    "wind.speed_mps": {"env.wind_speed_min_mps": 4.0, "env.wind_speed_max_mps": 10.0},
    "wind.turbulence_intensity": {"env.turbulence_intensity_min": 0.0, "env.turbulence_intensity_max": 0.15},
    "sim.initial_speed_mps": {"env.initial_speed_min_mps": 20.0, "env.initial_speed_max_mps": 30.0,
                              "env.initial_speed_per_wind_min": 0.0, "env.initial_speed_per_wind_max": 0.0},
    "sim.initial_speed_per_wind": {"env.initial_speed_per_wind_min": 4.0, "env.initial_speed_per_wind_max": 4.8},
}


@pytest.mark.parametrize("key", sorted(PINS))
def test_a_randomised_quantity_given_with_its_range_does_not_pin_it(key):
    """Given together with its range in the same layer the range is the one given; given with one key of its range,
    the rest of the range keeps its value (nothing is pinned)."""
    value, pinned = PINS[key]
    rng = RANGES[key]
    assert set(rng) == set(pinned)
    cfg = config_from_dict(_nested({key: value, **rng}))
    assert _get(cfg, key) == value and all(_get(cfg, r) == v for r, v in rng.items())
    cfg = load_config(None, [f"{key}={value}", *(f"{r}={v}" for r, v in rng.items())])
    assert _get(cfg, key) == value and all(_get(cfg, r) == v for r, v in rng.items())
    base = Config()
    for r, v in rng.items():
        layer = _nested({key: value, r: v})
        if key == "sim.initial_speed_per_wind":
            # not pinned: one bound of the range per m/s of wind set, the other left at 0, is refused
            with pytest.raises(ConfigError, match="initial_speed_per_wind"):
                config_from_dict(layer)
            continue
        cfg = config_from_dict(layer)
        assert _get(cfg, r) == v, (key, r)
        for other in rng:
            if other != r:
                assert _get(cfg, other) == _get(base, other), (key, r, other)


def test_pins_apply_per_layer():
    f_cfg = {"wind": {"speed_mps": 8.0}}
    cfg = config_from_dict({"env": {"wind_speed_max_mps": 10.0}}, config_from_dict(f_cfg))
    assert (cfg.wind.speed_mps, cfg.env.wind_speed_min_mps, cfg.env.wind_speed_max_mps) == (8.0, 8.0, 10.0)
    # a start speed of 0 follows the wind (sim.initial_speed_per_wind): nothing to pin
    cfg = load_config(None, ["sim.initial_speed_mps=0"])
    assert (cfg.env.initial_speed_min_mps, cfg.env.initial_speed_max_mps) == (22.0, 22.0)


@pytest.mark.parametrize("overrides", ["wind.speed_mps=8", b"wind.speed_mps=8", {"wind.speed_mps": 8}, 8],
                         ids=["str", "bytes", "dict", "int"])
def test_overrides_must_be_a_list_of_strings(overrides):
    """Overrides given as one string (or bytes, a dict, a number) raise one ConfigError that says what is expected,
    from load_config and from the environment's constructor; not a ConfigError per character."""
    from kite_env.envs.figure_eight import KiteFigureEightEnv

    for make in (lambda: load_config(None, overrides), lambda: KiteFigureEightEnv(overrides=overrides)):
        with pytest.raises(ConfigError, match="overrides must be a list of 'section.key=value' strings") as err:
            make()
        assert str(err.value).count("overrides must be") == 1
    if isinstance(overrides, str):
        with pytest.raises(ConfigError, match="wrap a single override in a list"):
            load_config(None, overrides)
    with pytest.raises(ConfigError, match="override 8 must be a string"):
        load_config(None, [8])


@pytest.mark.parametrize("dt", [0.015, 0.03, 0.0])
def test_the_fast_fidelitys_step_must_divide_the_control_period(dt):
    """sim.surrogate_dt_s: a whole number of fast-fidelity steps makes one control period (0.02 s); 0.01 s is the
    default, two steps per control period, as the env's n_physics says."""
    from kite_env.envs.figure_eight import KiteFigureEightEnv

    with pytest.raises(ConfigError, match="sim.surrogate_dt_s"):
        load_config(None, [f"sim.surrogate_dt_s={dt}"])
    env = KiteFigureEightEnv(fidelity="surrogate")
    assert env.n_physics == 2 and env.control_dt == pytest.approx(0.02)
    assert KiteFigureEightEnv().n_physics == 4  # the full model's 5 ms


# ---------------------------------------------------------------------------------------------------- key declarations
def test_generated_config_reference_is_current():
    """configs/default.yaml and docs/configuration.md are what kite_env.config_reference writes from the key
    declarations now: a key added or changed without regenerating them fails here."""
    from kite_env.config_reference import COMMAND, GENERATED

    for path, render in GENERATED.items():
        text = (ROOT / path).read_text() if (ROOT / path).is_file() else ""
        assert text == render(), f"{path} is out of date with kite_env/config.py: run `{COMMAND}` and commit it"


def test_every_key_is_declared_with_its_meaning_and_checks():
    """Every key of the sections declared in kite_env/config.py carries its documentation (a meaning; a unit for
    every number) and its default passes its own checks; every choice key's default is one of its choices; the
    generated reference lists every key of every section."""
    from dataclasses import fields

    from kite_env.config import check_key
    from kite_env.config_reference import _section_classes, section_keys

    cfg = Config()
    for sec, cls in _section_classes():
        documented = {k.name: k for k in section_keys(sec, cls)}
        assert set(documented) == set(cfg.to_dict()[sec]), sec
        for k in documented.values():
            assert k.doc, f"{sec}.{k.name} has no meaning"
            if isinstance(k.default, (int, float)) and not isinstance(k.default, bool):
                assert k.unit, f"{sec}.{k.name} has no unit"
        if sec in ("wind", "trajectory"):  # declared in their modules, with their own validate()
            continue
        for f in fields(cls):
            assert f.metadata.get("doc"), f"{sec}.{f.name} is not declared with kite_env.config.key"
            check_key(f"{sec}.{f.name}", f.default, f.metadata)
            if f.metadata["choices"] is not None:
                assert f.default in f.metadata["choices"]


def test_the_checks_read_from_the_declarations():
    """A choice, a range, a check and .inf where allowed: the messages name the key and what it takes."""
    with pytest.raises(ConfigError, match=r"'aero.negative_alpha' must be 'bounded' or 'breukels', got 'x'"):
        load_config(None, ["aero.negative_alpha=x"])
    with pytest.raises(ConfigError, match=r"'structure.carry_residual' must be 'sections' or 'full', got 'none'"):
        load_config(None, ["structure.carry_residual=none"])
    with pytest.raises(ConfigError, match=r"'aero.moment_chord_power' must be 1 or 2, got 1.5"):
        load_config(None, ["aero.moment_chord_power=1.5"])
    with pytest.raises(ConfigError, match=r"'structure.canopy_nu' must lie in \(-1, 0.5\), got 0.5"):
        load_config(None, ["structure.canopy_nu=0.5"])
    with pytest.raises(ConfigError, match=r"'structure.rho_inf' must lie in \[0, 1\], got 1.1"):
        load_config(None, ["structure.rho_inf=1.1"])
    with pytest.raises(ConfigError, match=r"'fsi.max_retries' must be >= 0, got -1"):
        load_config(None, ["fsi.max_retries=-1"])
    with pytest.raises(ConfigError, match=r"'kite.n_sections' must be odd and >= 7, got 36"):
        load_config(None, ["kite.n_sections=36"])
    with pytest.raises(ConfigError, match=r"'kite.n_chord' must be >= 3, got 2"):
        load_config(None, ["kite.n_chord=2"])
    with pytest.raises(ConfigError, match=r"'env.observation' must list distinct terms of position, heading"):
        load_config(None, ["env.observation=position,position"])
    assert load_config(None, ["env.start_curvature_max=.inf"]).env.start_curvature_max == float("inf")
    with pytest.raises(ConfigError, match=r"'env.max_episode_s' must be finite"):
        load_config(None, ["env.max_episode_s=.inf"])
    with pytest.raises(ConfigError, match=r"'env.start_curvature_max' must be positive"):
        load_config(None, ["env.start_curvature_max=0"])


def test_the_yaml_values_read_back_as_the_defaults():
    """configs/default.yaml holds each default as a YAML value of its own type (1.25e+9 a float, not the string
    '1.25e9' that YAML 1.1 reads), so that the file reads back as the defaults without conversion."""
    from kite_env.config_reference import yaml_value

    data = yaml.safe_load((ROOT / "configs" / "default.yaml").read_text())
    for sec, vals in Config().to_dict().items():
        for k, v in vals.items():
            assert type(data[sec][k]) is type(v) and data[sec][k] == v, f"{sec}.{k}"
    for v in (1.25e9, 8e-5, 15000.0, 0.0016, 1e-12, -3.5e20, float("inf"), "", "a: b", "true", 0, True):
        assert yaml.safe_load(yaml_value(v)) == v, v
