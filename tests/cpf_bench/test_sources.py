"""The code a cached bench cell depends on: the import closure and its prose-free digest."""

from __future__ import annotations

import shutil

import pytest

from cpf_bench import cache, sources
from cpf_env.infra.kernel_cache import KERNEL_SOURCES

MODULE = '''"""A module docstring: prose.

Over two lines, with a non-ASCII tail: θ ± 1 m."""

import math  # a comment


def speed(x):
    """Metres per second; the ±0.1 here is prose.  é"""
    # how it works
    return math.sqrt(x) * 2.0  # fmt: skip


class Plan:
    """A plan."""

    HORIZON = 40  #: steps
'''


def test_prose_leaves_the_code_text_unchanged():
    bare = "\n".join(
        [
            "import math",
            "def speed(x):",
            "    return math.sqrt(x) * 2.0",
            "class Plan:",
            "    HORIZON = 40",
        ]
    )
    assert sources.code_text(MODULE) == bare
    reworded = MODULE.replace("prose.", "other words, longer than before.").replace("#: steps", "")
    assert sources.code_text(reworded) == bare


@pytest.mark.parametrize(
    "edit",
    [("* 2.0", "* 2.5"), ("HORIZON = 40", "HORIZON = 41"), ("def speed(x)", "def speed(x, y=1)")],
)
def test_a_code_edit_changes_the_code_text(edit):
    assert sources.code_text(MODULE.replace(*edit)) != sources.code_text(MODULE)


def test_strings_line_breaks_and_page_breaks_keep_their_code():
    """Whitespace inside a string is code; a form feed or CRLF does not shift the cuts."""
    text = 'T = """a\n\n   \nb   \n"""  # c\n'
    assert sources.code_text(text) == 'T = """a\n\n   \nb   \n"""'
    assert sources.code_text(text) != sources.code_text('T = """a\nb\n"""\n')
    paged = 'RATE = 0.5\n\x0c\ndef f(a=1):\n    """Doc \u2028 é."""\n    return a * RATE  # é\n'
    assert sources.code_text(paged) == "RATE = 0.5\ndef f(a=1):\n    return a * RATE"
    assert sources.code_text(paged.replace("\n", "\r\n")) == sources.code_text(paged)
    assert sources.code_text(paged.replace("a=1", "a=2")) != sources.code_text(paged)


def test_modules_are_read_as_python_decodes_them(tmp_path):
    """A BOM or an encoding line changes neither the code read nor the digest."""
    texts = {
        "bom": "\ufeffX = 'é'\n".encode(),
        "latin": "# -*- coding: latin-1 -*-\nX = 'é'\n".encode("latin-1"),
        "plain": "X = 'é'\n".encode(),
    }
    for name, data in texts.items():
        (tmp_path / name / "baselines").mkdir(parents=True)
        (tmp_path / name / "baselines" / "a.py").write_bytes(data)
    digests = {sources.code_digest(["baselines.a"], tmp_path / name) for name in texts}
    assert len(digests) == 1


def test_the_closure_follows_imports_into_functions_and_relative_ones(tmp_path):
    package = tmp_path / "baselines"
    package.mkdir()
    (package / "__init__.py").write_text("X = 1\n")
    (package / "a.py").write_text("from . import b\n\ndef f():\n    from cpf_env import c\n")
    (package / "b.py").write_text("from baselines import X\nimport numpy\n")
    (tmp_path / "cpf_env").mkdir()
    (tmp_path / "cpf_env" / "c.py").write_text("")
    (package / "unused.py").write_text("")
    closure = sources.module_closure(["baselines.a"], tmp_path)
    assert list(closure) == ["baselines", "baselines.a", "baselines.b", "cpf_env.c"]
    with pytest.raises(ValueError, match=r"'baselines\.missing' is not a module"):
        sources.module_closure(["baselines.missing"], tmp_path)


def test_a_policys_cells_depend_on_the_simulator_kernels_and_metrics():
    closure = sources.module_closure(["baselines.mpc", *cache.RUNNERS])
    needed = {f"cpf_env.{name}" for name in KERNEL_SOURCES}
    needed |= {"baselines.mpc_kernels", "cpf_env.sim.fleet", "cpf_env.evaluation.fleet_metrics"}
    needed |= {"baselines", "cpf_bench.evaluate"}  # the name -> policy resolution
    assert needed <= closure.keys()


def test_code_edits_rekey_the_policies_that_import_them_and_prose_edits_do_not(tmp_path):
    for package in sources.PACKAGES:
        shutil.copytree(
            sources.ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__")
        )
    starts = {name: (f"baselines.{name}", *cache.RUNNERS) for name in ("mpc", "mpc_tuned")}

    def digests():
        return {name: sources.code_digest(start, tmp_path) for name, start in starts.items()}

    before = digests()
    assert before == {name: sources.code_digest(start) for name, start in starts.items()}
    fleet = tmp_path / "cpf_env" / "sim" / "fleet.py"
    fleet.write_text(fleet.read_text().replace('"""', '"""Reworded. ', 1))
    assert digests() == before  # prose only
    fleet.write_text(fleet.read_text() + "\nEXTRA = 1\n")
    after = digests()
    assert all(value != before[name] for name, value in after.items())
    (tmp_path / "baselines" / "unused.py").write_text("EXTRA = 2\n")  # imported by neither
    assert digests() == after
