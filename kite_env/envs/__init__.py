"""Gymnasium environments of kite_env (registered on ``import kite_env``); the physics modules never import gymnasium.

* ``KiteFigureEight-v1``: :class:`kite_env.envs.figure_eight.KiteFigureEightEnv`, the full aeroelastic model
  (``fidelity="surrogate"`` for the reduced-order wing).
* ``KiteFigureEightFast-v1``: the same environment with the reduced-order wing (``fidelity="surrogate"``).

Version history (Gymnasium's convention: the version changes when the dynamics change):

* v1: the flying model (the wing with inertia, the rope tether, the actuator's speed limit, the ground station's
  force limit), its reduced-order wing with a latent state, and action +-1 = +-1.5 m of steering.
* v0 (removed): the model before it flew (quasi-static wing, Eq. 3 as printed, rod tether, constant tether length),
  whose every flight ended within seconds; action +-1 = +-0.25 m.

Both have the ``vector_entry_point`` :func:`kite_env.envs.vector.make_vector_env`:
``gymnasium.make_vec(id, num_envs, vectorization_mode="vector_entry_point")`` (the default mode) gives the batched
:class:`kite_env.envs.vector.KiteFigureEightVectorEnv` in the surrogate fidelity (all kites in one compiled batch)
and a ``SyncVectorEnv`` of single envs in the FE fidelity; ``vectorization_mode="sync"`` always the latter.
"""

ENV_ID = "KiteFigureEight-v1"
FAST_ENV_ID = "KiteFigureEightFast-v1"
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
