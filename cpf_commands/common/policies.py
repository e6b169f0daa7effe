"""One policy resolver for every command: a baseline name, a trained agent, or an object.

Every command that runs a policy (``cpf-run``, ``cpf-bench``) goes through
``resolve_policy``, so an analytic controller and a trained agent are built,
labelled and evaluated the same way. A policy specification is one of:

* a name of ``baselines.POLICIES`` (``"nn_dsc"``, ``"dsc"``, ...);
* a path to a ``cpf-train --out`` folder, loaded by ``agents.load_policy``
  (imported only then, so the analytic side never needs the learning stack);
  the folder holds data only (a plain SB3 save, a pickle, is refused);
* a path to a ``.onnx`` file written by ``cpf-export``, run by onnxruntime
  (``agents.folder.onnx_policy``; the ``onnx`` extra);
* ``package.module:NAME``, a policy class or factory of the user's own
  (``user_policy``), imported only when named;
* a name registered by an installed package under the entry-point group
  ``cpf_env.policies`` (``registered_policies``; its code is imported only
  when the name is used);
* a ready policy object (``cpf_env.envs.policy.FleetPolicy``: ``act_batch``,
  ``reset``, ``diagnostics``) for programmatic use;
* a callable ``scenario -> policy object``, for a policy that must be built
  per scenario (the bench runs several).

A user's class or factory is called like ``baselines.make_policy`` without
the name: ``NAME(scenario, **options)``, and must return an object with the
policy contract (``act_batch``, ``reset``, ``diagnostics``; docs/extending.md).

Example:
    >>> policy = resolve_policy("nn_dsc", "wang2014")
    >>> policy.name, policy_label("runs/residual/")
    ('nn_dsc', 'runs/residual')
"""

from __future__ import annotations

import argparse
import importlib
import re
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

from cpf_bench.evaluate import policy_label
from cpf_env.envs.policy import FleetPolicy
from cpf_env.scenarios import Scenario, make_scenario

__all__ = [
    "ENTRY_POINT_GROUP",
    "FleetPolicy",
    "PolicySpec",
    "baseline_names",
    "policy_argument",
    "policy_label",
    "refers_to_file",
    "registered_policies",
    "resolve_policy",
    "user_policy",
]


PolicySpec = str | Path | FleetPolicy | Callable[[Scenario], FleetPolicy]

#: The entry-point group in which installed packages register policies: name -> "module:NAME".
ENTRY_POINT_GROUP = "cpf_env.policies"
#: A user's policy: ``package.module:NAME``.
_MODULE_SPEC = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*")


def baseline_names() -> list[str]:
    """The analytic policies by name: the deployable ones, then the privileged references."""
    from baselines import ALL_POLICIES

    return list(ALL_POLICIES)


def registered_policies() -> dict[str, metadata.EntryPoint]:
    """Policies installed packages register (group ``ENTRY_POINT_GROUP``), by name, not loaded.

    A package registers one in its ``pyproject.toml``::

        [project.entry-points."cpf_env.policies"]
        my_controller = "my_package.controllers:MyController"
    """
    return {point.name: point for point in metadata.entry_points(group=ENTRY_POINT_GROUP)}


def _is_module_spec(spec: object) -> bool:
    """Whether ``spec`` is a ``package.module:NAME`` string (and no existing file)."""
    return (
        isinstance(spec, str)
        and _MODULE_SPEC.fullmatch(spec) is not None
        and not Path(spec).exists()
    )


def refers_to_file(spec: PolicySpec) -> bool:
    """Whether ``spec`` names a folder or file (an agent), not a policy by name or code."""
    if isinstance(spec, Path):
        return True
    if not isinstance(spec, str):
        return False
    return not (spec in baseline_names() or _is_module_spec(spec) or spec in registered_policies())


