"""The agent-folder format: data only (safetensors and JSON), tied together by a manifest.

One format, ``cpf-agent``, for every trainer: the folder ``cpf-train`` and
``cpf-distill`` write (trainer ``sb3``) and the one ``agents.marl.save_marl_policy``
writes for a BenchMARL actor (trainer ``benchmarl``). It is the only thing
evaluation reads:

- ``policy.safetensors``: the deterministic actor's weights, float32
  (``hidden.<i>.weight`` (out, in), ``hidden.<i>.bias`` (out,), ``output.weight``,
  ``output.bias``), and with a neighbour encoder its tensors
  (``encoder.phi.0.weight`` (hidden, slot_size), ``encoder.phi.0.bias``,
  ``encoder.phi.2.weight`` (hidden, hidden), ``encoder.phi.2.bias``, and the
  scalars ``encoder.empty_weight`` and ``encoder.tolerance``), the MLP then
  reading the encoder's features (``agents.folder.encoder.NeighbourSetEncoder``);
- ``normalization.json``: the observation statistics (``mean``, ``var`` (k,),
  ``epsilon``, ``clip``), or ``null`` if the run did not normalize;
- ``config.json``: the trainer's record (``sb3``: ``{"config": TrainConfig, ...}``
  and the run's record; ``benchmarl``: the task, algorithm and layer sizes,
  ``agents.marl.policy_folder``), and, for an actor with an encoder or a
  history, the field ``actor``: ``encoder`` (``"deepsets"`` or null),
  ``history`` (own-history entries, ``agents.envs.history``) and, with an encoder,
  ``pooling``, ``hidden``, ``slot_size`` (3 + m), ``slots`` (K of training,
  which ``normalization.json`` covers) and ``tail`` (floats after the slots:
  extras and history);
- ``manifest.json``: the format name and version (3), the ``trainer``, the
  package version that wrote it, and the SHA-256 and size of each of the
  three files above.

Folders of earlier versions are read as before: ``cpf-agent`` versions 1 (an
MLP) and 2 (the ``actor`` field), and the BenchMARL actors' former format
name ``cpf-marl-agent`` (versions 1 and 2, the same layout): both without a
``trainer`` field, which the name implies (``LEGACY_FORMATS``).

Reading trusts nothing in the folder (``agents.folder.files``): only regular
files inside it are opened, with size and JSON depth limits; every field is
typed strictly; the weights must be float32 (float16, bfloat16, float64 or
integer tensors are refused, not converted) and finite, and their shapes must
match the configuration before any network is allocated: the ``actor``
record's ``slots``, ``slot_size`` and ``tail`` (an MLP: its input size) are
the learner input of the ``TrainConfig`` (``learner_slots``, ``learner_tail``).
Each failure is one line (``AgentFolderError``) naming the file and the field.

safetensors holds tensors and a JSON header only, so opening a folder runs no
code, unlike SB3's ``model.zip`` (cloudpickled entries) and ``VecNormalize``'s
pickle. ``read_agent`` checks every hash, so a file edited, truncated or left
over from another run is an error naming that file. SB3's ``model.zip`` may
sit beside these files (``cpf-train`` keeps it to resume training), but is not
listed in the manifest and is never opened by evaluation.

The actor itself (its layers, activations and SB3's deterministic action)
is ``agents.folder.actor.PolicyNetwork``.
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

from agents.folder.actor import ACTORS, PolicyNetwork, actor_record
from agents.folder.encoder import (
    POOLINGS,
    NeighbourSetEncoder,
    empty_weight_after,
    statistics_for_slots,
)
from agents.folder.files import (
    MAX_JSON_BYTES,
    MAX_WEIGHT_BYTES,
    AgentFolderError,
    check_fields,
    field,
    parse_json,
    read_file,
    read_manifest,
    read_verified,
    statistics_arrays,
)
from agents.training.config import ENCODERS, TrainConfig, upgrade_record
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.envs.residual import ResidualConfig
from cpf_env.infra import atomic

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "LEGACY_FORMATS",
    "MANIFEST",
    "TRAINERS",
    "Normalization",
    "actor_from_record",
    "agent_files",
    "check_empty_weight",
    "check_mlp_input",
    "network_from_layers",
    "network_from_tensors",
    "normalization_from_json",
    "read_agent",
    "read_agent_manifest",
    "read_json",
    "read_record",
    "read_weights",
    "training_config",
    "write_agent",
    "write_with_manifest",
]

FORMAT = "cpf-agent"
#: The version written (its manifest names the trainer).
FORMAT_VERSION = 3
#: The trainers whose folders the format holds: their ``config.json`` records differ
#: (``filter``: a learned correction of a navigation filter, ``agents.estimation``).
TRAINERS = ("sb3", "benchmarl", "filter")
#: Earlier (name, version) pairs read, and the trainer each implies (no ``trainer`` field).
LEGACY_FORMATS = {
    ("cpf-agent", 1): "sb3",
    ("cpf-agent", 2): "sb3",
    ("cpf-marl-agent", 1): "benchmarl",
    ("cpf-marl-agent", 2): "benchmarl",
}
MANIFEST = "manifest.json"
WEIGHTS = "policy.safetensors"
NORMALIZATION = "normalization.json"
CONFIG = "config.json"

#: Observation statistics applied as SB3's ``VecNormalize`` does at evaluation: the env
#: layer's ``InputStatistics`` (mean, var, epsilon, clip; ``apply``, ``to_json``), one
#: implementation for the SB3 agents, the MARL actors and ``TorchRLFleetEnv(normalize=True)``.
Normalization = InputStatistics


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


def write_with_manifest(folder: Path, files: dict[str, bytes], trainer: str) -> None:
    """Write ``files`` and the manifest of their hashes into ``folder``, each atomically.

    The caller makes the folder as a whole appear at once (``cpf_env.infra.atomic.staged_folder``).

    Args:
        folder: Existing folder to write into.
        files: The data files by name (``agent_files``).
        trainer: One of ``TRAINERS``: which record ``config.json`` holds.
    """
    import cpf_env

    if trainer not in TRAINERS:
        raise ValueError(f"trainer must be one of {TRAINERS}, got {trainer!r}.")
    for name, data in files.items():
        atomic.write_bytes(folder / name, data)
    manifest = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "trainer": trainer,
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

    An actor with an encoder, or a run with a history, gains the ``actor`` field
    in ``record``.

    Args:
        folder: Existing folder to write into.
        record: The ``config.json`` content (``{"config": TrainConfig.to_json(), ...}``).
        network: The actor.
        normalization: The observation statistics, or None.
    """
    actor = actor_record(network, TrainConfig.from_json(record["config"]))
    if actor is not None:
        record = {**record, "actor": actor}
    tensors = {name: value.detach().contiguous() for name, value in network.state_dict().items()}
    write_with_manifest(folder, agent_files(tensors, normalization, record), "sb3")


