"""The SB3 side of a training run: the algorithms by name, the vector env and the model.

``make_env`` builds a run's ``FleetVecEnv`` (or ``MixtureVecEnv``),
``build_model`` its untrained PPO or SAC model with the residual-learning
defaults (``agents.training.trainer`` lists them) and, with ``encoder="deepsets"``,
the ``DeepSetsExtractor`` in front of the actor and, with
``asymmetric_critic``, the ``AsymmetricActorCriticPolicy``; ``planned_timesteps`` the
budget SB3 really trains. ``agents.training.trainer.train`` and ``agents.training.run_folder`` use
them; reading an agent folder needs none of this (no SB3 import).
"""

from __future__ import annotations

import warnings
from typing import Any, cast

import gymnasium as gym
import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import (
    BaseFeaturesExtractor,
    MlpExtractor,
)
from stable_baselines3.common.vec_env import VecEnv

from agents.envs.mixture_env import MixtureVecEnv
from agents.envs.vec_env import FleetVecEnv
from agents.folder.actor import ENCODER_HIDDEN, ENCODER_POOLING
from agents.folder.encoder import NeighbourSetEncoder
from agents.training.config import TrainConfig
from agents.training.device import torch_device
from cpf_env.evaluation.privileged import UNOBSERVED_SIZE
from cpf_env.sim.observation import SLOTS, observation_box

__all__ = [
    "ALGORITHMS",
    "AsymmetricActorCriticPolicy",
    "DeepSetsExtractor",
    "LocalInputs",
    "build_model",
    "make_env",
    "planned_timesteps",
    "unobserved_columns",
]

#: SB3 algorithms by name.
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC}


class DeepSetsExtractor(BaseFeaturesExtractor):
    """``NeighbourSetEncoder`` as an SB3 features extractor (``policy_kwargs``).

    Args:
        observation_space: The learner's input space (its length fixes K for SB3's
            checks only; the weights do not depend on K).
        tail: Floats after the slots (extras, history).
        msg_size: Message length m (slot size 3 + m).
        hidden: Width of the per-slot MLP.
        pooling: ``"mean"`` or ``"sum"``.
        empty_weight: See ``NeighbourSetEncoder``.
    """

    def __init__(
        self,
        observation_space: gym.spaces.Box,
        tail: int = 0,
        msg_size: int = 1,
        hidden: int = 32,
        pooling: str = "mean",
        empty_weight: float = 0.0,
    ) -> None:
        encoder = NeighbourSetEncoder(
            3 + msg_size, tail=tail, hidden=hidden, pooling=pooling, empty_weight=empty_weight
        )
        encoder.slots_in(int(observation_space.shape[-1]))
        super().__init__(observation_space, encoder.features_dim)
        self.encoder = encoder

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        """Features (B, ``features_dim``) of observations (B, 18 + K (3 + m) + tail)."""
        return self.encoder(observations)


class LocalInputs(BaseFeaturesExtractor):
    """The actor's features: its input without the critic's unobserved state, through ``inner``.

    The run's input is ``[local input, unobserved state (UNOBSERVED_SIZE), history]``
    (``FleetVecEnv(critic_state=True)``, then ``HistoryVecEnv``); the actor reads
    ``[local input, history]``, which is what an agent folder's actor is given.

    Args:
        observation_space: The run's whole input space.
        unobserved_start: Where the unobserved state starts (the local input's length).
        inner: The features extractor over the actor's input (a ``FlattenExtractor``
            or a ``DeepSetsExtractor``).
    """

    def __init__(
        self, observation_space: gym.spaces.Box, unobserved_start: int, inner: BaseFeaturesExtractor
    ) -> None:
        super().__init__(observation_space, inner.features_dim)
        self.inner, self.unobserved_start = inner, unobserved_start

    @property
    def encoder(self) -> NeighbourSetEncoder | None:
        """The inner extractor's neighbour encoder, if it has one (what a folder keeps)."""
        encoder = getattr(self.inner, "encoder", None)
        return encoder if isinstance(encoder, NeighbourSetEncoder) else None

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        """Features of the actor's columns of ``observations`` (B, whole input)."""
        stop = self.unobserved_start + UNOBSERVED_SIZE
        local = torch.cat([observations[:, : self.unobserved_start], observations[:, stop:]], dim=1)
        return cast(torch.Tensor, self.inner(local))


