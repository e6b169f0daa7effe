"""One policy resolver for every command: a baseline name, a trained agent, or an object.

Every command that runs a policy (``cpf-run``, ``cpf-bench``) goes through
``resolve_policy``, so an analytic controller and a trained agent are built,
labelled and evaluated the same way. A policy specification is one of:

* a name of ``baselines.POLICIES`` (``"nn_dsc"``, ``"dsc"``, ...);
* a path to a ``cpf-train --out`` folder, loaded by ``agents.load_policy``
  (imported only then, so the analytic side never needs the learning stack);
  the folder holds data only; an old SB3 folder (pickles) is refused unless
  wrapped in ``TrustedAgentFolder`` (the commands' ``--trust-pickle``);
* a path to a ``.onnx`` file written by ``cpf-export``, run by onnxruntime
  (``agents.onnx_policy``; the ``onnx`` extra);
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
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from cpf_env.envs.policy import FleetPolicy
from cpf_env.scenarios import Scenario, make_scenario

__all__ = [
    "FleetPolicy",
    "PolicySpec",
    "TrustedAgentFolder",
    "baseline_names",
    "policy_argument",
    "policy_label",
    "resolve_policy",
    "trusting_pickles",
]


PolicySpec = str | Path | FleetPolicy | Callable[[Scenario], FleetPolicy]


class TrustedAgentFolder(str):
    """An agent folder whose pickles the user vouches for (``--trust-pickle``).

    A string (the folder's absolute path, so that Ray workers find it and the
    commands treat it as any folder argument) that ``resolve_policy`` loads
    with ``load_policy(..., trust_pickle=True)``: an old SB3 folder is then
    unpickled (with a warning), which runs any code its author put in it. A
    data-only folder loads as without the flag.

    Args:
        path: The folder.
        label: Its name in tables (default: ``path`` as given).
    """

    label: str

    def __new__(cls, path: str | Path, label: str | None = None) -> TrustedAgentFolder:  # noqa: D102
        folder = super().__new__(cls, str(Path(path).resolve()))
        folder.label = label if label is not None else policy_label(str(path))
        return folder


def baseline_names() -> list[str]:
    """The analytic policies by name: the deployable ones, then the privileged references."""
    from baselines import POLICIES, PRIVILEGED

    return [*POLICIES, *PRIVILEGED]


def trusting_pickles(specs: Sequence[str]) -> list[str]:
    """A command's policy arguments with every agent folder wrapped in ``TrustedAgentFolder``."""
    names = baseline_names()
    return [
        spec if spec in names or not Path(spec).is_dir() else TrustedAgentFolder(spec)
        for spec in specs
    ]


def _is_onnx(spec: str | Path) -> bool:
    """Whether ``spec`` names an existing ``.onnx`` file."""
    return str(spec).endswith(".onnx") and Path(spec).is_file()


def policy_label(spec: PolicySpec) -> str:
    """The name a policy goes by in tables and file names.

    A baseline's name, a trained agent's path as given (without a trailing
    slash), or an object's ``name`` attribute (else its class name).
    """
    if isinstance(spec, TrustedAgentFolder):
        return spec.label
    if isinstance(spec, Path):
        return str(spec)
    if isinstance(spec, str):
        return spec.rstrip("/") or spec
    return str(getattr(spec, "name", getattr(spec, "__name__", type(spec).__name__)))


def _check_name(spec: str | Path) -> None:
    """Raise ValueError unless ``spec`` is a baseline name or an existing folder."""
    names = baseline_names()
    if str(spec) not in names and not Path(spec).is_dir() and not _is_onnx(spec):
        raise ValueError(
            f"policy {str(spec)!r} is neither a baseline ({', '.join(sorted(names))}), "
            "an existing cpf-train --out folder nor a cpf-export .onnx file."
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
    from baselines import make_policy

    resolved = make_scenario(scenario)
    if isinstance(spec, str) and spec in baseline_names():
        return make_policy(spec, resolved, **options)
    if options:
        raise ValueError(
            f"options {sorted(options)} apply to baselines only, not to {policy_label(spec)!r}."
        )
    if isinstance(spec, str | Path):
        _check_name(spec)
        if _is_onnx(spec):
            try:
                from agents.onnx_policy import load_onnx_policy
            except ImportError as error:
                raise ValueError(
                    f"{str(spec)!r} is an ONNX policy, which needs onnxruntime and the learning "
                    "extra: pip install 'cpf_env[rl,onnx]'."
                ) from error
            return load_onnx_policy(spec, resolved)
        try:
            from agents import load_policy
        except ImportError as error:
            raise ValueError(
                f"{str(spec)!r} is a folder, but loading trained agents needs "
                "agents.load_policy (the learning extra: pip install 'cpf_env[rl]')."
            ) from error
        return load_policy(Path(spec), resolved, trust_pickle=isinstance(spec, TrustedAgentFolder))
    if isinstance(spec, FleetPolicy):
        return spec
    if callable(spec):
        return spec(resolved)
    raise ValueError(
        f"cannot use {type(spec).__name__} as a policy: give a baseline name, a cpf-train "
        "--out folder, an object with act_batch/reset/diagnostics, or a callable "
        "scenario -> policy."
    )
