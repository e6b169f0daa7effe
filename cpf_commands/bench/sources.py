"""The code a cached bench cell's numbers come from, and a digest of it that ignores prose.

``cpf_commands.bench.cache`` keys a receding-horizon policy's cells on the
code that computes them. That code is found statically: the modules named
(the policy's own and the episode runner's), then every module of this
repository's packages (``PACKAGES``) that they import, transitively,
including imports inside functions. A package's ``__init__`` counts only
where a statement imports from the package itself.

The digest reads each module's code without its docstrings and comments
(``code_text``), so an edit to prose leaves every key as it was, while an
edit to any statement, constant or signature re-keys the cells that import
it. The text is cut from the source at the positions ``ast`` and
``tokenize`` report, not rebuilt from a syntax tree, so the digest does
not change with the Python version.
"""

from __future__ import annotations

import ast
import hashlib
import io
import tokenize
from collections.abc import Iterable
from pathlib import Path

__all__ = ["PACKAGES", "ROOT", "code_digest", "code_text", "module_closure"]

#: The repository's packages whose modules a cell's code can import.
PACKAGES = ("cpf_env", "baselines", "cpf_commands")
#: The folder that holds the packages.
ROOT = Path(__file__).resolve().parents[2]

_Span = tuple[tuple[int, int], tuple[int, int]]  # (line, column) start and end; lines from 1


def _module_file(name: str, root: Path) -> Path | None:
    """The file of a dotted module name of ``PACKAGES``, None for any other or a missing one."""
    if name.split(".")[0] not in PACKAGES:
        return None
    base = root.joinpath(*name.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _imported(tree: ast.Module, package: str, root: Path) -> set[str]:
    """The module names the import statements anywhere in ``tree`` load from ``PACKAGES``.

    ``from p import x`` counts as ``p.x`` where that is a module, else as
    ``p`` (``x`` is a name ``p`` defines); ``package`` resolves relative imports.
    """
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            parts = package.split(".")
            prefix = ".".join(parts[: len(parts) - node.level + 1]) if node.level else ""
            base = ".".join(part for part in (prefix, node.module or "") if part)
            for alias in node.names:
                submodule = f"{base}.{alias.name}"
                names.add(submodule if _module_file(submodule, root) is not None else base)
    return {name for name in names if _module_file(name, root) is not None}


def module_closure(modules: Iterable[str], root: Path = ROOT) -> dict[str, Path]:
    """Module name -> file of ``modules`` and of all they import from ``PACKAGES``.

    Args:
        modules: Dotted names to start from, e.g. ``"baselines.mpc"``.
        root: The folder holding the packages.

    Raises:
        ValueError: A name of ``modules`` is not a module of ``PACKAGES`` under ``root``.
    """
    found: dict[str, Path] = {}
    pending = list(modules)
    for name in pending:
        if _module_file(name, root) is None:
            raise ValueError(f"{name!r} is not a module of {', '.join(PACKAGES)} under {root}.")
    while pending:
        name = pending.pop()
        path = _module_file(name, root)
        if path is None or name in found:
            continue
        found[name] = path
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        tree = ast.parse(path.read_text(), filename=str(path))
        pending.extend(_imported(tree, package, root) - found.keys())
    return dict(sorted(found.items()))


def _docstring_spans(tree: ast.Module) -> list[ast.Expr]:
    """The docstring statements of the module, its classes and its functions."""
    owners = [tree] + [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
    ]
    spans = []
    for owner in owners:
        first = owner.body[0] if owner.body else None
        if (
            isinstance(first, ast.Expr)
            and isinstance(first.value, ast.Constant)
            and isinstance(first.value.value, str)
        ):
            spans.append(first)
    return spans


def _column(line: str, byte_offset: int) -> int:
    """The character column of a UTF-8 byte offset into ``line`` (``ast`` counts bytes)."""
    return len(line.encode()[:byte_offset].decode())


def code_text(source: str) -> str:
    """``source`` without docstrings, comments, trailing blanks and empty lines.

    Args:
        source: The text of a Python module.
    """
    lines = source.splitlines()
    spans: list[_Span] = []
    for node in _docstring_spans(ast.parse(source)):
        end_line = node.end_lineno if node.end_lineno is not None else node.lineno
        end_offset = node.end_col_offset if node.end_col_offset is not None else 0
        spans.append(
            (
                (node.lineno, _column(lines[node.lineno - 1], node.col_offset)),
                (end_line, _column(lines[end_line - 1], end_offset)),
            )
        )
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            spans.append((token.start, token.end))
    for (first, start), (last, end) in sorted(spans, reverse=True):
        if first == last:
            lines[first - 1] = lines[first - 1][:start] + lines[first - 1][end:]
        else:
            lines[first - 1] = lines[first - 1][:start]
            lines[last - 1] = lines[last - 1][end:]
            lines[first : last - 1] = [""] * (last - 1 - first)
    return "\n".join(line.rstrip() for line in lines if line.strip())


def code_digest(modules: Iterable[str], root: Path = ROOT) -> str:
    """SHA-256 (hex) of the code (``code_text``) of ``module_closure(modules)``.

    Args:
        modules: Dotted names to start from.
        root: The folder holding the packages.
    """
    digest = hashlib.sha256()
    for name, path in module_closure(modules, root).items():
        digest.update(name.encode() + b"\0" + code_text(path.read_text()).encode() + b"\0")
    return digest.hexdigest()
