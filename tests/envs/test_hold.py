"""An agent that decides every k-th control step (kite_env.envs.hold): trained through HeldAction, flown by a
ModelAgent that holds its action; both give the same flight, and the recipe's action_hold is checked."""

from __future__ import annotations

import numpy as np
import pytest

from kite_env.envs.figure_eight import KiteFigureEightEnv
from kite_env.envs.hold import HeldAction
from kite_env.policies import ModelAgent

FAST = ["sim.fidelity=surrogate", "wind.speed_mps=7.0", "wind.turbulence_intensity=0.05"]


class _Decider:
    """A deterministic stand-in for an SB3 model's ``predict``: a smooth function of the observation, counting its
    calls."""

    def __init__(self):
        self.calls = 0

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        self.calls += 1
        obs = np.atleast_2d(obs)
        return np.tanh(0.7 * obs[:, :1] - 0.3 * obs[:, 1:2]).astype(np.float32), state


def test_a_held_action_agent_flies_as_it_was_trained():
    """HeldAction(env, 5) stepped with the decider's actions and a ModelAgent(action_hold=5) stepped every control
    step fly the same kite bit for bit: the agent decides (evaluates its network) at the episode's first step and
    every fifth after it."""
    k, decisions = 5, 40
    trained = HeldAction(KiteFigureEightEnv(overrides=FAST), k)
    obs, _ = trained.reset(seed=3)
    rewards = []
    for _ in range(decisions):
        a = _Decider().predict(obs)[0][0]
        obs, r, term, trunc, _ = trained.step(a)
        rewards.append(r)
        assert not (term or trunc)
    env = KiteFigureEightEnv(overrides=FAST)
    decider = _Decider()
    agent = ModelAgent(decider, None, action_hold=k)
    obs2, _ = env.reset(seed=3)
    actions, per_step = [], []
    for step in range(k * decisions):
        a, _ = agent.predict(obs2, episode_start=np.array([step == 0]))
        actions.append(float(np.asarray(a).ravel()[0]))
        obs2, r, *_ = env.step(np.asarray(a).ravel())
        per_step.append(r)
    np.testing.assert_array_equal(obs2, obs)
    np.testing.assert_allclose(np.add.reduceat(per_step, np.arange(0, k * decisions, k)), rewards, rtol=1e-12)
    assert decider.calls == decisions  # the network is evaluated once per decision, not at every step
    held = np.asarray(actions).reshape(decisions, k)
    assert np.all(held == held[:, :1]) and len(set(held[:, 0])) > 1
    # a new episode starts a new decision at its first step
    agent.predict(obs2, episode_start=np.array([True]))
    assert agent._age[0] == 1
    trained.close()
    env.close()


def test_the_held_action_ends_with_the_episode():
    """A hold that meets the end of the episode ends there: the wrapper's episode has the plain env's length and
    return (full steering: the episode ends within seconds, here not at a multiple of the hold)."""
    plain = KiteFigureEightEnv(overrides=FAST)
    plain.reset(seed=0)
    steps, total = 0, 0.0
    while True:
        _, r, term, trunc, info = plain.step(np.array([1.0]))
        steps, total = steps + 1, total + r
        if term or trunc:
            break
    k = next(k for k in (7, 8, 9) if steps % k)
    assert term
    held = HeldAction(KiteFigureEightEnv(overrides=FAST), k)
    held.reset(seed=0)
    calls, total_held = 0, 0.0
    while True:
        _, r, term, trunc, info2 = held.step(np.array([1.0]))
        calls, total_held = calls + 1, total_held + r
        if term or trunc:
            break
    assert calls == -(-steps // k) and info2["termination_reason"] == info["termination_reason"]
    assert total_held == pytest.approx(total, rel=1e-12)
    with pytest.raises(ValueError, match="action_hold"):
        HeldAction(plain, 0)
    plain.close()
    held.close()


def test_the_recipe_holds_the_action_only_where_it_can(tmp_path):
    """action_hold is a recipe key: a whole number >= 1, refused with the batched env (which steps every kite every
    control step) before anything is written."""
    from kite_env.training import UsageError, _vec_env_kind, load_hyperparameters

    assert load_hyperparameters(None, "sac")["action_hold"] == 5
    assert load_hyperparameters(None, "ppo").get("action_hold", 1) == 1
    bad = tmp_path / "r.yaml"
    bad.write_text("default:\n  action_hold: 0.5\n")
    with pytest.raises(UsageError, match="action_hold"):
        load_hyperparameters(bad, "sac")
    assert _vec_env_kind(None, "surrogate", 16, 5) == "dummy"
    assert _vec_env_kind(None, "surrogate", 16, 1) == "batched"
    with pytest.raises(UsageError, match="action_hold 5 needs vec_env dummy or subproc"):
        _vec_env_kind("batched", "surrogate", 16, 5)
