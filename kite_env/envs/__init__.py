"""Gymnasium environments of kite_env (registered on ``import kite_env``); the physics modules never import gymnasium.

* ``KiteFigureEight-v0``: :class:`kite_env.envs.figure_eight.KiteFigureEightEnv`, the full aeroelastic model
  (``fidelity="surrogate"`` for the reduced-order wing).
* ``KiteFigureEightFast-v0``: the same environment with the reduced-order wing (``fidelity="surrogate"``).

Both have the ``vector_entry_point`` :func:`kite_env.envs.vector.make_vector_env`:
``gymnasium.make_vec(id, num_envs, vectorization_mode="vector_entry_point")`` (the default mode) gives the batched
:class:`kite_env.envs.vector.KiteFigureEightVectorEnv` in the surrogate fidelity (all kites in one compiled batch)
and a ``SyncVectorEnv`` of single envs in the FE fidelity; ``vectorization_mode="sync"`` always the latter.
"""

ENV_ID = "KiteFigureEight-v0"
FAST_ENV_ID = "KiteFigureEightFast-v0"
_VECTOR_ENTRY_POINT = "kite_env.envs.vector:make_vector_env"


def register_envs() -> None:
    """Register the environments with Gymnasium (idempotent)."""
    from gymnasium.envs.registration import register, registry

    if ENV_ID not in registry:
        # no TimeLimit wrapper: the env truncates itself at env.max_episode_s (the step count depends on the config)
        register(id=ENV_ID, entry_point="kite_env.envs.figure_eight:KiteFigureEightEnv",
                 vector_entry_point=_VECTOR_ENTRY_POINT)
    if FAST_ENV_ID not in registry:
        register(id=FAST_ENV_ID, entry_point="kite_env.envs.figure_eight:KiteFigureEightEnv",
                 vector_entry_point=_VECTOR_ENTRY_POINT, kwargs={"fidelity": "surrogate"})
