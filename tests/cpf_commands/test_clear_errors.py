"""A user's bad setting gets one line that names it and says what to do, before anything runs."""

from __future__ import annotations

from pathlib import Path

import pytest

import cpf_env
from cpf_commands.bench.cli import bench_main
from cpf_commands.bench.run import run_bench
from cpf_commands.export import export_main
from cpf_commands.run.cli import run_main
from cpf_env import scenarios

AGENT = Path(__file__).resolve().parents[2] / "tests/fixtures/agents"


def _error(main, argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The last line a command prints on stderr when it refuses ``argv``."""
    with pytest.raises(SystemExit) as stopped:
        main(argv)
    assert stopped.value.code == 2
    return capsys.readouterr().err.strip().splitlines()[-1]


def test_a_negative_seed_names_its_flag(capsys, tmp_path):
    line = _error(run_main, ["--seed", "-1", "--out", str(tmp_path)], capsys)
    assert line == "cpf-run: error: argument --seed: must be an integer >= 0, got -1"
    line = _error(bench_main, ["--seed", "-1", "--out", str(tmp_path)], capsys)
    assert line == "cpf-bench: error: argument --seed: must be an integer >= 0, got -1"
    assert not list(tmp_path.iterdir())


def test_a_policy_listed_twice_is_refused_as_a_duplicate(capsys, tmp_path):
    argv = ["--policies", "nn_dsc", "nn_dsc", "--scenarios", "bench_mild"]
    line = _error(bench_main, [*argv, "--out", str(tmp_path / "b")], capsys)
    assert "policy 'nn_dsc' is listed twice; duplicates are not allowed" in line
    assert "mapping" not in line and not (tmp_path / "b").exists()
    with pytest.raises(ValueError, match="listed twice; duplicates are not allowed"):
        run_bench(["dsc", "dsc"], ["bench_mild"], num_seeds=1, max_steps=2)


def test_a_non_positive_max_steps_says_so_not_something_about_dt():
    for make in (
        lambda: cpf_env.parallel_env("wang2014", max_steps=-10),
        lambda: scenarios.get("wang2014").replace(max_steps=0),
    ):
        with pytest.raises(ValueError) as error:
            make()
        message = str(error.value)
        assert "max_steps must be positive" in message and "dt" not in message


@pytest.mark.parametrize(
    ("folder", "out", "expected"),
    [
        (
            "missing_agent",
            "agent.onnx",
            "the agent folder '{tmp}/missing_agent' does not exist; give a cpf-train --out folder.",
        ),
        ("empty", "agent.onnx", "'{tmp}/empty' is not an agent folder (no manifest.json)"),
        (
            str(AGENT / "residual_ppo_lossy_links"),
            "no/such/folder/agent.onnx",
            "the folder of the output, '{tmp}/no/such/folder', does not exist; create it first "
            "(mkdir -p {tmp}/no/such/folder).",
        ),
    ],
)
def test_cpf_export_says_which_path_is_missing(folder, out, expected, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    line = _error(export_main, [str(tmp_path / folder), str(tmp_path / out)], capsys)
    assert expected.format(tmp=tmp_path) in line
    assert line.startswith("cpf-export: error: ") and not (tmp_path / out).exists()


@pytest.mark.parametrize(
    ("module", "command", "absent", "extra"),
    [("cpf_commands.train", "cpf-train", "torch", "rl"),
     ("cpf_commands.distill", "cpf-distill", "torch", "rl"),
     ("cpf_commands.marl", "cpf-marl", "torch", "benchmarl")],
)  # fmt: skip
def test_learning_commands_without_their_extra_say_what_to_install(
    module: str, command: str, absent: str, extra: str
) -> None:
    """On the base install the command names the missing package and the install, no traceback."""
    import subprocess
    import sys

    hide = (  # the package cannot be imported, as on an install without the extra
        f"import sys; sys.modules[{absent!r}] = None; import runpy; "
        f"runpy.run_module({module!r}, run_name='__main__')"
    )
    done = subprocess.run([sys.executable, "-c", hide, "--help"], capture_output=True, text=True)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert done.stderr.startswith(f"{command}: needs {absent}, which is not installed")
    assert f"pip install -e '.[{extra}]'" in done.stderr
