"""cpf_env: cooperative path following of marine surface vessels as a multi-agent RL benchmark.

Factories (PettingZoo convention)::

    import cpf_env
    env = cpf_env.parallel_env("wang2014")          # ParallelEnv, one agent per vessel
    aec = cpf_env.env("lossy_links")                 # AEC form
    raw = cpf_env.raw_env(scenario, max_steps=500)   # the unwrapped class

Scenarios: ``cpf_env.scenarios.list_scenarios()``; the benchmark suite:
``cpf_env.scenarios.suite.list_suite()``. Documentation: ``docs/`` in the repository
(``docs/environment.md`` for the interface, ``docs/model.md`` for the equations).
"""

from __future__ import annotations

import os
from typing import Any

# numba's OpenMP threads (GNU libgomp) wait for work by spinning: next to another busy process
# on the same cores they steal its time and each other's. Passive waiting degrades gracefully
# (measured on 2 cores with one busy competitor, B = 256: FleetSim.step kept 34 % of its quiet
# rate spinning, 48 % waiting passively; FleetVecEnv.step 35 % and 76 %). It is set before the
# first parallel kernel starts the threads, unless the user chose: OMP_WAIT_POLICY=ACTIVE on a
# dedicated machine (docs/scaling.md, "Threads").
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# First: numba picks a kernel's cache key when it compiles the decorator (kernel_cache).
from cpf_env.infra import kernel_cache  # noqa: F401  # isort: skip

from pettingzoo.utils.env import AECEnv
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from cpf_env import scenarios
from cpf_env.envs.aec import CheckedAEC
from cpf_env.envs.gym_envs import register_envs
from cpf_env.envs.parallel import CooperativePathFollowingEnv
from cpf_env.scenarios import Scenario, suite
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.observation import ObsLayout

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

#: The ParallelEnv class itself (no wrapper); see ``CooperativePathFollowingEnv``.
raw_env = CooperativePathFollowingEnv


def parallel_env(
    scenario: str | Scenario = "wang2014", **kwargs: Any
) -> CooperativePathFollowingEnv:
    """Make the PettingZoo ``ParallelEnv``: one agent per vessel, all acting at once.

    Args:
        scenario: A registered name (``cpf_env.scenarios.list_scenarios()``:
            ``wang2014`` is the paper's simulation) or a ``Scenario`` object.
        **kwargs: ``render_mode`` (``"human"``, ``"rgb_array"`` or None);
            ``max_cycles`` (PettingZoo's name for the episode length in control
            steps, the same as ``max_steps``; give one of the two);
            ``info_level`` (``"none"``, the default of every route, ``"minimal"`` or
            ``"full"``: how much the per-step infos carry, see ``docs/environment.md``);
            ``base_policy`` and ``residual`` (the residual form: agents act through a
            bounded correction of a base policy object); and any
            ``Scenario`` field as an override, e.g. ``max_steps=500``, ``v0=0.2``,
            ``dt=0.02``, ``substeps=2``, ``links=LinkImpairments(0.1, 2)``,
            ``reward=RewardWeights(team=True)``. Unknown names raise ``ValueError``
            listing the valid ones; values are checked as ``Scenario`` checks them.

    Returns:
        A ``CooperativePathFollowingEnv``. Agents ``vessel_0 .. vessel_{n-1}``.
        ``action_space(agent)``: ``Box(4 + m)`` float32, [tau_u (N), tau_v (N),
        tau_r (N m), theta_dot (1/s), message (m floats)], bounded by the force
        limits (beyond them the plant saturates), +-theta_dot_max and
        +-message_max. ``observation_space(agent)``: ``Box(18 + K (3 + m))``
        float32, the vessel's local view (named slices in ``env.layout``). The
        class docstring (``help(cpf_env.CooperativePathFollowingEnv)``) and
        ``docs/environment.md`` give the tables, the reward, episode end and infos.

    Example:
        >>> import cpf_env
        >>> env = cpf_env.parallel_env("lossy_links", max_cycles=20)
        >>> observations, infos = env.reset(seed=0)
        >>> env.observation_space("vessel_0").shape, env.action_space("vessel_0").shape
        ((26,), (5,))
    """
    return CooperativePathFollowingEnv(scenario, **kwargs)


def env(scenario: str | Scenario = "wang2014", **kwargs: Any) -> AECEnv:
    """Make the AEC form of ``parallel_env``: agents act in turn, the fleet steps after the last.

    Arguments, spaces and agents are those of ``parallel_env`` (``max_cycles``
    included). Each action is checked at the turn it is given: a bad one raises
    ``ValueError`` and the same agent acts again (``cpf_env.envs.aec.CheckedAEC``).
    PettingZoo's ``OrderEnforcingWrapper`` is applied; its
    ``AssertOutOfBoundsWrapper`` is not, because force commands beyond the
    limits are legal (the plant saturates them).

    Example:
        >>> import cpf_env
        >>> aec = cpf_env.env("wang2014", max_cycles=5)
        >>> aec.reset(seed=0)
        >>> for agent in aec.agent_iter():
        ...     observation, reward, termination, truncation, info = aec.last()
        ...     aec.step(None if termination or truncation else aec.action_space(agent).sample())
    """
    aec = CheckedAEC(parallel_env(scenario, **kwargs))
    return OrderEnforcingWrapper(aec)


register_envs()
