"""The message of a command whose optional extra is not installed.

``cpf-train``, ``cpf-distill`` and ``cpf-marl`` import PyTorch (the first two
also Stable-Baselines3) when their modules load. On the base install (``pip
install -e .``) that import fails before an argument is parsed; each of these
modules turns the failure into this message, naming what is missing and the
install that brings it, instead of a traceback.
"""

from __future__ import annotations

__all__ = ["missing_extra"]


def missing_extra(command: str, error: ModuleNotFoundError, extra: str = "rl") -> str:
    """What ``command`` prints when ``error`` says a package of ``extra`` is missing."""
    return (
        f"{command}: needs {error.name or 'a package'}, which is not installed; install the "
        f"'{extra}' extra: pip install -e '.[{extra}]' in the cpf_env checkout."
    )
