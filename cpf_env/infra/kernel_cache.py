"""numba's on-disk cache of the simulator kernels, keyed on every source they compile from.

numba stamps each cached function with the modification time and size of
the file that defines it, and with nothing else. The fused step kernel of
``cpf_env.sim.kernels`` inlines helpers of ``cpf_env.sim.reward``,
``cpf_env.model.plant``, ``cpf_env.model.vessel`` and others, and freezes
module constants of ``cpf_env.sim.arrays`` and
``cpf_env.scenarios.reward_weights``: with numba's stamp, an edit to one of
those files would leave the cached kernel running the old code.

This module replaces the stamp of every cached function of ``cpf_env`` with
a SHA-256 digest of all of ``KERNEL_SOURCES``. Any edit to any of them makes
every cached kernel of the package stale, so the next process compiles
again (and overwrites the stale entries in place) instead of loading old
machine code. Where the cache lives is numba's decision, unchanged:
``NUMBA_CACHE_DIR`` when set, else ``__pycache__`` next to the sources
(numba's per-user directory when that is not writable).

It must run before any kernel module is imported (numba chooses a
function's cache locator when it decorates it), so ``cpf_env/__init__.py``
imports it first; importing any kernel module imports ``cpf_env`` first, so
the key is always in place. It lives in ``cpf_env.infra``, which every layer
may import and which imports nothing of the package. Functions of other packages
keep numba's own stamp, unless their package asks for this key with
``stamp_package`` (the compiled analytic policies of ``baselines`` inline
``cpf_env.model.vessel`` and read ``cpf_env.sim.observation``'s layout): then
their stamp is the digest of ``KERNEL_SOURCES`` and of the sources they name.
A locator list forced through numba's ``NUMBA_CACHE_LOCATOR_CLASSES`` setting
bypasses this key.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import Any

from numba.core import caching
from numba.core.caching import _CacheLocator

__all__ = [
    "KERNEL_MODULES",
    "KERNEL_SOURCES",
    "install",
    "kernel_sources_digest",
    "stamp_package",
]

#: The modules of ``cpf_env`` that define numba kernels (a test keeps this list complete).
KERNEL_MODULES = (
    "model.counter_rng",
    "model.disturbances",
    "model.paths",
    "model.plant",
    "model.vessel",
    "sim.kernels",
    "sim.observation",
    "evaluation.privileged",
    "evaluation.recording",
    "sim.reward",
)

#: Every module a kernel compiles from: the kernel modules and the modules
#: whose constants they read (a test checks that this list is closed under
#: the kernel modules' imports of ``cpf_env``).
KERNEL_SOURCES = (*KERNEL_MODULES, "scenarios.reward_weights", "sim.arrays")

_PACKAGE_DIRECTORY = Path(__file__).resolve().parent.parent  # cpf_env/
#: numba's cache machinery, whose locator list this module extends (``_CacheImpl`` before
#: numba renamed it ``CacheImpl``).
_CACHE_IMPL: Any = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl")  # noqa: B009


def kernel_sources_digest(package_directory: Path = _PACKAGE_DIRECTORY) -> str:
    """SHA-256 (hex) of the bytes of every module in ``KERNEL_SOURCES``, in that order.

    Args:
        package_directory: The ``cpf_env`` folder whose sources are hashed.
    """
    digest = hashlib.sha256()
    for name in KERNEL_SOURCES:
        path = package_directory.joinpath(*name.split(".")).with_suffix(".py")
        digest.update(name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


#: Package folders whose cached kernels carry the digest: folder -> its own extra sources.
_STAMPED: dict[Path, tuple[Path, ...]] = {_PACKAGE_DIRECTORY: ()}


def stamp_package(directory: Path, sources: tuple[Path, ...]) -> None:
    """Key the cached kernels defined under ``directory`` on ``KERNEL_SOURCES`` and ``sources``.

    Call it before the package's kernels are decorated (at the top of the
    module that defines them).

    Args:
        directory: The package folder whose kernels get the key.
        sources: Its own files the kernels compile from.
    """
    _STAMPED[directory.resolve()] = tuple(path.resolve() for path in sources)


def _stamp_of(py_file: str) -> str | None:
    """The stamp of a function defined in ``py_file``; None outside every stamped package."""
    try:
        path = Path(py_file).resolve()
    except OSError:
        return None
    for directory, sources in _STAMPED.items():
        if path.is_relative_to(directory):
            return _package_stamp(_digest(), sources) if sources else _digest()
    return None


@functools.cache
def _package_stamp(kernel_digest: str, sources: tuple[Path, ...]) -> str:
    """SHA-256 of the kernel sources' digest and a package's own sources (read once)."""
    digest = hashlib.sha256(kernel_digest.encode())
    for source in sources:
        digest.update(source.read_bytes())
    return digest.hexdigest()


class _KernelSourcesLocator(_CacheLocator):
    """numba's own locator of a ``cpf_env`` function, stamped with the kernel sources' digest."""

    def __init__(self, inner: _CacheLocator, stamp: str) -> None:
        self._inner = inner
        self._stamp = stamp

    def ensure_cache_path(self) -> None:
        self._inner.ensure_cache_path()

    def get_cache_path(self) -> str:
        return str(self._inner.get_cache_path())

    def get_source_stamp(self) -> Any:
        return ("cpf_env kernel sources", self._stamp)

    def get_disambiguator(self) -> str:
        return str(self._inner.get_disambiguator())

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> _KernelSourcesLocator | None:
        """Wrap the locator numba would pick, for functions of the stamped packages only."""
        stamp = _stamp_of(py_file)
        if stamp is None:
            return None
        for locator_class in _CACHE_IMPL._locator_classes:
            if locator_class is cls:
                continue
            inner = locator_class.from_function(py_func, py_file)
            if inner is not None:
                return cls(inner, stamp)
        return None


@functools.cache
def _digest() -> str:
    """The digest of this installation's kernel sources, computed once per process."""
    return kernel_sources_digest()


def install() -> None:
    """Put the kernel-sources locator first in numba's list (idempotent)."""
    if _KernelSourcesLocator not in _CACHE_IMPL._locator_classes:
        _CACHE_IMPL._locator_classes.insert(0, _KernelSourcesLocator)


install()
