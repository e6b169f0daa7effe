"""``--device``: the torch device of cpf-train and cpf-distill, checked before anything runs."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from agents.training.device import torch_device
from cpf_commands.distill import distill_main
from cpf_commands.train import train_main

NO_GPU = pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")


def test_known_devices_resolve() -> None:
    assert torch_device("cpu") == torch.device("cpu")
    assert torch_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")


def test_a_name_torch_does_not_know_is_refused() -> None:
    with pytest.raises(ValueError, match=r"'gpu0' is not a torch device.*auto, cpu, cuda"):
        torch_device("gpu0")


@NO_GPU
def test_cuda_without_a_gpu_says_what_to_do() -> None:
    for name in ("cuda", "cuda:1"):
        with pytest.raises(ValueError, match=r"sees none.*run with --device cpu \(or auto\)"):
            torch_device(name)


@NO_GPU
@pytest.mark.parametrize("main", [train_main, distill_main])
def test_the_commands_refuse_cuda_before_running(
    main: object, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "student.toml"
    config.write_text('scenario = "bench_mild"\nfleets = 2\n[distill]\nrounds = 1\n')
    argv = ["--out", str(tmp_path / "out"), "--device", "cuda"]
    if main is distill_main:
        argv += ["--config", str(config), "--seed", "0"]
    with pytest.raises(SystemExit):
        main(argv)  # type: ignore[operator]
    assert "asks for a CUDA GPU" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
