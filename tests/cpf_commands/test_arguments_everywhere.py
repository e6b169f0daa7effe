"""Every command refuses abbreviated options (``--num-seed`` is not ``--num-seeds``)."""

from __future__ import annotations

import argparse
import importlib
import re
from pathlib import Path

import pytest
from conftest import ROOT

_SECTION = (ROOT / "pyproject.toml").read_text().split("[project.scripts]")[1].split("\n[")[0]
SCRIPTS = dict(re.findall(r'^(cpf-[a-z]+) = "([^"]+)"', _SECTION, flags=re.MULTILINE))


class _Parsed(Exception):
    pass


@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_every_command_disallows_abbreviations(
    script: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[argparse.ArgumentParser] = []

    def capture(self: argparse.ArgumentParser, *args: object, **kwargs: object) -> None:
        seen.append(self)
        raise _Parsed

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", capture)
    module, function = SCRIPTS[script].split(":")
    with pytest.raises(_Parsed):
        getattr(importlib.import_module(module), function)([])
    assert seen and all(parser.allow_abbrev is False for parser in seen), script


def test_bench_num_seed_is_not_taken_for_num_seeds(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from cpf_commands.bench.cli import bench_main

    with pytest.raises(SystemExit):
        bench_main(["--num-seed", "3", "--out", str(tmp_path / "b")])
    assert "unrecognized arguments: --num-seed" in capsys.readouterr().err
