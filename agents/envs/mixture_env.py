"""``MixtureVecEnv``: one SB3 ``VecEnv`` over fleets of several scenarios at once.

A learner trained on one scenario learns that scenario's correction; trained
on a mixture it must find one that holds across conditions. The mixture is a
group of fleets per scenario, each group its own ``FleetVecEnv`` (its own
batched simulator and base policy), laid end to end:

    slots of group 0 (B_0 x n_0) | slots of group 1 (B_1 x n_1) | ...

so ``num_envs = sum_g B_g n_g`` and fleet sizes may differ between groups.
Every group gives the learner inputs of the same size: the neighbour slots
are padded to a common K (``ResidualConfig.neighbour_slots``, default the
largest degree of the mixture) and the message sizes must agree. Each
group's episodes are drawn from its scenario's own training distribution and
resampled at every reset (the group's generators go on, as in
``FleetVecEnv``).

Seeding: ``seed(s)`` gives fleet k of group g the seed ``s + offset_g + k``
with ``offset_g = B_0 + ... + B_{g-1}``, so no two fleets of the mixture
share a seed. The infos of a group's ending slots carry ``"scenario"`` (the
group's scenario name), from which ``agents.training.trainer`` logs per-scenario
episode costs.

Example:
    >>> env = MixtureVecEnv(["bench_mild", "bench_switching", "bench_large_fleet"], 6, "nn_dsc")
    >>> env.seed(0)
    [0, 1, 2, 3, 4, 5]
    >>> env.reset().shape  # 2 x 5 + 2 x 5 + 2 x 10 slots, K = 4 slots of 4 floats
    (40, 34)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from agents.envs.vec_env import FleetVecEnv
from cpf_env.envs.core import DEFAULT_INFO_LEVEL, check_num_fleets, checked_actions
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.sim.fleet import check_seed, observation_layout

__all__ = ["BalancedRewards", "MixtureVecEnv", "split_fleets"]


def split_fleets(num_fleets: int, groups: int) -> list[int]:
    """Fleets per group: ``num_fleets`` shared as evenly as possible, earlier groups first.

    Raises:
        ValueError: Fewer fleets than groups (every scenario needs one).
    """
    if num_fleets < groups:
        raise ValueError(
            f"a mixture of {groups} scenarios needs at least {groups} fleets (one per "
            f"scenario), got {num_fleets}; raise the number of fleets."
        )
    share, extra = divmod(num_fleets, groups)
    return [share + (g < extra) for g in range(groups)]


class MixtureVecEnv(VecEnv):
    """Fleets of several scenarios as one vector env, a slot per vessel.

    Args:
        scenarios: Two or more distinct scenarios (names or ``Scenario`` objects).
        num_fleets: Fleets in all, shared out by ``split_fleets``.
        base_policy: As ``FleetVecEnv``: a policy name (rebuilt per scenario), None,
            or one object per scenario (a sequence of them).
        residual: As ``FleetVecEnv``; ``neighbour_slots`` None becomes the largest
            degree of the mixture.
        stagger: Spread each group's horizons over its fleets (``EpisodeCore``).
        info_level: ``"none"`` (default), ``"minimal"`` or ``"full"`` (``FleetVecEnv``).
        policy_options: Options (gains) for a base policy given by name.
        scenario_overrides: Per-scenario ``Scenario`` overrides (same order), or None.
        critic_state: Append the unobserved state to each input (``FleetVecEnv``).

    Attributes:
        groups: The ``FleetVecEnv`` of each scenario, in order.
        scenario_names: Each group's scenario name.
        group_of_slot: (num_envs,) int, the group of every slot.
    """

    render_mode = None

    def __init__(
        self,
        scenarios: Sequence[str | Scenario],
        num_fleets: int = 64,
        base_policy: str | Sequence[FleetPolicy] | None = None,
        residual: ResidualConfig | None = None,
        stagger: bool = True,
        info_level: str = DEFAULT_INFO_LEVEL,
        policy_options: dict[str, Any] | None = None,
        scenario_overrides: Sequence[dict[str, Any]] | None = None,
        critic_state: bool = False,
    ) -> None:
        overrides = list(scenario_overrides or [{}] * len(scenarios))
        if len(overrides) != len(scenarios):
            raise ValueError(
                f"give one override dict per scenario: {len(scenarios)} scenarios, "
                f"{len(overrides)} override dicts."
            )
        resolved = [make_scenario(s, **o) for s, o in zip(scenarios, overrides, strict=True)]
        names = [s.name for s in resolved]
        if len(resolved) < 2 or len(set(names)) != len(names):
            raise ValueError(
                f"a mixture needs two or more distinct scenarios, got {names}; for one "
                "scenario use FleetVecEnv."
            )
        num_fleets = check_num_fleets(num_fleets)
        layouts = [observation_layout(s) for s in resolved]
        messages = sorted({layout.msg_size for layout in layouts})
        if len(messages) > 1:
            raise ValueError(
                f"the scenarios of a mixture must share a message size, got {messages} for {names}."
            )
        base_residual = ResidualConfig() if residual is None else residual
        if base_residual.neighbour_slots is None:
            slots = max(layout.n_slots for layout in layouts)
            base_residual = replace(base_residual, neighbour_slots=slots)
        bases = _per_scenario(base_policy, len(resolved))
        self.groups = [
            FleetVecEnv(
                scenario,
                num_fleets=fleets,
                base_policy=base,
                residual=base_residual,
                stagger=stagger,
                info_level=info_level,
                policy_options=policy_options,
                critic_state=critic_state,
            )
            for scenario, fleets, base in zip(
                resolved, split_fleets(int(num_fleets), len(resolved)), bases, strict=True
            )
        ]
        self.scenario_names = names
        self.num_fleets = int(num_fleets)
        sizes = [group.num_envs for group in self.groups]
        self._bounds = np.cumsum([0, *sizes])
        self.group_of_slot = np.repeat(np.arange(len(sizes)), sizes)
        first = self.groups[0]
        super().__init__(sum(sizes), first.observation_space, first.action_space)
        self._actions: NDArray[np.floating] | None = None

    # --- SB3 VecEnv interface -------------------------------------------------------------

    def seed(self, seed: int | None = None) -> list[int | None]:
        """Fleet k of group g starts from ``seed + offset_g + k`` at the next ``reset()``.

        Returns:
            Every fleet's seed, group by group (length ``num_fleets``).
        """
        seed = check_seed(seed)
        if seed is None:
            seed = int(np.random.default_rng().integers(np.iinfo(np.uint32).max))
        seeds: list[int | None] = []
        for group in self.groups:
            seeds += group.seed(seed + len(seeds))
        return seeds

    def reset(self) -> NDArray[np.float32]:
        """Reset every group; (num_envs, input_size) float32."""
        observations = [np.asarray(group.reset()) for group in self.groups]
        self.reset_infos = [info for group in self.groups for info in group.reset_infos]
        return np.concatenate(observations)

    def step_async(self, actions: NDArray[np.floating]) -> None:
        """Split the actions (num_envs, k) among the groups, all checked before any is stored."""
        shape = (self.num_envs, self.groups[0].core.action_size)
        checked = checked_actions(actions, shape, "(num_envs, k)", ("slot {}", "component {}"))
        for group, (start, stop) in zip(self.groups, self._group_bounds(), strict=True):
            group.step_async(checked[start:stop])

    def step_wait(self) -> VecEnvStepReturn:
        """Step every group; ending slots' infos also name their scenario."""
        obs, rewards, dones, infos = [], [], [], []
        for group, name in zip(self.groups, self.scenario_names, strict=True):
            group_obs, group_rewards, group_dones, group_infos = group.step_wait()
            for info in group_infos:
                if info:
                    info["scenario"] = name
            obs.append(np.asarray(group_obs))
            rewards.append(group_rewards)
            dones.append(group_dones)
            infos.extend(group_infos)
        return np.concatenate(obs), np.concatenate(rewards), np.concatenate(dones), infos

    def close(self) -> None:
        """Close every group."""
        for group in self.groups:
            group.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute of the group of every requested slot."""
        return [getattr(self.groups[g], attr_name) for g in self._groups_of(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the groups of the requested slots."""
        for g in sorted(set(self._groups_of(indices))):
            setattr(self.groups[g], attr_name, value)

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        """Call a method of the group of every requested slot, and collect the results."""
        return [
            getattr(self.groups[g], method_name)(*method_args, **method_kwargs)
            for g in self._groups_of(indices)
        ]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        """False for every slot: there is no Gymnasium env inside to wrap."""
        return [False] * len(self._groups_of(indices))

    # --- helpers --------------------------------------------------------------------------

    def _group_bounds(self) -> list[tuple[int, int]]:
        """(first slot, slot after the last) of every group."""
        return [(int(a), int(b)) for a, b in zip(self._bounds[:-1], self._bounds[1:], strict=True)]

    def _groups_of(self, indices: VecEnvIndices) -> list[int]:
        """The group of every slot of SB3's ``indices`` (None, an int or an iterable)."""
        slots = self._get_indices(indices)
        return [int(self.group_of_slot[i]) for i in slots]


