"""An agent that decides every ``k``-th control step and holds its action in between.

At the env's 20 ms control period one action changes the kite's state very little before the next, so the
difference in return between two actions at one step (the action gap) is small against the error of a learned
Q-function, and an off-policy actor-critic such as SAC learns a policy that follows that error: its actions jump by
a third of their range from step to step and the kite does not fly (docs/training.md). Q-learning degrades this way
as the time step shrinks (Tallec, Blier & Ollivier, "Making deep Q-learning methods robust to time discretization",
ICML 2019); deciding every ``k`` steps makes each action's effect on the return ``k`` times larger. The hold is the
agent's, not the env's: the env steps every 20 ms for every policy, and a trained agent applies its hold when it
flies (:class:`kite_env.policies.ModelAgent`), so every policy flies the same env.
"""

from __future__ import annotations

import gymnasium as gym


def check_action_hold(k) -> int:
    """``k`` as the number of control steps an action is held: a whole number >= 1, else ``ValueError``."""
    if not isinstance(k, int) or isinstance(k, bool) or k < 1:
        raise ValueError(f"action_hold must be a whole number of control steps >= 1, got {k!r}")
    return k


class HeldAction(gym.Wrapper):
    """Each action held for ``k`` control steps of ``env``: one step of this wrapper returns the observation after
    them, the sum of their rewards and the info of the last; it ends at the control step that ends the episode."""

    def __init__(self, env: gym.Env, k: int):
        super().__init__(env)
        self.k = check_action_hold(k)

    def step(self, action):
        total = 0.0
        for _ in range(self.k):
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            if terminated or truncated:
                break
        return obs, total, terminated, truncated, info
