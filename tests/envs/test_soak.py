"""The soak (kite_env.soak, scripts/soak.py): random-action episodes of the fast env, every step checked."""

from __future__ import annotations

import json


def test_a_short_soak_of_the_fast_env_counts_every_episode(tmp_path, load_script):
    mod = load_script("soak")
    assert mod.main(["--fidelity", "surrogate", "--episodes", "6", "--duration", "2", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "soak.json").read_text())
    assert res["episodes"] == 6 and sum(res["ends"].values()) == 6
    assert res["non_finite_steps"] == 0 and res["exceptions"] == []
    assert res["steps"] > 6 and "exception" not in res["ends"]
    assert (tmp_path / "soak.md").read_text().startswith("| surrogate: 6 random-action episodes")


def test_an_exception_is_counted_not_raised(monkeypatch):
    from kite_env import soak
    from kite_env.envs.figure_eight import KiteFigureEightEnv

    def broken(self, action):
        raise FloatingPointError("forced by the test")

    monkeypatch.setattr(KiteFigureEightEnv, "step", broken)
    res = soak.soak("surrogate", 2, duration_s=1.0)
    assert res["ends"] == {"exception": 2} and len(res["exceptions"]) == 2
    assert res["exceptions"][0]["exception"] == "FloatingPointError: forced by the test"


def test_the_batched_soak_counts_episodes_as_they_end():
    """The vector env (64 kites): 80 episodes of up to 1 s (50 control steps), the 64 kites' first episodes and 16 of
    their second ones (after the autoreset), each counted once with its own steps."""
    from kite_env import soak

    res = soak.soak("batched", 80, seed=5, duration_s=1.0)
    assert res["episodes"] == 80 and sum(res["ends"].values()) == 80
    assert res["non_finite_steps"] == 0 and res["exceptions"] == []
    assert res["ends"].get("time limit", 0) >= 1
    assert res["steps"] <= 80 * 50 and res["steps"] > 40 * 50


def test_an_exception_of_the_batch_is_counted_not_raised(monkeypatch):
    from kite_env import soak
    from kite_env.envs.vector import KiteFigureEightVectorEnv

    def broken(self, actions):
        raise FloatingPointError("forced by the test")

    monkeypatch.setattr(KiteFigureEightVectorEnv, "step", broken)
    res = soak.soak("batched", 10, duration_s=1.0)
    assert res["ends"] == {"exception": 1}
    assert res["exceptions"][0]["exception"] == "FloatingPointError: forced by the test"


def test_soaks_flown_in_parts_merge_into_one_table(tmp_path, load_script):
    """Two parts over disjoint seeds add up episode by episode; overlapping seeds or another fidelity are refused
    with exit 2 and nothing written."""
    mod = load_script("soak")
    a, b, out = tmp_path / "a", tmp_path / "b", tmp_path / "all"
    assert mod.main(["--fidelity", "surrogate", "--episodes", "2", "--duration", "1", "--out", str(a)]) == 0
    assert mod.main(["--fidelity", "surrogate", "--episodes", "3", "--seed", "2", "--duration", "1",
                     "--out", str(b)]) == 0
    parts = [json.loads((d / "soak.json").read_text()) for d in (a, b)]
    assert mod.main(["--merge", str(b), str(a), "--out", str(out)]) == 0
    res = json.loads((out / "soak.json").read_text())
    assert res["episodes"] == 5 and res["seeds"] == [0, 4] and res["seed_ranges"] == [[0, 1], [2, 4]]
    assert res["steps"] == parts[0]["steps"] + parts[1]["steps"]
    assert sum(res["ends"].values()) == 5
    assert (out / "soak.md").read_text().startswith("| surrogate: 5 random-action episodes of up to 1 s, seeds 0-4")
    assert mod.main(["--merge", str(a), str(a), "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()
