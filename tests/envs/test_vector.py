"""The batched fast env (kite_env.envs.vector) against SyncVectorEnv over single KiteFigureEightFast-v1 envs (the
default model's reduced-order wing)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import kite_env  # noqa: F401  (registers the environments)
from kite_env.envs.figure_eight import KiteFigureEightEnv
from kite_env.envs.vector import KiteFigureEightVectorEnv

# the shipped reduced-order wing of the default model (with the steering actuator's speed limit: random steering
# flies on for a while); randomised wind, turbulence and start; 0.2 s episodes (10 steps) so that truncation and
# autoreset happen
OVERRIDES = ["env.wind_speed_min_mps=4", "env.wind_speed_max_mps=9", "env.turbulence_intensity_max=0.1",
             "env.random_start=true", "env.max_episode_s=0.2"]


@pytest.fixture(scope="module")
def vec():
    return KiteFigureEightVectorEnv(2, overrides=OVERRIDES)


def _assert_same(x, y, what):
    if isinstance(y, np.ndarray) and y.dtype != object:
        np.testing.assert_array_equal(x, y, err_msg=what)
        assert x.dtype == y.dtype, what
    else:
        assert list(x) == list(y), what


def test_batch_equals_single_envs_with_autoreset(vec):
    """Same seeds and actions: observations, rewards, terminations, truncations and info (keys, masks, values) of
    the batch are bitwise those of SyncVectorEnv over single envs, through truncations, terminations and the
    NEXT_STEP autoresets."""
    assert vec.cfg.control.line_speed_max_mps > 0.0  # the default model's actuator
    sync = gym.vector.SyncVectorEnv([lambda: KiteFigureEightEnv(overrides=OVERRIDES, fidelity="surrogate")
                                     for _ in range(vec.num_envs)])
    assert vec.metadata["autoreset_mode"] == sync.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
    o1, i1 = vec.reset(seed=11)
    o2, i2 = sync.reset(seed=11)
    np.testing.assert_array_equal(o1, o2)
    assert sorted(i1) == sorted(i2)
    rng = np.random.default_rng(1)
    ended = autoreset = 0
    for _ in range(16):
        a = rng.uniform(-1.0, 1.0, (vec.num_envs, 1)).astype(np.float32)
        was_done = vec._autoreset.copy()
        r1, r2 = vec.step(a), sync.step(a)
        for x, y, what in zip(r1[:4], r2[:4], ("obs", "reward", "terminated", "truncated")):
            _assert_same(x, y, what)
        assert sorted(r1[4]) == sorted(r2[4])
        for key, y in r2[4].items():
            _assert_same(r1[4][key], y, key)
        ended += int(np.sum(r1[2] | r1[3]))
        if was_done.any():  # the kites that ended last step were reset: reward 0, reset info present
            autoreset += int(was_done.sum())
            assert np.all(r1[1][was_done] == 0.0) and np.all(r1[4]["_wind_seed"] == was_done)
            assert not np.any(r1[4].get("_reward_tracking", np.zeros(vec.num_envs, bool))[was_done])
    assert ended >= 2 and autoreset >= 2  # at least the truncations at 10 steps and their resets
    assert obs_in_space(vec, r1[0])


def test_batch_equals_single_envs_through_random_steering_to_the_ground():
    """Random full-range steering over whole episodes (up to 30 s, the soak's conditions): the batch ends each kite
    when and why the single env does, bitwise, through ground contacts, the fitted envelope and a slack rope (which
    goes slack and flies on: a slack tether ends an episode only on the rod tether or with the quasi-static wing)."""
    ovr = [*OVERRIDES[:-1], "env.max_episode_s=30", "env.initial_speed_per_wind_min=4.0",
           "env.initial_speed_per_wind_max=4.8"]
    n = 4
    vec = KiteFigureEightVectorEnv(n, overrides=ovr)
    assert vec.cfg.dynamics.tether == "rope" and vec.cfg.structure.dynamic
    sync = gym.vector.SyncVectorEnv([lambda: KiteFigureEightEnv(overrides=ovr, fidelity="surrogate")
                                     for _ in range(n)])
    np.testing.assert_array_equal(vec.reset(seed=3)[0], sync.reset(seed=3)[0])
    rng = np.random.default_rng(2)
    reasons, slack_steps = [], 0
    for _ in range(900):
        a = rng.uniform(-1.0, 1.0, (n, 1)).astype(np.float32)
        r1, r2 = vec.step(a), sync.step(a)
        for x, y, what in zip(r1[:4], r2[:4], ("obs", "reward", "terminated", "truncated")):
            _assert_same(x, y, what)
        _assert_same(r1[4]["termination_reason"], r2[4]["termination_reason"], "termination_reason")
        reasons += [str(r) for r in r1[4]["termination_reason"][r1[2]]]
        slack_steps += int(np.sum(r1[4].get("tether_force_N", np.full(n, np.inf)) < vec.cfg.env.slack_tether_N))
    assert "ground" in reasons and "slack tether" not in reasons, reasons
    assert slack_steps > 0  # the rope went slack and the kite flew on


def obs_in_space(env, obs):
    return obs.shape == env.observation_space.shape and bool(np.all(env.observation_space.contains(obs)))


def test_reset_mask_and_errors(vec):
    o, _ = vec.reset(seed=3)
    single = KiteFigureEightEnv(overrides=OVERRIDES, fidelity="surrogate")
    o_single, _ = single.reset(seed=4)  # kite 1 of a reset with seed 3
    np.testing.assert_array_equal(o[1], o_single)
    vec.step(np.zeros((2, 1), np.float32))
    o2, info = vec.reset(seed=[None, 4], options={"reset_mask": np.array([False, True])})
    np.testing.assert_array_equal(o2[1], o_single)
    assert list(info["_wind_seed"]) == [False, True]
    with pytest.raises(ValueError, match="finite"):
        vec.step(np.array([[np.nan], [0.0]], np.float32))
    with pytest.raises(ValueError, match="shape"):
        vec.step(np.zeros((2, 2), np.float32))


def test_make_vec_entry_points():
    v = gym.make_vec("KiteFigureEightFast-v1", num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(v, KiteFigureEightVectorEnv) and v.num_envs == 3
    assert v.observation_space.shape == (3, 22) and v.action_space.shape == (3, 1)
    v = gym.make_vec("KiteFigureEight-v1", num_envs=2, vectorization_mode="vector_entry_point",
                     fidelity="surrogate")
    assert isinstance(v, KiteFigureEightVectorEnv)
    v = gym.make_vec("KiteFigureEight-v1", num_envs=2)  # the FE model: one process per kite is not batched
    assert isinstance(v, gym.vector.SyncVectorEnv)
    with pytest.raises(ValueError, match="surrogate"):
        KiteFigureEightVectorEnv(2, fidelity="fe")


@pytest.mark.slow  # every 0.2 s episode starts again: an FE start per reset while no start table ships (~40 s)
def test_sb3_adapter_trains_ppo(vec):
    from stable_baselines3 import PPO

    from kite_env.envs.vector import SB3VecEnv

    venv = SB3VecEnv(vec, info_keys=("reward_tracking",))
    venv.seed(5)
    obs = venv.reset()
    assert obs.shape == (2, 22) and obs.dtype == np.float32
    assert [e._np_random_seed for e in vec.envs] == [5, 6]  # SB3's seeds reach the kites as seed + i
    dones_seen = 0
    for _ in range(10):  # 0.2 s episodes: every kite ends by step 10 and is reset in the same step (SB3 protocol)
        obs, rew, dones, infos = venv.step(np.zeros((2, 1), np.float32))
        assert rew.dtype == np.float32 and obs.shape == (2, 22)
        for i in np.flatnonzero(dones):
            dones_seen += 1
            assert infos[i]["terminal_observation"].shape == (22,)
            assert infos[i]["termination_reason"] is not None
            assert not vec._autoreset[i]  # already reset: the next step steps it
    assert dones_seen >= 2
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(32)
    assert model.num_timesteps == 32
