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