def read_agent_manifest(folder: Path, trainer: str | None = None) -> tuple[str, dict[str, Any]]:
    """The trainer and the checked manifest of an agent folder, any version read.

    Args:
        folder: The agent folder.
        trainer: The trainer the caller reads (one of ``TRAINERS``), or None for any.

    Returns:
        The trainer (``"sb3"`` or ``"benchmarl"``) and the manifest, its file list checked.

    Raises:
        AgentFolderError: ``folder`` is missing or a file, holds no manifest (a plain
            SB3 save among them), or its manifest is unreadable, of another format,
            version or trainer than ``trainer``.
    """
    if not folder.is_dir():
        what = "is a file" if folder.exists() else "does not exist"
        raise AgentFolderError(
            f"{folder} {what}: give a cpf-train --out folder (or a baseline name)."
        )
    path = folder / MANIFEST
    if not (path.exists() or path.is_symlink()):
        if (folder / "model.zip").is_file():
            raise AgentFolderError(
                f"{folder} holds a plain SB3 save (model.zip) and no {MANIFEST}: its files "
                "are pickles, which run any code their author put in them, so they are not "
                "read. Train the agent with cpf-train --out DIR, which writes its weights "
                "and statistics as data (safetensors and JSON)."
            )
        raise AgentFolderError(
            f"{folder} is not a cpf-train output folder: no {MANIFEST}. Train one with "
            "`cpf-train --out DIR`, or give a baseline name."
        )
    name = field(parse_json(read_file(path, MAX_JSON_BYTES, folder), path), "format", path)
    names = sorted({FORMAT, *(legacy for legacy, _ in LEGACY_FORMATS)})
    if name not in names:
        raise AgentFolderError(
            f"{path}: field 'format' is {name!r}; this cpf_env reads {' and '.join(names)} folders."
        )
    versions = [v for legacy, v in LEGACY_FORMATS if legacy == name]
    if name == FORMAT:
        versions.append(FORMAT_VERSION)
    manifest = read_manifest(path, str(name), tuple(versions))
    found = LEGACY_FORMATS.get((name, manifest["format_version"]))
    if found is None:
        check_fields(manifest, {"trainer": "str"}, path, required=True)
        found = manifest["trainer"]
        if found not in TRAINERS:
            raise AgentFolderError(
                f"{path}: field 'trainer' is {found!r}; this cpf_env reads {list(TRAINERS)}."
            )
    if trainer is not None and found != trainer:
        raise AgentFolderError(
            f"{path}: the folder holds a {found} agent, not a {trainer} one; load it with "
            "agents.load_policy, which reads every trainer's folder."
        )
    return found, manifest


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


