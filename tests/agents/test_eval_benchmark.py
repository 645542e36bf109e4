"""``kite-eval benchmark`` (kite_env.evaluation): the rl-zoo style benchmark table from kite-eval comparisons,
training steps of a model; ``kite-train curves`` (kite_env.training.plot_learning_curves): learning curves from
kite-train run folders."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import yaml

import kite_env.plots
import kite_env.policies
from kite_env.cli import eval as eval_cli, train as train_cli
from kite_env.config import config_from_dict, preset_name
from kite_env.evaluation import recipe_env, training_steps
from kite_env.training import read_monitor

ZOO_HEADER = "| algo | env_id | mean_reward | std_reward | n_timesteps | eval_episodes |"


def test_tiny_benchmark_writes_the_zoo_table(tmp_path, monkeypatch, capsys):
    """baseline and random (and 'sac', its model missing: left out with a warning) on one held-out episode each in the
    fast fidelity of the default model, in the shipped PPO recipe's randomised conditions: the zoo table's rows are
    kite-eval's numbers, under the env id of that fidelity (KiteFigureEightFast-v1)."""
    from kite_env.cli.train import default_recipe
    from kite_env.envs import FAST_ENV_ID

    monkeypatch.setattr(kite_env.policies, "MODELS_DIR", tmp_path / "no_models")  # no 'sac' model: left out
    monkeypatch.setattr(kite_env.plots, "make_plots", lambda log, cfg, out: [])
    out = tmp_path / "bench"
    assert eval_cli.main(["benchmark", "--out", str(out), "--policies", "baseline", "random", "sac", "--episodes",
                          "1", "--duration", "0.5", "--fidelity", "surrogate", "--recipe",
                          str(default_recipe("ppo"))]) == 0
    assert "'sac' left out" in capsys.readouterr().err
    md = (out / "benchmark.md").read_text().splitlines()
    assert md[0].startswith(ZOO_HEADER)
    assert md[0].endswith("| tracking error RMS [deg] | mean tether force [N] | crashes (n/N) | mean flight time [s] |")
    data = json.loads((out / "benchmark.json").read_text())
    assert data["skipped"] == ["sac"] and [r["algo"] for r in data["rows"]] == ["baseline", "random"]
    for line, row in zip(md[2:4], data["rows"]):
        cells = [c.strip() for c in line.strip("|").split("|")]
        # the numbers are kite-eval's for the same policy (its metrics.json in OUT/surrogate/<name>/)
        m = json.loads((out / "surrogate" / row["algo"] / "metrics.json").read_text())
        ep = m["episode_rows"][0]
        assert cells[:2] == [row["algo"], FAST_ENV_ID] and row["env_id"] == FAST_ENV_ID
        assert float(cells[2]) == pytest.approx(ep["episode_return"], abs=0.005) and float(cells[3]) == 0.0
        assert cells[4] == "-" and cells[5] == "1"
        assert cells[8] == f"{int(ep['crashed'])}/1"
        assert float(cells[9]) == pytest.approx(ep["sim_time_s"], rel=1e-3) and 0 < ep["sim_time_s"] <= 0.5 + 1e-9
        assert ep["seed"] == 1000  # held-out seed
        # the recipe's randomised conditions, in the fast fidelity of the default model
        cfg = yaml.safe_load((out / "surrogate" / row["algo"] / "config.yaml").read_text())
        assert cfg["sim"]["fidelity"] == "surrogate" and cfg["env"]["randomize"] is True
        assert cfg["sim"]["surrogate_start"] == "table"  # the recipe's training-only table_only: not in evaluations
        assert (cfg["env"]["wind_speed_min_mps"], cfg["env"]["wind_speed_max_mps"]) == (4.0, 10.0)
        assert cfg["env"]["random_start"] is True and cfg["env"]["turbulence_intensity_max"] == 0.1
        assert preset_name(config_from_dict(cfg)) == "default"


def test_the_default_recipe_is_the_shipped_one():
    """Without --recipe the conditions are those of the shipped PPO recipe (agents/recipes/ppo.yaml)."""
    from kite_env.cli.train import FAST_ENV_ID, default_recipe, load_hyperparameters, recipe_overrides

    recipe = eval_cli.build_benchmark_parser().parse_args(["--out", "x"]).recipe
    assert recipe == default_recipe("ppo") and recipe.is_file()
    assert recipe_env(recipe) == recipe_overrides(load_hyperparameters(default_recipe("ppo"), "ppo", FAST_ENV_ID))


def test_training_steps_from_zip_or_args(tmp_path):
    a = tmp_path / "a" / "model.zip"
    a.parent.mkdir()
    with zipfile.ZipFile(a, "w") as zf:
        zf.writestr("data", json.dumps({"num_timesteps": 1234, "n_epochs": 10}))
    assert training_steps(a) == 1234
    b = tmp_path / "b" / "model.zip"
    b.parent.mkdir()
    with zipfile.ZipFile(b, "w") as zf:
        zf.writestr("data", json.dumps({"n_epochs": 10}))
    assert training_steps(b) is None
    (b.parent / "args.yml").write_text(yaml.safe_dump({"algo": "ppo", "timesteps": 99}))
    assert training_steps(b) == 99


def test_learning_curves_from_run_folders(tmp_path, capsys):
    run = tmp_path / "runs" / "ppo_1"
    (run / "eval").mkdir(parents=True)
    np.savez(run / "eval" / "evaluations.npz", timesteps=np.array([100, 200]),
             results=np.array([[-50.0, -40.0, -45.0], [-30.0, -20.0, -25.0]]), ep_lengths=np.full((2, 3), 10))
    lengths = [3, 8, 5, 12]
    (run / "monitor.csv").write_text('#{"t_start": 0.0, "env_id": "None"}\nr,l,t\n'
                                     + "".join(f"{-10.0 * k},{n},{0.1 * k}\n" for k, n in enumerate(lengths)))
    ret, steps = read_monitor(run / "monitor.csv")
    assert list(ret) == [0.0, -10.0, -20.0, -30.0] and list(steps) == [3, 11, 16, 28]
    out = tmp_path / "out"
    assert train_cli.main(["curves", str(run), str(tmp_path / "empty_run"), "--out", str(out)]) == 0
    assert "empty_run" in capsys.readouterr().err
    png = (out / "learning_curves.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert sorted(p.name for p in out.iterdir()) == ["learning_curves.png"]
