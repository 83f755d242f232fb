"""Policies: the interface, the registry of policy specs, and the built-in policies."""

from rmbench.policies.base import BasePolicy, Policy
from rmbench.policies.registry import POLICIES, UnknownPolicyError, make_policy, register_policy

__all__ = ["POLICIES", "BasePolicy", "Policy", "UnknownPolicyError", "make_policy",
           "register_policy"]
