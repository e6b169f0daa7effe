"""Starting or joining Ray for the commands that distribute work (``cpf-sweep``, ``cpf-bench``).

Ray is an optional dependency (``pip install -e ".[ray]"``). Without an
address the commands start a new local Ray instance on this machine (nothing
to set up; it stops when the command ends), even if this machine already runs
a Ray cluster, unless Ray's own ``RAY_ADDRESS`` variable names one. With
``--address auto`` they join the cluster this machine belongs to (``ray start``
ran here), with ``--address HOST:6379`` a cluster's head node, with
``--address ray://HOST:10001`` they connect through Ray Client. An address
that does not answer is an error, reported after a few seconds rather than
waited on.

A local instance listens on 127.0.0.1 only (GCS, raylet, object manager,
runtime-env agent; no dashboard), so nothing on the network can reach it, and
Ray's token file (``~/.ray/auth_token``) is made private (0600) before Ray
reads it. Ray itself replaces 127.0.0.1 by the machine's outward address
(``services.resolve_ip_for_localhost``); ``_loopback_only`` suspends that
for the duration of ``ray.init``, a private Ray function that the ``ray``
tests check by listing the instance's listening sockets. What a cluster needs
before anyone joins one is in ``docs/scaling.md``.

Workers inherit two settings from the command's environment: ``NUMBA_CACHE_DIR``
(where the compiled kernels are cached; see ``cpf_env.sim.precompile``) and the
numba thread count, set to the CPUs each task reserves so that concurrent
tasks do not oversubscribe the cores.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import socket
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = [
    "add_address_argument",
    "private_token_file",
    "require_ray",
    "resolve_address",
    "start_ray",
    "worker_environment",
]

_INSTALL = (
    'install the optional Ray extra: pip install -e ".[ray]" (or pip install "ray[tune,client]")'
)

#: Seconds to wait for a cluster's address to accept a connection.
PROBE_SECONDS = 5.0

#: The only address a local Ray instance listens on.
LOOPBACK = "127.0.0.1"

#: Ray's token file (``ray._private.authentication``'s default path).
TOKEN_FILE = Path("~/.ray/auth_token")


def private_token_file(path: Path | None = None) -> Path | None:
    """Create Ray's token file readable by its owner only (0600), or make it so.

    Ray writes the file with the default permissions (0644 under the usual
    umask), so another user of the machine could read the token. A missing
    file is created here with a token from Ray's own generator, with 0600
    from the start; an existing one of ours is restricted to 0600.

    Args:
        path: The file; default: ``RAY_AUTH_TOKEN_PATH`` if set, else ``~/.ray/auth_token``.

    Returns:
        The token file's path, or None if ``RAY_AUTH_TOKEN`` gives the token (no file).
    """
    if path is None:
        if os.environ.get("RAY_AUTH_TOKEN"):
            return None
        path = Path(os.environ.get("RAY_AUTH_TOKEN_PATH") or TOKEN_FILE)
    token = path.expanduser()
    token.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    if not token.exists():
        from ray._private.authentication.authentication_token_generator import (
            generate_new_authentication_token,
        )

        with contextlib.suppress(FileExistsError):  # another process was first
            descriptor = os.open(token, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(descriptor, "w") as handle:
                handle.write(generate_new_authentication_token())
    if token.stat().st_uid == os.getuid() and token.stat().st_mode & 0o077:
        token.chmod(0o600)
    return token


@contextlib.contextmanager
def _loopback_only() -> Iterator[None]:
    """A private token file, and ``ray.init(_node_ip_address="127.0.0.1")`` keeping loopback.

    Raises:
        ImportError: This Ray lacks the functions used (a Ray release that moved them).
    """
    try:
        from ray._private import services
    except ImportError as error:
        raise ImportError(
            "this Ray release lacks ray._private.services, which cpf_env uses to keep a local "
            f"Ray instance on {LOOPBACK}; install a supported Ray: {_INSTALL}."
        ) from error
    private_token_file()
    resolve = services.resolve_ip_for_localhost
    services.resolve_ip_for_localhost = lambda host: host
    try:
        yield
    finally:
        services.resolve_ip_for_localhost = resolve


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
        help="Ray cluster to use: 'auto' (the cluster this machine joined with `ray start`), "
        "HOST:6379 (its head) or ray://HOST:10001 (Ray Client); default: a local Ray "
        "instance on this machine (or the cluster RAY_ADDRESS names)",
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


def _host_and_port(address: str) -> tuple[str, int] | None:
    """(host, port) of 'HOST:PORT' or 'ray://HOST:PORT'; None for 'auto' and 'local'."""
    if address in ("auto", "local"):
        return None
    location = address.removeprefix("ray://")
    host, colon, port = location.rpartition(":")
    if not colon or not host:
        raise ValueError(
            f"Ray address {address!r} has no port; use HOST:PORT (a cluster's head, e.g. "
            f"{location or 'HEAD'}:6379), ray://HOST:10001 (Ray Client) or 'auto'."
        )
    if not port.isdigit():
        raise ValueError(f"Ray address {address!r} has no valid port; use HOST:PORT or 'auto'.")
    return host.strip("[]"), int(port)


def _probe(address: str) -> None:
    """Raise ConnectionError if a HOST:PORT address does not accept a TCP connection."""
    location = _host_and_port(address)
    if location is None:
        return
    try:
        with socket.create_connection(location, timeout=PROBE_SECONDS):
            pass
    except OSError as error:
        raise ConnectionError(
            f"no Ray cluster answers at --address {address} ({error}); start one there with "
            "`ray start --head`, or fix --address (leave it out to run on this machine)."
        ) from error


def resolve_address(address: str | None) -> str:
    """The Ray address a command uses: ``address``, else ``RAY_ADDRESS``, else 'local'."""
    return address if address is not None else os.environ.get("RAY_ADDRESS") or "local"


def start_ray(address: str | None, cpus_per_task: int = 1, quiet: bool = False) -> ModuleType:
    """Start a local Ray instance (``address`` None) or join a cluster, and return ``ray``.

    Args:
        address: None for a new local instance (or the cluster ``RAY_ADDRESS``
            names), else a Ray address ('auto', 'HOST:PORT', 'ray://HOST:PORT').
        cpus_per_task: CPUs each task reserves (sets the workers' numba threads).
        quiet: Keep Ray's start-up and worker log lines off the terminal.

    Raises:
        ImportError: Ray is not installed, or Ray Client (for 'ray://') is not
            (the message says how to install it).
        ValueError: ``cpus_per_task`` is below 1, or the address is malformed.
        ConnectionError: No Ray cluster answers at the address.
    """
    if cpus_per_task < 1:
        raise ValueError(f"CPUs per task must be >= 1, got {cpus_per_task}.")
    ray = require_ray()
    address = resolve_address(address)
    _probe(address)
    options: dict[str, Any] = {
        "runtime_env": {"env_vars": worker_environment(cpus_per_task)},
        "log_to_driver": not quiet,
        "logging_level": "error" if quiet else "warning",
    }
    local = address == "local"
    if local:
        options["include_dashboard"] = False
        options["_node_ip_address"] = LOOPBACK
    with _loopback_only() if local else contextlib.nullcontext():
        _init(ray, address, options)
    return ray


def _init(ray: ModuleType, address: str, options: dict[str, Any]) -> None:
    """``ray.init`` with Ray's connection errors turned into the command's messages."""
    try:
        ray.init(address=address, **options)
    except ConnectionError as error:
        reason = str(error).strip().rstrip(".")
        raise ConnectionError(
            f"could not join a Ray cluster at --address {address} ({reason}); start one with "
            "`ray start --head`, or leave --address out to run on this machine."
        ) from error
    except ModuleNotFoundError as error:  # Ray Client's gRPC dependency
        raise ImportError(f"--address {address} needs Ray Client; {_INSTALL}.") from error
