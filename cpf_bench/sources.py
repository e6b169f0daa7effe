"""The code a cached bench cell's numbers come from, and a digest of it that ignores prose.

``cpf_bench.cache`` keys a receding-horizon policy's cells on the
code that computes them. That code is found statically: the modules named
(the policy's own, the resolver that builds it and the rollout that runs
it), then every module of this repository's packages (``PACKAGES``) that
they import, transitively, including imports inside functions. A
package's ``__init__`` counts where a statement imports from the package
itself.

The digest reads each module's code without its docstrings, comments,
trailing blanks and blank lines (``code_text``; text inside other string
literals is kept as it is), so an edit to prose leaves every key as it
was, while an edit to any statement, constant or signature re-keys the
cells that import it. The text is cut from the source at the positions
``ast`` and ``tokenize`` report, and every cut is checked against what it
removes, so the digest does not depend on how a Python version builds its
syntax tree. It covers this repository's code only: numpy's, numba's and
Python's versions are not part of it.
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
PACKAGES = ("cpf_env", "baselines", "cpf_bench")
#: The folder that holds the packages.
ROOT = Path(__file__).resolve().parents[1]

_Span = tuple[tuple[int, int], tuple[int, int]]  # (line, column) start and end; lines from 1


def _module_file(name: str, root: Path) -> Path | None:
    """The file of a dotted module name of ``PACKAGES``, None for any other or a missing one.

    A package comes before a module of the same name, as Python's import system has it.
    """
    if name.split(".")[0] not in PACKAGES:
        return None
    base = root.joinpath(*name.split("."))
    for path in (base / "__init__.py", base.with_suffix(".py")):
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
        tree = ast.parse(_read(path), filename=str(path))
        pending.extend(_imported(tree, package, root) - found.keys())
    return dict(sorted(found.items()))


def _read(path: Path) -> str:
    """A module's text as Python decodes it (its encoding line or UTF-8, a BOM dropped)."""
    with tokenize.open(path) as file:
        return file.read()


def _docstrings(tree: ast.Module) -> list[ast.Expr]:
    """The docstring statements of the module, its classes and its functions."""
    owners = [tree] + [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
    ]
    found = []
    for owner in owners:
        first = owner.body[0] if owner.body else None
        if (
            isinstance(first, ast.Expr)
            and isinstance(first.value, ast.Constant)
            and isinstance(first.value.value, str)
        ):
            found.append(first)
    return found


def _span(node: ast.expr | ast.stmt) -> tuple[int, int, int, int]:
    """A node's first and last line and its byte columns there (``ast`` sets all four)."""
    if node.end_lineno is None or node.end_col_offset is None:
        raise ValueError(f"ast gave no end position for line {node.lineno}.")
    return node.lineno, node.col_offset, node.end_lineno, node.end_col_offset


def _column(line: str, byte_offset: int) -> int:
    """The character column of a UTF-8 byte offset into ``line`` (``ast`` counts bytes)."""
    return len(line.encode()[:byte_offset].decode())


def _cut_text(lines: list[str], span: _Span) -> str:
    """The text a cut over ``span`` removes."""
    (first, start), (last, end) = span
    if first == last:
        return lines[first - 1][start:end]
    middle = lines[first : last - 1]
    return "\n".join([lines[first - 1][start:], *middle, lines[last - 1][:end]])


def code_text(source: str) -> str:
    """``source`` without docstrings, comments, trailing blanks and blank lines.

    Lines inside a multi-line string literal that is not a docstring are
    kept exactly, blanks included.

    Args:
        source: The text of a Python module.

    Raises:
        ValueError: A cut would not remove exactly a comment or a docstring (a
            position ``ast`` or ``tokenize`` reported does not match the text).
    """
    lines = source.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    tree = ast.parse(source)
    docstrings = _docstrings(tree)
    cuts: list[_Span] = []
    for node in docstrings:
        first, start, last, end = _span(node)
        span = ((first, _column(lines[first - 1], start)), (last, _column(lines[last - 1], end)))
        cuts.append(span)
        if ast.literal_eval(_cut_text(lines, span)) != ast.literal_eval(node.value):
            raise ValueError(f"the docstring at line {first} is not where ast puts it.")
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            cuts.append((token.start, token.end))
            if _cut_text(lines, (token.start, token.end)) != token.string:
                raise ValueError(f"the comment at line {token.start[0]} is not where it reads.")
    kept: set[int] = set()  # lines a multi-line string (not a docstring) runs over, but its last
    skipped = {id(docstring.value) for docstring in docstrings}
    for literal in ast.walk(tree):
        if isinstance(literal, ast.Constant | ast.JoinedStr) and id(literal) not in skipped:
            first, _, last, _ = _span(literal)
            kept.update(range(first, last))
    for (first, start), (last, end) in sorted(cuts, reverse=True):
        if first == last:
            lines[first - 1] = lines[first - 1][:start] + lines[first - 1][end:]
        else:
            lines[first - 1] = lines[first - 1][:start]
            lines[last - 1] = lines[last - 1][end:]
            lines[first : last - 1] = [""] * (last - 1 - first)
    return "\n".join(
        line if number in kept else line.rstrip()
        for number, line in enumerate(lines, start=1)
        if number in kept or line.strip()
    )


def code_digest(modules: Iterable[str], root: Path = ROOT) -> str:
    """SHA-256 (hex) of the code (``code_text``) of ``module_closure(modules)``.

    Args:
        modules: Dotted names to start from.
        root: The folder holding the packages.
    """
    digest = hashlib.sha256()
    for name, path in module_closure(modules, root).items():
        digest.update(name.encode() + b"\0" + code_text(_read(path)).encode() + b"\0")
    return digest.hexdigest()
