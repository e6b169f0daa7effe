"""Every console script also runs as ``python -m <module>`` with the same function."""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import pytest
import tomllib

PYPROJECT = Path(__file__).resolve().parents[2] / "pyproject.toml"
SCRIPTS = tomllib.loads(PYPROJECT.read_text())["project"]["scripts"]


def _main_block_calls(source: str) -> set[str]:
    """Names of the functions called inside the module's ``if __name__ == "__main__":`` block."""
    called: set[str] = set()
    for node in ast.parse(source).body:
        test = getattr(node, "test", None)
        if (
            isinstance(node, ast.If)
            and isinstance(test, ast.Compare)
            and isinstance(test.left, ast.Name)
            and test.left.id == "__name__"
        ):
            for inner in ast.walk(node):
                if isinstance(inner, ast.Call) and isinstance(inner.func, ast.Name):
                    called.add(inner.func.id)
    return called


@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_console_script_runs_as_module(script: str) -> None:
    module_name, function = SCRIPTS[script].split(":")
    module = importlib.import_module(module_name)
    assert callable(getattr(module, function))
    assert function in _main_block_calls(inspect.getsource(module)), (
        f"{script}: `python -m {module_name}` would not run {function}"
    )
