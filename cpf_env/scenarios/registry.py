"""The scenario registry: names to factories.

Every catalog module (``paper``, ``fine``, ``suite``) registers its factories
on import; importing ``cpf_env.scenarios`` imports them all.

    >>> from cpf_env.scenarios import registry
    >>> "wang2014" in registry.list_scenarios()
    True
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from cpf_env.scenarios.scenario import Scenario

__all__ = ["get", "list_scenarios", "make_scenario", "register"]

_REGISTRY: dict[str, Callable[[], Scenario]] = {}


def register(name: str, factory: Callable[[], Scenario]) -> None:
    """Register a scenario factory under ``name`` (overwriting is an error)."""
    if name in _REGISTRY:
        raise ValueError(f"a scenario named {name!r} is already registered.")
    _REGISTRY[name] = factory


def get(name: str) -> Scenario:
    """Build the named scenario; see ``list_scenarios()`` for names."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown scenario {name!r}; choose one of {list_scenarios()}.")
    return _REGISTRY[name]()


def list_scenarios() -> list[str]:
    """Names of the registered scenarios, in registration order."""
    return list(_REGISTRY)


def make_scenario(scenario: str | Scenario = "wang2014", **overrides: Any) -> Scenario:
    """Resolve a scenario name or object and apply field overrides (``Scenario.replace``).

    The one place every route resolves its ``scenario`` argument.

    Raises:
        TypeError: ``scenario`` is neither a name nor a ``Scenario``.
        ValueError: An unknown name or override (the message lists the valid ones).
    """
    if isinstance(scenario, str):
        scenario = get(scenario)
    elif not isinstance(scenario, Scenario):
        raise TypeError(
            f"scenario must be a name from {list_scenarios()} or a Scenario, "
            f"got {type(scenario).__name__}."
        )
    return scenario.replace(**overrides) if overrides else scenario