def read_record(folder: Path, manifest: dict[str, Any]) -> dict[str, Any]:
    """An ``sb3`` folder's ``config.json``, its ``config`` in today's layout.

    A folder of format 1 or 2 holds the ``TrainConfig`` of that time (``base`` and the
    residual's fields at the top level): ``agents.training.config.upgrade_record`` moves it
    to today's; a folder of format 3 is read as it is.

    Raises:
        AgentFolderError: An unreadable file or one that does not match the manifest.
    """
    record = read_json(folder, CONFIG, manifest)
    if manifest["format_version"] < FORMAT_VERSION and isinstance(record, dict):
        config = record.get("config")
        if isinstance(config, dict):  # its fields' types checked where the file has them
            types = {f.name: str(f.type) for f in dataclasses.fields(ResidualConfig)}
            check_fields(config, {**types, "base": "str"}, folder / CONFIG, "config.")
            record = {**record, "config": upgrade_record(config)}
    return record


def training_config(data: Any, source: Path | str) -> TrainConfig:
    """A ``TrainConfig`` from its JSON object, every field's JSON type checked first.

    Raises:
        AgentFolderError: A field of the wrong type (``residual.scale: true``, ``net_arch:
            ["64"]``), an unknown field, or a value ``TrainConfig`` refuses; naming ``source``.
    """
    types = {f.name: str(f.type) for f in dataclasses.fields(TrainConfig) if f.name != "residual"}
    check_fields(data, types, source, "config.")
    if isinstance(data, dict) and "residual" in data:
        residual = {f.name: str(f.type) for f in dataclasses.fields(ResidualConfig)}
        check_fields(data["residual"], residual, source, "config.residual.")
    try:
        config = TrainConfig.from_json(data)
        config.learner_slots()  # the home scenario's degree fits neighbour_slots
    except (TypeError, ValueError) as error:
        raise AgentFolderError(f"{source}: field 'config' is not a TrainConfig: {error}") from None
    _check_declared_size(list(config.net_arch), source)
    return config


#: JSON types of ``config.json``'s ``actor`` field (format version 2); the last five with an
#: encoder only.
ACTOR_FIELDS = {
    "encoder": "str | None",
    "history": "int",
    "pooling": "str",
    "hidden": "int",
    "slot_size": "int",
    "slots": "int",
    "tail": "int",
}

