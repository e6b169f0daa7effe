"""``cpf-train --config FILE.toml`` and ``--set KEY=VALUE``: hyperparameters from a file.

The file is TOML (read with the standard library's ``tomllib``, Python 3.11+;
no new dependency), its keys the ``agents.TrainConfig`` field names
(``n_epochs``, ``reward_form``, ``net_arch``, ``gamma``, ...), a ``[residual]``
table of ``cpf_env.envs.residual.ResidualConfig`` fields (``mode``, ``scale``,
``extras``, ...), and the run's schedule (``eval_every``, ``eval_num_seeds``,
``checkpoint_every``). A file may start from another: ``extends = "base.toml"``
(a path relative to the file; chains are followed, a cycle is refused) reads
that file first and lets this one override its keys (the ``[residual]``
table key by key). ``--set KEY=VALUE`` overrides one key, VALUE read as a
TOML value (``--set n_epochs=5 'net_arch=[64, 64]' residual.scale=0.3``; a
bare word is a string, and ``none`` leaves a field whose default is None
unset: ``--set encoder=none``). Precedence: the defaults, then the
file (after what it extends), then ``--set``, then the flags given.
``cpf-train`` writes the resolved values into the run folder as
``hyperparameters.toml``, so ``cpf-train --config runs/x/hyperparameters.toml
--out runs/y`` repeats a run; ``examples/hyperparameters/`` holds the defaults.

Example file::

    extends = "ppo_defaults.toml"
    scenario = "bench_lossy_links"
    net_arch = [64, 64]
    learning_rate = 3e-4

    [residual]
    mode = "force_and_rate"
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = [
    "EXTENDS",
    "SCHEDULE_KEYS",
    "hyperparameters_toml",
    "merge_settings",
    "moved_keys",
    "parse_settings",
    "read_hyperparameters",
    "toml_chain",
]

#: The key naming the file a hyperparameter file starts from.
EXTENDS = "extends"
#: Keys of the run's schedule (not ``TrainConfig`` fields).
SCHEDULE_KEYS = ("eval_every", "eval_num_seeds", "checkpoint_every")
#: The ``TrainConfig`` field that is a table (``ResidualConfig``), set key by key.
RESIDUAL = "residual"


def _valid_keys() -> list[str]:
    from agents.training.config import TrainConfig

    return [field.name for field in dataclasses.fields(TrainConfig)] + list(SCHEDULE_KEYS)


def _residual_keys() -> list[str]:
    from cpf_env.envs.residual import ResidualConfig

    return [field.name for field in dataclasses.fields(ResidualConfig)]


def moved_keys(unknown: list[str]) -> str:
    """A message part naming where the ``unknown`` keys that moved went ('' if none moved).

    The keys of files written before the ``[residual]`` table: ``base``, ``eval_seeds``
    and the residual's fields at the top level.
    """
    from agents.training.config import FLAT_RESIDUAL_FIELDS

    places = {"base": "base_policy", "eval_seeds": "eval_num_seeds"}
    places |= {name: f"[residual] {name}" for name in FLAT_RESIDUAL_FIELDS}
    moved = [f"{key} is now {places[key]}" for key in unknown if key in places]
    return f" ({'; '.join(moved)})" if moved else ""


def merge_settings(values: Mapping[str, Any], update: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` with ``update``'s keys over them, the ``residual`` table merged key by key."""
    merged = dict(values)
    for key, value in update.items():
        if key == RESIDUAL and isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = {**merged[key], **value}
        else:
            merged[key] = value
    return merged


def read_hyperparameters(path: str | Path) -> dict[str, Any]:
    """The keys and values of a hyperparameter file, after the files it extends.

    Raises:
        ValueError: A missing or unreadable file, invalid TOML, an unknown key (also a
            ``[section]``; the message lists the valid ones), or an ``extends`` that is
            not a string or comes back to a file of its chain. Values are checked by
            ``TrainConfig`` (a field whose value is a mapping is an inline table).
    """
    valid = _valid_keys()  # a [section] other than [residual] is an unknown key too
    merged: dict[str, Any] = {}
    for file, values in toml_chain(path, "hyperparameter"):
        unknown = sorted(set(values) - set(valid))
        if unknown:
            raise ValueError(
                f"{file} has unknown keys {unknown}{moved_keys(unknown)}; valid keys: {valid}."
            )
        residual = values.get(RESIDUAL, {})
        if not isinstance(residual, dict):
            raise ValueError(
                f"{file}: {RESIDUAL} must be a table ([residual] with keys "
                f"{_residual_keys()}), got {residual!r}."
            )
        unknown = sorted(set(residual) - set(_residual_keys()))
        if unknown:
            raise ValueError(
                f"{file}: [residual] has unknown keys {unknown}; valid keys: {_residual_keys()}."
            )
        merged = merge_settings(merged, values)
    return merged


