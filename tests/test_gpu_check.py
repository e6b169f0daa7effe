"""benchmarks/gpu_check.py: skipped without a GPU, and the timed run trains what it says."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]


def _load():
    path = ROOT / "benchmarks" / "gpu_check.py"
    spec = importlib.util.spec_from_file_location("gpu_check", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_without_a_cuda_device_it_says_so_and_trains_nothing(monkeypatch, capsys):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert _load().main(["--device", "cuda"]) == {}
    assert "no CUDA device" in capsys.readouterr().out


def test_a_run_reports_the_vessel_steps_it_trained(capsys):
    rates = _load().main(["--device", "cpu", "--timesteps", "1000", "--fleets", "4"])
    assert set(rates) == {"cpu"} and rates["cpu"] > 0.0
    out = capsys.readouterr().out
    trained = re.search(r"for ([\d,]+) vessel-steps \(-n 1,000 rounded up", out)  # cpf-train's
    assert trained is not None and f"cpu: {trained.group(1)} vessel-steps in" in out
    assert trained.group(1) != "1,000"  # whole rollouts: the count is read, not the budget
