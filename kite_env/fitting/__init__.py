"""Making the reduced-order wing (``kite-fit``): flights of the full model recorded step by step
(:mod:`.trajectories`), the wing fitted to them (:mod:`.fit`) and the agreement of the two fidelities over whole
flights (:mod:`.agreement`). These fly the full model through the environment and the policies, so they stand above
them; the wing they make (:mod:`kite_env.surrogate`: its model, inputs, start table and shipped files) stands below
the dynamics, which fly it. The start table is built by :mod:`kite_env.dynamics.start_table`.
"""
