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

Headroom references, not deployable (``PRIVILEGED``, ``baselines.privileged``):
``nn_dsc_privileged`` and ``backstepping_privileged``, told the true lumped
uncertainty and given ideal links; ``make_policy`` builds them too.

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
from baselines.policy import DIAGNOSTICS, AnalyticPolicy
from baselines.privileged import BacksteppingPrivileged, NNDSCPrivileged, PrivilegedPolicy

__all__ = [
    "DIAGNOSTICS",
    "HEADROOM_REFERENCE",
    "POLICIES",
    "PRIVILEGED",
    "AnalyticPolicy",
    "BacksteppingDelayCompensated",
    "BacksteppingGains",
    "BacksteppingPolicy",
    "BacksteppingPrivileged",
    "CooperativeGains",
    "DSCPolicy",
    "GlobalSpeedPolicy",
    "NNDSCDelayCompensated",
    "NNDSCGains",
    "NNDSCPolicy",
    "NNDSCPrivileged",
    "NoAuxPolicy",
    "PrivilegedPolicy",
    "make_policy",
]

#: Deployable policy classes by name (local observation only).
POLICIES: dict[str, type[AnalyticPolicy]] = {
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

#: Privileged references by name: not deployable, they read the simulator (headroom).
PRIVILEGED: dict[str, type[PrivilegedPolicy]] = {
    policy.name: policy for policy in (NNDSCPrivileged, BacksteppingPrivileged)
}
#: The privileged reference the benchmark's share of the gap closed is measured against.
HEADROOM_REFERENCE = NNDSCPrivileged.name


def make_policy(name: str, env: object, **options: Any) -> AnalyticPolicy:
    """Build the policy ``name`` for the scenario of ``env``.

    Args:
        name: A key of ``POLICIES`` or of ``PRIVILEGED``.
        env: A ``CooperativePathFollowingEnv``, a ``FleetSim``, any object with a
            ``.scenario``, a ``Scenario`` or a scenario name (a privileged
            reference built without a simulator must be bound to one before acting).
        **options: Gains of the policy's gains dataclass (e.g. ``K2=(30, 30, 5)``).

    Raises:
        ValueError: Unknown name or option (the message lists the valid ones).
    """
    known: dict[str, type[AnalyticPolicy]] = {**POLICIES, **PRIVILEGED}
    if name not in known:
        raise ValueError(f"unknown policy {name!r}; choose one of {sorted(known)}.")
    return known[name](env, **options)
