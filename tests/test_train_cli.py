"""kite-train: short PPO and SAC runs through the CLI, resume from a checkpoint, clear errors; agent configs load."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from kite_env.cli import train as train_cli

AGENT_CONFIGS = sorted((Path(__file__).parents[1] / "agents" / "recipes").glob("*.yaml"))
SHORT = ["--fidelity", "fe", "--set", "env.max_episode_s=0.4"]


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


@pytest.mark.slow  # the FE model: ~15-35 s
@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_short_training_run_gives_a_loadable_model(tmp_path, algo):
    from stable_baselines3 import PPO, SAC

    from kite_env.envs.figure_eight import KiteFigureEightEnv

    out = tmp_path / "run"
    rc = train_cli.main(["--algo", algo, "--timesteps", "32", "--out", str(out), "--recipe", _hp(tmp_path, algo),
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


@pytest.mark.slow  # the FE model: ~15-35 s
def test_resume_continues_from_the_last_checkpoint(tmp_path):
    from stable_baselines3 import PPO

    out = tmp_path / "run"
    hp = _hp(tmp_path, "ppo")
    assert train_cli.main(["--algo", "ppo", "--timesteps", "32", "--out", str(out), "--recipe", hp, *SHORT]) == 0
    assert (out / "checkpoints" / "model_32_steps.zip").is_file()
    assert (out / "checkpoints" / "model_vecnormalize_32_steps.pkl").is_file()
    # not empty: refuses without --resume
    assert train_cli.main(["--algo", "ppo", "--timesteps", "64", "--out", str(out), "--recipe", hp, *SHORT]) == 2
    assert train_cli.main(["--algo", "ppo", "--timesteps", "64", "--out", str(out), "--recipe", hp, "--resume",
                           *SHORT]) == 0
    assert PPO.load(out / "model.zip", device="cpu").num_timesteps == 64
    assert (out / "checkpoints" / "model_64_steps.zip").is_file()


def _failing_step(at_call: int, t: float):
    """``KiteFigureEightEnv.step`` that raises a forced NumericalFailure at time ``t`` on its ``at_call``-th call (per
    process), and the original step."""
    from kite_env.dynamics.simulator import NumericalFailure, SimulationError
    from kite_env.envs.figure_eight import KiteFigureEightEnv

    step = KiteFigureEightEnv.step
    calls = [0]

    def failing(self, action):
        calls[0] += 1
        if calls[0] == at_call:
            raise NumericalFailure(SimulationError("wing did not converge", "test: forced", "residual history (test)"),
                                   t, "test conditions")
        return step(self, action)

    return failing, step


@pytest.mark.slow  # the FE model: ~15-35 s
def test_a_numerical_failure_saves_a_checkpoint_and_exits_3_and_the_run_resumes(tmp_path, capsys, monkeypatch):
    """A NumericalFailure of the wing with inertia during training (forced at the env's 25th step) is reported as
    one error line with the failure's message, exit 3, after a checkpoint of what was learnt; --resume continues."""
    from stable_baselines3 import PPO

    from kite_env.envs.figure_eight import KiteFigureEightEnv

    failing, step = _failing_step(25, 0.5)
    monkeypatch.setattr(KiteFigureEightEnv, "step", failing)
    out = tmp_path / "run"
    hp = _hp(tmp_path, "ppo")
    assert train_cli.main(["--algo", "ppo", "--timesteps", "64", "--out", str(out), "--recipe", hp, *SHORT]) == 3
    err = capsys.readouterr().err
    line = [x for x in err.splitlines() if x.startswith("kite-train: error:")]
    assert len(line) == 1 and "numerical failure at t = 0.5000 s (test conditions): wing did not converge" in line[0]
    assert line[0].endswith("continue with --resume") and "residual history (test)" in err
    # the 24 steps made before the failing 25th are kept (the periodic checkpoint has 16), no final model
    assert (out / "checkpoints" / "model_24_steps.zip").is_file() and not (out / "model.zip").exists()
    monkeypatch.setattr(KiteFigureEightEnv, "step", step)
    assert train_cli.main(["--algo", "ppo", "--timesteps", "64", "--out", str(out), "--recipe", hp, "--resume",
                           *SHORT]) == 0
    assert "resuming from model_24_steps.zip" in capsys.readouterr().err
    assert PPO.load(out / "model.zip", device="cpu").num_timesteps >= 64  # (whole PPO rollouts of 16 from 24)


@pytest.mark.slow  # the FE model in two forked workers: ~15-35 s
def test_a_numerical_failure_in_a_subproc_worker_saves_a_checkpoint_and_exits_3(tmp_path, capsys, monkeypatch):
    """The same with the envs in subproc workers (forked here, so that they inherit the forced failure at each
    worker's 13th step): the worker writes its NumericalFailure into the run folder before it ends, and the run
    reports it as one error line with its message, exit 3, after a checkpoint; the report is removed; --resume
    continues."""
    import stable_baselines3.common.vec_env as sb3_vec

    from kite_env.envs.figure_eight import KiteFigureEightEnv

    class ForkedSubprocVecEnv(sb3_vec.SubprocVecEnv):
        def __init__(self, env_fns, start_method=None):
            super().__init__(env_fns, start_method="fork")

    failing, step = _failing_step(13, 0.26)

    monkeypatch.setattr(sb3_vec, "SubprocVecEnv", ForkedSubprocVecEnv)
    monkeypatch.setattr(KiteFigureEightEnv, "step", failing)
    out = tmp_path / "run"
    hp = _hp(tmp_path, "ppo")
    args = ["--algo", "ppo", "--timesteps", "64", "--out", str(out), "--recipe", hp, "--n-envs", "2",
            "--vec-env", "subproc", *SHORT]
    assert train_cli.main(args) == 3
    err = capsys.readouterr().err
    line = [x for x in err.splitlines() if x.startswith("kite-train: error:")]
    assert len(line) == 1 and "numerical failure at t = 0.2600 s (test conditions): wing did not converge" in line[0]
    assert line[0].endswith("continue with --resume") and "residual history (test)" in err
    # 12 steps of each of the two workers were made before their 13th failed
    assert (out / "checkpoints" / "model_24_steps.zip").is_file() and not (out / "model.zip").exists()
    assert not (out / train_cli.WORKER_FAILURES).exists()
    monkeypatch.setattr(KiteFigureEightEnv, "step", step)
    assert train_cli.main([*args, "--resume"]) == 0
    assert "resuming from model_24_steps.zip" in capsys.readouterr().err and (out / "model.zip").is_file()


def _one_error(capsys, *needles):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("kite-train: error:"), err
    for n in needles:
        assert n in err[0], (n, err[0])


def test_recipe_mistakes_exit_2_with_one_line_before_anything_is_written(tmp_path, capsys):
    """A misspelt argument, an unknown env id, a physics config given as the recipe and a recipe given as the
    physics config: one line each, exit 2, no run folder."""
    root = Path(__file__).parents[1]
    typo = tmp_path / "typo.yaml"
    typo.write_text(yaml.safe_dump({"default": {"learning_rte": 1e-3}}))
    wrong_id = tmp_path / "wrong_id.yaml"
    wrong_id.write_text(yaml.safe_dump({"KiteFigureEightFast-v0": {"n_envs": 2}}))
    cases = [(["--recipe", str(typo)], ("learning_rte", "did you mean 'learning_rate'")),
             (["--recipe", str(wrong_id)], ("unknown env id 'KiteFigureEightFast-v0'", "KiteFigureEightFast-v1")),
             (["--recipe", str(root / "configs" / "default.yaml")], ("is a physics config", "--config")),
             (["--config", str(root / "agents" / "recipes" / "ppo.yaml")], ("is a training recipe", "--recipe"))]
    for i, (extra, needles) in enumerate(cases):
        out = tmp_path / f"run{i}"
        assert train_cli.main(["--algo", "ppo", "--timesteps", "8", "--out", str(out), *extra]) == 2
        _one_error(capsys, *needles)
        assert not out.exists()


def test_the_command_line_wins_over_the_recipe_and_pins_a_randomised_quantity(tmp_path):
    """--set wind.speed_mps over a recipe that draws the wind from a range: the range becomes that value (the value
    given is the value flown); a range given with --set stays a range."""
    import argparse

    def cfg_of(*sets):
        args = argparse.Namespace(algo="ppo", recipe=None, config=None, set=list(sets), fidelity="surrogate")
        return train_cli.training_config(args)[0]

    base = cfg_of()
    assert (base.env.wind_speed_min_mps, base.env.wind_speed_max_mps) == (4.0, 10.0)  # the shipped recipe's range
    pinned = cfg_of("wind.speed_mps=8")
    assert (pinned.wind.speed_mps, pinned.env.wind_speed_min_mps, pinned.env.wind_speed_max_mps) == (8.0, 8.0, 8.0)
    ranged = cfg_of("wind.speed_mps=8", "env.wind_speed_max_mps=9")
    assert (ranged.env.wind_speed_min_mps, ranged.env.wind_speed_max_mps) == (4.0, 9.0)


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


@pytest.mark.slow  # the FE model: ~15-35 s
def test_kite_bench_writes_bench_json(tmp_path, capsys):
    import json

    from kite_env.cli import bench

    assert bench.main(["--out", str(tmp_path), "--steps", "10", "--fast-steps", "300"]) == 0
    data = json.loads((tmp_path / "bench.json").read_text())
    fe = data["fe"]
    assert fe["env_steps_per_s"] > 0 and fe["real_time_factor"] > 0 and fe["steps"] == 10
    assert abs(fe["real_time_factor"] * fe["env_steps_per_s"] * fe["control_dt_s"] - 1.0) < 1e-9
    assert "env steps/s" in capsys.readouterr().out
    assert bench.main(["--out", str(tmp_path / "x"), "--set", "env.nope=1"]) == 2
    assert not (tmp_path / "x").exists()


# ------------------------------------------------------------------ recipes and the batched fast env
FAST = ["--fidelity", "surrogate", "--set", "env.max_episode_s=0.3"]
RECIPE_ENV = {"env.wind_speed_min_mps": 4.0, "env.wind_speed_max_mps": 9.0, "env.random_start": True,
              "env.initial_speed_min_mps": 19.0}


def _recipe(tmp_path, algo, **extra):
    """A recipe for KiteFigureEightFast-v1: 4 batched envs, the env overrides above, a tiny algorithm."""
    base = {"ppo": {"n_steps": 8, "batch_size": 16, "n_epochs": 1},
            "sac": {"learning_starts": 8, "batch_size": 8, "buffer_size": 1000}}[algo]
    f = tmp_path / f"recipe_{algo}.yaml"
    f.write_text(yaml.safe_dump({
        "default": {**base, "checkpoint_freq": 32, "eval_freq": 10**6, "env": {"env.w_traction": 0.25}},
        "KiteFigureEight-v1": {"env": {"env.w_traction": 0.75}},
        "KiteFigureEightFast-v1": {"n_envs": 4, "vec_env": "batched", "env": dict(RECIPE_ENV), **extra}}))
    return str(f)


def _params(path) -> dict:
    from stable_baselines3 import PPO, SAC

    algo = {"ppo": PPO, "sac": SAC}[path.parent.name.split("_")[0]]
    return {k: v.numpy().copy() for k, v in algo.load(path, device="cpu").policy.state_dict().items()}


def test_recipe_overrides_as_set_strings(tmp_path):
    hp = train_cli.load_hyperparameters(_recipe(tmp_path, "ppo"), "ppo", train_cli.FAST_ENV_ID)
    assert hp["n_envs"] == 4 and hp["vec_env"] == "batched" and hp["n_steps"] == 8
    # the default entry's env mapping merged with the env id's
    assert sorted(train_cli.recipe_overrides(hp)) == ["env.initial_speed_min_mps=19.0", "env.random_start=true",
                                                      "env.w_traction=0.25", "env.wind_speed_max_mps=9.0",
                                                      "env.wind_speed_min_mps=4.0"]
    fe = train_cli.load_hyperparameters(_recipe(tmp_path, "ppo"), "ppo", train_cli.ENV_ID)
    assert train_cli.recipe_overrides(fe) == ["env.w_traction=0.75"] and "vec_env" not in fe
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"default": {"vec_env": "threads"}}))
    with pytest.raises(train_cli.UsageError, match="vec_env"):
        train_cli.load_hyperparameters(bad, "ppo")


