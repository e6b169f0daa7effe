"""The staging and locking helpers under kills and links; cpf-sweep's and cpf-export's outputs."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from fault_injection import killed_at

from cpf_commands.export import export_main
from cpf_commands.sweep.cli import run_sweep
from cpf_env.infra import atomic


def _tree(folder: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in sorted(folder.iterdir())}


def test_a_staged_folder_killed_at_any_stage_is_old_or_new_after_recovery(tmp_path: Path) -> None:
    folder = tmp_path / "out"
    old, new = {"a.csv": "old", "b.csv": "old"}, {"a.csv": "new", "c.csv": "new"}

    def write() -> None:
        with atomic.FolderLock(folder), atomic.staged_folder(folder) as staging:
            for name, text in new.items():
                atomic.write_text(staging / name, text)

    for stage in range(1, 40):
        folder.mkdir()
        for name, text in old.items():
            (folder / name).write_text(text)
        killed = killed_at(stage, write)
        with atomic.FolderLock(folder):
            assert _tree(folder) in (old, new), stage
        assert sorted(p.name for p in tmp_path.iterdir()) == [".out.lock", "out"]
        if not killed:
            assert _tree(folder) == new
            break
        shutil.rmtree(folder)
    assert stage == 11  # 2 files x 3 stages, the swap's 4, then it finished


def test_a_staged_folder_over_a_link_is_refused_before_anything_is_built(tmp_path: Path) -> None:
    (tmp_path / "real").mkdir()
    (tmp_path / "out").symlink_to(tmp_path / "real")
    built = []
    with pytest.raises(ValueError, match="is a symbolic link"):
        with atomic.staged_folder(tmp_path / "out") as staging:
            built.append(staging)
    assert built == [] and sorted(p.name for p in tmp_path.iterdir()) == ["out", "real"]


def test_a_sweep_into_a_link_is_refused(tmp_path: Path) -> None:
    from cpf_commands.sweep.spec import SweepSpec

    (tmp_path / "real").mkdir()
    (tmp_path / "sweep").symlink_to(tmp_path / "real")
    with pytest.raises(ValueError, match="is a symbolic link"):
        run_sweep(SweepSpec(("bench_mild",), (0,), fixed={"timesteps": 100}), tmp_path / "sweep")
    assert list((tmp_path / "real").iterdir()) == []


def _agent(tmp_path: Path) -> str:
    """A folder that passes cpf-export's first look (it is refused before it is read)."""
    (tmp_path / "agent").mkdir()
    (tmp_path / "agent" / "manifest.json").write_text("{}")
    return str(tmp_path / "agent")


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as raised:
        export_main(argv)
    assert raised.value.code == 2
    return capsys.readouterr().err


def test_an_export_into_a_link_is_refused_and_its_target_kept(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    victim = tmp_path / "victim.onnx"
    victim.write_text("keep me")
    (tmp_path / "agent.onnx").symlink_to(victim)
    err = _refused([_agent(tmp_path), str(tmp_path / "agent.onnx")], capsys)
    assert "is a symbolic link" in err and victim.read_text() == "keep me"


def test_a_second_export_to_one_file_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    agent = _agent(tmp_path)
    with atomic.FolderLock(tmp_path / "agent.onnx", "another cpf-export"):
        err = _refused([agent, str(tmp_path / "agent.onnx")], capsys)
    assert "being written by another cpf-export" in err
