"""Compile every numba kernel once, so that later processes only load them.

The simulator's kernels are compiled by numba on first use and cached on disk
(``cache=True``): next to the sources (``__pycache__``), or under
``NUMBA_CACHE_DIR`` when that is set (numba's own setting). A process that
finds the cache warm loads the machine code in about 0.35 s; one that finds it
cold compiles for 15-30 s. Many processes starting together on a cold cache
(Ray Tune trials, RLlib env runners, test workers) each compile. Call
``precompile()`` (or the ``cpf-precompile`` command) once per machine or
container image, with the same ``NUMBA_CACHE_DIR`` the workers will see.

The cache is specific to the CPU model and to the kernels' sources: nodes of
another CPU type compile again once, and so does every process after an edit
to any module a kernel compiles from (``cpf_env.infra.kernel_cache`` keys the cache
on all of them, so no stale kernel is ever loaded).

Example:
    >>> from cpf_env.sim.precompile import precompile
    >>> first = precompile(["wang2014"])  # compiles, or loads from the cache
    >>> again = precompile(["wang2014"])  # this process holds every kernel already
    >>> again.compiled, again.loaded
    (0, 0)
"""

from __future__ import annotations

import importlib
import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numba
import numpy as np
from numba.core.registry import CPUDispatcher

from cpf_env import scenarios
from cpf_env.infra.kernel_cache import KERNEL_MODULES
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.threads import PARALLEL_MIN_FLEETS

__all__ = [
    "KERNEL_MODULES",
    "PrecompileReport",
    "cache_directory",
    "kernels_of_package",
    "precompile",
]


@dataclass(frozen=True)
class PrecompileReport:
    """What one ``precompile`` call did (kernels this process already held count in neither).

    Attributes:
        scenarios: Scenario names exercised.
        loaded: Kernel signatures loaded from the on-disk cache (entry kernels
            only: a loaded kernel brings its callees with it).
        compiled: Function signatures compiled by this call and saved to
            the cache (entry kernels and the callees they compile).
        seconds: Wall time (s).
        cache_directory: Where the cache lives.
    """

    scenarios: tuple[str, ...]
    loaded: int
    compiled: int
    seconds: float
    cache_directory: str


def _configured_cache() -> str:
    """The ``CACHE_DIR`` numba read from ``NUMBA_CACHE_DIR`` ('' when unset)."""
    return str(getattr(numba.config, "CACHE_DIR", "") or "")


def cache_directory() -> str:
    """The directory numba caches this package's kernels in.

    numba's ``CACHE_DIR`` (read from ``NUMBA_CACHE_DIR`` when numba was
    imported) if set, else the package's ``__pycache__`` folders (numba falls
    back to a per-user directory when those are not writable).
    """
    configured = _configured_cache()
    if configured:
        return configured
    return os.path.join(os.path.dirname(__file__), "__pycache__")


def _require_writable_cache() -> None:
    """Create numba's configured cache directory, or raise ValueError if it cannot be written."""
    configured = _configured_cache()
    if not configured:
        return
    try:
        os.makedirs(configured, exist_ok=True)
        writable = os.access(configured, os.W_OK | os.X_OK)
    except OSError:
        writable = False
    if not writable:
        raise ValueError(
            f"NUMBA_CACHE_DIR={configured} is not a directory this user can write, so no "
            "kernel would be cached; point it at a writable directory (shared by the "
            "workers), or unset it to cache next to the sources."
        )


def kernels_of_package() -> dict[str, CPUDispatcher]:
    """Every numba-compiled function of ``cpf_env``, by qualified name."""
    found: dict[str, CPUDispatcher] = {}
    for name in KERNEL_MODULES:
        module = importlib.import_module(f"cpf_env.{name}")
        for value in vars(module).values():
            if isinstance(value, CPUDispatcher):
                found[f"{value.py_func.__module__}.{value.py_func.__name__}"] = value
    return found


def _exercise(name: str) -> None:
    """Run the kernels a scenario uses: serial and parallel steps, resets, paths, plant."""
    task = scenarios.get(name)
    for num_fleets in (1, PARALLEL_MIN_FLEETS):
        sim = FleetSim(task, num_fleets=num_fleets)
        sim.reset(seeds=list(range(num_fleets)))
        for _ in range(2):
            sim.step(np.zeros((num_fleets, task.n, sim.act_dim)))
        sim.accelerations()
    for path in task.paths:
        path.evaluate(np.zeros(2))


def _cache_counts(dispatchers: Iterable[CPUDispatcher]) -> tuple[int, int]:
    """(signatures loaded from the cache, signatures compiled) by this process so far."""
    dispatchers = list(dispatchers)
    loaded = sum(sum(d.stats.cache_hits.values()) for d in dispatchers)
    compiled = sum(sum(d.stats.cache_misses.values()) for d in dispatchers)
    return loaded, compiled


def precompile(scenario_names: Sequence[str] | None = None) -> PrecompileReport:
    """Compile (or load) every kernel for the given scenarios.

    Args:
        scenario_names: Registered scenario names (default: all of them). The
            kernels' types do not depend on the scenario, so one is enough for
            the simulator; all of them also cover every path kind.

    Returns:
        A ``PrecompileReport``.

    Raises:
        ValueError: An unknown scenario name, or ``NUMBA_CACHE_DIR`` names a
            directory that cannot be written.
    """
    names = tuple(scenarios.list_scenarios() if scenario_names is None else scenario_names)
    for name in names:
        scenarios.get(name)  # unknown names raise before any work
    _require_writable_cache()
    dispatchers = kernels_of_package().values()
    loaded_before, compiled_before = _cache_counts(dispatchers)
    start = time.perf_counter()
    for name in names:
        _exercise(name)
    loaded, compiled = _cache_counts(dispatchers)
    return PrecompileReport(
        scenarios=names,
        loaded=loaded - loaded_before,
        compiled=compiled - compiled_before,
        seconds=time.perf_counter() - start,
        cache_directory=cache_directory(),
    )
