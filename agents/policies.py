"""Policies for ``kite-eval``: kept here for users' imports; they live in the library, :mod:`kite_env.policies`
(the library never imports this package). Patch ``kite_env.policies.MODELS_DIR``, not this module's copy, to move
the shipped models' folder."""

from kite_env.policies import (
    MODELS_DIR,
    SHIPPED,
    ConstantAgent,
    ModelAgent,
    PolicyError,
    RandomAgent,
    load_model_agent,
    make_agent,
    model_algorithm,
    model_path,
    model_record,
    policy_label,
    shipped_model,
)

__all__ = ["MODELS_DIR", "SHIPPED", "ConstantAgent", "ModelAgent", "PolicyError", "RandomAgent", "load_model_agent",
           "make_agent", "model_algorithm", "model_path", "model_record", "policy_label", "shipped_model"]