#: What each of ``actor``'s layout fields is, for messages.
_LAYOUT = {
    "slots": "neighbour slots K: the home scenario's degree or neighbour_slots",
    "slot_size": "floats per slot, 3 + message size",
    "tail": "floats after the slots: the extras, then history x (18 + actions + 1)",
}


def actor_from_record(
    record: Any, version: int, config: TrainConfig, source: Path
) -> dict[str, Any] | None:
    """The encoder's layout from ``config.json``'s ``actor`` field, checked against ``config``.

    Args:
        record: The ``config.json`` object.
        version: The manifest's format version (1: no ``actor`` field; 2: one; 3: one
            for an encoder or a history).
        config: The record's ``TrainConfig``.
        source: ``config.json``, for messages.

    Returns:
        The ``actor`` field of an encoder actor (``pooling``, ``hidden``, ``slot_size``,
        ``slots``, ``tail``), or None for an MLP.

    Raises:
        AgentFolderError: A version-1 folder whose configuration has an encoder or a
            history, a missing, mistyped or unknown field, or one the configuration
            contradicts (``slots`` and ``slot_size``: ``config.learner_slots()``; ``tail``:
            ``config.learner_tail()``), naming ``source``.
    """
    described = "actor" in record or config.encoder is not None or bool(config.history)
    if version == FORMAT_VERSION and not described:
        return None
    if version == 1:
        if described:
            raise AgentFolderError(
                f"{source} describes an encoder or a history (field 'actor', or config encoder="
                f"{config.encoder!r}, history={config.history}) but the manifest says format "
                "version 1, an MLP without history; the folder is damaged."
            )
        return None
    actor = field(record, "actor", source)
    names = list(ACTOR_FIELDS) if config.encoder is not None else ["encoder", "history"]
    check_fields(actor, {name: ACTOR_FIELDS[name] for name in names}, source, "actor.", True)
    unknown = sorted(set(actor) - set(names))
    if unknown:
        raise AgentFolderError(f"{source}: field 'actor' has unknown field(s) {unknown}.")
    if actor["encoder"] != config.encoder or actor["history"] != config.history:
        raise AgentFolderError(
            f"{source}: field 'actor' gives encoder {actor['encoder']!r} and history "
            f"{actor['history']}, the config {config.encoder!r} and {config.history}."
        )
    if config.encoder is None:
        return None
    if actor["encoder"] not in ENCODERS or actor["pooling"] not in POOLINGS:
        raise AgentFolderError(
            f"{source}: field 'actor' has encoder {actor['encoder']!r} and pooling "
            f"{actor['pooling']!r}; known: {list(ENCODERS)} and {list(POOLINGS)}."
        )
    if actor["hidden"] < 1:
        raise AgentFolderError(
            f"{source}: field 'actor.hidden' must be >= 1, got {actor['hidden']}."
        )
    slots, slot_size = config.learner_slots()  # valid: training_config checked it
    expected = {"slots": slots, "slot_size": slot_size, "tail": config.learner_tail()}
    for name, value in expected.items():
        if actor[name] != value:
            raise AgentFolderError(
                f"{source}: field 'actor.{name}' is {actor[name]} but the config's learner input "
                f"has {value} ({_LAYOUT[name]}); the folder is damaged."
            )
    return actor


