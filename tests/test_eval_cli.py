"""``kite-eval`` in-process: bad input is refused cleanly, and one short real flight writes every output."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

import kite_env.envs.figure_eight
import kite_env.flight
import kite_env.plots
from kite_env.cli.eval import main
from kite_env.metrics import read_timeseries

# the metric keys required by the issue
ISSUE_KEYS = [
    "sim_time_s", "wall_time_s", "real_time_factor", "crashed", "termination_reason", "figure_eights_completed",
    "tracking_error_rms_deg", "tether_force_mean_N", "tether_force_min_N", "tether_force_max_N",
    "kite_speed_min_mps", "kite_speed_max_mps", "lift_to_drag_min", "lift_to_drag_max", "lift_to_drag_mean",
    "alpha_mid_mean_deg", "alpha_left_min_deg", "alpha_right_min_deg", "force_ratio_mu_min", "force_ratio_mu_max",
    "steering_input_max_m", "yaw_rate_steering_corr", "heading_rate_mean_deg_s", "tip_distance_reduction_mean_m",
    "tip_distance_variation_m", "tip_displacement_left_mean_m", "tip_displacement_right_mean_m", "metrics_window",
    "paper_comparison",
]
PNGS = ["path.png", "wing_turn.png", "alpha.png", "tip_forces.png", "forces.png", "steering.png",
        "yaw_vs_steering.png", "lift_to_drag.png", "tip_displacement.png"]
SHORT = ["--duration", "0.3", "--set", "sim.warmup_s=0.1", "--quiet"]


@pytest.mark.parametrize("args, token", [
    (["--set", "dynamics.no_such_key=1"], "dynamics.no_such_key"),
    (["--set", "dynamics.mass_le_kg=abc"], "dynamics.mass_le_kg"),
    (["--set", "wind.speed_mps=-1"], "wind.speed_mps"),
    (["--set", "dynamics.mass_kcu_kg=-3"], "dynamics.mass_kcu_kg"),
    (["--set", "kite.name=nosuchkite"], "nosuchkite"),
    (["--set", "no_equals_sign"], "no_equals_sign"),
    (["--config", "does_not_exist.yaml"], "does_not_exist.yaml"),
    (["--duration", "0"], "--duration"),
    (["--duration", "-5"], "--duration"),
    (["--duration", "nan"], "--duration"),
    (["--duration", "abc"], "--duration"),
    (["--seed", "1.5"], "--seed"),
    (["--policy", "nosuchpolicy"], "baseline"),
    (["--policy", "constant:2"], "[-1, 1]"),
    (["--policy", "constant:abc"], "constant"),
    (["--policy", "missing/model.zip"], "missing/model.zip"),
    (["--episodes", "0"], "--episodes"),
    (["--compare", "baseline", "no_such_run_or_policy"], "no_such_run_or_policy"),
    (["--policy", "random", "--compare", "baseline"], "--compare"),
])
def test_bad_input_exit_2_one_line_no_output(tmp_path, capsys, monkeypatch, args, token):
    monkeypatch.chdir(tmp_path)  # a relative config path is looked up here
    out = tmp_path / "run"
    rc = main(["--out", str(out), *args])
    cap = capsys.readouterr()
    assert rc == 2
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kite-eval: error: ")
    assert token in lines[0]
    assert cap.out == ""
    assert list(tmp_path.iterdir()) == []  # neither the folder nor a temporary sibling


def test_unknown_policy_lists_valid_ones(tmp_path, capsys):
    assert main(["--policy", "ppo2", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "'ppo2'" in err and "valid: baseline" in err and "ppo, sac" in err


@pytest.mark.parametrize("args", [["--policy", "ppo"], ["--compare", "baseline", "sac"]])
def test_shipped_name_without_model_is_one_clear_error(tmp_path, capsys, monkeypatch, args):
    import kite_env.policies

    models = tmp_path / "models"
    monkeypatch.setattr(kite_env.policies, "MODELS_DIR", models)
    name = args[-1]
    assert main([*args, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("kite-eval: error: ")
    assert f"'{name}'" in err[0] and str(models / name / "model.zip") in err[0]
    assert not (tmp_path / "x").exists()


@pytest.fixture(scope="module")
def shipped_ppo(tmp_path_factory):
    """A models folder holding a tiny kite-train PPO run (16 steps, fast fidelity, w_traction 0.3) as ``ppo``."""
    import shutil

    from kite_env.cli import train as train_cli

    base = tmp_path_factory.mktemp("models")
    hp = base / "hp.yaml"
    hp.write_text(yaml.safe_dump({"default": {"n_steps": 8, "batch_size": 8, "n_epochs": 1, "checkpoint_freq": 10**6,
                                              "eval_freq": 10**6}}))
    run = base / "run"
    assert train_cli.main(["--algo", "ppo", "--timesteps", "16", "--out", str(run), "--recipe", str(hp),
                           "--fidelity", "surrogate", "--set", "env.max_episode_s=0.2",
                           "--set", "env.w_traction=0.3"]) == 0
    models = base / "models"
    (models / "ppo").mkdir(parents=True)
    for name in ("model.zip", "vecnormalize.pkl", "config.yml", "model.json"):
        shutil.copy(run / name, models / "ppo" / name)
    return models


def test_every_policy_flies_the_one_env_of_the_command(shipped_ppo, tmp_path, monkeypatch):
    """``--policy ppo`` loads agents/models/ppo/model.zip with its normalisation; ``--compare`` flies it and every
    other policy in the one env of --config and --set (not the config of the agent's training run), and the table
    names that env."""
    import kite_env.policies

    monkeypatch.setattr(kite_env.policies, "MODELS_DIR", shipped_ppo)
    monkeypatch.setattr(kite_env.plots, "make_plots", lambda log, cfg, out: [])  # figures: tested above
    env = kite_env.envs.figure_eight.KiteFigureEightEnv(overrides=["env.max_episode_s=0.2"], fidelity="surrogate")
    agent = kite_env.policies.make_agent("ppo", env)
    assert agent.obs_norm is not None and agent.model.num_timesteps == 16
    assert kite_env.policies.policy_label("ppo") == "ppo"
    out = tmp_path / "cmp"
    assert main(["--compare", "ppo", "random", "--episodes", "2", "--duration", "0.1", "--set", "sim.warmup_s=0.02",
                 "--fidelity", "surrogate", "--out", str(out), "--quiet"]) == 0
    m = json.loads((out / "ppo" / "metrics.json").read_text())
    assert m["policy"] == "ppo" and m["episode_rows"][0]["episode_steps"] <= 5
    cfgs = [yaml.safe_load((out / name / "config.yaml").read_text()) for name in ("ppo", "random")]
    assert cfgs[0] == cfgs[1] and cfgs[0]["sim"]["fidelity"] == "surrogate" and cfgs[0]["env"]["w_traction"] == 0.5
    # the return is the sum of the reward terms with the env's weights
    r = m["episode_rows"][0]
    assert r["episode_return"] == pytest.approx(sum(v for k, v in r.items() if k.startswith("reward_")))
    md = (out / "compare.md").read_text().splitlines()
    assert md[0].startswith("env KiteFigureEightFast-v1 (fidelity surrogate), model 'default' (")
    assert "2 episode(s) of 0.1 s, seeds 0-1" in md[0]
    assert md[2] == "| | ppo | random |"


def test_an_agent_of_another_model_is_refused_naming_the_keys(shipped_ppo, tmp_path, capsys, monkeypatch):
    import kite_env.policies

    monkeypatch.setattr(kite_env.policies, "MODELS_DIR", shipped_ppo)
    out = tmp_path / "x"
    assert main(["--policy", "ppo", "--set", "control.delta_l_max_m=0.25", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "agent '" in err[0] and "control.delta_l_max_m (1.5 there, 0.25 here)" in err[0]
    assert not out.exists()


def test_out_is_a_file_or_missing(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["--out", str(f)]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert main([]) == 2  # --out is required
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_interrupt_leaves_nothing(tmp_path, capsys, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(kite_env.flight, "run_episode", interrupted)
    assert main(["--out", str(tmp_path / "run"), *SHORT]) == 130
    assert list(tmp_path.iterdir()) == []
    assert "interrupted" in capsys.readouterr().err


@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    """One short real flight (0.3 s, warm-up 0.1 s) into a non-empty folder replaced with --force."""
    base = tmp_path_factory.mktemp("eval")
    out = base / "run"
    out.mkdir()
    (out / "old.txt").write_text("previous results")
    refused = main(["--out", str(out), *SHORT])  # non-empty: refused without --force, folder untouched
    assert refused == 2 and (out / "old.txt").read_text() == "previous results"
    rc = main(["--out", str(out), "--seed", "7", "--force", *SHORT])
    return rc, base, out


def test_real_flight_writes_everything(real_run):
    rc, base, out = real_run
    assert rc == 0
    assert [p.name for p in base.iterdir()] == ["run"]  # no temporary or backup folder left
    names = {p.name for p in out.iterdir()}
    assert "old.txt" not in names
    assert {"metrics.json", "config.yaml", "timeseries.npz", "timeseries.csv", "command.txt", *PNGS} <= names
    for png in PNGS:
        data = (out / png).read_bytes()
        assert len(data) > 5000 and data[:8] == b"\x89PNG\r\n\x1a\n", png


def test_real_flight_metrics_and_config(real_run):
    _, _, out = real_run
    metrics = json.loads((out / "metrics.json").read_text())
    missing = [k for k in ISSUE_KEYS if k not in metrics]
    assert not missing
    assert metrics["policy"] == "baseline" and metrics["wind_seed"] == 7
    assert metrics["crashed"] is False and metrics["termination_reason"] == "completed"
    assert metrics["sim_time_s"] == pytest.approx(0.3)
    assert metrics["metrics_window_start_s"] == pytest.approx(0.1)
    assert metrics["tether_force_min_N"] <= metrics["tether_force_mean_N"] <= metrics["tether_force_max_N"]
    assert metrics["tether_force_min_N"] > 0
    cfg = yaml.safe_load((out / "config.yaml").read_text())
    assert cfg["sim"]["duration_s"] == pytest.approx(0.3) and cfg["sim"]["warmup_s"] == pytest.approx(0.1)
    assert cfg["wind"]["seed"] == 7
    log = read_timeseries(out / "timeseries.npz")
    t = log.series["t"]
    assert t[-1] == pytest.approx(0.3) and np.all(np.diff(t) > 0)
    assert log.meta["warmup_s"] == pytest.approx(0.1)
    # the metrics agree with the stored series over the window t >= 0.1 s
    win = t >= 0.1
    assert metrics["tether_force_max_N"] == pytest.approx(log.series["tether_force"][win].max())
    rows = (out / "timeseries.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + t.size and rows[0].startswith("t,")


def test_crash_is_a_result_not_an_error(real_run, tmp_path, capsys, monkeypatch):
    """A crashed flight: files written, crashed=true in metrics.json, a warning, exit 0 (progress bar and summary
    on, the flight and the figures replaced by stand-ins to keep the test fast)."""
    _, _, first = real_run
    log = read_timeseries(first / "timeseries.npz")
    log.meta.update(crashed=True, termination_reason="ground")

    def crashed_flight(env, agent, seed=None, options=None, progress=None, record=True):
        for t in log.series["t"][::4]:
            progress(float(t))
        return log, {"wind_seed": 0, "episode_return": -50.0, "episode_steps": 3, "termination_reason": "ground"}

    monkeypatch.setattr(kite_env.flight, "run_episode", crashed_flight)
    monkeypatch.setattr(kite_env.plots, "make_plots", lambda log, cfg, out: [])
    out = tmp_path / "crash"
    rc = main(["--out", str(out), "--duration", "0.3", "--set", "sim.warmup_s=0.1"])
    cap = capsys.readouterr()
    assert rc == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["crashed"] is True and metrics["termination_reason"] == "ground"
    assert "kite-eval: warning:" in cap.err and "ground" in cap.err
    assert "tether force min/mean/max" in cap.out and "traction (tether) force range" in cap.out


def test_damaged_model_file_is_one_clear_error(tmp_path, capsys):
    bad = tmp_path / "model.zip"
    bad.write_text("not a zip")
    assert main(["--policy", str(bad), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a Stable-Baselines3 model zip" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.zip"]


def test_episodes_give_rows_and_the_compare_table(real_run, tmp_path):
    """Two episodes each of random and constant:0 (0.15 s), next to the earlier baseline run folder: one table in
    Markdown and CSV, one run folder per evaluated policy with its episode rows."""
    _, _, first = real_run
    out = tmp_path / "cmp"
    rc = main(["--compare", "random", "constant:0", str(first), "--episodes", "2", "--duration", "0.15",
               "--set", "sim.warmup_s=0.05", "--seed", "3", "--out", str(out), "--quiet"])
    assert rc == 0
    assert {"compare.md", "compare.csv", "random", "constant_0", "command.txt"} <= {p.name for p in out.iterdir()}
    for name in ("random", "constant_0"):
        m = json.loads((out / name / "metrics.json").read_text())
        assert m["episodes"] == 2 and len(m["episode_rows"]) == 2
        assert [r["seed"] for r in m["episode_rows"]] == [3, 4]
        assert [r["wind_seed"] for r in m["episode_rows"]] == [3, 4]
        assert m["episode_return"] == m["episode_rows"][0]["episode_return"]
        rets = [r["episode_return"] for r in m["episode_rows"]]
        assert m["episode_return_mean"] == pytest.approx(np.mean(rets))
        for r in m["episode_rows"]:  # the reward terms add up to the return
            terms = sum(v for k, v in r.items() if k.startswith("reward_"))
            assert terms == pytest.approx(r["episode_return"])
        lines = (out / name / "episodes.csv").read_text().strip().splitlines()
        assert len(lines) == 3 and lines[0].startswith("episode,seed,")
    const = json.loads((out / "constant_0" / "metrics.json").read_text())
    # constant action, no turbulence: both episodes fly the same flight
    assert const["episode_rows"][0]["episode_return"] == const["episode_rows"][1]["episode_return"]
    md = (out / "compare.md").read_text().strip().splitlines()
    assert md[0].startswith("env KiteFigureEight-v1 (fidelity fe), model 'default' (") and "seeds 3-4" in md[0]
    assert md[2] == f"| | random | constant_0 | {first.name} |"
    body = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]] for ln in md[4:]}
    assert body["episodes"] == ["2", "2", "1"] and "+-" in body["return"][0] and "+-" not in body["return"][2]
    rows = (out / "compare.csv").read_text().strip().splitlines()
    assert len(rows) == 4 and rows[0].startswith("policy,episodes,crashed,end,episode_return_mean,episode_return_se")


def test_run_folders_joined_by_plus_are_one_column_and_traction_is_paired_by_seed(real_run, tmp_path, capsys):
    """One policy flown in parts (seeds 3 and 4 in two runs) pooled into one column by ``A+B``: the same episodes as
    one run of two episodes, so its paired traction difference from that run is 0 over 2 pairs; parts of another
    policy, another configuration or a repeated seed are refused (exit 2, nothing written)."""
    _, _, first = real_run
    short = ["--duration", "0.15", "--set", "sim.warmup_s=0.05", "--quiet"]

    def fly(name, seed, *extra, policy="constant:0", episodes=1):
        out = tmp_path / name
        assert main(["--policy", policy, "--episodes", str(episodes), "--seed", str(seed), "--out", str(out),
                     *short, *extra]) == 0
        return str(out)

    whole, a, b = fly("whole", 3, episodes=2), fly("a", 3), fly("b", 4)
    out = tmp_path / "cmp"
    assert main(["--compare", whole, f"{a}+{b}", "--out", str(out), "--quiet"]) == 0
    md = (out / "compare.md").read_text().strip().splitlines()
    assert md[0] == "| | whole | a+1 |"
    body = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]] for ln in md[2:]}
    assert body["episodes"] == ["2", "2"] and body["return"][0] == body["return"][1]
    assert body["traction vs whole, paired by seed [%]"] == ["-", "+0.00 +- 0 (2 pairs)"]
    capsys.readouterr()
    for parts, why in (([a, a], "repeat a seed"), ([a, str(first)], "one column pools one policy"),
                       ([a, fly("windy", 4, "--set", "wind.speed_mps=6")], "different configurations (")):
        bad = tmp_path / "bad"
        assert main(["--compare", whole, "+".join(parts), "--out", str(bad), "--quiet"]) == 2
        assert why in capsys.readouterr().err and not bad.exists()


def test_a_random_episode_does_not_depend_on_the_episodes_before_it():
    """RandomAgent is reseeded with each episode's seed by run_episode: episode 1 of a run is the episode flown
    alone with its seed (kite-eval end-reasons flies each episode alone, by seed)."""
    from kite_env.policies import RandomAgent

    def returns(seeds):
        env = kite_env.envs.figure_eight.KiteFigureEightEnv(overrides=["env.max_episode_s=0.3"], fidelity="surrogate")
        agent = RandomAgent(seeds[0])
        out = [kite_env.flight.run_episode(env, agent, seed=s, record=False)[1]["episode_return"] for s in seeds]
        env.close()
        return out

    both, alone = returns([4, 5]), returns([5])
    assert both[1] == alone[0]
    assert both[0] != both[1]  # the seeds draw other actions


def test_a_start_without_a_converged_wing_is_one_message_and_nothing_written(tmp_path, capsys):
    """The wing at the start does not converge (here: one Newton iteration allowed, not even from the faster starts
    of the continuation): one line naming it, exit 1, no output folder (before: a traceback)."""
    out = tmp_path / "run"
    assert main(["--duration", "0.1", "--out", str(out), "--set", "fsi.max_newton_iter=1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert "reset failed: the wing did not converge at the start" in err[-1] and "nothing written" in err[-1]
    assert not out.exists() and not list(tmp_path.iterdir())


def test_a_numerical_failure_of_the_wing_with_inertia_is_exit_3_with_its_residual_history(tmp_path, capsys,
                                                                                       monkeypatch):
    """A step of the wing with inertia that fails even in sixteenths (forced here from t = 0.1 s) is a bug of the
    simulator, not an end of the flight: kite-eval says where and in which conditions, prints the wing
    solver's residual history, exits 3 and writes nothing."""
    from kite_env.dynamics.wing_dynamics import WingDynamics
    from kite_env.fsi import WingConvergenceError

    step = WingDynamics.step

    def failing(self, dt, *args, **kw):
        if self.t_forced >= 0.1:
            raise WingConvergenceError("dynamic wing step failed: test: forced failure\nresidual history (last 2):\n"
                                       "    1  5.0e+02\n    2  4.0e+02", [])
        self.t_forced += dt
        return step(self, dt, *args, **kw)

    monkeypatch.setattr(WingDynamics, "t_forced", 0.0, raising=False)
    monkeypatch.setattr(WingDynamics, "step", failing)
    out = tmp_path / "run"
    assert main(["--duration", "0.3", "--out", str(out)]) == 3
    err = capsys.readouterr().err
    first = [line for line in err.splitlines() if line.startswith("kite-eval: error:")]
    assert len(first) == 1 and first[0].startswith("kite-eval: error: numerical failure at t = 0.1")
    assert "(wind 5.000 m/s" in first[0] and first[0].endswith("nothing written")
    assert "not an end of the flight" in err and "residual history (last 2)" in err and "4.0e+02" in err
    assert not out.exists() and not list(tmp_path.iterdir())
