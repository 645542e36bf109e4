"""kite-bench (kite_env.benchmark, kite_env.cli.bench): what the full model's benchmark and the static wing's
benchmark (``kite-bench wing``) measure and report, and bad input refused with nothing written."""

import json

import pytest

from kite_env.cli import bench


def test_kite_bench_reports_the_full_models_newton_iterations():
    """kite-bench's fe row: wall time per simulated second and the Newton iterations per physics step (the speed
    targets: mean below 2, p99 below 10) from the env's ``info["newton_iters"]``."""
    from kite_env.cli.bench import bench_env

    r = bench_env(3)
    assert r["steps"] == 3 and r["real_time_factor"] > 0.0
    assert 1.0 <= r["newton_iters_mean"] <= r["newton_iters_p99"] <= r["newton_iters_max"] <= 30


def test_kite_bench_times_the_full_model_at_another_time_step(tmp_path, capsys):
    """The full model at a 10 ms physics step (``--set dynamics.dt_s=0.01``, the time-step study): the requested
    steps of the same 20 ms control period, the real-time factor the wall time per simulated second; bad input is
    exit 2 with nothing written."""
    out = tmp_path / "bench"
    assert bench.main(["--out", str(out), "--fidelity", "fe", "--steps", "2", "--set", "dynamics.dt_s=0.01"]) == 0
    data = json.loads((out / "bench.json").read_text())
    assert list(data) == ["fe"]
    fe = data["fe"]
    assert fe["steps"] == 2 and fe["control_dt_s"] == pytest.approx(0.02)
    assert fe["real_time_factor"] == pytest.approx(1.0 / (fe["env_steps_per_s"] * fe["control_dt_s"]))
    assert fe["newton_iters_mean"] >= 1.0 and fe["reset_s"] > 0.0
    assert "env steps/s" in capsys.readouterr().out
    bad = tmp_path / "bad"
    assert bench.main(["--out", str(bad), "--fidelity", "fe", "--steps", "0"]) == 2
    assert bench.main(["--out", str(bad), "--fidelity", "fe", "--steps", "2", "--set", "dynamics.dt_s=-1"]) == 2
    assert "--steps" in capsys.readouterr().err and not bad.exists()


def test_kite_bench_wing_times_each_resolution_and_refuses_bad_input(tmp_path, capsys):
    """``kite-bench wing``: one row per mesh resolution (a cold solve and the warm steps asked for), the summary row
    the default resolution's or else the first, the paper's wall time per step; bad input is exit 2 with nothing
    written."""
    out = tmp_path / "wing"
    assert bench.main(["wing", "--out", str(out), "--resolutions", "21x4", "--steps", "3"]) == 0
    data = json.loads((out / "bench_wing.json").read_text())
    (row,) = data["resolutions"]
    assert (row["n_sections"], row["n_chord"], row["n_steps"]) == (21, 4, 3) and row["cold_failed"] is False
    assert row["dof"] == 6 * row["nodes"] and row["cold_solve_s"] > 0.0
    assert 0.0 < row["warm_step_ms_median"] <= row["warm_step_ms_p90"] and row["failed_steps"] == 0
    assert {k: data[k] for k in row} == row  # the summary row: 37x6 is not among them, so the first
    assert data["paper_wall_per_step_ms"] == pytest.approx(27.5 * 5.3) and "python" in data["machine"]
    text = capsys.readouterr().out
    assert "kite-bench wing: rhino16 21x4 ..." in text and "| 21 | 4 | 84 |" in text
    for argv in (["--resolutions", "21x4x2"], ["--resolutions", "21x"], ["--steps", "0"], ["--kite", "nope"]):
        assert bench.main(["wing", "--out", str(tmp_path / "x"), *argv]) == 2, argv
        assert capsys.readouterr().err.startswith("kite-bench wing: error: ")
    assert not (tmp_path / "x").exists()


def test_kite_bench_warm_flies_each_fidelity_it_is_given_and_refuses_an_unknown_one(capsys):
    """``kite-bench warm`` (run by the test command before its workers start) flies the fidelities it is given and
    names each with its wall time; an unknown fidelity is exit 2."""
    assert bench.main(["warm", "--fidelity", "surrogate", "--fidelity", "batched"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[2] for ln in lines] == ["surrogate", "batched"]
    assert all(ln.startswith("kite-bench warm: ") and ln.endswith(" s") for ln in lines)
    assert bench.main(["warm", "--fidelity", "rigid"]) == 2
    assert "invalid choice: 'rigid'" in capsys.readouterr().err
