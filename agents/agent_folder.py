"""The agent-folder format: data only (safetensors and JSON), tied together by a manifest.

A folder that ``cpf-train`` writes, and the only thing evaluation reads:

- ``policy.safetensors``: the deterministic actor's weights, float32
  (``hidden.<i>.weight`` (out, in), ``hidden.<i>.bias`` (out,), ``output.weight``,
  ``output.bias``);
- ``normalization.json``: the observation statistics (``mean``, ``var`` (k,),
  ``epsilon``, ``clip``), or ``null`` if the run did not normalize;
- ``config.json``: the ``TrainConfig`` and the run's record (as before);
- ``manifest.json``: the format name and version, the package version that
  wrote it, and the SHA-256 and size of each of the three files above.

Reading trusts nothing in the folder (``agents.folder_files``): only regular
files inside it are opened, with size and JSON depth limits; every field is
typed strictly; the weights must be float32 (float16, bfloat16, float64 or
integer tensors are refused, not converted) and finite, and their shapes must
match the configuration before any network is allocated. Each failure is one
line (``AgentFolderError``) naming the file and the field.

safetensors holds tensors and a JSON header only, so opening a folder runs no
code, unlike SB3's ``model.zip`` (cloudpickled entries) and ``VecNormalize``'s
pickle. ``read_agent`` checks every hash, so a file edited, truncated or left
over from another run is an error naming that file. SB3's ``model.zip`` may
sit beside these files (``cpf-train`` keeps it to resume training), but is not
listed in the manifest and is never opened by evaluation.

The actor is an MLP with ``tanh`` (PPO) or ``ReLU`` (SAC) hidden layers; its
deterministic action is the output clipped to [-1, 1] (PPO, as SB3's
``predict`` clips) or squashed by ``tanh`` and unscaled from [-1, 1] as SB3
does (SAC), in float32, so it has the bits of SB3's ``predict``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load as load_tensors
from safetensors.torch import save as save_tensors

from agents.folder_files import (
    MAX_JSON_BYTES,
    MAX_WEIGHT_BYTES,
    AgentFolderError,
    check_fields,
    field,
    parse_json,
    read_manifest,
    read_verified,
    statistics_arrays,
)
from agents.train_config import TrainConfig
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.infra import atomic

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MANIFEST",
    "Normalization",
    "PolicyNetwork",
    "actor_tensors",
    "agent_files",
    "network_from_layers",
    "network_from_tensors",
    "normalization_from_json",
    "read_agent",
    "read_json",
    "read_weights",
    "training_config",
    "write_agent",
    "write_with_manifest",
]

FORMAT = "cpf-agent"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
WEIGHTS = "policy.safetensors"
NORMALIZATION = "normalization.json"
CONFIG = "config.json"

#: Hidden-layer activation and output transform of each algorithm's actor.
ACTORS = {"ppo": ("tanh", "clip"), "sac": ("relu", "tanh")}


#: Observation statistics applied as SB3's ``VecNormalize`` does at evaluation: the env
#: layer's ``InputStatistics`` (mean, var, epsilon, clip; ``apply``, ``to_json``), one
#: implementation for the SB3 agents, the MARL actors and ``TorchRLFleetEnv(normalize=True)``.
Normalization = InputStatistics


class PolicyNetwork(torch.nn.Module):
    """The deterministic actor: (R, k) float32 inputs -> (R, a) actions in [-1, 1].

    Args:
        sizes: Layer widths, input first and action size last.
        activation: ``"tanh"`` or ``"relu"`` between hidden layers.
        output: ``"clip"`` (clip to [-1, 1]) or ``"tanh"`` (squash, then SB3's unscaling).
    """

    def __init__(self, sizes: list[int], activation: str, output: str) -> None:
        super().__init__()
        self.activation, self.output_transform = activation, output
        self.hidden = torch.nn.ModuleList(
            torch.nn.Linear(a, b) for a, b in itertools.pairwise(sizes[:-1])
        )
        self.output = torch.nn.Linear(sizes[-2], sizes[-1])
        self.input_size, self.action_size = sizes[0], sizes[-1]

    def forward(self, rows: torch.Tensor) -> torch.Tensor:
        """Deterministic actions (R, a) in [-1, 1]."""
        act = torch.tanh if self.activation == "tanh" else torch.relu
        latent = rows
        for layer in self.hidden:
            latent = act(layer(latent))
        action = self.output(latent)
        if self.output_transform == "clip":
            return torch.clamp(action, -1.0, 1.0)
        return -1.0 + 0.5 * (torch.tanh(action) + 1.0) * 2.0  # SB3's unscale_action on [-1, 1]


def actor_tensors(model: Any, algo: str) -> dict[str, torch.Tensor]:
    """The deterministic actor's layers of an SB3 PPO or SAC model, as ``PolicyNetwork`` names."""
    if algo == "ppo":
        hidden = model.policy.mlp_extractor.policy_net
        output = model.policy.action_net
    else:
        hidden = model.actor.latent_pi
        output = model.actor.mu
    layers = [module for module in hidden if isinstance(module, torch.nn.Linear)]
    tensors: dict[str, torch.Tensor] = {}
    for i, layer in enumerate(layers):
        tensors[f"hidden.{i}.weight"] = layer.weight.detach().clone()
        tensors[f"hidden.{i}.bias"] = layer.bias.detach().clone()
    tensors["output.weight"] = output.weight.detach().clone()
    tensors["output.bias"] = output.bias.detach().clone()
    return tensors


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def agent_files(
    tensors: dict[str, torch.Tensor], normalization: Normalization | None, record: dict[str, Any]
) -> dict[str, bytes]:
    """The bytes of an agent's three data files: weights, normalization, config.

    Args:
        tensors: The actor's weights by ``PolicyNetwork`` name (float32).
        normalization: The observation statistics, or None.
        record: The ``config.json`` content.
    """
    return {
        WEIGHTS: save_tensors(tensors),
        NORMALIZATION: (
            json.dumps(None if normalization is None else normalization.to_json()) + "\n"
        ).encode(),
        CONFIG: (json.dumps(record, indent=2) + "\n").encode(),
    }


def write_with_manifest(
    folder: Path, files: dict[str, bytes], format_name: str, format_version: int
) -> None:
    """Write ``files`` and the manifest of their hashes into ``folder``, each atomically.

    The caller makes the folder as a whole appear at once (``cpf_env.infra.atomic.staged_folder``).
    """
    import cpf_env

    for name, data in files.items():
        atomic.write_bytes(folder / name, data)
    manifest = {
        "format": format_name,
        "format_version": format_version,
        "cpf_env": cpf_env.__version__,
        "files": {
            name: {"sha256": _sha256(data), "bytes": len(data)} for name, data in files.items()
        },
    }
    atomic.write_text(folder / MANIFEST, json.dumps(manifest, indent=2) + "\n")


def write_agent(
    folder: Path,
    record: dict[str, Any],
    network: PolicyNetwork,
    normalization: Normalization | None,
) -> None:
    """Write the agent files and their manifest into ``folder`` (a staging folder).

    Each file is written atomically; the caller makes the folder as a whole
    appear at once (``cpf_env.infra.atomic.staged_folder``).

    Args:
        folder: Existing folder to write into.
        record: The ``config.json`` content (``{"config": TrainConfig.to_json(), ...}``).
        network: The actor.
        normalization: The observation statistics, or None.
    """
    tensors = {name: value.detach().contiguous() for name, value in network.state_dict().items()}
    write_with_manifest(folder, agent_files(tensors, normalization, record), FORMAT, FORMAT_VERSION)


def read_json(folder: Path, name: str, manifest: dict[str, Any]) -> Any:
    """A JSON file of the folder, bounded, checked against the manifest and parsed."""
    data = read_verified(folder, name, manifest, MAX_JSON_BYTES, MANIFEST)
    return parse_json(data, folder / name)


def read_weights(folder: Path, manifest: dict[str, Any]) -> dict[str, torch.Tensor]:
    """The tensors of ``policy.safetensors``, bounded and checked against the manifest."""
    data = read_verified(folder, WEIGHTS, manifest, MAX_WEIGHT_BYTES, MANIFEST)
    try:
        return load_tensors(data)
    except Exception as error:  # safetensors raises its own error type
        message = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise AgentFolderError(f"{folder / WEIGHTS} is not a safetensors file: {message}") from None


def training_config(data: Any, source: Path | str) -> TrainConfig:
    """A ``TrainConfig`` from its JSON object, every field's JSON type checked first.

    Raises:
        AgentFolderError: A field of the wrong type (``scale: true``, ``net_arch: ["64"]``),
            an unknown field, or a value ``TrainConfig`` refuses; naming ``source``.
    """
    types = {f.name: str(f.type) for f in dataclasses.fields(TrainConfig)}
    check_fields(data, types, source, "config.")
    try:
        config = TrainConfig.from_json(data)
    except (TypeError, ValueError) as error:
        raise AgentFolderError(f"{source}: field 'config' is not a TrainConfig: {error}") from None
    _check_declared_size(list(config.net_arch), source)
    return config


def _check_declared_size(sizes: list[int], source: Path | str) -> None:
    """Refuse layer sizes whose weights exceed ``MAX_WEIGHT_BYTES``, before reading any."""
    parameters = sum(a * b + b for a, b in itertools.pairwise(sizes))
    if 4 * parameters > MAX_WEIGHT_BYTES:
        raise AgentFolderError(
            f"{source}: layer sizes {sizes} declare {4 * parameters:,} bytes of float32 "
            f"weights, more than the {MAX_WEIGHT_BYTES:,} this loader reads."
        )


def network_from_layers(
    tensors: dict[str, torch.Tensor], sizes: list[int], actor: tuple[str, str], source: Path
) -> PolicyNetwork:
    """The actor of layer ``sizes`` (input first), its tensors checked before any allocation.

    Args:
        tensors: The weights by ``PolicyNetwork`` name.
        sizes: Layer widths, input first and action size last.
        actor: (hidden activation, output transform), as ``PolicyNetwork`` takes them.
        source: The weights file, for messages.

    Raises:
        AgentFolderError: Other tensor names, a shape that is not the layer's, a dtype
            other than float32, or a non-finite weight or bias (each naming the tensor).
    """
    _check_declared_size(sizes, source)
    depth = len(sizes) - 2
    shapes: dict[str, tuple[int, ...]] = {}
    for i, (a, b) in enumerate(itertools.pairwise(sizes)):
        name = f"hidden.{i}" if i < depth else "output"
        shapes[f"{name}.weight"], shapes[f"{name}.bias"] = (b, a), (b,)
    if set(tensors) != set(shapes):
        raise AgentFolderError(
            f"{source} holds tensors {sorted(tensors)}, not the actor of layer sizes {sizes} "
            f"({sorted(shapes)})."
        )
    for name, shape in shapes.items():
        tensor = tensors[name]
        if tuple(tensor.shape) != shape:
            raise AgentFolderError(
                f"{source}: tensor {name} has shape {tuple(tensor.shape)}, not {shape} "
                f"(layer sizes {sizes})."
            )
        if tensor.dtype != torch.float32:
            raise AgentFolderError(
                f"{source}: tensor {name} is {str(tensor.dtype).removeprefix('torch.')}; the "
                "format holds float32 weights. Convert them (tensor.float()) and write the "
                "folder again."
            )
        if not bool(torch.isfinite(tensor).all()):
            raise AgentFolderError(f"{source}: tensor {name} holds a NaN or infinite value.")
    with torch.device("meta"):  # no memory until the checked tensors are assigned
        network = PolicyNetwork(sizes, *actor)
    network.load_state_dict({k: v.contiguous() for k, v in tensors.items()}, assign=True)
    return network.eval()


def network_from_tensors(
    tensors: dict[str, torch.Tensor], algo: str, net_arch: tuple[int, ...], source: Path
) -> PolicyNetwork:
    """Rebuild the actor from its tensors, checking them against the configuration.

    Raises:
        AgentFolderError: Names, shapes, dtypes or values that do not fit ``net_arch``
            (``network_from_layers``).
    """
    ends = [tensors.get("hidden.0.weight"), tensors.get("output.weight")]
    if any(tensor is None or tensor.ndim != 2 for tensor in ends):
        raise AgentFolderError(
            f"{source} holds tensors {sorted(tensors)} ({', '.join(_shapes(tensors))}), not "
            f"the actor of the net_arch {list(net_arch)} config.json gives: hidden.0.weight "
            "and output.weight must be matrices."
        )
    sizes = [int(ends[0].shape[1]), *net_arch, int(ends[1].shape[0])]  # type: ignore[union-attr]
    return network_from_layers(tensors, sizes, ACTORS[algo], source)


def _shapes(tensors: dict[str, torch.Tensor]) -> list[str]:
    return [f"{name} {tuple(tensor.shape)}" for name, tensor in sorted(tensors.items())[:4]]


def read_agent(folder: Path) -> tuple[dict[str, Any], PolicyNetwork, Normalization | None]:
    """Read an agent folder, verifying every file against the manifest.

    Returns:
        The ``config.json`` record, the actor, and the statistics (or None).

    Raises:
        AgentFolderError: A missing, unreadable, altered or inconsistent file (named).
    """
    manifest = read_manifest(folder / MANIFEST, FORMAT, FORMAT_VERSION)
    record = read_json(folder, CONFIG, manifest)
    config = training_config(field(record, "config", folder / CONFIG), folder / CONFIG)
    network = network_from_tensors(
        read_weights(folder, manifest), config.algo, config.net_arch, folder / WEIGHTS
    )
    statistics = read_json(folder, NORMALIZATION, manifest)
    normalization = (
        None
        if statistics is None
        else normalization_from_json(statistics, folder / NORMALIZATION, network.input_size)
    )
    if (normalization is not None) != config.normalize_observations:
        raise AgentFolderError(
            f"{folder / NORMALIZATION} {'holds' if normalization else 'lacks'} statistics but "
            f"config.json says normalize_observations={config.normalize_observations}."
        )
    return record, network, normalization


def normalization_from_json(data: Any, source: Path, inputs: int) -> Normalization:
    """``normalization.json``'s statistics for a network of ``inputs`` inputs, strictly checked.

    Raises:
        AgentFolderError: A field missing or mistyped, a non-finite value, or statistics
            for another number of inputs (naming ``source`` and the field).
    """
    mean, var, epsilon, clip = statistics_arrays(data, source)
    if mean.shape != (inputs,):
        raise AgentFolderError(
            f"{source} has statistics for {mean.shape[0]} inputs but the network in {WEIGHTS} "
            f"takes {inputs}."
        )
    return Normalization(mean, var, epsilon, clip)