def _per_scenario(
    base_policy: str | Sequence[FleetPolicy] | None, count: int
) -> list[str | FleetPolicy | None]:
    """One base per scenario: a name or None repeated, or the given sequence (checked)."""
    if base_policy is None or isinstance(base_policy, str):
        return [base_policy] * count
    bases: list[str | FleetPolicy | None] = list(base_policy)
    if len(bases) != count:
        raise ValueError(
            f"give one base policy object per scenario: {count} scenarios, {len(bases)} policies "
            "(or a policy name, rebuilt for each scenario)."
        )
    return bases


class BalancedRewards(VecEnvWrapper):
    """Each scenario's rewards divided by its running mean per-step cost (for learning only).

    In a mixture the scenarios' costs differ several-fold (``bench_lossy_links``
    costs ``nn_dsc`` about five times what ``bench_mild`` does), and so do their
    advantages: the scenario with the largest cost steers every update, and a
    correction good for it is learned at the others' expense (measured: see
    ``docs/residual_rl.md``). Dividing each group's rewards by the mean cost per
    step it has seen so far (all slots, all steps since the start) gives every
    scenario rewards of order one. The scale changes slowly (a running mean over
    millions of steps); put the wrapper after ``VecMonitor`` so episode returns
    stay in the benchmark's units.

    Args:
        venv: A vector env over a ``MixtureVecEnv`` (maybe monitored).
        mixture: That ``MixtureVecEnv`` (its ``group_of_slot``).

    Attributes:
        scales: (groups,) the running mean cost per step of every group.
    """

    def __init__(self, venv: VecEnv, mixture: MixtureVecEnv) -> None:
        super().__init__(venv)
        self._group = mixture.group_of_slot
        groups = len(mixture.groups)
        self._sums = np.zeros(groups)
        self._counts = np.zeros(groups)
        self._slots = np.bincount(self._group, minlength=groups).astype(np.float64)
        self.scales = np.ones(groups)

    def reset(self) -> NDArray[np.float32]:
        """Reset the wrapped env (the running scales are kept)."""
        return np.asarray(self.venv.reset())

    def step_wait(self) -> VecEnvStepReturn:
        """Step, update each group's mean cost per step, and divide its rewards by it."""
        obs, rewards, dones, infos = self.venv.step_wait()
        cost = -np.asarray(rewards, dtype=np.float64)
        self._sums += np.bincount(self._group, weights=cost, minlength=len(self._sums))
        self._counts += self._slots
        self.scales = np.maximum(self._sums / self._counts, np.finfo(np.float32).tiny)
        balanced = (rewards / self.scales[self._group]).astype(np.float32)
        return obs, balanced, dones, infos
