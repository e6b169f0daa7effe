"""Starting or joining Ray for the commands that distribute work (``cpf-sweep``, ``cpf-bench``).

Ray is an optional dependency (``pip install -e ".[ray]"``). Without an
address the commands start a local Ray instance on this machine (nothing to
set up; it stops when the command ends). With ``--address auto`` they join the
cluster this machine belongs to (``ray start`` ran here), with
``--address ray://HOST:10001`` they connect through Ray Client; Ray's own
``RAY_ADDRESS`` variable works as usual.

Workers inherit two settings from the command's environment: ``NUMBA_CACHE_DIR``
(where the compiled kernels are cached; see ``cpf_env.precompile``) and the
numba thread count, set to the CPUs each task reserves so that concurrent
tasks do not oversubscribe the cores.
"""

from __future__ import annotations

import argparse
import os
from types import ModuleType
from typing import Any

__all__ = ["add_address_argument", "require_ray", "start_ray", "worker_environment"]

_INSTALL = 'install the optional Ray extra: pip install -e ".[ray]" (or pip install "ray[tune]")'


def require_ray() -> ModuleType:
    """Import Ray, or raise ImportError saying how to install it."""
    try:
        import ray
    except ImportError as error:
        raise ImportError(f"this command needs Ray, which is not installed; {_INSTALL}.") from error
    return ray


def add_address_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--address`` (where Ray runs) to a command's parser."""
    parser.add_argument(
        "--address",
        default=None,
        metavar="ADDRESS",
        help="Ray cluster to use: 'auto' (the cluster this machine joined with `ray start`) "
        "or ray://HOST:10001 (Ray Client); default: a local Ray instance on this machine",
    )


def worker_environment(cpus_per_task: int) -> dict[str, str]:
    """Environment variables every Ray worker of the command gets.

    Args:
        cpus_per_task: CPUs each task or trial reserves; numba uses that many threads.

    Returns:
        ``NUMBA_NUM_THREADS`` and, if set here, ``NUMBA_CACHE_DIR``.
    """
    variables = {"NUMBA_NUM_THREADS": str(int(cpus_per_task))}
    if os.environ.get("NUMBA_CACHE_DIR"):
        variables["NUMBA_CACHE_DIR"] = os.environ["NUMBA_CACHE_DIR"]
    return variables


def start_ray(address: str | None, cpus_per_task: int = 1, quiet: bool = False) -> ModuleType:
    """Start a local Ray instance (``address`` None) or join a cluster, and return ``ray``.

    Args:
        address: None for a local instance, else a Ray address ('auto', 'ray://...').
        cpus_per_task: CPUs each task reserves (sets the workers' numba threads).
        quiet: Keep Ray's start-up and worker log lines off the terminal.

    Raises:
        ImportError: Ray is not installed (the message says how to install it).
        ValueError: ``cpus_per_task`` is below 1.
    """
    if cpus_per_task < 1:
        raise ValueError(f"CPUs per task must be >= 1, got {cpus_per_task}.")
    ray = require_ray()
    options: dict[str, Any] = {
        "runtime_env": {"env_vars": worker_environment(cpus_per_task)},
        "log_to_driver": not quiet,
        "logging_level": "error" if quiet else "warning",
    }
    if address is None:
        options["include_dashboard"] = False
    ray.init(address=address, **options)
    return ray
