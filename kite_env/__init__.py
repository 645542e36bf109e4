"""kite_env: a dynamic nonlinear aeroelastic kite model (Bosch, Schmehl, Tiso & Rixen) as an RL environment."""

__version__ = "0.1.0"


def _register() -> None:
    try:
        import gymnasium  # noqa: F401
    except ImportError:  # the physics runs without gymnasium; the environments need it
        return
    from kite_env.envs import register_envs

    register_envs()


_register()
