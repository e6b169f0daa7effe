"""A trained BenchMARL actor as data, loaded as a ``cpf-bench`` policy.

``save_marl_policy(experiment, folder)`` writes, for the shared actor of
BenchMARL's PPO family (MAPPO, IPPO: ``share_policy_params=True``, an MLP over
each vessel's local input):

- ``policy.safetensors``: the actor MLP as ``agents.agent_folder.PolicyNetwork``
  tensors (``hidden.<i>.weight`` (out, in), ``hidden.<i>.bias``, ``output.weight``,
  ``output.bias``), float32. The output layer keeps only the rows of the
  Gaussian's location: the deterministic action BenchMARL evaluates with is
  ``tanh(loc)`` on [-1, 1] (its ``TanhNormal``), so the scale rows are dropped;
- ``normalization.json``: the env's frozen ``InputStatistics``, or ``null``;
- ``config.json``: the task config (``CpfTaskConfig``), the algorithm, the layer
  sizes and activation, and the run's record (seed, frames, iterations);
- ``manifest.json``: format ``cpf-marl-agent``, and the SHA-256 and size of each
  file (the manifest of ``agents.agent_folder``, with its own format name).

``load_marl_policy`` reads it back (every hash checked; no pickle anywhere) as
an ``agents.TrainedPolicy``: the named base policy underneath, the same
residual composition and statistics, local observations only. ``load_policy``
(and so ``cpf-bench --policy FOLDER``) dispatches here on the format name.
Nothing here imports BenchMARL: a saved folder loads with the ``rl`` extra.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
from safetensors.torch import load as load_tensors

from agents.agent_folder import (
    CONFIG,
    MANIFEST,
    NORMALIZATION,
    WEIGHTS,
    AgentFolderError,
    PolicyNetwork,
    agent_files,
    read_verified,
    write_with_manifest,
)
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.infra import atomic
from cpf_env.scenarios import Scenario, make_scenario

if TYPE_CHECKING:
    from agents.loading import TrainedPolicy

__all__ = ["MARL_FORMAT", "is_marl_folder", "load_marl_policy", "save_marl_policy"]

MARL_FORMAT = "cpf-marl-agent"
MARL_FORMAT_VERSION = 1
#: BenchMARL algorithms whose actor this format holds (a Gaussian over [-1, 1], tanh-squashed).
ALGORITHMS = ("mappo", "ippo")


def is_marl_folder(folder: Path) -> bool:
    """Whether ``folder`` holds a manifest of this format (nothing else is read)."""
    try:
        manifest = json.loads((folder / MANIFEST).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return False
    return isinstance(manifest, dict) and manifest.get("format") == MARL_FORMAT


def _actor_layers(experiment: Any, group: str) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """(weight, bias) of each linear layer of the shared actor MLP, input first."""
    actor = experiment.algorithm.get_policy_for_loss(group)
    state = actor.state_dict()
    prefix = next((key.split("mlp.params.")[0] for key in state if "mlp.params." in key), None)
    if prefix is None:
        raise ValueError(
            "the experiment's actor is not BenchMARL's MLP model (no mlp.params in its state); "
            "save_marl_policy holds MLP actors only."
        )
    indices = sorted({int(key.split("mlp.params.")[1].split(".")[0]) for key in state})
    layers = []
    for index in indices:
        weight = state[f"{prefix}mlp.params.{index}.weight"]
        if weight.ndim != 2:
            raise ValueError(
                "the actor has one network per vessel (share_policy_params=False); this format "
                "holds a shared actor. Train with experiment.share_policy_params=True."
            )
        layers.append((weight, state[f"{prefix}mlp.params.{index}.bias"]))
    return layers


def save_marl_policy(
    experiment: Any, folder: str | Path, algorithm: str, group: str = "vessel"
) -> Path:
    """Write a trained BenchMARL experiment's actor as a policy folder (see the module docstring).

    Args:
        experiment: A ``benchmarl.experiment.Experiment`` on a ``CpfTask``.
        folder: The folder to write (an existing one is replaced whole, at once).
        algorithm: ``"mappo"`` or ``"ippo"`` (recorded; both share this actor form).
        group: The agent group.

    Returns:
        The folder.

    Raises:
        ValueError: Another algorithm, model or parameter sharing.
    """
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}.")
    model = experiment.model_config
    if model.activation_class is not torch.nn.Tanh:
        raise ValueError(f"the actor must use Tanh activations, got {model.activation_class}.")
    layers = _actor_layers(experiment, group)
    env = experiment.test_env.base_env
    k = env.action_size
    weight, bias = layers[-1]
    if weight.shape[0] != 2 * k:
        raise ValueError(
            f"the actor's last layer has {weight.shape[0]} outputs, not 2 k = {2 * k}."
        )
    tensors = {}
    for i, (w, b) in enumerate(layers[:-1]):
        tensors[f"hidden.{i}.weight"], tensors[f"hidden.{i}.bias"] = w, b
    tensors["output.weight"], tensors["output.bias"] = weight[:k], bias[:k]
    tensors = {
        name: value.detach().to(torch.float32).contiguous() for name, value in tensors.items()
    }
    sizes = [int(layers[0][0].shape[1]), *(int(w.shape[0]) for w, _ in layers[:-1]), k]
    record = {
        "task": dict(experiment.task.config),
        "algorithm": algorithm,
        "sizes": sizes,
        "activation": "tanh",
        "output": "tanh",
        "seed": int(experiment.seed),
        "frames": int(experiment.total_frames),
        "iterations": int(experiment.n_iters_performed),
    }
    target = Path(folder)
    with atomic.staged_folder(target) as staging:
        write_with_manifest(
            staging,
            agent_files(tensors, env.input_statistics, record),
            MARL_FORMAT,
            MARL_FORMAT_VERSION,
        )
    return target


def load_marl_policy(folder: str | Path, scenario: str | Scenario | None = None) -> TrainedPolicy:
    """A saved MARL actor as a policy with the analytic policies' interface.

    Args:
        folder: A folder ``save_marl_policy`` wrote.
        scenario: Evaluation scenario; default: the task's scenario (its own
            ``max_steps``, not the training episodes').

    Raises:
        AgentFolderError: A missing, altered or inconsistent file (named).
    """
    from agents.loading import TorchActor, TrainedPolicy
    from agents.train_config import TrainConfig

    path = Path(folder)
    manifest = json.loads((path / MANIFEST).read_text())
    if manifest.get("format_version") != MARL_FORMAT_VERSION:
        raise AgentFolderError(
            f"{path / MANIFEST} has format version {manifest.get('format_version')!r}; this "
            f"cpf_env reads version {MARL_FORMAT_VERSION}."
        )
    try:
        record = json.loads(read_verified(path, CONFIG, manifest))
        task, sizes = record["task"], [int(x) for x in record["sizes"]]
        config = TrainConfig(
            algo="ppo",
            scenario=task["scenario"],
            base=task["base"],
            mode=task["mode"],
            scale=float(task["scale"]),
            extras=tuple(task["extras"]),
            normalize_observations=bool(task["normalize"]),
            net_arch=tuple(sizes[1:-1]),
        )
        statistics = json.loads(read_verified(path, NORMALIZATION, manifest))
        normalization = None
        if statistics is not None:
            normalization = InputStatistics.from_json(statistics)
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as error:
        if isinstance(error, AgentFolderError):
            raise
        raise AgentFolderError(f"{path} holds an invalid MARL policy record: {error}") from None
    try:
        tensors = load_tensors(read_verified(path, WEIGHTS, manifest))
    except AgentFolderError:
        raise
    except Exception as error:  # safetensors raises its own error type
        raise AgentFolderError(f"{path / WEIGHTS} is not a safetensors file: {error}") from None
    network = PolicyNetwork(sizes, "tanh", "tanh")
    try:
        network.load_state_dict(tensors)
    except RuntimeError as error:
        raise AgentFolderError(f"{path / WEIGHTS} does not fit sizes {sizes}: {error}") from None
    resolved = make_scenario(config.home_scenario if scenario is None else scenario)
    actor = TorchActor(network.eval(), normalization)
    return TrainedPolicy(path.name, config, actor, resolved)
