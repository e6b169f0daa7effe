"""The one-way layering of the packages, checked on their import statements.

Each layer may import only itself and the layers listed for it below; an
upward import (the simulator importing an env, ``baselines`` importing a
learning library, one command family importing another it does not build on)
fails here. Every import counts, also one inside a function: a lazy import
still ties the layers together. The imports between the project's own
modules must also form no cycle, at any scope: a function-level (or
``TYPE_CHECKING``) import defers a cycle, it does not remove it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from conftest import ROOT

PACKAGES = ("cpf_env", "baselines", "cpf_bench", "agents", "cpf_commands")

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
    "cpf_bench": ("cpf_env", "baselines", "cpf_bench"),
    "agents": ("cpf_env", "baselines", "cpf_bench", "agents"),
    "cpf_commands.common": ("cpf_env", "baselines", "cpf_bench", "agents", "cpf_commands.common"),
    "cpf_commands.run": (
        "cpf_env",
        "baselines",
        "cpf_bench",
        "agents",
        "cpf_commands.common",
        "cpf_commands.run",
    ),
    "cpf_commands.bench": (
        "cpf_env",
        "baselines",
        "cpf_bench",
        "agents",
        "cpf_commands.common",
        "cpf_commands.bench",
    ),
    "cpf_commands.sweep": (
        "cpf_env",
        "baselines",
        "cpf_bench",
        "agents",
        "cpf_commands.common",
        "cpf_commands.bench",
        "cpf_commands.sweep",
    ),
    "cpf_commands": ("cpf_env", "baselines", "cpf_bench", "agents", "cpf_commands"),
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


def _resolve(module: str, node: ast.ImportFrom, modules: dict[str, Path]) -> str:
    """The absolute module a ``from`` import names."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    is_package = modules[module].name == "__init__.py"
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _imports(
    module: str, source: str | None = None, modules: dict[str, Path] = MODULES
) -> list[tuple[str, int, bool]]:
    """(imported module, line, at module scope) for every import in ``module``.

    ``modules`` (default: the project's) resolves relative imports and submodules.
    """
    text = modules[module].read_text() if source is None else source
    tree = ast.parse(text, filename=str(modules[module]))
    top_level = {id(node) for node in tree.body}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.append((alias.name, node.lineno, id(node) in top_level))
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(module, node, modules)
            for alias in node.names:
                submodule = f"{target}.{alias.name}"
                name = submodule if submodule in modules else target
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


def _graph(modules: dict[str, Path], sources: dict[str, str] | None = None) -> dict[str, set[str]]:
    """Module -> the project's modules it imports, at any scope (functions, TYPE_CHECKING too).

    A package's ``__init__`` importing its own submodules is how packages work and
    counts as an edge like any other; a cycle through it is a cycle.
    """
    sources = sources or {}
    return {
        module: {name for name, _, _ in _imports(module, sources.get(module), modules)}
        & set(modules) - {module}
        for module in modules
    }


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for name in sorted(graph.get(module, ())):
            if name not in index:
                visit(name)
                low[module] = min(low[module], low[name])
            elif name in on_stack:
                low[module] = min(low[module], index[name])
        if low[module] == index[module]:
            group = []
            while True:
                name = stack.pop()
                on_stack.discard(name)
                group.append(name)
                if name == module:
                    break
            if len(group) > 1:
                cycles.append(sorted(group))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return cycles


def _own_package_imports(graph: dict[str, set[str]], modules: dict[str, Path]) -> list[str]:
    """Submodules that import their own package's ``__init__`` (run before them on import)."""
    return [
        f"{module} imports its own package {name}"
        for module, names in sorted(graph.items())
        for name in sorted(names)
        if modules[name].name == "__init__.py" and module.startswith(name + ".")
    ]


def test_no_import_cycle_at_any_scope() -> None:
    graph = _graph(MODULES)
    assert import_cycles(graph) == []
    assert _own_package_imports(graph, MODULES) == []


@pytest.mark.parametrize(
    "sources",
    [
        {"pkg.a": "from pkg.b import x\n", "pkg.b": "from pkg.a import y\n"},
        {
            "pkg.a": "def f():\n    from pkg.b import x\n",
            "pkg.b": "import pkg.c\n",
            "pkg.c": "class C:\n    def g(self):\n        from . import a\n",
        },
        {
            "pkg.a": "import typing\nif typing.TYPE_CHECKING:\n    from pkg.b import B\n",
            "pkg.b": "def f():\n    import pkg.a\n",
        },
    ],
)
def test_the_checker_sees_an_import_cycle_at_any_scope(sources: dict[str, str]) -> None:
    modules = {name: Path(*name.split(".")).with_suffix(".py") for name in sources}
    cycles = import_cycles(_graph(modules, sources))
    assert len(cycles) == 1 and len(cycles[0]) >= 2
    acyclic = dict(sources, **{name: "" for name in list(sources)[-1:]})
    assert import_cycles(_graph(modules, acyclic)) == []


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
