"""A trained BenchMARL actor as data, loaded as a ``cpf-bench`` policy.

``save_marl_policy(experiment, folder)`` writes, for the shared actor of
BenchMARL's PPO family (MAPPO, IPPO: ``share_policy_params=True``, an MLP over
each vessel's local input, or ``agents.marl.models.NeighbourSetMlp``: the
neighbour encoder, then an MLP):

- ``policy.safetensors``: the actor MLP as ``agents.folder.actor.PolicyNetwork``
  tensors (``hidden.<i>.weight`` (out, in), ``hidden.<i>.bias``, ``output.weight``,
  ``output.bias``), float32. The output layer keeps only the rows of the
  Gaussian's location: the deterministic action BenchMARL evaluates with is
  ``tanh(loc)`` on [-1, 1] (its ``TanhNormal``), so the scale rows are dropped.
  With the encoder, also its tensors (``encoder.phi.*``, ``encoder.empty_weight``,
  ``encoder.tolerance``: ``agents.folder.format``'s names);
- ``normalization.json``: the env's frozen ``InputStatistics``, or ``null``;
- ``config.json``: the task config (``CpfTaskConfig``), the algorithm, the layer
  sizes and activation, and the run's record (seed, frames, iterations); with
  the encoder, the field ``actor`` of ``agents.folder.format``'s version 2
  (``encoder``, ``history``, ``pooling``, ``hidden``, ``slot_size``, ``slots``,
  ``tail``);
- ``manifest.json``: ``agents.folder.format``'s manifest (format ``cpf-agent``,
  version 3) with trainer ``benchmarl``, and the SHA-256 and size of each
  file. Folders of the former format name ``cpf-marl-agent`` (versions 1 and
  2) are read too.

``read_marl_agent`` reads it back (every hash checked, every field typed
strictly, the weights' shapes, dtype and values checked before any network is
allocated: ``agents.folder.format``'s discipline; no pickle anywhere) as a
``TrainConfig``, the actor and its statistics; ``agents.load_policy`` (and so
``cpf-bench --policies FOLDER`` and ``cpf-run --policy FOLDER``) dispatches
here on the manifest's trainer and runs it as an ``agents.TrainedPolicy``: the named
base policy underneath, the same residual composition and statistics, local
observations only. An encoder actor runs on any number of neighbour slots
(its statistics shared by the slots, ``agents.folder.encoder.statistics_for_slots``),
so on scenarios of a higher degree than its task's. Nothing here imports
BenchMARL: a saved folder loads with the ``rl`` extra.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from agents.folder.actor import PolicyNetwork, encoder_layout
from agents.folder.files import AgentFolderError, check_fields, field
from agents.folder.format import (
    CONFIG,
    NORMALIZATION,
    WEIGHTS,
    actor_from_record,
    agent_files,
    check_empty_weight,
    network_from_layers,
    normalization_from_json,
    read_agent_manifest,
    read_json,
    read_weights,
    write_with_manifest,
)
from agents.training.config import TrainConfig
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.envs.residual import ResidualConfig
from cpf_env.infra import atomic
from cpf_env.scenarios import make_scenario

__all__ = ["marl_config", "marl_overrides", "read_marl_agent", "save_marl_policy"]

#: ``config.json``'s ``actor.encoder`` of an encoder actor (``TrainConfig.encoder``).
ENCODER = "deepsets"
#: BenchMARL algorithms whose actor this format holds (a Gaussian over [-1, 1], tanh-squashed).
ALGORITHMS = ("mappo", "ippo")
#: The actor's hidden activation and output transform (``PolicyNetwork``'s arguments).
ACTOR = ("tanh", "tanh")
#: JSON types of the record's fields, and of its task's fields that the policy uses.
RECORD_FIELDS = {
    "algorithm": "str",
    "sizes": "tuple[int, ...]",
    "activation": "str",
    "output": "str",
}
TASK_FIELDS = {
    "scenario": "str",
    "base_policy": "str",
    "mode": "str",
    "scale": "float",
    "extras": "tuple[str, ...]",
    "normalize": "bool",
}


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
    env = experiment.test_env.base_env
    k = env.core.action_size
    actor = experiment.algorithm.get_policy_for_loss(group)
    networks = [module for module in actor.modules() if isinstance(module, PolicyNetwork)]
    record: dict[str, Any] = {"task": dict(experiment.task.config), "algorithm": algorithm}
    if networks:  # agents.marl.models.NeighbourSetMlp
        network = networks[0]
        encoder = network.encoder
        assert encoder is not None
        record["actor"] = {"encoder": ENCODER, "history": 0, **encoder_layout(encoder)}
        record["actor"]["slots"] = encoder.slots_in(env.core.input_size)
        first = encoder.features_dim
        layers = [(layer.weight, layer.bias) for layer in [*network.hidden, network.output]]
        tensors = {f"encoder.{key}": value for key, value in encoder.state_dict().items()}
    else:
        if experiment.model_config.activation_class is not torch.nn.Tanh:
            raise ValueError(
                "the actor must use Tanh activations, got "
                f"{experiment.model_config.activation_class}."
            )
        layers = _actor_layers(experiment, group)
        first, tensors = int(layers[0][0].shape[1]), {}
    weight, bias = layers[-1]
    if weight.shape[0] != 2 * k:
        raise ValueError(
            f"the actor's last layer has {weight.shape[0]} outputs, not 2 k = {2 * k}."
        )
    for i, (w, b) in enumerate(layers[:-1]):
        tensors[f"hidden.{i}.weight"], tensors[f"hidden.{i}.bias"] = w, b
    tensors["output.weight"], tensors["output.bias"] = weight[:k], bias[:k]
    tensors = {
        name: value.detach().to("cpu", torch.float32).contiguous()  # trained on any device
        for name, value in tensors.items()
    }
    record["sizes"] = [first, *(int(w.shape[0]) for w, _ in layers[:-1]), k]
    record.update(
        activation="tanh",
        output="tanh",
        seed=int(experiment.seed),
        frames=int(experiment.total_frames),
        iterations=int(experiment.n_iters_performed),
    )
    target = Path(folder)
    with atomic.staged_folder(target) as staging:
        files = agent_files(tensors, env.input_statistics, record)
        write_with_manifest(staging, files, "benchmarl")
    return target


def marl_config(record: Any, source: Path) -> tuple[TrainConfig, list[int], dict[str, Any]]:
    """The ``TrainConfig``, layer sizes and scenario overrides of a MARL ``config.json`` record.

    Every field strictly checked. The overrides (``task.overrides``, ``marl_overrides``)
    have no ``TrainConfig`` field: ``agents.load_policy`` applies them to the default
    evaluation scenario.

    Raises:
        AgentFolderError: A missing or mistyped field (``scale: "10"``, ``normalize:
            "false"``), layer sizes that are not >= 1, another algorithm or actor form,
            overrides the scenario refuses.
    """
    check_fields(record, RECORD_FIELDS, source, required=True)
    check_fields(field(record, "task", source), TASK_FIELDS, source, "task.", required=True)
    if record["algorithm"] not in ALGORITHMS:
        raise AgentFolderError(
            f"{source}: field 'algorithm' must be one of {ALGORITHMS}, got {record['algorithm']!r}."
        )
    if (record["activation"], record["output"]) != ACTOR:
        raise AgentFolderError(
            f"{source}: fields 'activation' and 'output' must be {ACTOR}, got "
            f"{(record['activation'], record['output'])}."
        )
    sizes = record["sizes"]
    if len(sizes) < 3 or min(sizes) < 1:
        raise AgentFolderError(
            f"{source}: field 'sizes' must list the input, hidden and output layer sizes, "
            f"each >= 1, got {sizes}."
        )
    task = record["task"]
    shared = task.get("shared_slot_statistics", False)  # absent before the encoder actor
    if not isinstance(shared, bool):
        raise AgentFolderError(
            f"{source}: field 'task.shared_slot_statistics' must be true or false, got "
            f"{type(shared).__name__}."
        )
    try:
        config = TrainConfig(
            algo="ppo",
            scenario=task["scenario"],
            base_policy=task["base_policy"],
            residual=ResidualConfig(
                mode=task["mode"],
                scale=task["scale"],
                extras=tuple(task["extras"]),
                messages=task.get("messages", 0),  # absent before learned messages
            ),
            normalize_observations=task["normalize"],
            shared_slot_statistics=shared,
            net_arch=tuple(sizes[1:-1]),
            encoder=ENCODER if "actor" in record else None,
        )
    except ValueError as error:
        raise AgentFolderError(f"{source}: field 'task' is not a valid task: {error}") from None
    return config, sizes, marl_overrides(task, source)


def marl_overrides(task: dict[str, Any], source: Path) -> dict[str, Any]:
    """The ``Scenario`` field overrides the task trained with (``task.overrides``), checked.

    A record without the field has none. The overrides are applied to the task's
    scenario here, so a folder whose overrides the scenario refuses fails to load.

    Raises:
        AgentFolderError: ``task.overrides`` is not a JSON object, or names a field
            or a value its scenario refuses (``make_scenario``'s message).
    """
    overrides = task.get("overrides", {})
    if not isinstance(overrides, dict):
        raise AgentFolderError(
            f"{source}: field 'task.overrides' must be a JSON object of Scenario fields, "
            f"got {type(overrides).__name__}."
        )
    try:
        make_scenario(task["scenario"], **overrides)
    except (TypeError, ValueError) as error:
        raise AgentFolderError(
            f"{source}: field 'task.overrides' does not apply to scenario "
            f"{task['scenario']!r}: {error}"
        ) from None
    return dict(overrides)


def read_marl_agent(
    folder: Path,
) -> tuple[TrainConfig, PolicyNetwork, InputStatistics | None, dict[str, Any]]:
    """Read a folder ``save_marl_policy`` wrote, verifying every file against the manifest.

    Returns:
        The task as a ``TrainConfig`` (PPO, the task's base, residual and statistics
        settings), the actor, the statistics (or None), and the task's ``Scenario``
        field overrides (``marl_overrides``).

    Raises:
        AgentFolderError: A missing, unreadable, altered or inconsistent file (named).
    """
    _, manifest = read_agent_manifest(folder, "benchmarl")
    record = read_json(folder, CONFIG, manifest)
    config, sizes, overrides = marl_config(record, folder / CONFIG)
    encoder = actor_from_record(record, manifest["format_version"], config, folder / CONFIG)
    statistics = read_json(folder, NORMALIZATION, manifest)
    normalization = None
    inputs = sizes[0] if encoder is None else config.learner_input_size()
    if statistics is not None:
        normalization = normalization_from_json(statistics, folder / NORMALIZATION, inputs)
    if (normalization is not None) != config.normalize_observations:
        raise AgentFolderError(
            f"{folder / NORMALIZATION} {'holds' if normalization else 'lacks'} statistics but "
            f"config.json says task.normalize={config.normalize_observations}."
        )
    network = network_from_layers(
        read_weights(folder, manifest), sizes, ACTOR, folder / WEIGHTS, encoder
    )
    if encoder is not None:
        check_empty_weight(network, normalization, encoder, folder / NORMALIZATION)
    return config, network, normalization, overrides
