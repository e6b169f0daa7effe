"""cpf_env: cooperative path following of marine surface vessels as a multi-agent RL benchmark.

Factories (PettingZoo convention)::

    import cpf_env
    env = cpf_env.parallel_env("wang2014")          # ParallelEnv, one agent per vessel
    aec = cpf_env.env("lossy_links")                 # AEC form
    raw = cpf_env.raw_env(scenario, max_steps=500)   # the unwrapped class

Scenarios: ``cpf_env.scenarios.list_scenarios()``; the benchmark suite:
``cpf_env.suite.list_suite()``.
"""

from __future__ import annotations

from typing import Any

from pettingzoo.utils import parallel_to_aec
from pettingzoo.utils.env import AECEnv
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from cpf_env import scenarios, suite
from cpf_env.env import CooperativePathFollowingEnv
from cpf_env.gym_envs import register_envs
from cpf_env.observation import ObsLayout
from cpf_env.scenarios import Scenario
from cpf_env.sim import FleetSim

__all__ = [
    "CooperativePathFollowingEnv",
    "FleetSim",
    "ObsLayout",
    "Scenario",
    "env",
    "parallel_env",
    "raw_env",
    "scenarios",
    "suite",
]
__version__ = "0.1.0"

raw_env = CooperativePathFollowingEnv


def parallel_env(
    scenario: str | Scenario = "wang2014", **kwargs: Any
) -> CooperativePathFollowingEnv:
    """The ParallelEnv for ``scenario`` (a name or a ``Scenario``); kwargs override its fields."""
    return CooperativePathFollowingEnv(scenario, **kwargs)


def env(scenario: str | Scenario = "wang2014", **kwargs: Any) -> AECEnv:
    """The AEC form of ``parallel_env`` (agents act in turn; the step happens after the last)."""
    aec = parallel_to_aec(parallel_env(scenario, **kwargs))
    # No AssertOutOfBoundsWrapper: force commands beyond the limits are legal (the plant saturates).
    return OrderEnforcingWrapper(aec)


register_envs()
