"""Training checkpoints: everything a run needs to continue bit for bit, as data only.

``save_checkpoint(folder, model, extra)`` writes, into ``folder`` (a staging
folder the caller swaps in whole):

- ``tensors.safetensors``: the networks' and optimizers' ``state_dict``s (SB3's
  ``get_parameters``, plus SAC's entropy coefficient) and torch's random state;
- ``arrays.npz``: every numpy array of the state (read with ``allow_pickle=False``);
- ``state.json``: the rest as a tree (``agents.training.snapshot``): SB3's counters,
  last observations and episode buffers, numpy's and Python's random states,
  the whole vector env below the model (simulator arrays, base policy's
  adaptive weights, link buffers, random generators, ``VecMonitor`` and
  ``VecNormalize`` statistics), SAC's replay buffer, and ``extra`` (the
  callbacks' own state).

``load_checkpoint(folder, model)`` writes that state into a model (and its
env) freshly built from the same ``TrainConfig``, with its logger set (the
values recorded but not yet written to ``progress.csv`` are restored too),
and returns ``extra``.
A checkpoint is taken at the start of a rollout (after the previous update),
where SB3's loop holds no other state, so ``model.learn(..., reset_num_timesteps=False)``
after loading continues exactly as the uninterrupted run did.
"""

from __future__ import annotations

import io
import json
import random
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors.torch import load as load_tensors
from safetensors.torch import save as save_tensors
from stable_baselines3.common.base_class import BaseAlgorithm

from agents.training.snapshot import SnapshotError, capture, decode_value, encode_value, restore
from cpf_env.infra import atomic

__all__ = ["CHECKPOINT_FILES", "checkpoint_timesteps", "load_checkpoint", "save_checkpoint"]

TENSORS = "tensors.safetensors"
ARRAYS = "arrays.npz"
STATE = "state.json"
#: The files of a checkpoint folder.
CHECKPOINT_FILES = (TENSORS, ARRAYS, STATE)
#: SB3 attributes of the model that change while it learns (besides networks and env).
MODEL_FIELDS = (
    "num_timesteps",
    "_n_updates",
    "_episode_num",
    "_current_progress_remaining",
    "_last_obs",
    "_last_episode_starts",
    "_last_original_obs",
    "ep_info_buffer",
    "ep_success_buffer",
)
FORMAT = "cpf-checkpoint"
FORMAT_VERSION = 1


def _torch_variables(model: BaseAlgorithm) -> dict[str, torch.Tensor]:
    """SB3's extra torch variables of ``model`` (SAC's entropy coefficient), by name."""
    _, names = model._get_torch_save_params()
    return {name: getattr(model, name) for name in names}


def _pending_log(model: BaseAlgorithm) -> Any:
    """The values recorded in SB3's logger but not yet dumped (the next progress.csv row's)."""
    logger = model.logger
    pending = {
        "values": dict(logger.name_to_value),
        "counts": dict(logger.name_to_count),
        "excluded": {k: tuple(v) if v else () for k, v in logger.name_to_excluded.items()},
    }
    return encode_value(pending, "logger", {})


def save_checkpoint(folder: Path, model: BaseAlgorithm, extra: dict[str, Any]) -> None:
    """Write the complete training state of ``model`` (and its env) into ``folder``.

    Args:
        folder: An existing, empty folder (a staging folder).
        model: The PPO or SAC model, between rollouts.
        extra: JSON-ready state of the caller (schedules, best cost so far).

    Raises:
        agents.training.snapshot.SnapshotError: Env state that cannot be stored as data.
    """
    tensors: dict[str, Any] = {}
    arrays: dict[str, Any] = {}
    state = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "parameters": encode_value(model.get_parameters(), "parameters", tensors),
        "variables": encode_value(
            {k: v.detach() for k, v in _torch_variables(model).items()}, "variables", tensors
        ),
        "torch_random": encode_value(torch.get_rng_state(), "torch_random", tensors),
        # SB3 draws minibatch orders from numpy's legacy global generator
        "numpy_random": encode_value(np.random.get_state(), "numpy_random", arrays),  # noqa: NPY002
        "python_random": encode_value(random.getstate(), "python_random", arrays),
        "model": {name: encode_value(getattr(model, name), name, arrays) for name in MODEL_FIELDS},
        "env": capture(model.get_env(), "env", arrays),
        "logger": _pending_log(model),
        "replay_buffer": (
            None
            if getattr(model, "replay_buffer", None) is None
            else capture(model.replay_buffer, "replay_buffer", arrays)  # type: ignore[attr-defined]
        ),
        "extra": extra,
    }
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    atomic.write_bytes(folder / TENSORS, save_tensors(tensors))
    atomic.write_bytes(folder / ARRAYS, buffer.getvalue())
    atomic.write_text(folder / STATE, json.dumps(state) + "\n")


def checkpoint_timesteps(folder: Path) -> int:
    """Vessel-steps (SB3 timesteps) the checkpoint in ``folder`` had trained.

    Raises:
        agents.training.snapshot.SnapshotError: No readable checkpoint there.
    """
    try:
        state = json.loads((folder / STATE).read_text())
        return int(decode_value(state["model"]["num_timesteps"], {}))
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise SnapshotError(f"{folder / STATE} is not a readable checkpoint: {error}") from None


def load_checkpoint(folder: Path, model: BaseAlgorithm) -> dict[str, Any]:
    """Write a checkpoint's state into ``model``, built fresh from the run's configuration.

    Returns:
        The ``extra`` state given to ``save_checkpoint``.

    Raises:
        agents.training.snapshot.SnapshotError: A missing or damaged file, or a model or env
            built differently from the one that wrote the checkpoint.
    """
    missing = [name for name in CHECKPOINT_FILES if not (folder / name).is_file()]
    if missing:
        raise SnapshotError(f"{folder} is not a complete checkpoint: {missing} missing.")
    try:
        state = json.loads((folder / STATE).read_text())
        tensors = load_tensors((folder / TENSORS).read_bytes())
        with np.load(folder / ARRAYS, allow_pickle=False) as archive:
            arrays: dict[str, Any] = {key: archive[key] for key in archive.files}
    except (OSError, ValueError) as error:
        raise SnapshotError(f"{folder} holds an unreadable checkpoint: {error}") from None
    if state.get("format") != FORMAT or state.get("format_version") != FORMAT_VERSION:
        raise SnapshotError(f"{folder / STATE} is not a {FORMAT} version {FORMAT_VERSION} file.")
    model.set_parameters(decode_value(state["parameters"], tensors), exact_match=True)
    with torch.no_grad():
        for name, value in decode_value(state["variables"], tensors).items():
            getattr(model, name).copy_(value)
    torch.set_rng_state(decode_value(state["torch_random"], tensors))
    np.random.set_state(decode_value(state["numpy_random"], arrays))  # noqa: NPY002
    saved_random = decode_value(state["python_random"], arrays)
    random.setstate((saved_random[0], tuple(saved_random[1]), saved_random[2]))
    for name, node in state["model"].items():
        setattr(model, name, decode_value(node, arrays))
    restore(model.get_env(), state["env"], "env", {**arrays, **tensors})
    pending = decode_value(state["logger"], arrays)
    model.logger.name_to_value.update(pending["values"])
    model.logger.name_to_count.update(pending["counts"])
    model.logger.name_to_excluded.update(pending["excluded"])
    if state["replay_buffer"] is not None:
        restore(model.replay_buffer, state["replay_buffer"], "replay_buffer", arrays)  # type: ignore[attr-defined]
    return dict(state["extra"])
