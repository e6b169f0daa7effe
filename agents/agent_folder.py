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

import hashlib
import itertools
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors.torch import load as load_tensors
from safetensors.torch import save as save_tensors

from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.infra import atomic

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MANIFEST",
    "AgentFolderError",
    "Normalization",
    "PolicyNetwork",
    "actor_tensors",
    "agent_files",
    "network_from_tensors",
    "read_agent",
    "read_verified",
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


class AgentFolderError(ValueError):
    """An agent folder that is incomplete, inconsistent or not of this format."""


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


def read_verified(folder: Path, name: str, manifest: dict[str, Any]) -> bytes:
    """A file's bytes, checked against the manifest's hash."""
    path = folder / name
    entry = manifest["files"].get(name)
    if not isinstance(entry, dict) or "sha256" not in entry:
        raise AgentFolderError(f"{folder / MANIFEST} does not list {name}; the folder is damaged.")
    if not path.is_file():
        raise AgentFolderError(f"{path} is missing; the manifest lists it. Copy the whole folder.")
    data = path.read_bytes()
    if _sha256(data) != entry["sha256"]:
        raise AgentFolderError(
            f"{path} does not match its SHA-256 in {MANIFEST}: it was edited, truncated or "
            "comes from another run. Use the folder as cpf-train wrote it."
        )
    return data


def _read_manifest(folder: Path) -> dict[str, Any]:
    path = folder / MANIFEST
    try:
        manifest = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise AgentFolderError(f"{path} is not readable JSON: {error}") from error
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise AgentFolderError(f"{path} is not a {FORMAT} manifest.")
    if manifest.get("format_version") != FORMAT_VERSION or not isinstance(
        manifest.get("files"), dict
    ):
        raise AgentFolderError(
            f"{path} has format version {manifest.get('format_version')!r}; this cpf_env "
            f"reads version {FORMAT_VERSION}. Upgrade cpf_env or convert the folder."
        )
    return manifest


def network_from_tensors(
    tensors: dict[str, torch.Tensor], algo: str, net_arch: tuple[int, ...], source: Path
) -> PolicyNetwork:
    """Rebuild the actor from its tensors, checking them against the configuration.

    Raises:
        AgentFolderError: Names, shapes or layer sizes that do not fit ``net_arch``.
    """
    depth = len(net_arch)
    expected = {f"hidden.{i}.{kind}" for i in range(depth) for kind in ("weight", "bias")}
    expected |= {"output.weight", "output.bias"}
    if set(tensors) != expected or tensors["output.weight"].ndim != 2:
        raise AgentFolderError(
            f"{source} holds tensors {sorted(tensors)}, not the actor of the net_arch "
            f"{list(net_arch)} config.json gives."
        )
    sizes = [
        int(tensors["hidden.0.weight"].shape[1]),
        *net_arch,
        int(tensors["output.weight"].shape[0]),
    ]
    network = PolicyNetwork(sizes, *ACTORS[algo])
    try:
        network.load_state_dict({k: v.to(torch.float32) for k, v in tensors.items()})
    except RuntimeError as error:
        raise AgentFolderError(
            f"{source} does not fit net_arch {list(net_arch)}: {error}"
        ) from None
    return network.eval()


def read_agent(folder: Path) -> tuple[dict[str, Any], PolicyNetwork, Normalization | None]:
    """Read an agent folder, verifying every file against the manifest.

    Returns:
        The ``config.json`` record, the actor, and the statistics (or None).

    Raises:
        AgentFolderError: A missing, unreadable, altered or inconsistent file (named).
    """
    from agents.train_config import TrainConfig

    manifest = _read_manifest(folder)
    try:
        record = json.loads(read_verified(folder, CONFIG, manifest))
        config = TrainConfig.from_json(record["config"])
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as error:
        raise AgentFolderError(
            f"{folder / CONFIG} is not a valid training record: {error}"
        ) from None
    try:
        tensors = load_tensors(read_verified(folder, WEIGHTS, manifest))
    except AgentFolderError:
        raise
    except Exception as error:  # safetensors raises its own error type
        raise AgentFolderError(f"{folder / WEIGHTS} is not a safetensors file: {error}") from None
    network = network_from_tensors(tensors, config.algo, config.net_arch, folder / WEIGHTS)
    statistics = json.loads(read_verified(folder, NORMALIZATION, manifest))
    normalization = (
        None if statistics is None else _normalization(statistics, folder / NORMALIZATION)
    )
    if (normalization is not None) != config.normalize_observations:
        raise AgentFolderError(
            f"{folder / NORMALIZATION} {'holds' if normalization else 'lacks'} statistics but "
            f"config.json says normalize_observations={config.normalize_observations}."
        )
    if normalization is not None and normalization.mean.shape != (network.input_size,):
        raise AgentFolderError(
            f"{folder / NORMALIZATION} has statistics for {normalization.mean.shape[0]} inputs "
            f"but the network in {WEIGHTS} takes {network.input_size}."
        )
    return record, network, normalization


def _normalization(data: Any, source: Path) -> Normalization:
    """Parse and check ``normalization.json``."""
    try:
        mean = np.asarray(data["mean"], dtype=np.float64)
        var = np.asarray(data["var"], dtype=np.float64)
        epsilon, clip = float(data["epsilon"]), float(data["clip"])
    except (KeyError, TypeError, ValueError) as error:
        raise AgentFolderError(f"{source} lacks or mangles a field: {error}") from None
    if mean.ndim != 1 or var.shape != mean.shape:
        raise AgentFolderError(f"{source}: mean and var must be lists of the same length.")
    if not (np.all(np.isfinite(mean)) and np.all(var >= 0) and epsilon > 0 and clip > 0):
        raise AgentFolderError(f"{source}: statistics must be finite, var >= 0, epsilon, clip > 0.")
    return Normalization(mean, var, epsilon, clip)