class AsymmetricActorCriticPolicy(ActorCriticPolicy):
    """SB3's actor-critic with a critic that also reads what no vessel observes.

    The input holds the unobserved state (``cpf_env.evaluation.privileged.
    unobserved_state``) at ``unobserved_start``; the critic's extractor reads the
    whole input, the actor's (``LocalInputs``) the rest, and each has its own
    MLP from its own feature width (``share_features_extractor`` is always
    False). Everything else is SB3's ``ActorCriticPolicy``: the actor's modules
    (``pi_features_extractor``, ``mlp_extractor.policy_net``, ``action_net``) are
    where ``agents.folder.actor.sb3_actor_layers`` reads them, so the agent
    folder holds an ordinary local actor.

    Args:
        unobserved_start: Where the unobserved state starts in the input.
        *args, **kwargs: ``ActorCriticPolicy``'s.
    """

    def __init__(self, *args: Any, unobserved_start: int, **kwargs: Any) -> None:
        self.unobserved_start = unobserved_start
        super().__init__(*args, **{**kwargs, "share_features_extractor": False})

    def _build(self, lr_schedule: Any) -> None:
        """Give the actor its ``LocalInputs`` extractor, then build as SB3 does."""
        kwargs = dict(self.features_extractor_kwargs)
        if issubclass(self.features_extractor_class, DeepSetsExtractor):
            kwargs["tail"] -= UNOBSERVED_SIZE  # the actor's tail lacks the unobserved state
        size = int(self.observation_space.shape[0]) - UNOBSERVED_SIZE  # type: ignore[index]
        inner = self.features_extractor_class(observation_box(size), **kwargs)
        actor = LocalInputs(
            cast(gym.spaces.Box, self.observation_space), self.unobserved_start, inner
        )
        self.features_extractor = self.pi_features_extractor = actor
        self.features_dim = actor.features_dim
        super()._build(lr_schedule)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        """SB3's, and ``unobserved_start`` (so ``policy.save`` / ``load`` rebuild it)."""
        return {**super()._get_constructor_parameters(), "unobserved_start": self.unobserved_start}

    def _build_mlp_extractor(self) -> None:
        """An actor MLP on the actor's features and a critic MLP on the critic's."""
        extractor, critic = (
            MlpExtractor(width, self.net_arch, self.activation_fn, self.device)
            for width in (self.features_dim, self.vf_features_extractor.features_dim)
        )
        extractor.value_net = critic.value_net
        self.mlp_extractor = extractor


def unobserved_columns(model: BaseAlgorithm) -> range:
    """The input columns only the critic reads (empty unless the run has an asymmetric critic).

    An agent folder's observation statistics leave them out, as its actor does.
    """
    start = getattr(model.policy, "unobserved_start", None)
    return range(0) if start is None else range(start, start + UNOBSERVED_SIZE)


def make_env(config: TrainConfig, num_fleets: int | None = None) -> FleetVecEnv | MixtureVecEnv:
    """The vector env of a run (``num_fleets`` overrides ``config.fleets``).

    A ``FleetVecEnv`` for one scenario, a ``MixtureVecEnv`` for several.
    """
    base = None if config.base_policy == "none" else config.base_policy
    fleets = config.fleets if num_fleets is None else num_fleets
    residual = config.residual
    if len(config.scenarios) > 1:
        return MixtureVecEnv(
            config.scenarios,
            num_fleets=fleets,
            base_policy=base,
            residual=residual,
            scenario_overrides=[config.scenario_overrides(name) for name in config.scenarios],
            critic_state=config.asymmetric_critic,
        )
    return FleetVecEnv(
        config.home_scenario,
        num_fleets=fleets,
        base_policy=base,
        residual=residual,
        critic_state=config.asymmetric_critic,
        **config.scenario_overrides(),
    )


