"""What a sweep runs: scenarios x seeds x settings of ``agents.TrainConfig``.

A ``SweepSpec`` is the grid (every combination is one trial), the fields held
fixed, how each trained agent is evaluated and the CPUs per trial. It is
saved as ``sweep.json`` in the sweep's folder, with the package's version;
running the same command again resumes that sweep, and a different sweep (or
package version) in the same folder is refused. The grid's fields are kept
in name order, so the order of ``--set`` does not change the sweep.

``--set`` values on the command line: ``FIELD=VALUE`` fixes a field,
``FIELD=V1,V2,...`` sweeps it, and ``FIELD=[...]`` (JSON) gives values that
contain commas themselves, e.g. ``residual.extras=[[],["base_action"]]``. A
field of the residual (``cpf_env.envs.residual.ResidualConfig``) is named
``residual.FIELD``.

Example:
    >>> spec = SweepSpec(("bench_mild",), (0, 1), grid={"residual.scale": (0.1, 0.2)})
    >>> [trial_name(p, spec) for p in spec.trials()][:2]
    ['bench_mild-seed0-residual.scale0.1', 'bench_mild-seed0-residual.scale0.2']
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import re
import typing
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cpf_env
from agents.training.config import TrainConfig
from cpf_env.envs.residual import ResidualConfig
from cpf_env.infra import atomic
from cpf_env.scenarios.splits import EVALUATION_SEED, VALIDATION_SEED

__all__ = ["SweepSpec", "parse_setting", "trial_name"]

#: TrainConfig fields a sweep sets through its own flags, not ``--set``.
#: TrainConfig fields the sweep's own options set, and those options.
_OWN_FLAGS = {"scenario": "--scenarios", "seed": "--seed and --num-seeds"}


def _field_types() -> dict[str, Any]:
    """TrainConfig field name (``residual.FIELD``: of its ``ResidualConfig``) -> its type."""
    types = typing.get_type_hints(TrainConfig)
    del types["residual"]
    residual = typing.get_type_hints(ResidualConfig)
    return {**types, **{f"residual.{name}": kind for name, kind in residual.items()}}


def _convert(name: str, value: Any, kind: Any) -> Any:
    """``value`` (parsed JSON or a string) converted to the field's type, or ValueError."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if type(None) in args:  # X | None
        if value in (None, "none", "None", "null"):
            return None
        kind = next(a for a in args if a is not type(None))
        origin, args = typing.get_origin(kind), typing.get_args(kind)
    try:
        if origin is tuple:
            items = value if isinstance(value, list) else [] if value == "" else [value]
            return tuple(_convert(name, item, args[0]) for item in items)
        if kind is bool:
            if isinstance(value, bool):
                return value
            if str(value).lower() in ("true", "false"):
                return str(value).lower() == "true"
            raise ValueError
        if kind is int and isinstance(value, float):
            raise ValueError
        return kind(value)
    except (TypeError, ValueError):
        raise ValueError(
            f"--set {name}: {value!r} is not a valid {getattr(kind, '__name__', kind)}."
        ) from None


def parse_setting(text: str) -> tuple[str, tuple[Any, ...]]:
    """Parse one ``FIELD=VALUE[,VALUE...]`` or ``FIELD=[JSON list]`` into (field, values).

    Raises:
        ValueError: Not ``FIELD=VALUES``, an unknown field, a field with its own
            flag, or a value of the wrong type.
    """
    name, sep, raw = text.partition("=")
    types = _field_types()
    if not sep or not name:
        raise ValueError(f"--set takes FIELD=VALUE or FIELD=V1,V2; got {text!r}.")
    if name in _OWN_FLAGS:
        raise ValueError(f"set {name} with {_OWN_FLAGS[name]}, not --set.")
    if name not in types:
        choices = sorted(set(types) - set(_OWN_FLAGS))
        raise ValueError(f"--set: unknown TrainConfig field {name!r}; fields are {choices}.")
    if raw.startswith("["):
        try:
            values = json.loads(raw)
        except json.JSONDecodeError as error:
            raise ValueError(f"--set {name}: {raw!r} is not a JSON list ({error}).") from None
    else:
        values = raw.split(",")
    if not values:
        raise ValueError(f"--set {name}: give at least one value.")
    return name, tuple(_convert(name, value, types[name]) for value in values)


