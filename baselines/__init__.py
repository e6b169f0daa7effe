"""Analytic policies for cooperative path following: the paper's controller and baselines.

==========================  ===========================================================
name                        policy
==========================  ===========================================================
``nn_dsc``                  NN-based adaptive DSC + saturation auxiliary system +
                            path-variable consensus + distributed speed estimator
                            (Wang, Wang & Peng 2014; the reference policy)
``dsc``                     ``nn_dsc`` without the NN term
``nn_dsc_no_aux``           ``nn_dsc`` without the auxiliary system
``backstepping``            analytic derivative of alpha, nominal-model cancellation
``nn_dsc_delay_comp``       ``nn_dsc`` with neighbour theta advanced by packet age x dt x vhat_j
``backstepping_delay_comp`` ``backstepping`` with the same delay compensation
``mpc``                     receding-horizon control per vessel on the benchmark's
                            stage cost, from its local observation (``baselines.mpc``)
``mpc_tuned``               ``mpc`` with a fast, rate-limited v0 estimator tuned on the
                            training seeds (``baselines.mpc_tuned``)
==========================  ===========================================================

For hulls without a sway force (``UNDERACTUATED``, deployable, in the hard
track's default set): ``ilos``, integral line-of-sight guidance with surge
and heading control and the cooperative law's path variable (Børhaug, Pavlov
& Pettersen 2008; ``baselines.ilos``).

For vessels that observe noisy, late pose fixes and maybe no velocity
(``Scenario.sensors``; ``FILTERED``, deployable, in the hard track's default set):
``nn_dsc_ekf``, ``mpc_tuned_ekf`` and ``ilos_ekf``, ``nn_dsc``, ``mpc_tuned`` and
``ilos`` on the estimate of an extended Kalman filter on the nominal vessel model
with a disturbance bias (``baselines.estimator``); ``mpc_tuned_mmae``, ``mpc_tuned``
on a bank of four such filters, from calm-water to wave process noise, weighted
by the likelihood of their innovations (multiple-model adaptive estimation).

Privileged references, not deployable (``PRIVILEGED``): ``nn_dsc_global_v0``,
``nn_dsc`` told v0's schedule on every vessel (no estimator; an ablation
of the speed estimator, which a vessel cut off from the leader cannot
run: ``bench_switching`` steps v0 while no vessel hears it); ``oracle``, the same
receding-horizon control told everything (true model and future disturbances
via copies of the simulator, ideal links, true v0, centralized), the
benchmark's headroom bound (``HEADROOM_REFERENCE``); ``mpc_privileged``,
``mpc`` told what it lacks; ``mpc_told_dynamics``, ``mpc_told_links`` and
``mpc_told_v0`` (``baselines.mpc_told``), ``mpc`` told one of those things
each (its own true model and residual force, ideal links, the true v0), which
split ``mpc``'s headroom by piece of information; ``nn_dsc_privileged`` and
``backstepping_privileged`` (``baselines.privileged``), told the true lumped
uncertainty and given ideal links, an ablation. ``make_policy`` builds them too.

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
from baselines.estimator import (
    Filtered,
    ILOSFiltered,
    MPCTunedAdaptive,
    MPCTunedFiltered,
    NNDSCFiltered,
)
from baselines.gains import BacksteppingGains, CooperativeGains, NNDSCGains
from baselines.ilos import ILOSGains, ILOSPolicy
from baselines.mpc import MPCPolicy, MPCPrivileged, OraclePolicy, RecedingHorizonGains
from baselines.mpc_told import MPCToldDynamics, MPCToldLinks, MPCToldV0
from baselines.mpc_tuned import MPCTuned
from baselines.nn_dsc import DSCPolicy, GlobalSpeedPolicy, NNDSCPolicy, NoAuxPolicy
from baselines.policy import DIAGNOSTICS, AnalyticPolicy
from baselines.privileged import BacksteppingPrivileged, NNDSCPrivileged, PrivilegedPolicy
from baselines.safety import MPCTunedFilteredSafe, MPCTunedSafe, NNDSCSafe, SafetyFiltered
from cpf_env.envs.policy import FleetPolicy

__all__ = [
    "ALL_POLICIES",
    "DEPLOYABLE",
    "DIAGNOSTICS",
    "FILTERED",
    "HEADROOM_REFERENCE",
    "POLICIES",
    "PRIVILEGED",
    "SAFE",
    "UNDERACTUATED",
    "AnalyticPolicy",
    "BacksteppingDelayCompensated",
    "BacksteppingGains",
    "BacksteppingPolicy",
    "BacksteppingPrivileged",
    "CooperativeGains",
    "DSCPolicy",
    "Filtered",
    "GlobalSpeedPolicy",
    "ILOSFiltered",
    "ILOSGains",
    "ILOSPolicy",
    "MPCPolicy",
    "MPCPrivileged",
    "MPCToldDynamics",
    "MPCToldLinks",
    "MPCToldV0",
    "MPCTuned",
    "MPCTunedAdaptive",
    "MPCTunedFiltered",
    "MPCTunedFilteredSafe",
    "MPCTunedSafe",
    "NNDSCDelayCompensated",
    "NNDSCFiltered",
    "NNDSCGains",
    "NNDSCPolicy",
    "NNDSCPrivileged",
    "NNDSCSafe",
    "NoAuxPolicy",
    "OraclePolicy",
    "PrivilegedPolicy",
    "RecedingHorizonGains",
    "SafetyFiltered",
    "make_policy",
]

#: Deployable policy classes by name (local observation only).
POLICIES: dict[str, type[FleetPolicy]] = {
    policy.name: policy
    for policy in (
        NNDSCPolicy,
        DSCPolicy,
        NoAuxPolicy,
        BacksteppingPolicy,
        NNDSCDelayCompensated,
        BacksteppingDelayCompensated,
        MPCPolicy,
        MPCTuned,
    )
}

#: Deployable designs for hulls without a sway force (local observation only): they
#: command no sway force on any hull. In cpf-bench's default set on the hard track only:
#: on the fully actuated core suite ``ilos`` loses to ``nn_dsc`` on every scenario.
UNDERACTUATED: dict[str, type[FleetPolicy]] = {ILOSPolicy.name: ILOSPolicy}

FILTERED: dict[str, type[FleetPolicy]] = {
    policy.name: policy
    for policy in (NNDSCFiltered, MPCTunedFiltered, MPCTunedAdaptive, ILOSFiltered)
}
#: Deployable designs under the separation's safety filter (``baselines.safety``), for the
#: scenarios whose messages carry its broadcast (the crossing scenarios).
SAFE: dict[str, type[FleetPolicy]] = {
    policy.name: policy for policy in (NNDSCSafe, MPCTunedSafe, MPCTunedFilteredSafe)
}

#: Privileged references by name: not deployable, they read what no local observation
#: holds (the simulator, or the scenario's v0 schedule).
PRIVILEGED: dict[str, type[FleetPolicy]] = {
    policy.name: policy
    for policy in (
        GlobalSpeedPolicy,
        OraclePolicy,
        MPCPrivileged,
        MPCToldDynamics,
        MPCToldLinks,
        MPCToldV0,
        NNDSCPrivileged,
        BacksteppingPrivileged,
    )
}
#: Every deployable analytic policy by name: the default set and those for the hard conditions.
DEPLOYABLE: dict[str, type[FleetPolicy]] = {**POLICIES, **UNDERACTUATED, **FILTERED, **SAFE}
#: Every policy class by name: ``POLICIES``, ``UNDERACTUATED``, ``FILTERED``, then ``PRIVILEGED``.
ALL_POLICIES: dict[str, type[FleetPolicy]] = {
    **POLICIES,
    **UNDERACTUATED,
    **FILTERED,
    **SAFE,
    **PRIVILEGED,
}
#: The headroom bound the benchmark's normalized score is measured against.
HEADROOM_REFERENCE = OraclePolicy.name


def make_policy(name: str, env: object, **options: Any) -> FleetPolicy:
    """Build the policy ``name`` for the scenario of ``env``.

    Args:
        name: A key of ``POLICIES``, ``UNDERACTUATED``, ``FILTERED`` or ``PRIVILEGED``.
        env: A ``CooperativePathFollowingEnv``, a ``FleetSim``, any object with a
            ``.scenario``, a ``Scenario`` or a scenario name (a privileged
            reference built without a simulator must be bound to one before acting).
        **options: Gains of the policy's gains dataclass (e.g. ``K2=(30, 30, 5)``).

    Raises:
        ValueError: Unknown name or option (the message lists the valid ones).
    """
    if name not in ALL_POLICIES:
        raise ValueError(f"unknown policy {name!r}; choose one of {sorted(ALL_POLICIES)}.")
    builder: Any = ALL_POLICIES[name]  # every member takes (env, **options)
    policy: FleetPolicy = builder(env, **options)
    return policy
