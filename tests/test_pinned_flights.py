"""One short flight of each fidelity, pinned bit for bit: the paper's baseline controller (built as ``kite-eval
--policy baseline`` builds it) flies the default config from ``reset(seed=0)``. The final KCU position, tether force
and sum of rewards must equal, exactly, the numbers the code gave when they were recorded: a change of module layout
(or any other refactoring) that moves no physics leaves them as they are."""

from __future__ import annotations

import numpy as np
import pytest

from kite_env.envs.figure_eight import KiteFigureEightEnv
from kite_env.policies import make_agent

#: fidelity, control steps, (final KCU position [m], final tether force [N], sum of rewards)
PINNED = {
    "surrogate": (100, ([40.4227760896261, -18.31119748209464, 66.56349765434268], 6120.872309597604,
                        159.42243115489177)),
    "fe": (10, ([60.38236333834816, -0.6220416708371347, 52.47459634752276], 6794.7480478229945,
                 16.079313424183713)),
}


def _fly(fidelity: str, steps: int):
    env = KiteFigureEightEnv(fidelity=fidelity)
    agent = make_agent("baseline", env)
    obs, _ = env.reset(seed=0)
    total, start = 0.0, True
    for _ in range(steps):
        action, _ = agent.predict(obs, episode_start=np.array([start]), deterministic=True)
        start = False
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        assert not (terminated or truncated), info
    assert env.rec is not None
    out = ([float(x) for x in env.rec.state.r[4]], float(env.rec.tether_force), total)
    env.close()
    return out


@pytest.mark.parametrize("fidelity", sorted(PINNED))
def test_pinned_flight(fidelity):
    steps, expected = PINNED[fidelity]
    assert _fly(fidelity, steps) == expected
