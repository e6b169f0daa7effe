"""A learned filter's folder: data only, as every agent folder (``agents.folder.format``).

``policy.safetensors`` holds the correction's arrays (``Correction.arrays``:
the matrix's ``ARRAYS`` and the network's ``layers.{k}.weight`` and
``.bias``), ``config.json`` the fit's record under ``filter`` (its base,
scenarios, window, the bank's filters read, ridge, network, rounds, the
validation costs), and ``manifest.json`` names both with their SHA-256 and
the trainer ``filter``. ``agents.load_policy`` reads it as a ``LearnedFilter``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors.torch import save as save_tensors

from agents.estimation.correction import Correction
from agents.estimation.policy import LearnedFilter
from agents.folder.files import AgentFolderError, check_fields, field
from agents.folder.format import (
    CONFIG,
    WEIGHTS,
    read_agent_manifest,
    read_json,
    read_weights,
    write_with_manifest,
)
from cpf_env.infra import atomic
from cpf_env.scenarios import Scenario

__all__ = ["ARRAYS", "TRAINER", "load_filter", "read_filter", "save_filter"]

#: The trainer named in the folder's manifest.
TRAINER = "filter"
#: The matrix's arrays in the weights file (the network's follow them).
ARRAYS = ("weights", "input_mean", "input_scale", "offset", "target_scale")


def save_filter(out: str | Path, correction: Correction, record: dict[str, Any]) -> None:
    """Write the folder ``out`` (module docstring), as a whole, atomically."""
    tensors = {
        name: torch.from_numpy(np.ascontiguousarray(a)) for name, a in correction.arrays.items()
    }
    files = {
        WEIGHTS: save_tensors(tensors),
        CONFIG: (json.dumps({"filter": record}, indent=2) + "\n").encode(),
    }
    with atomic.staged_folder(Path(out)) as folder:
        write_with_manifest(folder, files, TRAINER)


def read_filter(folder: str | Path) -> tuple[Correction, dict[str, Any]]:
    """The correction and record of a folder ``save_filter`` wrote (data only, checked).

    Raises:
        AgentFolderError: Not such a folder, a file altered, missing or inconsistent.
    """
    path = Path(folder)
    _, manifest = read_agent_manifest(path, TRAINER)
    record = field(read_json(path, CONFIG, manifest), "filter", path / CONFIG)
    fields = {"base": "str", "scenarios": "tuple[str, ...]", "window": "int", "members": "int"}
    check_fields(record, fields, path / CONFIG, required=True)
    tensors = read_weights(path, manifest)
    depth = sum(name.startswith("layers.") for name in tensors) // 2
    network = [f"layers.{k}.{part}" for k in range(depth) for part in ("weight", "bias")]
    if set(tensors) != {*ARRAYS, *network}:
        raise AgentFolderError(
            f"{path / WEIGHTS} holds {sorted(tensors)}; a correction holds {list(ARRAYS)} "
            "and, for a network of k layers, layers.0.weight, layers.0.bias ... to k - 1."
        )
    arrays = {name: tensors[name].numpy().astype(np.float64) for name in (*ARRAYS, *network)}
    layers = tuple(
        (arrays.pop(f"layers.{k}.weight"), arrays.pop(f"layers.{k}.bias")) for k in range(depth)
    )
    try:
        correction = Correction(
            int(record["window"]), int(record["members"]), **arrays, layers=layers
        )
    except ValueError as error:
        raise AgentFolderError(f"{path}: {error}") from None
    return correction, record


def load_filter(folder: str | Path, scenario: str | Scenario | None = None) -> LearnedFilter:
    """The ``LearnedFilter`` of ``folder`` on ``scenario`` (default: its first training scenario).

    Raises:
        AgentFolderError: As ``read_filter``.
        ValueError: The scenario has ideal sensors (``LearnedFilter``).
    """
    path = Path(folder)
    correction, record = read_filter(path)
    task = record["scenarios"][0] if scenario is None else scenario
    return LearnedFilter(task, correction, base=record["base"], name=path.name)
