"""The soak (kite_env.soak, kite-bench soak): random-action episodes of the fast env, every step checked."""

from __future__ import annotations

import json

from kite_env.cli import bench


def test_a_short_soak_of_the_fast_env_counts_every_episode(tmp_path):
    assert bench.main(["soak", "--fidelity", "surrogate", "--episodes", "6", "--duration", "2",
                       "--out", str(tmp_path)]) == 0
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


def test_soaks_flown_in_parts_merge_into_one_table(tmp_path):
    """Two parts over disjoint seeds add up episode by episode; overlapping seeds or another fidelity are refused
    with exit 2 and nothing written."""
    a, b, out = tmp_path / "a", tmp_path / "b", tmp_path / "all"
    assert bench.main(["soak", "--fidelity", "surrogate", "--episodes", "2", "--duration", "1", "--out", str(a)]) == 0
    assert bench.main(["soak", "--fidelity", "surrogate", "--episodes", "3", "--seed", "2", "--duration", "1",
                       "--out", str(b)]) == 0
    parts = [json.loads((d / "soak.json").read_text()) for d in (a, b)]
    assert bench.main(["soak", "--merge", str(b), str(a), "--out", str(out)]) == 0
    res = json.loads((out / "soak.json").read_text())
    assert res["episodes"] == 5 and res["seeds"] == [0, 4] and res["seed_ranges"] == [[0, 1], [2, 4]]
    assert res["steps"] == parts[0]["steps"] + parts[1]["steps"]
    assert sum(res["ends"].values()) == 5
    assert (out / "soak.md").read_text().startswith("| surrogate: 5 random-action episodes of up to 1 s, seeds 0-4")
    assert bench.main(["soak", "--merge", str(a), str(a), "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()


def test_bad_soak_input_is_exit_2_and_nothing_written(tmp_path, capsys):
    """A missing --fidelity, a bad count, an unknown config key or a folder that is not a soak: one error line, exit
    2, no output folder; ``kite-bench soak --help`` is its own."""
    out = tmp_path / "x"
    for argv in (["--episodes", "2"], ["--fidelity", "surrogate", "--episodes", "0"],
                 ["--fidelity", "surrogate", "--episodes", "1", "--set", "env.nope=1"],
                 ["--merge", str(tmp_path)]):
        assert bench.main(["soak", *argv, "--out", str(out)]) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("kite-bench soak: error: "), err
        assert not out.exists()
    assert bench.main(["soak", "--help"]) == 0
    assert capsys.readouterr().out.startswith("usage: kite-bench soak")
