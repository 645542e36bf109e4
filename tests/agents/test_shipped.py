"""The shipped agents (agents/models/ppo, agents/models/sac): they load by name, beat the paper's controller on
return on fixed held-out seeds in the fast fidelity under the training conditions, and fly the full model."""

from __future__ import annotations

import numpy as np
import pytest

from agents.policies import SHIPPED, make_agent, shipped_model
from kite_env.cli.train import FAST_ENV_ID, load_hyperparameters, recipe_overrides
from kite_env.envs.figure_eight import KiteFigureEightEnv
from kite_env.flight import evaluation_config, run_episode

SEEDS = range(2000, 2012)  # held out: training used seeds 0.. (kites) and 10,000.. (evaluations)
#: the benchmark's held-out seeds (scripts/benchmark_agents.py, README table); checkpoints are chosen on 3000..
#: (scripts/select_checkpoint.py), so these seeds took no part in training or in the choice of the shipped model
BENCHMARK_SEEDS = range(1000, 1020)
#: shipped agents that beat the paper's controller on return on BENCHMARK_SEEDS (README: trained agents; SAC does
#: not: 134.4 against 144.7)
BEATS_BASELINE = ("ppo",)
#: a larger held-out set: the validation seeds of scripts/select_checkpoint.py are 3000-3049, so 3050-3199 took no
#: part in training or in the choice of checkpoint either (150 episodes: a return difference of ~15 is ~2 standard
#: errors of the paired difference, where 20 episodes resolve only ~60)
LARGE_SEEDS = range(3050, 3200)


def _conditions() -> list[str]:
    """The PPO recipe's randomised conditions (wind 4-10 m/s, turbulence, random start); its training-only start
    rule becomes the evaluations' (flight.evaluation_config)."""
    return recipe_overrides(load_hyperparameters("configs/agents/ppo.yaml", "ppo", FAST_ENV_ID))


def _returns(spec: str, fidelity: str, seeds, duration: float = 60.0) -> list[float]:
    from kite_env.config import load_config

    model = shipped_model(spec) if spec in SHIPPED else None
    cfg = load_config(str(model.parent / "config.yml") if model else None,
                      [*_conditions(), f"sim.fidelity={fidelity}"])
    env = KiteFigureEightEnv(config=evaluation_config(cfg, duration, randomize=True))
    agent = make_agent(spec, env)
    return [run_episode(env, agent, seed=s, record=False)[1]["episode_return"] for s in seeds]


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_agent_loads_by_name_and_flies_the_fast_fidelity(name):
    """The shipped agent loads by name with its training config and normalisation, and flies held-out seeds of the
    training conditions deterministically (same seed, same return). Whether it beats the baseline on return is
    tested below for the agents that do (BEATS_BASELINE)."""
    assert shipped_model(name).is_file(), f"{name} is not shipped"
    seeds = list(SEEDS)[:4]
    first = _returns(name, "surrogate", seeds)
    assert np.all(np.isfinite(first)) and len(set(np.round(first, 6))) > 1  # different conditions, different flights
    assert _returns(name, "surrogate", seeds[:1]) == first[:1]
    base = _returns("baseline", "surrogate", seeds)
    assert not np.allclose(first, base)  # a policy of its own, not the controller


@pytest.mark.parametrize("name", BEATS_BASELINE)
def test_shipped_agent_beats_the_baseline_on_held_out_seeds(name):
    """On the benchmark's 20 held-out episodes in the fast fidelity (training conditions: wind 4-10 m/s, turbulence,
    random start) the agent's mean return is higher than the paper's controller's, and it is not one lucky episode:
    it does at least as well in most episodes."""
    agent = np.array(_returns(name, "surrogate", BENCHMARK_SEEDS))
    base = np.array(_returns("baseline", "surrogate", BENCHMARK_SEEDS))
    assert agent.mean() > base.mean(), (agent.mean(), base.mean())
    assert np.sum(agent >= base - 1.0) >= 15, np.round(agent - base, 1)


@pytest.fixture(scope="module")
def baseline_large():
    return np.array(_returns("baseline", "surrogate", LARGE_SEEDS))


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_agent_beats_the_baseline_on_150_held_out_episodes(name, baseline_large):
    """Every shipped agent: higher mean return than the paper's controller over 150 held-out episodes of the
    training conditions (paired: the same wind, turbulence and start), by more than one standard error of the
    paired difference, and at least as good in most episodes."""
    d = np.array(_returns(name, "surrogate", LARGE_SEEDS)) - baseline_large
    se = d.std() / np.sqrt(d.size)
    assert d.mean() > se > 0, (d.mean(), se)
    assert np.mean(d >= -1.0) > 0.6, np.mean(d >= -1.0)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_agent_flies_the_full_model(name):
    """A short full-model episode: the agent's actions drive the FE wing (the flight moves and steers)."""
    from kite_env.config import load_config

    cfg = load_config(str(shipped_model(name).parent / "config.yml"), ["sim.fidelity=fe"])
    env = KiteFigureEightEnv(config=evaluation_config(cfg, 0.4))
    agent = make_agent(name, env)
    log, info = run_episode(env, agent, seed=0)
    assert info["episode_steps"] == 20 and info["termination_reason"] == "time limit"
    assert np.isfinite(info["episode_return"]) and info["episode_return"] > 0
    assert env.cfg.sim.fidelity == "fe" and type(env.sim).__name__ == "FlightSimulator"
