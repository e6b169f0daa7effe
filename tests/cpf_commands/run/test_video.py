"""``cpf-run --video``: a trained agent's episode rendered to a GIF (or an MP4 with ffmpeg)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from PIL import Image

from cpf_commands.run import cli
from cpf_commands.run.cli import run_main
from cpf_commands.run.video import frame_period

AGENT = ROOT / "tests/fixtures/agents/residual_ppo_lossy_links"


def test_an_agent_episode_becomes_a_gif_on_its_training_scenario(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    video = tmp_path / "enjoy.gif"
    argv = ["--policy", str(AGENT), "--video", str(video), "--video-every", "4",
            "--max-steps", "12", "--out", str(tmp_path / "out"),
            "--no-figures", "--quiet"]  # fmt: skip
    assert run_main(argv) == 0
    printed = capsys.readouterr().out
    assert "bench_lossy_links with" in printed  # the folder's training scenario by default
    assert f"Video of fleet 0: {video} (4 frames, one every 4 steps = 0.20 s" in printed
    with Image.open(video) as gif:
        assert gif.n_frames == 4 and gif.size == (640, 480)  # t = 0, 4, 8, 12 steps
        assert gif.info["duration"] == 50  # 20 frames/s
        first = np.asarray(gif.convert("RGB"))
        gif.seek(3)
        last = np.asarray(gif.convert("RGB"))
    assert first.std() > 10 and not np.array_equal(first, last)  # drawn, and it moves


def test_mp4_needs_ffmpeg_and_the_error_suggests_a_gif(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(SystemExit):
        run_main(["--video", str(tmp_path / "a.mp4"), "--max-steps", "2", "--quiet"])
    error = capsys.readouterr().err
    assert "needs the ffmpeg program on PATH" in error and f"--video {tmp_path / 'a.gif'}" in error
    with pytest.raises(SystemExit):
        run_main(["--video", str(tmp_path / "a.avi"), "--max-steps", "2", "--quiet"])
    assert "ending in .mp4 (needs ffmpeg) or .gif" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # refused before anything ran


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg is not installed")
def test_mp4_with_ffmpeg(tmp_path: Path) -> None:
    video = tmp_path / "enjoy.mp4"
    assert run_main(["--scenario", "wang2014", "--video", str(video), "--max-steps", "6",
                     "--out", str(tmp_path / "out"), "--no-figures", "--quiet"]) == 0  # fmt: skip
    assert video.read_bytes()[4:8] == b"ftyp"  # an MP4 container


def test_default_frame_period_keeps_videos_short() -> None:
    assert frame_period(3000) == 10 and frame_period(12) == 1 and frame_period(301) == 2
    assert cli.DEFAULT_SCENARIO == "wang2014_fine"
