"""scripts/start_transients.py: episodes grouped by the path's curvature at their start, early ends counted."""

from __future__ import annotations

import json

import pytest


def test_summary_counts_early_ends_but_not_the_time_limit(load_script):
    mod = load_script("start_transients")
    rows = [{"group": "turn", "end_s": 0.1, "termination_reason": "wing did not converge"},
            {"group": "turn", "end_s": 0.3, "termination_reason": "ground"},
            {"group": "turn", "end_s": 0.8, "termination_reason": "ground"},
            {"group": "straight", "end_s": 0.2, "termination_reason": "time limit"},
            {"group": "straight", "end_s": 0.4, "termination_reason": "slack tether"}]
    turn, straight = mod.summary(rows, early=0.5)
    assert (turn["episodes"], turn["early"], turn["median_end_s"]) == (3, 2, pytest.approx(0.2))
    assert turn["reasons"] == {"wing did not converge": 1, "ground": 1}
    assert (straight["episodes"], straight["early"], straight["reasons"]) == (2, 1, {"slack tether": 1})


def test_script_groups_episodes_by_the_curvature_at_the_start(load_script, tmp_path, capsys):
    mod = load_script("start_transients")
    out = tmp_path / "st.json"
    assert mod.main(["--fidelity", "surrogate", "--episodes", "6", "--duration", "0.1", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    rows = data["episodes"]
    assert [r["seed"] for r in rows] == list(range(7000, 7006))
    for r in rows:
        assert r["group"] == ("turn" if abs(r["curvature_per_rad"]) > 1.0 else "straight")
        assert 4.0 <= r["wind_speed_mps"] <= 10.0 and 18.0 <= r["initial_speed_mps"] <= 26.0
        assert 0.0 < r["end_s"] <= 0.1 + 1e-9
    assert {g["group"] for g in data["summary"]} == {"turn", "straight"}
    assert sum(g["episodes"] for g in data["summary"]) == 6
    assert "median end" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [["--episodes", "0"], ["--curvature", "nan"], ["--set", "env.bogus=1"],
                                  ["--policy", "nope"], ["--recipe", "missing.yaml"]])
def test_bad_input_is_one_error_and_writes_nothing(load_script, tmp_path, argv):
    mod = load_script("start_transients")
    out = tmp_path / "st.json"
    with pytest.raises(SystemExit) as exc:
        mod.main([*argv, "--out", str(out)])
    assert exc.value.code == 2 and not out.exists()
