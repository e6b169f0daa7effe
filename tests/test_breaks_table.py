"""The table of deliberate breaks (tools/breaks.py) matches the current code."""

from __future__ import annotations

import importlib.util
import shutil
import sys
from pathlib import Path

import pytest
from conftest import ROOT

_SPEC = importlib.util.spec_from_file_location("breaks", ROOT / "tools" / "breaks.py")
assert _SPEC is not None and _SPEC.loader is not None
breaks = importlib.util.module_from_spec(_SPEC)
sys.modules["breaks"] = breaks  # dataclasses look their module up there
_SPEC.loader.exec_module(breaks)


@pytest.mark.parametrize("entry", breaks.BREAKS, ids=lambda entry: entry.name)
def test_each_break_applies_to_the_current_code(entry, tmp_path: Path) -> None:
    """Its text occurs exactly once, its edit changes the file, its targets exist."""
    copy = tmp_path / entry.path
    copy.parent.mkdir(parents=True)
    shutil.copy(ROOT / entry.path, copy)
    breaks.apply_break(entry, tmp_path)
    assert copy.read_text() != (ROOT / entry.path).read_text()
    assert entry.targets and all((ROOT / target).is_file() for target in entry.targets)


def test_a_break_whose_text_is_gone_says_what_to_update(tmp_path: Path) -> None:
    entry = breaks.Break("gone", "a.py", "old text", "new text", ("tests/conftest.py",))
    (tmp_path / "a.py").write_text("old text, old text\n")
    with pytest.raises(ValueError, match=r"occurs 2 times in a\.py"):
        breaks.apply_break(entry, tmp_path)


def test_names_are_unique() -> None:
    names = [entry.name for entry in breaks.BREAKS]
    assert len(names) == len(set(names))


def test_a_break_of_a_missing_file_says_what_to_update(tmp_path: Path) -> None:
    entry = breaks.Break("moved", "gone.py", "old", "new", ("tests/conftest.py",))
    with pytest.raises(ValueError, match=r"gone\.py does not exist"):
        breaks.apply_break(entry, tmp_path)
