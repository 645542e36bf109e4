"""kite-train: short PPO and SAC runs through the CLI, resume from a checkpoint, clear errors; agent configs load."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from kite_env.cli import train as train_cli

AGENT_CONFIGS = sorted((Path(__file__).parents[1] / "configs" / "agents").glob("*.yaml"))
SHORT = ["--set", "env.max_episode_s=0.4"]


@pytest.mark.parametrize("path", AGENT_CONFIGS, ids=[p.name for p in AGENT_CONFIGS])
def test_agent_configs_load(path):
    algo = path.stem
    hp = train_cli.load_hyperparameters(path, algo)
    assert hp["policy"] == "MlpPolicy" and "learning_rate" in hp


def _hp(tmp_path, algo, **extra):
    base = {"ppo": {"n_steps": 16, "batch_size": 16, "n_epochs": 1},
            "sac": {"learning_starts": 8, "batch_size": 8, "buffer_size": 1000}}[algo]
    f = tmp_path / f"{algo}.yaml"
    f.write_text(yaml.safe_dump({"default": {**base, "checkpoint_freq": 16, "eval_freq": 10**6, **extra}}))
    return str(f)


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_short_training_run_gives_a_loadable_model(tmp_path, algo):
    from stable_baselines3 import PPO, SAC

    from kite_env.envs.figure_eight import KiteFigureEightEnv

    out = tmp_path / "run"
    rc = train_cli.main(["--algo", algo, "--timesteps", "32", "--out", str(out), "--config", _hp(tmp_path, algo),
                         "--seed", "1", *SHORT])
    assert rc == 0
    for name in ("model.zip", "vecnormalize.pkl", "config.yml", "args.yml", "command.txt"):
        assert (out / name).is_file(), name
    assert list((out / "tb").iterdir())
    model = {"ppo": PPO, "sac": SAC}[algo].load(out / "model.zip", device="cpu")
    assert model.num_timesteps >= 32
    env = KiteFigureEightEnv(overrides=["env.max_episode_s=0.2"])
    obs, _ = env.reset(seed=0)
    a, _ = model.predict(obs, deterministic=True)
    obs, r, term, trunc, info = env.step(a)
    assert np.isfinite(r)
    # kite-eval loads the model (algorithm from the zip, normalisation and config from its run folder) and flies it
    from kite_env.cli import eval as eval_cli

    ev = tmp_path / "eval"
    assert eval_cli.main(["--policy", str(out / "model.zip"), "--duration", "0.1", "--set", "sim.warmup_s=0.05",
                          "--out", str(ev), "--quiet"]) == 0
    m = yaml.safe_load((ev / "metrics.json").read_text())
    assert m["policy"] == str(out / "model.zip") and m["sim_time_s"] == pytest.approx(0.1)
    assert m["episode_rows"][0]["episode_steps"] == 5 and np.isfinite(m["episode_return"])


def test_resume_continues_from_the_last_checkpoint(tmp_path):
    from stable_baselines3 import PPO

    out = tmp_path / "run"
    hp = _hp(tmp_path, "ppo")
    assert train_cli.main(["--algo", "ppo", "--timesteps", "32", "--out", str(out), "--config", hp, *SHORT]) == 0
    assert (out / "checkpoints" / "model_32_steps.zip").is_file()
    assert (out / "checkpoints" / "model_vecnormalize_32_steps.pkl").is_file()
    # not empty: refuses without --resume
    assert train_cli.main(["--algo", "ppo", "--timesteps", "64", "--out", str(out), "--config", hp, *SHORT]) == 2
    assert train_cli.main(["--algo", "ppo", "--timesteps", "64", "--out", str(out), "--config", hp, "--resume",
                           *SHORT]) == 0
    assert PPO.load(out / "model.zip", device="cpu").num_timesteps == 64
    assert (out / "checkpoints" / "model_64_steps.zip").is_file()


def test_bad_input_is_one_clear_error(tmp_path, capsys):
    assert train_cli.main(["--algo", "ppo", "--timesteps", "8", "--out", str(tmp_path / "a"),
                           "--config", str(tmp_path / "missing.yaml")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert train_cli.main(["--algo", "ppo", "--timesteps", "8", "--out", str(tmp_path / "b"),
                           "--set", "env.bogus=1"]) == 2
    assert "env.bogus" in capsys.readouterr().err
    assert train_cli.main(["--algo", "ppo", "--timesteps", "8", "--out", str(tmp_path / "c"), "--resume"]) == 2
    assert "no checkpoint" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()


def test_kite_bench_writes_bench_json(tmp_path, capsys):
    import json

    from kite_env.cli import bench

    assert bench.main(["--out", str(tmp_path), "--steps", "10"]) == 0
    data = json.loads((tmp_path / "bench.json").read_text())
    fe = data["fe"]
    assert fe["env_steps_per_s"] > 0 and fe["real_time_factor"] > 0 and fe["steps"] == 10
    assert abs(fe["real_time_factor"] * fe["env_steps_per_s"] * fe["control_dt_s"] - 1.0) < 1e-9
    assert "env steps/s" in capsys.readouterr().out
    assert bench.main(["--out", str(tmp_path / "x"), "--set", "env.nope=1"]) == 2
    assert not (tmp_path / "x").exists()
