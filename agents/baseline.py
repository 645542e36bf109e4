"""The paper's steering controller as a policy: kept here for users' imports; it lives in the library,
:mod:`kite_env.policies.baseline` (the library never imports this package)."""

from kite_env.policies.baseline import V_REF_MPS, BaselineAgent, BaselinePolicy

__all__ = ["V_REF_MPS", "BaselineAgent", "BaselinePolicy"]
