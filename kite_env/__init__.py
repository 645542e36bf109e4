"""kite_env: a dynamic nonlinear aeroelastic kite model (Bosch, Schmehl, Tiso & Rixen) as an RL environment."""

__version__ = "0.1.0"
