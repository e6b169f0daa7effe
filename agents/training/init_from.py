"""Starting a PPO run from an agent folder: fine-tuning a distilled student (``--init-from``).

``read_init_source(folder, config)`` reads an agent folder (a ``cpf-distill``
student, or a ``cpf-train`` agent) and checks that its recipe is the run's:
the keys of ``RECIPE`` and the learner's input layout (neighbour slots, slot
size, input length). ``InitSource.apply`` then gives the fresh PPO model the
folder's actor (hidden layers, output layer, and with ``encoder="deepsets"`` the
actor's encoder) and gives ``VecNormalize`` the folder's observation
statistics, so the run's deterministic policy before any update is the
folder's (``tests/agents/test_init_from.py``). What is not the folder's:

- the critic (and, with an encoder, the critic's own encoder) is freshly
  initialised, as in any run: an agent folder holds no value function. With
  ``asymmetric_critic`` its unobserved-state inputs keep mean 0 and variance 1
  (they are of order one: ``cpf_env.evaluation.privileged.unobserved_state``). Its
  first estimates are poor, so the first updates' advantages are noisy; the
  small exploration noise below and PPO's clipped steps are what limits how
  far the actor moves from the student meanwhile;
- the exploration noise: ``TrainConfig.log_std_init``, for which ``cpf-train
  --init-from`` defaults to ``agents.training.config.INIT_LOG_STD`` (-2.5: a standard
  deviation of 0.08 of the residual range, 4 % of the force limits at ``scale = 0.5``) instead of
  -1, whose noise (0.37 of the range) would move the student far from what it
  learned;
- nothing else changes during the run but the weights: the observation
  statistics stay frozen at the folder's (``VecNormalize.training`` off, in
  resumed parts too). Updated on the fine-tuning scenario they drift by
  several standard deviations from the distilled statistics, which moves the
  actor's inputs away from what it learned (measured in
  ``docs/residual_rl.md``, "Fine-tuning a distilled student with PPO").

The run records the folder and the SHA-256 of its ``manifest.json``
(``InitSource.record``) in ``run.json`` and in the agent's ``config.json``
(key ``init_from``).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from agents.folder.actor import PolicyNetwork, sb3_actor_layers
from agents.folder.format import MANIFEST, Normalization, read_agent, training_config
from agents.training.algorithms import unobserved_columns
from agents.training.config import TrainConfig

__all__ = ["RECIPE", "InitSource", "read_init_source"]

#: ``TrainConfig`` fields (``residual.*``: of its ``ResidualConfig``) an agent folder must
#: share with the run it starts; the neighbour slots are compared as the learner's K.
RECIPE = (
    "algo",
    "base_policy",
    "residual.mode",
    "residual.scale",
    "residual.kinematic_scale",
    "residual.extras",
    "residual.hide_residual_from_base",
    "residual.yield_at_limit",
    "residual.messages",
    "normalize_observations",
    "shared_slot_statistics",
    "encoder",
    "history",
    "net_arch",
)


@dataclass(frozen=True)
class InitSource:
    """An agent folder checked to start a run: its actor, statistics and identity.

    Attributes:
        folder: The agent folder, as given (recorded so; the digest identifies it).
        manifest_sha256: SHA-256 of its ``manifest.json`` (which lists every file's hash).
        network: Its actor.
        normalization: Its observation statistics, or None.
    """

    folder: Path
    manifest_sha256: str
    network: PolicyNetwork
    normalization: Normalization | None

    def record(self) -> dict[str, str]:
        """The JSON-ready record kept in ``run.json`` and ``config.json`` (``init_from``)."""
        return {"folder": str(self.folder), "manifest_sha256": self.manifest_sha256}

    def apply(self, model: BaseAlgorithm, env: VecEnv) -> None:
        """Give ``model``'s actor the folder's weights, ``env``'s ``VecNormalize`` its statistics.

        Args:
            model: A fresh PPO model of the run (``agents.training.algorithms.build_model``).
            env: The model's env (its outermost wrapper, ``VecNormalize`` when the run
                normalizes).
        """
        encoder, hidden, output = sb3_actor_layers(model, "ppo")
        with torch.no_grad():
            sources = [cast(torch.nn.Linear, layer) for layer in self.network.hidden]
            for layer, source in zip(hidden, sources, strict=True):
                layer.weight.copy_(source.weight)
                layer.bias.copy_(source.bias)
            output.weight.copy_(self.network.output.weight)
            output.bias.copy_(self.network.output.bias)
            if self.network.encoder is not None:
                assert encoder is not None  # the encoder is in RECIPE
                encoder.load_state_dict(self.network.encoder.state_dict())
        if self.normalization is not None:
            assert isinstance(env, VecNormalize)  # normalize_observations is in RECIPE
            rms = cast(RunningMeanStd, env.obs_rms)
            mean = np.array(self.normalization.mean, dtype=np.float64)
            var = np.array(self.normalization.var, dtype=np.float64)
            columns = unobserved_columns(model)  # an asymmetric critic's own inputs: left unscaled
            rms.mean = np.insert(mean, columns.start, np.zeros(len(columns)))
            rms.var = np.insert(var, columns.start, np.ones(len(columns)))
            env.epsilon, env.clip_obs = self.normalization.epsilon, self.normalization.clip


def _value(config: TrainConfig, key: str) -> Any:
    """The value of a ``RECIPE`` key (``"residual.mode"``: ``config.residual.mode``)."""
    value: Any = config
    for name in key.split("."):
        value = getattr(value, name)
    return value


def read_init_source(folder: str | Path, config: TrainConfig) -> InitSource:
    """Read the agent folder ``folder`` and check that it can start the run ``config``.

    Raises:
        ValueError: A run that is not PPO, an unreadable or altered agent folder, or a
            recipe that differs from the run's (the differing keys are named, with
            both values).
    """
    if config.algo != "ppo":
        raise ValueError(
            f"--init-from starts a PPO run from an agent folder; this run is {config.algo!r} "
            "(use --algo ppo)."
        )
    path = Path(folder)
    if not (path / MANIFEST).is_file():
        raise ValueError(
            f"--init-from {folder}: not an agent folder (no {MANIFEST}); give a folder "
            "written by cpf-train or cpf-distill."
        )
    record, network, normalization = read_agent(path)
    saved = training_config(record["config"], path / "config.json")
    differ = [
        f"{key} (folder {_value(saved, key)!r}, run {_value(config, key)!r})"
        for key in RECIPE
        if _value(saved, key) != _value(config, key)
    ]
    layout = ("neighbour_slots", saved.learner_slots()[0], config.learner_slots()[0])
    if not differ and layout[1] != layout[2]:
        differ.append(f"{layout[0]} (folder {layout[1]!r}, run {layout[2]!r})")
    if not differ and saved.learner_input_size() != config.learner_input_size():
        differ.append(
            f"the learner's input size (folder {saved.learner_input_size()}, run "
            f"{config.learner_input_size()}; the scenarios' message sizes differ)"
        )
    if differ:
        raise ValueError(
            f"--init-from {folder} was trained with another recipe; these differ from the "
            f"run's: {'; '.join(differ)}. Give the run the folder's settings "
            "(its config.json)."
        )
    digest = hashlib.sha256((path / MANIFEST).read_bytes()).hexdigest()
    return InitSource(path, digest, network, normalization)
