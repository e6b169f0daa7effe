"""One policy resolver for every command: a baseline name, a trained agent, or an object.

Every command that runs a policy (``cpf-run``, ``cpf-bench``) goes through
``resolve_policy``, so an analytic controller and a trained agent are built,
labelled and evaluated the same way. A policy specification is one of:

* a name of ``baselines.POLICIES`` (``"nn_dsc"``, ``"dsc"``, ...);
* a path to a ``cpf-train --out`` folder, loaded by ``agents.load_policy``
  (imported only then, so the analytic side never needs the learning stack);
* a ready policy object (``cpf_env.envs.policy.FleetPolicy``: ``act_batch``,
  ``reset``, ``diagnostics``) for programmatic use;
* a callable ``scenario -> policy object``, for a policy that must be built
  per scenario (the bench runs several).

Example:
    >>> policy = resolve_policy("nn_dsc", "wang2014")
    >>> policy.name, policy_label("runs/residual/")
    ('nn_dsc', 'runs/residual')
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cpf_env.envs.parallel import make_scenario
from cpf_env.envs.policy import FleetPolicy
from cpf_env.scenarios import Scenario

__all__ = [
    "BenchPolicy",
    "FleetPolicy",
    "PolicySpec",
    "policy_argument",
    "policy_label",
    "resolve_policy",
]


#: The policy contract (``cpf_env.envs.policy.FleetPolicy``) under the name the commands used
#: before it was defined once; kept for existing callers.
BenchPolicy = FleetPolicy

PolicySpec = str | Path | FleetPolicy | Callable[[Scenario], FleetPolicy]


def policy_label(spec: PolicySpec) -> str:
    """The name a policy goes by in tables and file names.

    A baseline's name, a trained agent's path as given (without a trailing
    slash), or an object's ``name`` attribute (else its class name).
    """
    if isinstance(spec, Path):
        return str(spec)
    if isinstance(spec, str):
        return spec.rstrip("/") or spec
    return str(getattr(spec, "name", getattr(spec, "__name__", type(spec).__name__)))


def _check_name(spec: str | Path) -> None:
    """Raise ValueError unless ``spec`` is a baseline name or an existing folder."""
    from baselines import POLICIES

    if str(spec) not in POLICIES and not Path(spec).is_dir():
        raise ValueError(
            f"policy {str(spec)!r} is neither a baseline ({', '.join(sorted(POLICIES))}) "
            "nor an existing cpf-train --out folder."
        )


def policy_argument(text: str) -> str:
    """``argparse`` type of a policy argument: a baseline name or an existing folder.

    Raises:
        argparse.ArgumentTypeError: Neither (argparse reports the message).
    """
    try:
        _check_name(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from error
    return text


def resolve_policy(spec: PolicySpec, scenario: str | Scenario, **options: Any) -> FleetPolicy:
    """Build the policy ``spec`` for ``scenario``.

    Args:
        spec: One of the specifications listed in this module's docstring.
        scenario: The evaluation scenario (name or object).
        **options: Gains for a baseline (e.g. ``K2=(30, 30, 5)``); only baselines take them.

    Returns:
        A ``FleetPolicy``.

    Raises:
        ValueError: A name that is neither a baseline nor an existing folder,
            options for a non-baseline, or a trained agent without ``agents.load_policy``.
    """
    from baselines import POLICIES, make_policy

    resolved = make_scenario(scenario)
    if isinstance(spec, str) and spec in POLICIES:
        return make_policy(spec, resolved, **options)
    if options:
        raise ValueError(
            f"options {sorted(options)} apply to baselines only, not to {policy_label(spec)!r}."
        )
    if isinstance(spec, str | Path):
        _check_name(spec)
        try:
            from agents import load_policy
        except ImportError as error:
            raise ValueError(
                f"{str(spec)!r} is a folder, but loading trained agents needs "
                "agents.load_policy (the learning extra: pip install 'cpf_env[rl]')."
            ) from error
        return load_policy(Path(spec), resolved)
    if isinstance(spec, FleetPolicy):
        return spec
    if callable(spec):
        return spec(resolved)
    raise ValueError(
        f"cannot use {type(spec).__name__} as a policy: give a baseline name, a cpf-train "
        "--out folder, an object with act_batch/reset/diagnostics, or a callable "
        "scenario -> policy."
    )