def _check_declared_size(
    sizes: list[int], source: Path | str, encoder: dict[str, Any] | None = None
) -> None:
    """Refuse layer sizes whose weights exceed ``MAX_WEIGHT_BYTES``, before reading any.

    With an encoder, its weights (``actor.hidden`` x (``actor.slot_size`` + ``actor.hidden``
    + 2) + 2) count too, and the message names those fields.
    """
    layers = sum(a * b + b for a, b in itertools.pairwise(sizes))
    if encoder is None:
        if 4 * layers > MAX_WEIGHT_BYTES:
            raise AgentFolderError(
                f"{source}: layer sizes {sizes} declare {4 * layers:,} bytes of float32 "
                f"weights, more than the {MAX_WEIGHT_BYTES:,} this loader reads."
            )
        return
    hidden, slot_size = encoder["hidden"], encoder["slot_size"]
    encoding = hidden * (slot_size + hidden + 2) + 2
    if 4 * (layers + encoding) > MAX_WEIGHT_BYTES:
        raise AgentFolderError(
            f"{source}: layer sizes {sizes} ({4 * layers:,} bytes) and an encoder of "
            f"config.json's actor.hidden = {hidden}, actor.slot_size = {slot_size} "
            f"({4 * encoding:,} bytes) declare {4 * (layers + encoding):,} bytes of float32 "
            f"weights, more than the {MAX_WEIGHT_BYTES:,} this loader reads."
        )


def _encoder_shapes(encoder: dict[str, Any]) -> dict[str, tuple[int, ...]]:
    """The encoder's tensors and shapes, by ``PolicyNetwork`` name."""
    hidden, slot_size = encoder["hidden"], encoder["slot_size"]
    return {
        "encoder.phi.0.weight": (hidden, slot_size),
        "encoder.phi.0.bias": (hidden,),
        "encoder.phi.2.weight": (hidden, hidden),
        "encoder.phi.2.bias": (hidden,),
        "encoder.empty_weight": (),
        "encoder.tolerance": (),
    }


def network_from_layers(
    tensors: dict[str, torch.Tensor],
    sizes: list[int],
    actor: tuple[str, str],
    source: Path,
    encoder: dict[str, Any] | None = None,
) -> PolicyNetwork:
    """The actor of layer ``sizes`` (input first), its tensors checked before any allocation.

    Args:
        tensors: The weights by ``PolicyNetwork`` name.
        sizes: Layer widths, input first and action size last.
        actor: (hidden activation, output transform), as ``PolicyNetwork`` takes them.
        source: The weights file, for messages.
        encoder: The encoder's layout (``actor_from_record``), or None for an MLP.

    Raises:
        AgentFolderError: Other tensor names, a shape that is not the layer's, a dtype
            other than float32, a non-finite weight or bias, a negative tolerance, or an
            MLP whose input is not the encoder's features (each naming the tensor).
    """
    _check_declared_size(sizes, source, encoder)
    depth = len(sizes) - 2
    shapes: dict[str, tuple[int, ...]] = {}
    for i, (a, b) in enumerate(itertools.pairwise(sizes)):
        name = f"hidden.{i}" if i < depth else "output"
        shapes[f"{name}.weight"], shapes[f"{name}.bias"] = (b, a), (b,)
    module = None
    if encoder is not None:
        shapes.update(_encoder_shapes(encoder))
        with torch.device("meta"):
            module = NeighbourSetEncoder(
                encoder["slot_size"], encoder["tail"], encoder["hidden"], encoder["pooling"]
            )
        if module.features_dim != sizes[0]:
            raise AgentFolderError(
                f"{source}: tensor hidden.0.weight reads {sizes[0]} features but the encoder "
                f"of config.json's 'actor' gives {module.features_dim}."
            )
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
    if encoder is not None and float(tensors["encoder.tolerance"]) < 0.0:
        raise AgentFolderError(f"{source}: tensor encoder.tolerance is negative.")
    with torch.device("meta"):  # no memory until the checked tensors are assigned
        network = PolicyNetwork(sizes, *actor, module)
    network.load_state_dict({k: v.contiguous() for k, v in tensors.items()}, assign=True)
    return network.eval()


