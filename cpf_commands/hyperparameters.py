"""``cpf-train --config FILE.toml``: hyperparameters from a file, overridden by flags.

The file is TOML (read with the standard library's ``tomllib``, Python 3.11+;
no new dependency), flat, its keys the ``agents.TrainConfig`` field names
(``n_epochs``, ``reward_form``, ``net_arch``, ``gamma``, ... also those without a
flag) and the run's schedule (``eval_every``, ``eval_seeds``,
``checkpoint_every``). Precedence: the defaults, then the file, then the
flags given on the command line. ``cpf-train`` writes the resolved values
into the run folder as ``hyperparameters.toml``, so
``cpf-train --config runs/x/hyperparameters.toml --out runs/y`` repeats a run;
``examples/hyperparameters/`` holds the defaults.

Example file::

    algo = "ppo"
    scenario = "bench_lossy_links"
    net_arch = [64, 64]
    learning_rate = 3e-4
    eval_every = 500_000
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["SCHEDULE_KEYS", "hyperparameters_toml", "read_hyperparameters"]

#: Keys of the run's schedule (not ``TrainConfig`` fields).
SCHEDULE_KEYS = ("eval_every", "eval_seeds", "checkpoint_every")


def _valid_keys() -> list[str]:
    from agents.train_config import TrainConfig

    return [field.name for field in dataclasses.fields(TrainConfig)] + list(SCHEDULE_KEYS)


def read_hyperparameters(path: str | Path) -> dict[str, Any]:
    """The keys and values of a hyperparameter file (checked by name, not yet by value).

    Raises:
        ValueError: A missing or unreadable file, invalid TOML, or an unknown key (also a
            ``[section]``; the message lists the valid ones). Values are checked by
            ``TrainConfig`` (a field whose value is a mapping is an inline table).
    """
    try:
        import tomllib
    except ImportError:  # Python 3.10
        raise ValueError(
            "--config needs Python 3.11 or later (the standard library's tomllib); give the "
            "settings as flags instead."
        ) from None
    file = Path(path)
    try:
        values = tomllib.loads(file.read_text())
    except OSError as error:
        raise ValueError(f"cannot read the hyperparameter file {file}: {error}") from None
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{file} is not valid TOML: {error}") from None
    valid = _valid_keys()  # a [section] is an unknown key too: the file is flat
    unknown = sorted(set(values) - set(valid))
    if unknown:
        raise ValueError(f"{file} has unknown keys {unknown}; valid keys: {valid}.")
    return values


def _toml_value(value: Any) -> str:
    """One TOML value: strings, booleans, integers, floats, and lists and mappings of them."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(item) for item in value) + "]"
    if isinstance(value, dict):  # an inline table, keys quoted
        items = ", ".join(f"{json.dumps(str(k))} = {_toml_value(v)}" for k, v in value.items())
        return "{" + items + "}"
    raise ValueError(f"cannot write {value!r} as a TOML value.")


def hyperparameters_toml(config: Mapping[str, Any], schedule: Mapping[str, Any]) -> str:
    """The resolved hyperparameters as a file ``read_hyperparameters`` reads back exactly.

    Args:
        config: ``TrainConfig.to_json()``; None values (TOML has no null) are left
            out, which reads back as their default, None.
        schedule: ``eval_every``, ``eval_seeds``, ``checkpoint_every``.
    """
    lines = ["# cpf-train hyperparameters (cpf-train --config FILE); flags override them."]
    for key, value in {**config, **schedule}.items():
        if value is not None:
            lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"
