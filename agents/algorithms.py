"""The SB3 side of a training run: the algorithms by name, the vector env and the model.

``make_env`` builds a run's ``FleetVecEnv`` (or ``MixtureVecEnv``),
``build_model`` its untrained PPO or SAC model with the residual-learning
defaults (``agents.training`` lists them), ``planned_timesteps`` the budget
SB3 really trains. ``agents.training.train`` and ``agents.run_folder`` use
them; reading an agent folder needs none of this (no SB3 import).
"""

from __future__ import annotations

import warnings
from typing import cast

import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecEnv

from agents.mixture_env import MixtureVecEnv
from agents.train_config import TrainConfig
from agents.vec_env import FleetVecEnv

__all__ = ["ALGORITHMS", "build_model", "make_env", "planned_timesteps"]

#: SB3 algorithms by name.
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC}


def make_env(config: TrainConfig, num_fleets: int | None = None) -> FleetVecEnv | MixtureVecEnv:
    """The vector env of a run (``num_fleets`` overrides ``config.fleets``).

    A ``FleetVecEnv`` for one scenario, a ``MixtureVecEnv`` for several.
    """
    base = None if config.base == "none" else config.base
    fleets = config.fleets if num_fleets is None else num_fleets
    residual = config.residual_config()
    if len(config.scenarios) > 1:
        return MixtureVecEnv(
            config.scenarios,
            num_fleets=fleets,
            base_policy=base,
            residual=residual,
            scenario_overrides=[config.scenario_overrides(name) for name in config.scenarios],
        )
    return FleetVecEnv(
        config.home_scenario,
        num_fleets=fleets,
        base_policy=base,
        residual=residual,
        **config.scenario_overrides(),
    )


def build_model(config: TrainConfig, env: VecEnv) -> BaseAlgorithm:
    """The untrained PPO or SAC model ``train`` uses, on ``env``; the mean action starts at zero.

    Args:
        config: The run (algorithm, network, learning settings, seed).
        env: The (monitored, maybe normalized) ``FleetVecEnv`` from ``make_env``.
    """
    arch = list(config.net_arch)
    if config.algo == "ppo":
        rollout = config.n_steps * env.num_envs
        if config.batch_size > rollout:
            warnings.warn(
                f"batch_size {config.batch_size} is larger than one rollout (n_steps x vessel "
                f"slots = {config.n_steps} x {env.num_envs} = {rollout}); PPO uses minibatches "
                f"of {rollout}. Lower --batch-size or raise --n-steps or --fleets.",
                stacklevel=2,
            )
        model: BaseAlgorithm = PPO(
            "MlpPolicy",
            env,
            learning_rate=config.learning_rate,
            n_steps=config.n_steps,
            batch_size=min(config.batch_size, rollout),  # <= one rollout
            n_epochs=config.n_epochs,
            gamma=config.gamma,
            seed=config.seed,
            device="cpu",
            policy_kwargs={"net_arch": arch, "log_std_init": config.log_std_init},
        )
        layer = cast(torch.nn.Linear, model.policy.action_net)
    else:
        model = SAC(
            "MlpPolicy",
            env,
            learning_rate=config.learning_rate,
            buffer_size=config.buffer_size,
            batch_size=config.batch_size,
            gradient_steps=config.gradient_steps,
            learning_starts=0,
            gamma=config.gamma,
            seed=config.seed,
            device="cpu",
            policy_kwargs={"net_arch": arch, "log_std_init": config.log_std_init},
        )
        layer = cast(torch.nn.Linear, model.actor.mu)
        log_std = cast(torch.nn.Linear, model.actor.log_std)
        with torch.no_grad():  # state-independent initial noise exp(log_std_init)
            log_std.weight.zero_()
            log_std.bias.fill_(config.log_std_init)
    with torch.no_grad():
        layer.weight.zero_()
        layer.bias.zero_()
    return model


def planned_timesteps(config: TrainConfig, num_envs: int) -> int:
    """Vessel-steps a run of ``config.timesteps`` really trains: SB3 completes whole rollouts.

    PPO collects ``n_steps x num_envs`` vessel-steps per rollout, SAC ``num_envs``
    per vector-env step, so the budget is rounded up to a multiple of that.
    """
    per_call = config.n_steps * num_envs if config.algo == "ppo" else num_envs
    return -(-config.timesteps // per_call) * per_call