def network_from_tensors(
    tensors: dict[str, torch.Tensor],
    algo: str,
    net_arch: tuple[int, ...],
    source: Path,
    encoder: dict[str, Any] | None = None,
) -> PolicyNetwork:
    """Rebuild the actor from its tensors, checking them against the configuration.

    Args:
        tensors: The weights by ``PolicyNetwork`` name.
        algo: ``"ppo"`` or ``"sac"`` (the activation and output transform).
        net_arch: The MLP's hidden sizes.
        source: The weights file, for messages.
        encoder: The encoder's layout (``actor_from_record``), or None for an MLP.

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
    return network_from_layers(tensors, sizes, ACTORS[algo], source, encoder)


def _shapes(tensors: dict[str, torch.Tensor]) -> list[str]:
    return [f"{name} {tuple(tensor.shape)}" for name, tensor in sorted(tensors.items())[:4]]


def read_agent(folder: Path) -> tuple[dict[str, Any], PolicyNetwork, Normalization | None]:
    """Read an ``sb3`` agent folder (any version), verifying every file against the manifest.

    Returns:
        The ``config.json`` record, the actor, and the statistics (or None).

    Raises:
        AgentFolderError: A missing, unreadable, altered or inconsistent file (named).
    """
    _, manifest = read_agent_manifest(folder, "sb3")
    record = read_record(folder, manifest)
    config = training_config(field(record, "config", folder / CONFIG), folder / CONFIG)
    encoder = actor_from_record(record, manifest["format_version"], config, folder / CONFIG)
    network = network_from_tensors(
        read_weights(folder, manifest), config.algo, config.net_arch, folder / WEIGHTS, encoder
    )
    inputs = config.learner_input_size()  # the encoder's: checked by actor_from_record
    if encoder is None:
        check_mlp_input(network, config, folder / WEIGHTS, folder / CONFIG)
    statistics = read_json(folder, NORMALIZATION, manifest)
    normalization = (
        None
        if statistics is None
        else normalization_from_json(statistics, folder / NORMALIZATION, inputs)
    )
    if (normalization is not None) != config.normalize_observations:
        raise AgentFolderError(
            f"{folder / NORMALIZATION} {'holds' if normalization else 'lacks'} statistics but "
            f"config.json says normalize_observations={config.normalize_observations}."
        )
    if encoder is not None:
        check_empty_weight(network, normalization, encoder, folder / NORMALIZATION)
    return record, network, normalization


def check_mlp_input(
    network: PolicyNetwork, config: TrainConfig, weights: Path, source: Path
) -> None:
    """Refuse an MLP whose input size is not the learner input ``config`` gives.

    Args:
        network: The actor (an MLP: ``input_size`` set).
        config: The ``TrainConfig`` of ``source``.
        weights: The weights file, for messages.
        source: The ``config.json``, for messages.

    Raises:
        AgentFolderError: ``network.input_size`` is not ``config.learner_input_size()``.
    """
    inputs = config.learner_input_size()
    if network.input_size != inputs:
        raise AgentFolderError(
            f"{weights}: tensor hidden.0.weight reads {network.input_size} inputs but the "
            f"TrainConfig of {source} gives the learner {inputs} (18 + K x (3 + m) + extras + "
            "history); the files come from different runs."
        )


def check_empty_weight(
    network: PolicyNetwork,
    normalization: Normalization | None,
    encoder: dict[str, Any],
    source: Path,
) -> None:
    """Refuse statistics that differ between slots, or an empty weight they do not give."""
    empty = 0.0
    if normalization is not None:
        try:
            statistics_for_slots(normalization, encoder["slots"], encoder["slot_size"], 1)
            empty = empty_weight_after(normalization, encoder["slots"], encoder["slot_size"])
        except ValueError as error:
            raise AgentFolderError(f"{source}: {error}") from None
    held = float(network.encoder.empty_weight) if network.encoder is not None else empty
    if held != float(torch.tensor(empty, dtype=torch.float32)):
        raise AgentFolderError(
            f"{source}: an empty slot's a_ij becomes {empty} after these statistics, but the "
            f"encoder in {WEIGHTS} masks slots at {held}; the files come from different runs."
        )


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
