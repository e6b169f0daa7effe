"""Your own controller on the command line: package.module:NAME and the entry-point group."""

from __future__ import annotations

import csv
import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from cpf_commands.bench.cli import bench_main
from cpf_commands.bench.run import run_bench
from cpf_commands.common import policies
from cpf_commands.common.policies import (
    ENTRY_POINT_GROUP,
    policy_argument,
    refers_to_file,
    resolve_policy,
)
from cpf_commands.run.cli import run_main
from cpf_env.evaluation.fleet_metrics import METRICS

FACTORIES = """
from baselines import make_policy


def mine(*a, **k):
    return make_policy("backstepping", *a, **k)


def not_a_policy(scenario):
    return 3


NOT_CALLABLE = 3
"""


@pytest.fixture
def user_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """A module of the user's own, importable as ``my_factories`` (not imported yet)."""
    (tmp_path / "my_factories.py").write_text(FACTORIES)
    (tmp_path / "never_imported.py").write_text("raise RuntimeError('imported')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "my_factories", raising=False)
    return "my_factories"


@pytest.fixture
def installed(monkeypatch: pytest.MonkeyPatch, user_module: str) -> None:
    """Two installed policies in the group: one the tests use, one whose import would fail."""
    points = [
        metadata.EntryPoint("mine_installed", f"{user_module}:mine", ENTRY_POINT_GROUP),
        metadata.EntryPoint("unused", "never_imported:Policy", ENTRY_POINT_GROUP),
    ]

    def entry_points(group: str) -> list[metadata.EntryPoint]:
        return [p for p in points if p.group == group]

    monkeypatch.setattr(policies.metadata, "entry_points", entry_points)


def _same_costs(cells, first: int, second: int) -> None:
    for name in METRICS:
        np.testing.assert_array_equal(cells[first].metrics[name], cells[second].metrics[name])


def test_a_factory_of_your_own_benches_exactly_like_the_baseline_it_wraps(user_module):
    policies = ["backstepping", f"{user_module}:mine"]
    cells = run_bench(policies, ["bench_mild"], num_seeds=2, max_steps=20)
    assert [c.policy for c in cells] == ["backstepping", "my_factories:mine"]
    _same_costs(cells, 0, 1)


def test_an_installed_policy_benches_by_name_and_only_named_code_is_imported(installed):
    assert policy_argument("mine_installed") == "mine_installed"  # checked without importing
    assert "my_factories" not in sys.modules
    cells = run_bench(["backstepping", "mine_installed"], ["bench_mild"], num_seeds=2, max_steps=20)
    assert cells[1].policy == "mine_installed"
    _same_costs(cells, 0, 1)
    assert "never_imported" not in sys.modules


def test_cpf_bench_labels_user_policies_by_their_spec_and_benches_the_template(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.syspath_prepend(str(ROOT / "examples"))
    specs = ["my_policy:ProportionalPolicy", "my_policy:tuned_backstepping"]
    out = tmp_path / "bench"
    argv = ["--policies", "nn_dsc", *specs, "--scenarios", "bench_mild", "--num-seeds", "2"]
    assert (
        bench_main([*argv, "--max-steps", "20", "--quiet", "--no-figures", "--out", str(out)]) == 0
    )
    with open(out / "summary.csv") as handle:
        labels = {row["policy"] for row in csv.DictReader(handle)}
    assert labels == {"nn_dsc", *specs}
    printed = capsys.readouterr().out
    assert all(spec in printed for spec in specs)


def test_cpf_run_takes_a_user_policy_and_writes_a_folder_without_colon(
    user_module, tmp_path, capsys
):
    argv = ["--policy", f"{user_module}:mine", "--scenario", "bench_mild", "--max-steps", "10"]
    assert run_main([*argv, "--no-figures", "--quiet", "--out", str(tmp_path)]) == 0
    assert "bench_mild with my_factories:mine" in capsys.readouterr().out
    assert not any(":" in p.name for p in tmp_path.iterdir())
    assert [p.name for p in tmp_path.iterdir() if p.is_dir()] == ["bench_mild_my_factories+mine"]
    assert (tmp_path / "bench_mild_my_factories+mine" / "metrics.json").is_file()


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("no_such_module_here:Policy", "cannot import module 'no_such_module_here'"),
        ("my_factories:missing", "module 'my_factories' has no 'missing'"),
        ("my_factories:NOT_CALLABLE", "is a int, not a policy class or a factory"),
        ("my_factories:not_a_policy", "built a int, which lacks the policy contract"),
        ("never_imported:Policy", "importing module 'never_imported' failed: RuntimeError"),
    ],
)
def test_a_user_policy_that_cannot_be_used_says_why(user_module, name, message):
    with pytest.raises(ValueError, match=message):
        resolve_policy(name, "bench_mild")


def test_a_broken_installed_policy_names_its_entry_point(installed):
    with pytest.raises(ValueError, match="as 'never_imported:Policy', which cannot be loaded"):
        resolve_policy("unused", "bench_mild")


def test_specs_are_told_from_files(tmp_path, user_module):
    assert not refers_to_file(f"{user_module}:mine") and not refers_to_file("nn_dsc")
    assert refers_to_file("runs/agent") and refers_to_file(tmp_path)
    folder = tmp_path / "odd:name"
    folder.mkdir()
    assert refers_to_file(str(folder))  # an existing folder is a folder, whatever its name