def build_model(config: TrainConfig, env: VecEnv, device: str = "cpu") -> BaseAlgorithm:
    """The untrained PPO or SAC model ``train`` uses, on ``env``; the mean action starts at zero.

    Args:
        config: The run (algorithm, network, learning settings, seed).
        env: The (monitored, maybe normalized, maybe with history) ``FleetVecEnv`` from
            ``make_env``.
        device: The torch device SB3 trains on (``agents.training.device.torch_device``).

    Raises:
        ValueError: A device torch does not know or this machine does not have.
    """
    where = torch_device(device)
    arch = list(config.net_arch)
    if config.algo == "ppo":
        rollout = config.n_steps * env.num_envs
        if config.batch_size > rollout:
            warnings.warn(
                f"batch_size {config.batch_size} is larger than one rollout (n_steps x vessel "
                f"slots = {config.n_steps} x {env.num_envs} = {rollout}); PPO uses minibatches "
                f"of {rollout}. Lower batch_size or raise n_steps (--set) or --fleets.",
                stacklevel=2,
            )
        model: BaseAlgorithm = PPO(
            AsymmetricActorCriticPolicy if config.asymmetric_critic else "MlpPolicy",
            env,
            learning_rate=config.learning_rate,
            n_steps=config.n_steps,
            batch_size=min(config.batch_size, rollout),  # <= one rollout
            n_epochs=config.n_epochs,
            gamma=config.gamma,
            seed=config.seed,
            device=where,
            policy_kwargs={
                "net_arch": arch,
                "log_std_init": config.log_std_init,
                **_encoder_kwargs(config, env),
                **_critic_kwargs(config, env),
            },
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
            device=where,
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


def _encoder_kwargs(config: TrainConfig, env: VecEnv) -> dict[str, Any]:
    """PPO's ``policy_kwargs`` for the run's encoder: none, or a ``DeepSetsExtractor``.

    The actor and the critic get an encoder each (``share_features_extractor=False``):
    rewards are not normalized, so the value loss is on the cost's own scale and,
    shared, would shape the actor's features as much as the policy loss; alone, the
    actor's encoder is what the agent folder keeps, trained by the policy loss only.
    """
    if config.encoder is None:
        return {}
    slots, slot_size = config.learner_slots()
    size = int(env.observation_space.shape[0])  # type: ignore[index]
    return {
        "features_extractor_class": DeepSetsExtractor,
        "features_extractor_kwargs": {
            "tail": size - SLOTS - slots * slot_size,
            "msg_size": slot_size - 3,
            "hidden": ENCODER_HIDDEN,
            "pooling": ENCODER_POOLING,
        },
        "share_features_extractor": False,
    }


def _critic_kwargs(config: TrainConfig, env: VecEnv) -> dict[str, Any]:
    """``AsymmetricActorCriticPolicy``'s ``unobserved_start`` (none for a symmetric critic).

    The fleets' env (under the wrappers) ends with the unobserved state, so it
    starts ``UNOBSERVED_SIZE`` before the end of that env's input.
    """
    if not config.asymmetric_critic:
        return {}
    size = int(env.unwrapped.observation_space.shape[0])  # type: ignore[index]
    return {"unobserved_start": size - UNOBSERVED_SIZE}


def planned_timesteps(config: TrainConfig, num_envs: int) -> int:
    """Vessel-steps a run of ``config.timesteps`` really trains: SB3 completes whole rollouts.

    PPO collects ``n_steps x num_envs`` vessel-steps per rollout, SAC ``num_envs``
    per vector-env step, so the budget is rounded up to a multiple of that.
    """
    per_call = config.n_steps * num_envs if config.algo == "ppo" else num_envs
    return -(-config.timesteps // per_call) * per_call