def toml_chain(path: str | Path, kind: str) -> list[tuple[Path, dict[str, Any]]]:
    """A TOML file and those it ``extends``, each with its own keys, the first base first.

    Args:
        path: The file.
        kind: What the file is, for messages (``"hyperparameter"``, ``"distillation"``).

    Raises:
        ValueError: A missing or unreadable file, invalid TOML, an ``extends`` that is
            not a string, or a chain that comes back to one of its files.
    """
    try:
        import tomllib
    except ImportError:  # Python 3.10
        raise ValueError(
            "a TOML file needs Python 3.11 or later (the standard library's tomllib); give "
            "the settings with --set instead."
        ) from None
    chain: list[tuple[Path, dict[str, Any]]] = []
    file = Path(path)
    while True:
        if file.resolve() in [known.resolve() for known, _ in chain]:
            names = " -> ".join(str(known) for known, _ in [*chain, (file, {})])
            raise ValueError(f"{EXTENDS} comes back to a file of its chain: {names}.")
        try:
            values = tomllib.loads(file.read_text())
        except OSError as error:
            raise ValueError(f"cannot read the {kind} file {file}: {error}") from None
        except tomllib.TOMLDecodeError as error:
            raise ValueError(f"{file} is not valid TOML: {error}") from None
        base = values.pop(EXTENDS, None)
        chain.append((file, values))
        if base is None:
            return chain[::-1]
        if not isinstance(base, str):
            raise ValueError(f"{file}: {EXTENDS} must be a file name (a string), got {base!r}.")
        file = file.parent / base


def parse_settings(items: list[str]) -> dict[str, Any]:
    """``--set KEY=VALUE`` items as keys and values (VALUE a TOML value, a bare word a string).

    ``residual.FIELD=VALUE`` sets one field of the ``residual`` table.

    Raises:
        ValueError: Not ``KEY=VALUE``, or an unknown key (the message lists the valid ones).
    """
    import tomllib

    from agents.training.config import TrainConfig
    from cpf_env.envs.residual import ResidualConfig

    valid = [key for key in _valid_keys() if key != RESIDUAL]
    valid += [f"{RESIDUAL}.{name}" for name in _residual_keys()]
    optional = {f.name for f in dataclasses.fields(TrainConfig) if f.default is None}
    optional |= {
        f"{RESIDUAL}.{f.name}" for f in dataclasses.fields(ResidualConfig) if f.default is None
    }
    settings: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--set takes KEY=VALUE (e.g. n_epochs=5), got {item!r}.")
        if key not in valid:
            raise ValueError(f"--set: unknown key {key!r}{moved_keys([key])}; valid keys: {valid}.")
        if raw == "none" and key in optional:
            value: Any = None  # TOML has no null: "none" leaves an optional field unset
        else:
            try:
                value = tomllib.loads(f"value = {raw}")["value"]
            except tomllib.TOMLDecodeError:
                value = raw  # a bare word: the string itself
        if key.startswith(f"{RESIDUAL}."):
            settings = merge_settings(settings, {RESIDUAL: {key.split(".", 1)[1]: value}})
        else:
            settings[key] = value
    return settings


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
            out, which reads back as their default, None; ``residual`` is written as
            the ``[residual]`` table, last.
        schedule: ``eval_every``, ``eval_num_seeds``, ``checkpoint_every``.
    """
    lines = ["# cpf-train hyperparameters (cpf-train --config FILE); flags override them."]
    flat = {key: value for key, value in {**config, **schedule}.items() if key != RESIDUAL}
    for key, value in flat.items():
        if value is not None:
            lines.append(f"{key} = {_toml_value(value)}")
    if config.get(RESIDUAL):
        lines += ["", f"[{RESIDUAL}]"]
        for key, value in config[RESIDUAL].items():
            if value is not None:
                lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"
