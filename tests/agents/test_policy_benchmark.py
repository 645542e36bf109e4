"""The policy benchmark: the shipped PPO and SAC agents against the paper's controller and a negative control, in the
fast fidelity of the default model, on held-out seeds (70000 and up: used neither in training, nor in its evaluations,
nor in the choice of the checkpoint; ``kite_env.training.select_checkpoint`` lists the project's seed ranges).

Every policy flies the same episodes: one env, ``reset(seed=s)`` for each, so each seed's start (the start table's
entry for the drawn wind, turbulence, start point and speed) is the same for all; the draws are those the agent was
trained in (the shipped recipe's conditions: wind 4-10 m/s, turbulence up to 0.1, starts on the straight parts of the
figure-eight). The comparison is paired, seed by seed: the difference of the returns, mean +- standard error.

What it asserts is what ``agents/models/ppo/README.md`` and ``agents/models/sac/README.md`` report: each agent's lead
over the paper's controller on these episodes (within three standard errors of the measured lead, and more than three
above zero), and ``constant:0`` (no steering at all) losing to the controller by more than three standard errors, so
that a benchmark that could not tell a steering policy from none fails.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

SEEDS = range(70000, 70016)
DURATION_S = 20.0
#: the paired lead of the shipped PPO over the baseline on SEEDS (return per 20 s episode) when it shipped:
#: 218.3 +- 43.4 (agents/models/ppo/README.md); the baseline's mean return is 1,938
PPO_LEAD = 218.3
#: the same for the shipped SAC (it decides every fifth step and holds its action): 243.9 +- 19.6
#: (agents/models/sac/README.md)
SAC_LEAD = 243.9


def fly_benchmark(specs=("baseline", "ppo", "sac", "constant:0")) -> dict[str, list[dict]]:
    """Each policy of ``specs`` over the episodes of :data:`SEEDS`: ``run_episode``'s info per episode."""
    from kite_env.config import load_config
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.flight import evaluation_config, run_episode
    from kite_env.policies import make_agent
    from kite_env.training import default_recipe

    recipe = yaml.safe_load(default_recipe("ppo").read_text())["KiteFigureEightFast-v1"]["env"]
    cfg = load_config(None, [f"{k}={v}" for k, v in recipe.items()] + ["sim.fidelity=surrogate"])
    env = KiteFigureEightEnv(config=evaluation_config(cfg, DURATION_S, randomize=True))
    out: dict[str, list[dict]] = {}
    for spec in specs:
        agent = make_agent(spec, env)
        out[spec] = [run_episode(env, agent, seed=s, record=False)[1] for s in SEEDS]
    return out


@pytest.fixture(scope="module")
def flights():
    return fly_benchmark()


def _paired(flights, a: str, b: str) -> tuple[float, float]:
    d = np.array([x["episode_return"] - y["episode_return"] for x, y in zip(flights[a], flights[b])])
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(len(d)))


def test_every_policy_flew_the_same_episodes(flights):
    keys = ("wind_speed_mps", "turbulence_intensity", "wind_seed", "start_s", "initial_speed_mps")
    for spec in ("ppo", "sac", "constant:0"):
        for x, y in zip(flights["baseline"], flights[spec]):
            assert [x[k] for k in keys] == [y[k] for k in keys]


def test_the_shipped_ppo_leads_the_papers_controller_and_does_not_crash(flights):
    """The lead, and how the agent's episodes end: none on the ground; one of the 16 (seed 70002, where the baseline
    also scores its lowest) leaves the fast wing's fitted envelope at 16.8 s, as when it shipped."""
    lead, se = _paired(flights, "ppo", "baseline")
    assert lead > 3.0 * se
    assert abs(lead - PPO_LEAD) <= 3.0 * se, (lead, se)
    ends = [x["termination_reason"] for x in flights["ppo"]]
    assert "ground" not in ends
    assert sum(e == "outside surrogate envelope" for e in ends) <= 1, ends
    assert all(e in ("time limit", "outside surrogate envelope") for e in ends), ends


def test_the_shipped_sac_leads_the_papers_controller_and_completes_every_episode(flights):
    lead, se = _paired(flights, "sac", "baseline")
    assert lead > 3.0 * se
    assert abs(lead - SAC_LEAD) <= 3.0 * se, (lead, se)
    assert [x["termination_reason"] for x in flights["sac"]] == ["time limit"] * len(SEEDS)


def test_no_steering_loses_to_the_papers_controller(flights):
    gap, se = _paired(flights, "constant:0", "baseline")
    assert gap < -3.0 * se, (gap, se)
