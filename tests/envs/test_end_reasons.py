"""``kite-eval end-reasons`` (kite_env.evaluation.end_reasons): its count of why randomised episodes end.

The episodes fly in the fast fidelity for speed. A numerical failure of the wing with inertia or a start that does not
converge is forced by patching the env for one seed (``jobs`` 1: the episodes fly in this process); what is checked is
the count's own logic: the count, the kind, the time and wind of a failure, its kept message, the exit status, and
that its episodes are kite-eval's (``--randomize --seed``), alone or ``--jobs`` at a time.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from kite_env.cli import eval as eval_cli
from kite_env.envs.figure_eight import KiteFigureEightEnv, StartError
from kite_env.evaluation import END_REASON_RANGES

FAST = ["--fidelity", "surrogate", "--duration", "0.3"]


def _rows(out: Path) -> list[dict]:
    with open(out / "episodes.csv") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture()
def seeded(monkeypatch):
    """The env remembers the seed of its last reset (``_test_seed``)."""
    reset = KiteFigureEightEnv.reset

    def remember(self, *, seed=None, options=None):
        self._test_seed = seed
        return reset(self, seed=seed, options=options)

    monkeypatch.setattr(KiteFigureEightEnv, "reset", remember)


def test_a_numerical_failure_is_counted_with_its_time_and_wind_and_the_command_exits_3(seeded, monkeypatch,
                                                                                       tmp_path, capsys):
    from kite_env.dynamics.simulator import NumericalFailure, SimulationError

    step = KiteFigureEightEnv.step

    def failing(self, action):
        if self._test_seed == 301 and self.steps == 5:
            raise NumericalFailure(SimulationError("wing did not converge", "forced", "residual history (last 1): "
                                                   "test"), 7.25, self._conditions())
        return step(self, action)

    monkeypatch.setattr(KiteFigureEightEnv, "step", failing)
    out = tmp_path / "er"
    rc = eval_cli.main(["end-reasons", "--episodes", "4", "--jobs", "1", "--seed", "300", *FAST, "--out", str(out)])
    assert rc == 3
    rows = _rows(out)
    assert [int(r["seed"]) for r in rows] == [300, 301, 302, 303] and [r["episode"] for r in rows] == list("0123")
    failed = rows[1]
    assert failed["termination_reason"] == "numerical failure" and float(failed["sim_time_s"]) == 7.25
    assert 4.0 <= float(failed["wind_speed_mps"]) <= 10.0
    assert f"wind {float(failed['wind_speed_mps']):.3f} m/s" in (out / "failures" / "seed_301.log").read_text()
    assert "residual history (last 1): test" in (out / "failures" / "seed_301.log").read_text()
    assert sorted(p.name for p in (out / "failures").iterdir()) == ["seed_301.log"]
    table = (out / "end_reasons.md").read_text()
    assert table.startswith(f"4 episodes of 0.3 s, policy random, `{' '.join(END_REASON_RANGES)} "
                            "sim.fidelity=surrogate`")
    assert "| numerical failure | 1 | numerical (a bug) | 7.25 | 7.25 |" in table
    others = [r for r in rows if r is not failed]
    for reason in {r["termination_reason"] for r in others}:
        n = sum(r["termination_reason"] == reason for r in others)
        kind = "none" if reason == "completed" else "physical"
        assert f"| {reason} | {n} | {kind} | " in table
    winds = sorted(float(r["wind_speed_mps"]) for r in rows)
    assert table.rstrip().endswith(f"wind {winds[0]:.1f}-{winds[-1]:.1f} m/s; starts that did not converge "
                                   "(drawn again): 0")
    assert table in capsys.readouterr().out + "\n"


def test_a_start_that_does_not_converge_stops_the_count_and_bad_input_is_exit_2(monkeypatch, tmp_path, capsys):
    reset = KiteFigureEightEnv.reset

    def no_start(self, *, seed=None, options=None):
        if seed == 11:
            raise StartError("reset failed: the wing did not converge at the start (forced)")
        return reset(self, seed=seed, options=options)

    monkeypatch.setattr(KiteFigureEightEnv, "reset", no_start)
    out = tmp_path / "x"
    assert eval_cli.main(["end-reasons", "--episodes", "3", "--jobs", "1", "--seed", "10", *FAST,
                          "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["kite-eval end-reasons: error: seed 11: reset failed: the wing did not converge at the start "
                   "(forced); nothing written"]
    for argv in (["--set", "env.nope=1"], ["--policy", "nope"], ["--episodes", "0"], ["--duration", "0"],
                 ["--config", str(tmp_path / "none.yaml")]):
        assert eval_cli.main(["end-reasons", "--jobs", "1", *FAST, *argv, "--out", str(out)]) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("kite-eval end-reasons: error: "), err
    assert not out.exists()


def test_the_episodes_are_kite_evals_alone_or_jobs_at_a_time(tmp_path, monkeypatch):
    """Three episodes counted with two processes, with one, and flown by ``kite-eval --randomize --episodes 3`` in
    one env: the same episodes (all columns but the wall time's), so a count splits its episodes freely."""
    import kite_env.plots

    monkeypatch.setattr(kite_env.plots, "make_plots", lambda log, cfg, out: [])
    wall = "real_time_factor"
    counts = []
    for jobs in ("2", "1"):
        out = tmp_path / f"jobs_{jobs}"
        assert eval_cli.main(["end-reasons", "--episodes", "3", "--jobs", jobs, "--seed", "20", *FAST,
                              "--out", str(out)]) == 0
        assert not (out / "failures").exists()
        counts.append([{k: v for k, v in r.items() if k != wall} for r in _rows(out)])
    assert counts[0] == counts[1] and [r["seed"] for r in counts[0]] == ["20", "21", "22"]
    sets = [a for s in END_REASON_RANGES for a in ("--set", s)]
    ev = tmp_path / "eval"
    assert eval_cli.main(["--policy", "random", "--randomize", "--episodes", "3", "--seed", "20", *FAST, *sets,
                          "--out", str(ev), "--quiet"]) == 0
    assert [{k: v for k, v in r.items() if k != wall} for r in _rows(ev)] == counts[0]
    assert (tmp_path / "jobs_1" / "end_reasons.md").read_text() == (tmp_path / "jobs_2" / "end_reasons.md").read_text()
    m = json.loads((ev / "metrics.json").read_text())
    assert [r["termination_reason"] for r in m["episode_rows"]] == [r["termination_reason"] for r in counts[0]]
