"""The flight benchmark (kite_env.benchmark.bench_flight, scripts/bench_flight.py): what it measures and reports."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from kite_env.benchmark import bench_flight, format_flight_table

ROOT = Path(__file__).resolve().parents[2]


def test_bench_flight_times_the_requested_flight_per_time_step():
    rows = bench_flight(duration_s=0.04, dt_values=(0.005, 0.01))
    assert [r["dt_ms"] for r in rows] == [5.0, 10.0]
    for r in rows:
        assert r["completed"] and r["sim_time_s"] == pytest.approx(0.04)
        assert r["real_time_factor"] == pytest.approx(r["wall_time_s"] / r["sim_time_s"])
        assert 0.0 < r["step_ms_median"] <= r["step_ms_p90"]
        assert 0.0 <= r["other_wall_s"] < r["wall_time_s"]
    table = format_flight_table(rows)
    assert table.count("\n") == 3 and "| 10.0 |" in table


def test_bench_flight_script_rejects_bad_input_and_writes_nothing(tmp_path):
    out = tmp_path / "bench"
    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "bench_flight.py"), "--out", str(out),
                          "--dt-ms", "5,x"], capture_output=True, text=True)
    assert res.returncode == 2 and "--dt-ms" in res.stderr
    assert not out.exists()
    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "bench_flight.py"), "--out", str(out),
                          "--duration", "0.02", "--dt-ms", "10"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    data = json.loads((out / "bench_flight.json").read_text())
    assert data["flight"][0]["dt_ms"] == 10.0 and data["paper_real_time_factor"] == 27.5


def test_kite_bench_reports_the_full_models_newton_iterations():
    """kite-bench's fe row: wall time per simulated second and the Newton iterations per physics step (the speed
    targets: mean below 2, p99 below 10) from the env's ``info["newton_iters"]``."""
    from kite_env.cli.bench import bench_env

    r = bench_env(3)
    assert r["steps"] == 3 and r["real_time_factor"] > 0.0
    assert 1.0 <= r["newton_iters_mean"] <= r["newton_iters_p99"] <= r["newton_iters_max"] <= 30