@pytest.mark.parametrize("path", AGENT_CONFIGS, ids=[p.name for p in AGENT_CONFIGS])
def test_shipped_recipes_give_the_training_conditions(path):
    from kite_env.config import load_config

    hp = train_cli.load_hyperparameters(path, path.stem, train_cli.FAST_ENV_ID)
    # PPO steps its 16 kites in one batch; SAC, which holds each action 5 steps, steps 16 single envs
    assert hp["n_envs"] == 16
    assert (hp["vec_env"], hp.get("action_hold", 1)) == {"ppo": ("batched", 1), "sac": ("dummy", 5)}[path.stem]
    env = load_config(None, train_cli.recipe_overrides(hp)).env
    # the conditions the reduced-order wing was fitted in (kite_env.fitting.trajectories.EpisodePlan)
    assert (env.wind_speed_min_mps, env.wind_speed_max_mps) == (4.0, 10.0)
    assert env.turbulence_intensity_max == 0.1 and env.random_start is True and env.randomize is True
    assert env.start_curvature_max == 1.0
    assert (env.initial_speed_per_wind_min, env.initial_speed_per_wind_max) == (4.0, 4.8)


def test_vec_env_kind_defaults_and_errors(tmp_path, capsys):
    kind = train_cli._vec_env_kind
    assert kind(None, "surrogate", 4) == "batched" and kind(None, "surrogate", 1) == "dummy"
    assert kind(None, "fe", 4) == "subproc" and kind(None, "fe", 1) == "dummy"
    assert kind("dummy", "surrogate", 4) == "dummy" and kind("batched", "surrogate", 1) == "batched"
    out = tmp_path / "run"
    assert train_cli.main(["--algo", "ppo", "--timesteps", "8", "--out", str(out), "--vec-env", "batched",
                           "--fidelity", "fe", "--recipe", _hp(tmp_path, "ppo")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "batched" in err[0] and "surrogate" in err[0]
    assert not out.exists()


@pytest.fixture(scope="module")
def batched_runs(tmp_path_factory):
    """Tiny PPO runs on 4 batched fast kites: seed 5 twice, seed 6 once, and seed 5 stopped at 32 steps then
    resumed to 64. The resumed run's episodes last at most 0.1 s (5 steps), so that each part (8 steps per kite)
    completes episodes and the monitor file's continuation can be checked."""
    base = tmp_path_factory.mktemp("batched")
    recipe = _recipe(base, "ppo")
    rc = {}
    short = ["--set", "env.max_episode_s=0.1"]
    for name, seed, steps in (("ppo_a", 5, 64), ("ppo_b", 5, 64), ("ppo_c", 6, 64), ("ppo_r", 5, 32)):
        rc[name] = train_cli.main(["--algo", "ppo", "--timesteps", str(steps), "--out", str(base / name),
                                   "--recipe", recipe, "--seed", str(seed), "--set", "env.wind_speed_max_mps=7.5",
                                   *FAST, *(short if name == "ppo_r" else [])])
    rc["ppo_r2"] = train_cli.main(["--algo", "ppo", "--timesteps", "64", "--out", str(base / "ppo_r"), "--recipe",
                                   recipe, "--seed", "5", "--resume", "--set", "env.wind_speed_max_mps=7.5", *FAST,
                                   *short])
    return base, rc


def test_batched_run_records_recipe_and_monitor(batched_runs):
    base, rc = batched_runs
    assert rc == {"ppo_a": 0, "ppo_b": 0, "ppo_c": 0, "ppo_r": 0, "ppo_r2": 0}
    out = base / "ppo_a"
    cfg = yaml.safe_load((out / "config.yml").read_text())
    assert cfg["sim"]["fidelity"] == "surrogate"
    env = cfg["env"]
    assert env["wind_speed_min_mps"] == 4.0 and env["random_start"] is True and env["initial_speed_min_mps"] == 19.0
    assert env["w_traction"] == 0.25  # the default entry's env
    assert env["wind_speed_max_mps"] == 7.5  # --set wins over the recipe's 9.0
    args = yaml.safe_load((out / "args.yml").read_text())
    assert args["vec_env"] == "batched" and args["n_envs"] == 4 and args["env_id"] == "KiteFigureEightFast-v1"
    # VecMonitor: one row per finished episode; 0.3 s episodes = at most 15 steps, 16 steps per kite were run
    lines = (out / "monitor.csv").read_text().splitlines()
    assert lines[0].startswith("#") and lines[1] == "r,l,t"
    rows = np.array([[float(x) for x in ln.split(",")] for ln in lines[2:]])
    assert len(rows) >= 4 and np.all((rows[:, 1] >= 1) & (rows[:, 1] <= 15))
    assert rows[:, 1].sum() <= 64


def test_batched_run_same_seed_same_model(batched_runs):
    base, _ = batched_runs
    a, b, c = (_params(base / n / "model.zip") for n in ("ppo_a", "ppo_b", "ppo_c"))
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert not all(np.array_equal(a[k], c[k]) for k in a)
    ma = (base / "ppo_a" / "monitor.csv").read_text().splitlines()[2:]
    mb = (base / "ppo_b" / "monitor.csv").read_text().splitlines()[2:]
    assert [r.rsplit(",", 1)[0] for r in ma] == [r.rsplit(",", 1)[0] for r in mb]  # same returns and lengths


def test_batched_run_resumes_from_its_checkpoint(batched_runs):
    from stable_baselines3 import PPO

    base, _ = batched_runs
    out = base / "ppo_r"
    assert PPO.load(out / "model.zip", device="cpu").num_timesteps == 64
    assert {"model_32_steps.zip", "model_64_steps.zip", "model_vecnormalize_32_steps.pkl"} <= {
        p.name for p in (out / "checkpoints").iterdir()}
    # the monitor file goes on: the first part's episodes stay, the resumed part's are appended. Each part runs 8
    # steps per kite and completes at least one 5-step episode per kite; more than 32 steps of complete episodes in
    # the file means both parts' episodes are there (the resumed part alone has 32 steps)
    lines = (out / "monitor.csv").read_text().splitlines()
    assert sum(ln == "r,l,t" for ln in lines) == 1
    lengths = [int(float(ln.split(",")[1])) for ln in lines[2:]]
    assert len(lengths) >= 8 and all(1 <= n <= 5 for n in lengths)
    assert 32 < sum(lengths) <= 64


def test_select_validates_every_checkpoint_and_ships_the_best(batched_runs, tmp_path, capsys):
    """``kite-train select``: the baseline and every checkpoint fly the same validation episodes (seeds 30000 and
    up) in the run's environment; one row each, ``selection.json`` names the best mean return, ``--ship`` copies it
    with the run's records into a folder kite-eval loads; bad input is exit 2 with nothing written."""
    import json
    import shutil

    from kite_env.cli import eval as eval_cli

    base, _ = batched_runs
    run = tmp_path / "ppo_a"
    shutil.copytree(base / "ppo_a", run)
    dest = tmp_path / "models" / "ppo"
    assert train_cli.main(["select", str(run), "--episodes", "2", "--duration", "0.2", "--ship", str(dest)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["checkpoint", "mean", "return", "std", "flight", "[s]", "crashes"]
    assert [ln.split()[0] for ln in out[1:4]] == ["baseline", "32", "64"]
    assert out[4].startswith("best: ") and out[5] == f"shipped -> {dest}"
    sel = json.loads((run / "selection.json").read_text())
    assert sel["run"] == "ppo_a" and sel["validation_seeds"] == [30000, 30001]
    rows = sel["rows"]
    assert [r["checkpoint"] for r in rows] == ["baseline", "32", "64"] and rows[0]["steps"] is None
    assert all(r["episodes"] == 2 and 0.0 < r["flight_time_mean_s"] <= 0.2 + 1e-9 for r in rows)
    best = max(rows[1:], key=lambda r: r["mean_return"])
    assert sel["best_steps"] == best["steps"] and train_cli.best_row(sel) == best
    assert out[4].startswith(f"best: {best['steps']} steps, mean return {best['mean_return']:.1f} (baseline")
    assert f"{best['mean_return']:>12.1f}" in out[1 + rows.index(best)]
    ckpt = run / "checkpoints"
    assert (dest / "model.zip").read_bytes() == (ckpt / f"model_{best['steps']}_steps.zip").read_bytes()
    assert (dest / "vecnormalize.pkl").read_bytes() == (
        ckpt / f"model_vecnormalize_{best['steps']}_steps.pkl").read_bytes()
    assert sorted(p.name for p in dest.iterdir()) == sorted(
        ["model.zip", "vecnormalize.pkl", "model.json", "config.yml", "args.yml", "command.txt", "selection.json"])
    assert not dest.with_name("ppo.tmp").exists()
    assert eval_cli.main(["--policy", str(dest / "model.zip"), "--fidelity", "surrogate", "--duration", "0.1",
                          "--out", str(tmp_path / "ev"), "--quiet"]) == 0
    # every k-th checkpoint counted from the newest; the same seeds give the same numbers
    assert train_cli.main(["select", str(run), "--episodes", "2", "--duration", "0.2", "--every", "2"]) == 0
    again = json.loads((run / "selection.json").read_text())["rows"]
    assert [r["checkpoint"] for r in again] == ["baseline", "64"] and again == [rows[0], rows[2]]
    capsys.readouterr()
    # bad input: exit 2, one error line, nothing written
    before = (dest / "model.zip").stat().st_mtime_ns
    assert train_cli.main(["select", str(run), "--ship", str(dest)]) == 2
    assert "exists (use --force" in capsys.readouterr().err and (dest / "model.zip").stat().st_mtime_ns == before
    assert train_cli.main(["select", str(run), "--min-steps", "100"]) == 2
    assert "no checkpoints" in capsys.readouterr().err
    assert train_cli.main(["select", str(tmp_path / "models"), "--episodes", "1"]) == 2
    assert "not a kite-train run folder" in capsys.readouterr().err
    assert train_cli.main(["select", str(run), "--episodes", "0"]) == 2
    assert "at least 1" in capsys.readouterr().err
    assert again == json.loads((run / "selection.json").read_text())["rows"]
    # a run recorded before a key was retired: flown on where it held the one value left, refused at another
    recorded = yaml.safe_load((run / "config.yml").read_text())
    for value, rc in (("element_energy", 0), ("max_end", 2)):
        recorded["structure"]["tube_curvature"] = value
        (run / "config.yml").write_text(yaml.safe_dump(recorded, sort_keys=False))
        assert train_cli.main(["select", str(run), "--episodes", "2", "--duration", "0.2", "--every", "2"]) == rc
        if rc == 0:
            assert json.loads((run / "selection.json").read_text())["rows"] == again
        else:
            assert "structure.tube_curvature" in capsys.readouterr().err


def test_batched_sac_with_held_out_evaluations(tmp_path):
    from stable_baselines3 import SAC

    out = tmp_path / "sac_run"
    assert train_cli.main(["--algo", "sac", "--timesteps", "48", "--out", str(out), "--seed", "2",
                           "--recipe", _recipe(tmp_path, "sac", eval_freq=24, eval_episodes=2), *FAST]) == 0
    assert SAC.load(out / "model.zip", device="cpu").num_timesteps == 48
    assert (out / "checkpoints" / "model_replay_buffer_48_steps.pkl").is_file()
    ev = np.load(out / "eval" / "evaluations.npz")
    assert list(ev["timesteps"]) == [24, 48] and ev["results"].shape == (2, 2)
    # a held-out episode is at most 0.3 s = 15 steps; the reward per step is bounded by the crash penalty
    assert np.all((ev["ep_lengths"] >= 1) & (ev["ep_lengths"] <= 15)) and np.all(np.isfinite(ev["results"]))


def test_linear_schedules():
    """``lin_<x>`` (rl-zoo) becomes a rate falling linearly from x to 0 over the run; numbers stay; typos fail."""
    kw = train_cli.schedules({"learning_rate": "lin_3e-4", "clip_range": 0.2, "n_steps": 8})
    lr = kw["learning_rate"]
    assert lr(1.0) == pytest.approx(3e-4) and lr(0.25) == pytest.approx(0.75e-4) and lr(0.0) == 0.0
    assert kw["clip_range"] == 0.2 and kw["n_steps"] == 8
    assert train_cli.schedules({"learning_rate": "3e-4"})["learning_rate"] == 3e-4  # YAML's string for 3e-4
    for bad in ("linear_3e-4", "lin_x", "lin_"):
        with pytest.raises(train_cli.UsageError, match="learning_rate: expected a number or 'lin_<number>'"):
            train_cli.schedules({"learning_rate": bad})


@pytest.mark.slow  # two processes, each importing torch and training two tiny trials: ~30-60 s
def test_two_optimize_workers_add_trials_to_one_sqlite_study(tmp_path):
    """``kite-train --optimize`` in two processes on one SQLite study: both add trials (each records its worker), the
    study holds all of them, and the best trial is written as a recipe that kite-train reads."""
    import subprocess
    import sys

    import optuna

    recipe = tmp_path / "recipe.yaml"
    recipe.write_text(yaml.safe_dump({"default": {"checkpoint_freq": 10**6, "eval_freq": 32, "eval_episodes": 1},
                                      "KiteFigureEightFast-v1": {"n_envs": 2, "vec_env": "batched"}}))
    out = tmp_path / "study"
    storage = f"sqlite:///{tmp_path / 'study.db'}"
    cmd = [sys.executable, "-m", "kite_env.cli.train", "--algo", "ppo", "--optimize", "--timesteps", "64",
           "--n-trials", "2", "--storage", storage, "--study-name", "two-workers", "--recipe", str(recipe),
           "--out", str(out), "--set", "env.max_episode_s=0.2"]
    procs = [subprocess.Popen([*cmd, "--seed", str(seed)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              text=True) for seed in (0, 100)]
    logs = [p.communicate(timeout=600)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], logs
    study = optuna.load_study(study_name="two-workers", storage=storage)
    assert len(study.trials) == 4
    workers = {t.user_attrs["worker"] for t in study.trials}
    assert len(workers) == 2
    best = yaml.safe_load((out / "best_recipe.yaml").read_text())
    assert best["KiteFigureEightFast-v1"]["learning_rate"] == study.best_trial.params["learning_rate"]
    hp = train_cli.load_hyperparameters(out / "best_recipe.yaml", "ppo", train_cli.FAST_ENV_ID)
    assert hp["n_steps"] == study.best_trial.params["n_steps"] and hp["n_envs"] == 2


def test_init_starts_a_new_run_from_a_trained_agent(tmp_path, capsys):
    """``--init ppo``: the run starts from the shipped agent's weights (after one small update they are within 0.05 of
    them, where a fresh network differs by its whole size) and its observation statistics; a model that is not there
    or of the other algorithm is one error line, exit 2, nothing written."""
    import pickle

    from stable_baselines3 import PPO

    from kite_env.policies import shipped_model

    out = tmp_path / "run"
    fast = ["--fidelity", "surrogate", "--n-envs", "1", "--set", "env.max_episode_s=0.4"]
    hp = _hp(tmp_path, "ppo")
    assert train_cli.main(["--algo", "ppo", "--timesteps", "16", "--out", str(out), "--recipe", hp, "--init", "ppo",
                           *fast]) == 0
    shipped = PPO.load(shipped_model("ppo"), device="cpu").policy.state_dict()
    tuned = PPO.load(out / "model.zip", device="cpu").policy.state_dict()
    assert shipped.keys() == tuned.keys()
    assert max(float((shipped[k] - tuned[k]).abs().max()) for k in shipped) < 0.05
    assert yaml.safe_load((out / "args.yml").read_text())["init"] == "ppo"
    with open(shipped_model("ppo").with_name("vecnormalize.pkl"), "rb") as f:
        mean0 = pickle.load(f).obs_rms.mean
    with open(out / "vecnormalize.pkl", "rb") as f:
        mean1 = pickle.load(f).obs_rms.mean
    assert np.max(np.abs(mean1 - mean0)) < 0.05 * (np.max(np.abs(mean0)) + 1.0)
    capsys.readouterr()
    for bad, what in ((["--algo", "sac", "--init", "ppo"], "is a PPO model, not SAC"),
                      (["--algo", "ppo", "--init", str(tmp_path / "none")], "no model")):
        dest = tmp_path / f"bad_{len(what)}"
        assert train_cli.main([*bad, "--timesteps", "16", "--out", str(dest), *fast]) == 2
        assert what in capsys.readouterr().err and not dest.exists()
