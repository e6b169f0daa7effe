"""The one-way layering of the packages, checked on their import statements.

Each layer may import only itself and the layers listed for it below; an
upward import (the simulator importing an env, ``baselines`` importing a
learning library, one command family importing another it does not build on)
fails here. Every import counts, also one inside a function: a lazy import
still ties the layers together. Module-scope imports between the project's
own modules must also form no cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from conftest import ROOT

PACKAGES = ("cpf_env", "baselines", "agents", "cpf_commands")

#: Layer of a module: the longest prefix listed here wins.
#: Value: the prefixes (of the project's modules) that layer may import.
ALLOWED: dict[str, tuple[str, ...]] = {
    "cpf_env.infra": ("cpf_env.infra",),
    "cpf_env.model": ("cpf_env.infra", "cpf_env.model"),
    "cpf_env.scenarios": ("cpf_env.infra", "cpf_env.model", "cpf_env.scenarios"),
    "cpf_env.sim": ("cpf_env.infra", "cpf_env.model", "cpf_env.scenarios", "cpf_env.sim"),
    "cpf_env.evaluation": (
        "cpf_env.infra",
        "cpf_env.model",
        "cpf_env.scenarios",
        "cpf_env.sim",
        "cpf_env.evaluation",
    ),
    "cpf_env.envs": (
        "cpf_env.infra",
        "cpf_env.model",
        "cpf_env.scenarios",
        "cpf_env.sim",
        "cpf_env.envs",
    ),
    "cpf_env": ("cpf_env",),
    "baselines": ("cpf_env", "baselines"),
    "agents": ("cpf_env", "baselines", "agents"),
    "cpf_commands.common": ("cpf_env", "baselines", "agents", "cpf_commands.common"),
    "cpf_commands.run": (
        "cpf_env",
        "baselines",
        "agents",
        "cpf_commands.common",
        "cpf_commands.run",
    ),
    "cpf_commands.bench": (
        "cpf_env",
        "baselines",
        "agents",
        "cpf_commands.common",
        "cpf_commands.bench",
    ),
    "cpf_commands.sweep": (
        "cpf_env",
        "baselines",
        "agents",
        "cpf_commands.common",
        "cpf_commands.bench",
        "cpf_commands.sweep",
    ),
    "cpf_commands": ("cpf_env", "baselines", "agents", "cpf_commands"),
}

#: Third-party learning libraries each layer must not import (``cpf_env`` and
#: ``baselines`` hold no learning code; the TorchRL env is the one optional view).
NO_LEARNING = ("torch", "stable_baselines3", "torchrl", "tensordict", "ray", "gymnasium.wrappers")
LEARNING_ALLOWED_IN = ("cpf_env.envs.torchrl_env", "cpf_env.envs.torchrl_specs")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            found[_module_name(path)] = path
    return found


MODULES = _modules()


def _layer(module: str) -> str:
    matches = [p for p in ALLOWED if module == p or module.startswith(p + ".")]
    return max(matches, key=len)


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """The absolute module a ``from`` import names."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    is_package = MODULES[module].name == "__init__.py"
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _imports(module: str, source: str | None = None) -> list[tuple[str, int, bool]]:
    """(imported module, line, at module scope) for every import in ``module``."""
    text = MODULES[module].read_text() if source is None else source
    tree = ast.parse(text, filename=str(MODULES[module]))
    top_level = {id(node) for node in tree.body}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.append((alias.name, node.lineno, id(node) in top_level))
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(module, node)
            for alias in node.names:
                submodule = f"{target}.{alias.name}"
                name = submodule if submodule in MODULES else target
                found.append((name, node.lineno, id(node) in top_level))
    return found


def _own(name: str) -> bool:
    return name.split(".")[0] in PACKAGES


def _violations(module: str, source: str | None = None) -> list[str]:
    """What breaks the layering in ``module`` (its file, or ``source`` in its place)."""
    layer = _layer(module)
    allowed = ALLOWED[layer]
    where = MODULES[module].relative_to(ROOT)
    found = []
    for name, line, _ in _imports(module, source):
        if _own(name):
            if not any(name == p or name.startswith(p + ".") for p in allowed):
                found.append(f"{where}:{line} imports {name}; layer {layer} may import {allowed}")
        elif module.startswith(("cpf_env", "baselines")) and module not in LEARNING_ALLOWED_IN:
            if any(name == p or name.startswith(p + ".") for p in NO_LEARNING):
                found.append(f"{where}:{line} imports the learning library {name}")
    return found


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_only_the_layers_below(module: str) -> None:
    assert _violations(module) == []


def test_no_import_cycle_at_module_scope() -> None:
    graph = {
        module: sorted(
            {name for name, _, top in _imports(module) if top and name in MODULES} - {module}
        )
        for module in MODULES
    }
    done: set[str] = set()

    def visit(module: str, stack: list[str]) -> None:
        if module in stack:
            cycle = [*stack[stack.index(module) :], module]
            raise AssertionError("import cycle: " + " -> ".join(cycle))
        if module in done:
            return
        for name in graph[module]:
            # A package's __init__ importing its own submodules is how packages work;
            # a submodule importing its package's __init__ back is the cycle to catch.
            if MODULES[module].name == "__init__.py" and name.startswith(module + "."):
                visit(name, [*stack, module])
            elif not (MODULES[name].name == "__init__.py" and module.startswith(name + ".")):
                visit(name, [*stack, module])
            else:
                raise AssertionError(f"{module} imports its own package {name} at module scope")
        done.add(module)

    for module in MODULES:
        visit(module, [])


@pytest.mark.parametrize(
    ("module", "source"),
    [
        ("cpf_env.sim.fleet", "from cpf_env.envs.parallel import CooperativePathFollowingEnv\n"),
        ("cpf_env.model.vessel", "def f():\n    from cpf_env.scenarios import Scenario\n"),
        ("cpf_env.envs.residual", "from baselines import make_policy\n"),
        ("baselines.nn_dsc", "import torch\n"),
        ("baselines.nn_dsc", "from agents import load_policy\n"),
        ("cpf_commands.bench.cli", "from cpf_commands.sweep import spec\n"),
        ("cpf_commands.common.policies", "from ..run import cli\n"),
    ],
)
def test_the_checker_sees_an_upward_import(module: str, source: str) -> None:
    assert len(_violations(module, source)) == 1