def _slug(value: Any) -> str:
    """A short, filesystem-safe rendering of a setting's value."""
    text = "-".join(map(str, value)) if isinstance(value, tuple) else str(value)
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", text) or "none"


@dataclass(frozen=True)
class SweepSpec:
    """A sweep: every combination of scenarios x seeds x ``grid`` is one trial.

    Attributes:
        scenarios: Registered scenario names to train on.
        seeds: Training seeds.
        grid: TrainConfig field -> the values it takes (two or more).
        fixed: TrainConfig field -> the value it keeps in every trial.
        eval_num_seeds: Evaluation episodes per trial (paired with the base policy);
            0 skips the evaluation.
        eval_max_steps: Evaluation horizon (None: each scenario's ``max_steps``).
        cpus_per_trial: CPUs each trial reserves, and its torch threads unless
            ``torch_threads`` is set. Part of the sweep because the thread
            count changes floating-point results: a resume with another count
            is refused rather than mixing the two.
    """

    scenarios: tuple[str, ...]
    seeds: tuple[int, ...]
    grid: dict[str, tuple[Any, ...]] = field(default_factory=dict)
    fixed: dict[str, Any] = field(default_factory=dict)
    eval_num_seeds: int = 5
    eval_max_steps: int | None = None
    cpus_per_trial: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "scenarios", tuple(self.scenarios))
        object.__setattr__(self, "seeds", tuple(int(seed) for seed in self.seeds))
        object.__setattr__(self, "grid", {k: tuple(self.grid[k]) for k in sorted(self.grid)})
        if not self.scenarios or not self.seeds:
            raise ValueError("a sweep needs at least one scenario and one seed.")
        for name, count in (("scenarios", self.scenarios), ("seeds", self.seeds)):
            if len(set(count)) != len(count):
                raise ValueError(f"{name} repeat: {list(count)}; give each once.")
        available = EVALUATION_SEED - VALIDATION_SEED
        if not 0 <= self.eval_num_seeds <= available:
            raise ValueError(
                f"eval seeds must be from 0 to the {available} validation seeds, got "
                f"{self.eval_num_seeds}."
            )
        if self.cpus_per_trial < 1:
            raise ValueError(f"CPUs per trial must be >= 1, got {self.cpus_per_trial}.")
        fields = _field_types()
        for name in [*self.grid, *self.fixed]:
            if name in _OWN_FLAGS or name not in fields:
                choices = sorted(set(fields) - set(_OWN_FLAGS))
                raise ValueError(f"{name!r} is not a field a sweep can set; fields are {choices}.")
        for name, values in self.grid.items():
            if len(set(map(_slug, values))) != len(values):
                listed = typing.get_origin(fields[name]) is tuple
                hint = f" One list value is written in JSON: {name}=[[64,64]]." if listed else ""
                raise ValueError(
                    f"--set {name}: values repeat ({list(values)}); give each once.{hint}"
                )
        threads = [self.fixed.get("torch_threads"), *self.grid.get("torch_threads", ())]
        if any(value is not None and value > self.cpus_per_trial for value in threads):
            raise ValueError(
                f"torch_threads {max(v for v in threads if v is not None)} is more than the "
                f"{self.cpus_per_trial} CPU(s) each trial reserves: trials would crowd each "
                "other's cores; raise --cpus-per-trial or lower torch_threads."
            )
        for params in self.trials():  # every trial's TrainConfig is valid before any starts
            try:
                self.config(params)
            except ValueError as error:
                raise ValueError(f"trial {trial_name(params, self)}: {error}") from None

    @classmethod
    def from_settings(
        cls, scenarios: Sequence[str], seeds: Sequence[int], settings: Sequence[str], **kwargs: Any
    ) -> SweepSpec:
        """Build from ``--set`` texts: one value fixes a field, several sweep it."""
        grid: dict[str, tuple[Any, ...]] = {}
        fixed: dict[str, Any] = {}
        for text in settings:
            name, values = parse_setting(text)
            if name in grid or name in fixed:
                raise ValueError(f"--set {name} is given twice; give all its values at once.")
            if len(values) == 1:
                fixed[name] = values[0]
            else:
                grid[name] = values
        return cls(tuple(scenarios), tuple(seeds), grid, fixed, **kwargs)

    def trials(self) -> Iterator[dict[str, Any]]:
        """Each trial's varying parameters: scenario, seed and one value per grid field."""
        names = ("scenario", "seed", *self.grid)
        for values in itertools.product(self.scenarios, self.seeds, *self.grid.values()):
            yield dict(zip(names, values, strict=True))

    def config(self, params: dict[str, Any]) -> TrainConfig:
        """The ``TrainConfig`` a trial with varying parameters ``params`` trains with.

        ``torch_threads`` is the CPUs per trial unless the sweep sets it.
        """
        values = {"torch_threads": self.cpus_per_trial, **self.fixed, **params}
        fields = {key: value for key, value in values.items() if not key.startswith("residual.")}
        residual = {
            key.removeprefix("residual."): value
            for key, value in values.items()
            if key.startswith("residual.")
        }
        return TrainConfig(**fields, residual=ResidualConfig(**residual))

    def param_space(self, tune: Any) -> dict[str, Any]:
        """Ray Tune's parameter space: a grid search over every varying parameter."""
        space = {"scenario": tune.grid_search(list(self.scenarios))}
        space["seed"] = tune.grid_search(list(self.seeds))
        space.update({name: tune.grid_search(list(v)) for name, v in self.grid.items()})
        return space

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (tuples become lists), with ``cpf_env``'s version."""
        record = dataclasses.asdict(self) | {"cpf_env_version": cpf_env.__version__}
        return json.loads(json.dumps(record))

    def check_folder(self, folder: Path) -> bool:
        """Check that ``folder`` can hold this sweep, without writing anything.

        Returns:
            True if the folder already holds this sweep (a resume), False if
            it is new or holds no sweep yet.

        Raises:
            ValueError: ``folder`` is a file, or holds a different sweep.
        """
        if folder.exists() and not folder.is_dir():
            raise ValueError(f"--out {folder} is a file; give a folder (new or of this sweep).")
        path = folder / "sweep.json"
        if not path.exists():
            return False
        saved, wanted = json.loads(path.read_text()), self.to_json()
        version = "cpf_env_version"
        if saved.get(version) != wanted[version]:
            raise ValueError(
                f"{folder} holds a sweep made by cpf_env {saved.get(version) or 'before 0.1.0'}; "
                f"this is {wanted[version]}, and a sweep is resumed only by the version that "
                "made it (its trials would mix two versions): choose another --out."
            )
        if saved != wanted:
            differ = ", ".join(
                f"{key} (saved {saved.get(key)!r}, now {wanted.get(key)!r})"
                for key in sorted(set(saved) | set(wanted))
                if saved.get(key) != wanted.get(key)
            )
            raise ValueError(
                f"{folder} holds a different sweep ({path}): it differs in {differ}. Rerun "
                "with its exact arguments to resume it, or choose another --out."
            )
        return True

    def save(self, folder: Path) -> None:
        """Write ``sweep.json`` to ``folder`` (created if needed)."""
        folder.mkdir(parents=True, exist_ok=True)
        atomic.write_text(folder / "sweep.json", json.dumps(self.to_json(), indent=2) + "\n")


def trial_name(params: dict[str, Any], spec: SweepSpec) -> str:
    """Folder name of a trial: scenario, seed and the grid fields' values."""
    parts = [params["scenario"], f"seed{params['seed']}"]
    parts += [f"{name}{_slug(params[name])}" for name in spec.grid]
    return "-".join(parts)
