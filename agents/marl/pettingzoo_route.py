"""The PettingZoo route as BenchMARL tasks: TorchRL's ``PettingZooWrapper`` in a ``SerialEnv``.

BenchMARL's own ``PettingZooClass`` cannot load this package (it looks tasks
up by PettingZoo module name) and builds every ``SerialEnv`` worker with the
same seed, so all workers play identical episodes. ``CpfPettingZooTask``
has the members and configs of ``CpfTask`` on the same residual composition,
one residual ``cpf_env.parallel_env`` per worker (over the named base policy,
resolved by ``agents.envs.resolve``), and seeds the i-th env its maker builds
with seed + i: distinct, reproducible episodes in every worker (TorchRL's
``SerialEnv`` may build one more env first, for its specs; it takes seed + 0).
With ``parallel_collection=True`` the maker is copied into each process and
the seeds repeat: use ``SerialEnv`` (BenchMARL's default) on this route.

``normalize`` applies the same frozen statistics as the native env
(``estimate_input_statistics``: 16 fleets, seeds 0 .. 15), as
TorchRL transforms in float32 (``ObservationNorm`` and a clip to +-10), so the
inputs match the native env's to float32 rounding, not bit for bit.

This route is for checking and for code that must take any PettingZoo env: it
steps one fleet per worker in Python, a few thousand vessel-steps/s against
the native env's hundreds of thousands (``docs/torchrl.md``).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import torch

import cpf_env
from agents.envs.resolve import resolve_base_policy
from agents.marl.tasks import CpfTask, CpfTaskClass, CpfTaskEnum, checked_config
from cpf_env.envs.input_statistics import estimate_input_statistics
from cpf_env.envs.residual import learner_config
from cpf_env.envs.torchrl_env import GROUP
from cpf_env.scenarios import make_scenario

from benchmarl.environments import TaskClass  # isort: skip  (after agents.marl.tasks)
from torchrl.envs import ClipTransform, EnvBase, ObservationNorm, PettingZooWrapper, Transform

__all__ = ["ENV_NAME", "CpfPettingZooTask", "CpfPettingZooTaskClass"]

ENV_NAME = "cpf_pettingzoo"


class CpfPettingZooTaskClass(CpfTaskClass):
    """``CpfTaskClass`` on one ``PettingZooWrapper`` per worker, worker i seeded seed + i."""

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
    ) -> Callable[[], EnvBase]:
        """A maker of one-fleet envs; the i-th env it builds is seeded ``seed + i``.

        Raises:
            ValueError: Discrete actions, a held-out scenario, evaluation seeds or
                ``privileged_state`` (the native tasks' field).
        """
        config, first = self.training_config(continuous_actions, seed, int(num_envs) + 1)
        if config.privileged_state:
            raise ValueError(
                "privileged_state is a field of the native tasks (cpf/<task>): the PettingZoo "
                "route's state is the ParallelEnv's state(), which holds no unobserved "
                "quantity. Set privileged_state: false in this task's config, or train on "
                "the native task."
            )
        scenario = make_scenario(config.scenario, max_steps=config.max_steps, **config.overrides)
        built = itertools.count()

        def make() -> EnvBase:
            base = resolve_base_policy(config.base_policy, scenario)
            env = cpf_env.parallel_env(scenario, base_policy=base, residual=config.residual())
            return PettingZooWrapper(
                env,
                seed=first + next(built),
                return_state=config.state,
                device=device,
            )

        return make

    def get_env_transforms(self, env: EnvBase) -> list[Transform]:
        """The frozen input statistics as TorchRL transforms, if the config asks for them."""
        config = checked_config(self.config)
        if not config.normalize:
            return []
        scenario = make_scenario(config.scenario, max_steps=config.max_steps, **config.overrides)
        base = resolve_base_policy(config.base_policy, scenario)
        stats = estimate_input_statistics(
            scenario,
            base,
            learner_config(base, config.residual()),
            steps=config.normalization_steps,
        )
        key = (GROUP, "observation")
        loc = torch.as_tensor(stats.mean, dtype=torch.float32)
        scale = torch.sqrt(torch.as_tensor(stats.var + stats.epsilon, dtype=torch.float32))
        return [
            ObservationNorm(loc=loc, scale=scale, in_keys=[key], standard_normal=True),
            ClipTransform(in_keys=[key], low=-stats.clip, high=stats.clip),
        ]

    @staticmethod
    def env_name() -> str:
        """``"cpf_pettingzoo"``."""
        return ENV_NAME


class _PettingZooTaskEnum(CpfTaskEnum):
    """The PettingZoo route's enum: ``CpfTask``'s members on ``CpfPettingZooTaskClass``."""

    @staticmethod
    def associated_class() -> type[TaskClass]:
        """``CpfPettingZooTaskClass``."""
        return CpfPettingZooTaskClass


#: ``CpfTask``'s members, each built on the PettingZoo route.
CpfPettingZooTask = _PettingZooTaskEnum("CpfPettingZooTask", list(CpfTask.__members__))
