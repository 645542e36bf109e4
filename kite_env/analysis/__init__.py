"""Analyses of the model: studies that measure what the wing and the flight model do, not used by the env or the
dynamics.

* :mod:`kite_env.analysis.turn_rate`: open-loop steering authority (the turn rate a held steering input gives),
  where a steering input goes (the wing's stiffness at the steering points), the quasi-steady lateral balance, the
  wing with inertia on its lines (the yaw rig) and its linearisation (docs/steering.md);
* :mod:`kite_env.analysis.lift_to_drag`: the wing's L/D split into the sections' own and the arc's projection
  (docs/validation.md, "Mesh refinement, L/D, the figure's elevation").

They build on the library (the wing, the simulators, the env's configuration); nothing of the library builds on them:
no module outside ``kite_env.analysis`` imports it (tests/test_layers.py). The studies' command-line front ends are in
the top-level ``analyses/`` folder (analyses/README.md); the tests keep their findings in CI.
"""
