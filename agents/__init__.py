"""Training recipes (``agents/recipes``) and the shipped trained models (``agents/models``). The policies live in
the library, :mod:`kite_env.policies`; :mod:`agents.baseline` and :mod:`agents.policies` re-export them."""
