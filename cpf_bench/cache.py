"""Content-keyed cache of the bench's slow cells: the receding-horizon planners.

The headroom bound (``oracle``), ``mpc`` and ``mpc_tuned`` (and, on the hard
track, ``mpc_tuned`` under the navigation filters and the safety filter) plan
by rolling candidate plans out over their horizon at every revision, about a
hundred times the work of the other analytic policies. Their episodes are a
pure function of what they are run on (and each episode of its seed alone:
the policies seed their sampling from the episode, not from its row in the
batch), so
``cpf-bench`` keeps each (policy, scenario) cell's metrics per seed in a JSON
file keyed by a SHA-256 digest of:

* the policy's name (built with its default gains: ``cpf-bench`` passes none);
* the scenario, every field (``repr`` of the frozen dataclass);
* the horizon in steps;
* the code the numbers come from (``cpf_bench.sources.code_digest``):
  the module that defines the policy and ``RUNNERS`` (the resolver that
  builds it by name, the rollout and the episode runner), with every module
  of the repository they import, transitively: the simulator, its kernels,
  the scenarios, the planners and the metrics. Docstrings and comments are
  left out, so an edit to prose keeps the keys; an edit to code re-keys the
  cells of every policy that imports it.

A cell whose seeds the matching file all holds is read instead of run; any
other is run and, when it ran whole episodes, its seeds merged into the file
(written atomically).
``CACHE_DIRECTORY`` is ``results/bench_cache`` of a source checkout, where
the files for the suite's test (20 seeds) and shift (10 seeds) splits are
committed;
outside a checkout (an installed package) nothing is cached. The files are
data (JSON numbers), never code.
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from baselines import ALL_POLICIES
from cpf_bench.sources import code_digest
from cpf_env.infra import atomic
from cpf_env.scenarios import Scenario

__all__ = ["CACHED_POLICIES", "CACHE_DIRECTORY", "RUNNERS", "cell_key", "load_cell", "store_cell"]

#: Policy names whose cells are cached (given by name, i.e. with their default gains).
CACHED_POLICIES = (
    "oracle",
    "mpc",
    "mpc_tuned",
    "mpc_tuned_ekf",
    "mpc_tuned_mmae",
    "mpc_tuned_safe",
    "mpc_tuned_ekf_safe",
)
#: The modules that build a policy by name, run its episodes and measure them.
RUNNERS = (
    "cpf_bench.evaluate",
    "cpf_bench.rollout",
    "cpf_bench.episodes",
)
#: Where the cells live: results/bench_cache of the source checkout.
CACHE_DIRECTORY = Path(__file__).resolve().parents[1] / "results" / "bench_cache"


@functools.cache
def _code_digest(policy: str) -> str:
    """``code_digest`` of the policy's module and ``RUNNERS`` (read once per process)."""
    return code_digest((ALL_POLICIES[policy].__module__, *RUNNERS))


def cell_key(policy: str, task: Scenario, max_steps: int | None) -> str:
    """The content key (SHA-256, hex) of a policy's episodes on a scenario (module docstring).

    Raises:
        ValueError: ``policy`` is not one of ``CACHED_POLICIES``.
    """
    if policy not in CACHED_POLICIES:
        raise ValueError(f"only {', '.join(CACHED_POLICIES)} are cached, not {policy!r}.")
    horizon = task.max_steps if max_steps is None else int(max_steps)
    digest = hashlib.sha256()
    for part in (policy, repr(task), str(horizon), _code_digest(policy)):
        digest.update(part.encode() + b"\0")
    return digest.hexdigest()


def _read(path: Path, key: str) -> dict[str, dict[str, float]]:
    """Seed (as text) -> metric -> value of a cache file, empty if absent or of another key."""
    if not path.is_file():
        return {}
    stored = json.loads(path.read_text())
    if stored.get("key") != key:
        return {}
    episodes: dict[str, dict[str, float]] = stored["episodes"]
    return episodes


def _path(directory: Path, policy: str, task: Scenario, key: str) -> Path:
    return directory / f"{policy}-{task.name}-{key[:16]}.json"


def load_cell(
    policy: str,
    task: Scenario,
    seeds: Sequence[int],
    max_steps: int | None,
    directory: Path | None = None,
) -> dict[str, NDArray[np.float64]] | None:
    """The cached metrics (name -> (S,)) of a cell, or None unless every seed is cached.

    ``directory`` defaults to ``CACHE_DIRECTORY``.
    """
    directory = CACHE_DIRECTORY if directory is None else directory
    key = cell_key(policy, task, max_steps)
    episodes = _read(_path(directory, policy, task, key), key)
    if not seeds or any(str(int(seed)) not in episodes for seed in seeds):
        return None
    names = episodes[str(int(seeds[0]))].keys()
    return {
        name: np.array([episodes[str(int(seed))][name] for seed in seeds], dtype=np.float64)
        for name in names
    }


def store_cell(
    policy: str,
    task: Scenario,
    seeds: Sequence[int],
    max_steps: int | None,
    metrics: dict[str, NDArray[np.float64]],
    directory: Path | None = None,
) -> Path | None:
    """Merge a cell's episodes into its cache file; None (nothing written) outside a checkout.

    ``directory`` defaults to ``CACHE_DIRECTORY``.
    """
    directory = CACHE_DIRECTORY if directory is None else directory
    if not directory.parent.is_dir():
        return None
    directory.mkdir(exist_ok=True)
    key = cell_key(policy, task, max_steps)
    path = _path(directory, policy, task, key)
    episodes = _read(path, key)
    for k, seed in enumerate(seeds):
        episodes[str(int(seed))] = {name: float(values[k]) for name, values in metrics.items()}
    record = {
        "key": key,
        "policy": policy,
        "scenario": task.name,
        "steps": task.max_steps if max_steps is None else int(max_steps),
        "episodes": dict(sorted(episodes.items(), key=lambda item: int(item[0]))),
    }
    atomic.write_text(path, json.dumps(record, indent=1) + "\n")
    return path
