"""Reading an old SB3 agent folder (``model.zip`` + ``vecnormalize.pkl``): pickles, trust needed.

Before the data-only format (``agents.agent_folder``), ``cpf-train`` wrote
SB3's ``model.zip``, whose ``data`` entries are cloudpickled, and
``VecNormalize``'s pickle. Unpickling runs whatever code the file's author
put in it, so these folders are read only when the caller says they trust
them (``load_policy(..., trust_pickle=True)``, ``--trust-pickle``), with a
warning, and are best converted once (``convert_sb3_folder``) into the
format that holds data only.
"""

from __future__ import annotations

import pickle
import warnings
from pathlib import Path
from typing import Any, cast

from agents.agent_folder import (
    Normalization,
    PolicyNetwork,
    actor_tensors,
    check_mlp_input,
    network_from_tensors,
    training_config,
    write_agent,
)
from agents.folder_files import MAX_JSON_BYTES, AgentFolderError, field, parse_json, read_file
from cpf_env.infra import atomic

__all__ = ["PICKLE_WARNING", "convert_sb3_folder", "is_sb3_folder", "read_sb3_folder"]

PICKLE_WARNING = (
    "{folder} is an SB3 agent folder: loading it unpickles model.zip and vecnormalize.pkl, "
    "which runs any code their author put in them. Do this only for folders you made or "
    "trust, and convert them to the data-only format (agents.legacy.convert_sb3_folder)."
)


def is_sb3_folder(folder: Path) -> bool:
    """Whether ``folder`` looks like an old SB3 agent folder (``model.zip`` + ``config.json``)."""
    return (folder / "model.zip").is_file() and (folder / "config.json").is_file()


def read_sb3_folder(
    folder: Path,
) -> tuple[dict[str, Any], PolicyNetwork, Normalization | None]:
    """Read an old SB3 folder by unpickling it (warns; the caller must trust the folder).

    Returns:
        The ``config.json`` record, the actor, and the statistics (or None).

    Raises:
        AgentFolderError: A missing statistics file the config asks for, or an
            unreadable file (named).
    """
    from agents.algorithms import ALGORITHMS

    warnings.warn(PICKLE_WARNING.format(folder=folder), UserWarning, stacklevel=3)
    source = folder / "config.json"
    record = parse_json(read_file(source, MAX_JSON_BYTES, folder), source)
    config = training_config(field(record, "config", source), source)
    try:
        model = ALGORITHMS[config.algo].load(folder / "model.zip", device="cpu")
    except Exception as error:  # SB3 raises assorted errors on a damaged zip
        raise AgentFolderError(f"{folder / 'model.zip'} cannot be loaded: {error!r}") from None
    network = network_from_tensors(
        actor_tensors(model, config.algo), config.algo, config.net_arch, folder / "model.zip"
    )
    check_mlp_input(network, config, folder / "model.zip", source)
    normalization = None
    statistics_file = folder / "vecnormalize.pkl"
    if config.normalize_observations:
        if not statistics_file.is_file():
            raise AgentFolderError(
                f"{statistics_file} is missing but config.json says the run normalized its "
                "observations; without it the agent would act on unnormalized inputs."
            )
        try:
            with open(statistics_file, "rb") as handle:
                statistics = pickle.load(handle)  # trusted by the caller (trust_pickle=True)
            rms = statistics.obs_rms
            normalization = Normalization(
                rms.mean.astype("float64"),
                rms.var.astype("float64"),
                float(statistics.epsilon),
                float(statistics.clip_obs),
            )
        except Exception as error:
            raise AgentFolderError(f"{statistics_file} cannot be read: {error!r}") from None
        if normalization.mean.shape != (network.input_size,):
            raise AgentFolderError(
                f"{statistics_file} has statistics for {normalization.mean.shape} inputs but the "
                f"network in model.zip takes {network.input_size}."
            )
    return cast(dict[str, Any], record), network, normalization


def convert_sb3_folder(source: str | Path, destination: str | Path) -> Path:
    """Convert a trusted SB3 agent folder into the data-only format.

    The destination holds only the data-only files (no pickle); it may be the
    source itself, which is then replaced atomically.

    Args:
        source: An SB3 folder you trust (it is unpickled).
        destination: The folder to write (replaced if it exists).

    Returns:
        The destination.
    """
    record, network, normalization = read_sb3_folder(Path(source))
    target = Path(destination)
    with atomic.FolderLock(target, "convert_sb3_folder"), atomic.staged_folder(target) as staging:
        write_agent(staging, record, network, normalization)
    return target
