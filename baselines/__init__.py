"""Analytic policies for cooperative path following: the paper's controller and baselines.

==========================  ===========================================================
name                        policy
==========================  ===========================================================
``nn_dsc``                  NN-based adaptive DSC + saturation auxiliary system +
                            path-variable consensus + distributed speed estimator
                            (Wang, Wang & Peng 2014; the reference policy)
``dsc``                     ``nn_dsc`` without the NN term
``nn_dsc_no_aux``           ``nn_dsc`` without the auxiliary system
``nn_dsc_global_v0``        ``nn_dsc`` with v0 known to every vessel (no estimator)
``backstepping``            analytic derivative of alpha, nominal-model cancellation
``nn_dsc_delay_comp``       ``nn_dsc`` with neighbour theta advanced by packet age x dt x vhat_j
``backstepping_delay_comp`` ``backstepping`` with the same delay compensation
==========================  ===========================================================

Example:
    >>> import cpf_env, baselines
    >>> env = cpf_env.parallel_env("wang2014", max_steps=20)
    >>> policy = baselines.make_policy("nn_dsc", env, K2=(30, 30, 5))
    >>> observations, infos = env.reset(seed=0)
    >>> while env.agents:
    ...     observations, *_ = env.step(policy.act(observations))
"""

from __future__ import annotations

from typing import Any

from baselines.backstepping import BacksteppingPolicy
from baselines.delay_compensated import BacksteppingDelayCompensated, NNDSCDelayCompensated
from baselines.gains import BacksteppingGains, CooperativeGains, NNDSCGains
from baselines.nn_dsc import DSCPolicy, GlobalSpeedPolicy, NNDSCPolicy, NoAuxPolicy
from baselines.policy import DIAGNOSTICS, Policy

__all__ = [
    "DIAGNOSTICS",
    "POLICIES",
    "BacksteppingDelayCompensated",
    "BacksteppingGains",
    "BacksteppingPolicy",
    "CooperativeGains",
    "DSCPolicy",
    "GlobalSpeedPolicy",
    "NNDSCDelayCompensated",
    "NNDSCGains",
    "NNDSCPolicy",
    "NoAuxPolicy",
    "Policy",
    "make_policy",
]

#: Policy classes by name.
POLICIES: dict[str, type[Policy]] = {
    policy.name: policy
    for policy in (
        NNDSCPolicy,
        DSCPolicy,
        NoAuxPolicy,
        GlobalSpeedPolicy,
        BacksteppingPolicy,
        NNDSCDelayCompensated,
        BacksteppingDelayCompensated,
    )
}


def make_policy(name: str, env: object, **options: Any) -> Policy:
    """Build the policy ``name`` for the scenario of ``env``.

    Args:
        name: A key of ``POLICIES``.
        env: A ``CooperativePathFollowingEnv``, a ``FleetSim``, any object with a
            ``.scenario``, a ``Scenario`` or a scenario name.
        **options: Gains of the policy's gains dataclass (e.g. ``K2=(30, 30, 5)``).

    Raises:
        ValueError: Unknown name or option (the message lists the valid ones).
    """
    if name not in POLICIES:
        raise ValueError(f"unknown policy {name!r}; choose one of {sorted(POLICIES)}.")
    return POLICIES[name](env, **options)