def user_policy(spec: str) -> Callable[..., Any]:
    """The class or factory a ``package.module:NAME`` spec or a registered name stands for.

    Imports the named module (or loads the entry point) and nothing else.

    Raises:
        ValueError: The module cannot be imported, has no such name, or the
            name is not callable.
    """
    points = registered_policies()
    if spec in points and not _is_module_spec(spec):
        try:
            target = points[spec].load()
        except Exception as error:  # the package's own code failed: say whose and why
            raise ValueError(
                f"policy {spec!r} is registered by an installed package as "
                f"{points[spec].value!r}, which cannot be loaded: "
                f"{type(error).__name__}: {error}"
            ) from error
    else:
        module_name, _, name = spec.partition(":")
        try:
            module = importlib.import_module(module_name)
        except ImportError as error:
            raise ValueError(
                f"policy {spec!r}: cannot import module {module_name!r} ({error}); install "
                "its package or put its folder on PYTHONPATH."
            ) from error
        except Exception as error:  # the user's module failed while importing
            raise ValueError(
                f"policy {spec!r}: importing module {module_name!r} failed: "
                f"{type(error).__name__}: {error}"
            ) from error
        if not hasattr(module, name):
            raise ValueError(f"policy {spec!r}: module {module_name!r} has no {name!r}.")
        target = getattr(module, name)
    if not callable(target):
        raise ValueError(
            f"policy {spec!r} is a {type(target).__name__}, not a policy class or a factory "
            "called like baselines.make_policy without the name: NAME(scenario, **options)."
        )
    return target


def _build_user_policy(spec: str, scenario: Scenario, options: dict[str, Any]) -> FleetPolicy:
    """A user's policy built for ``scenario``, checked against the policy contract."""
    policy = user_policy(spec)(scenario, **options)
    if not isinstance(policy, FleetPolicy):
        raise ValueError(
            f"policy {spec!r} built a {type(policy).__name__}, which lacks the policy "
            "contract (act_batch, reset, diagnostics; see docs/extending.md)."
        )
    return policy


def _is_onnx(spec: str | Path) -> bool:
    """Whether ``spec`` names an existing ``.onnx`` file."""
    return str(spec).endswith(".onnx") and Path(spec).is_file()


def _check_name(spec: str | Path) -> None:
    """Raise ValueError unless ``spec`` names a policy, an existing folder or an .onnx file."""
    if not refers_to_file(spec) or Path(spec).is_dir() or _is_onnx(spec):
        return
    installed = sorted(registered_policies())
    names = ", ".join([*sorted(baseline_names()), *installed])
    raise ValueError(
        f"policy {str(spec)!r} is neither a baseline nor an installed policy ({names}), "
        "nor a package.module:NAME of your own, an existing cpf-train --out folder or a "
        "cpf-export .onnx file."
    )


def policy_argument(text: str) -> str:
    """``argparse`` type of a policy argument: a policy's name or spec, or an existing folder.

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
        **options: Gains for a baseline (e.g. ``K2=(30, 30, 5)``), or keyword arguments of a
            user's policy class or factory; no other policy takes them.

    Returns:
        A ``FleetPolicy``.

    Raises:
        ValueError: A name that is neither a policy nor an existing folder, a user's
            policy that cannot be imported or breaks the contract, options for a
            trained agent or object, or a trained agent without ``agents.load_policy``.
    """
    from baselines import make_policy

    resolved = make_scenario(scenario)
    if isinstance(spec, str) and spec in baseline_names():
        return make_policy(spec, resolved, **options)
    if isinstance(spec, str) and not refers_to_file(spec):
        return _build_user_policy(spec, resolved, options)
    if options:
        raise ValueError(
            f"options {sorted(options)} apply to baselines only (and to your own policy "
            f"classes or factories), not to {policy_label(spec)!r}."
        )
    if isinstance(spec, str | Path):
        _check_name(spec)
        if _is_onnx(spec):
            try:
                from agents.folder.onnx_policy import load_onnx_policy
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
                "agents.load_policy (the learning extra: pip install -e '.[rl]')."
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
