"""``cpf-run --video FILE``: an episode rendered to an MP4 or a GIF (the "enjoy" path).

``VideoRecorder`` is a rollout observer (``cpf_bench.rollout``): it
draws fleet 0 with the environments' own renderer
(``cpf_env.envs.render.FleetRenderer``: paths, hulls, trails, targets, links)
at the first step and every ``every`` steps after, then ``write`` encodes the
frames at ``fps`` frames per second:

- ``.gif``: with Pillow (installed with matplotlib), always available;
- ``.mp4``: H.264 with the ``ffmpeg`` program on ``PATH`` (``apt-get install
  ffmpeg``, ``brew install ffmpeg``, ...); without it ``check_video_path``
  says so before the episode runs and suggests a ``.gif``.

The file is written atomically (``cpf_env.infra.atomic``).
"""

from __future__ import annotations

import io
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.render import FleetRenderer
from cpf_env.infra import atomic
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import FleetSim

__all__ = ["FPS", "FRAMES", "VIDEO_SUFFIXES", "VideoRecorder", "check_video_path", "frame_period"]

#: Video formats by file suffix.
VIDEO_SUFFIXES = (".mp4", ".gif")
#: Playback frame rate (frames per second).
FPS = 20
#: Frames a video has at most by default (``frame_period``).
FRAMES = 300


def check_video_path(path: str | Path) -> Path:
    """The video file to write, checked before anything runs.

    Raises:
        ValueError: Another suffix, a folder, or ``.mp4`` without ``ffmpeg`` on ``PATH``.
    """
    file = Path(path)
    if file.suffix.lower() not in VIDEO_SUFFIXES:
        raise ValueError(
            f"--video {file}: give a file ending in .mp4 (needs ffmpeg) or .gif (always works)."
        )
    if file.is_dir():
        raise ValueError(f"--video {file} is a folder; give a file name.")
    if file.suffix.lower() == ".mp4" and shutil.which("ffmpeg") is None:
        raise ValueError(
            f"--video {file}: writing .mp4 needs the ffmpeg program on PATH, which is not "
            "installed (apt-get install ffmpeg); or write a GIF instead: "
            f"--video {file.with_suffix('.gif')}"
        )
    return file


def frame_period(horizon: int, frames: int = FRAMES) -> int:
    """Control steps between frames so that an episode of ``horizon`` steps gives <= ``frames``."""
    return max(1, -(-int(horizon) // frames))


class VideoRecorder:
    """Renders fleet 0 of a rollout every ``every`` steps (a ``StepObserver``).

    Args:
        scenario: The episode's scenario.
        every: Control steps between frames (>= 1).
        fps: Playback frames per second.

    Attributes:
        frames: The rendered frames, each (H, W, 3) uint8.
        seconds_per_frame: Simulated seconds between frames.
    """

    def __init__(self, scenario: Scenario, every: int, fps: int = FPS) -> None:
        if every < 1:
            raise ValueError(f"frames must be at least one step apart, got {every}.")
        self.every, self.fps = int(every), int(fps)
        self.seconds_per_frame = self.every * scenario.dt
        self.frames: list[NDArray[np.uint8]] = []
        self._renderer = FleetRenderer(scenario, "rgb_array")
        self._drawn_start = False

    def before(self, sim: FleetSim, actions: NDArray[np.float64], policy: FleetPolicy) -> None:
        """Draw the initial state once."""
        del actions, policy
        if not self._drawn_start:
            self._draw(sim)
            self._drawn_start = True

    def after(self, sim: FleetSim) -> None:
        """Draw every ``every``-th step."""
        if int(sim.arrays.step[0]) % self.every == 0:
            self._draw(sim)

    def _draw(self, sim: FleetSim) -> None:
        frame = self._renderer.draw(sim, fleet=0)
        assert frame is not None  # rgb_array mode
        self.frames.append(frame)

    def write(self, path: str | Path) -> Path:
        """Encode the frames into ``path`` (``.gif`` or ``.mp4``; see the module docstring)."""
        fps = self.fps
        self._renderer.close()
        file = check_video_path(path)
        if not self.frames:
            raise ValueError("no frame was rendered; run at least one step.")
        if file.suffix.lower() == ".gif":
            from PIL import Image

            images = [Image.fromarray(frame) for frame in self.frames]
            buffer = io.BytesIO()
            images[0].save(buffer, format="GIF", save_all=True, append_images=images[1:],
                           duration=round(1000 / fps), loop=0)  # fmt: skip
            atomic.write_bytes(file, buffer.getvalue())
        else:
            atomic.write_bytes(file, _encode_mp4(self.frames, fps))
        return file


def _encode_mp4(frames: list[NDArray[np.uint8]], fps: int) -> bytes:
    """H.264 MP4 bytes of the frames, encoded by ffmpeg from raw RGB on its standard input."""
    height, width = frames[0].shape[:2]
    with tempfile.TemporaryDirectory() as scratch:
        target = Path(scratch) / "video.mp4"
        command = [
            str(shutil.which("ffmpeg")), "-loglevel", "error", "-y", "-f", "rawvideo",
            "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", str(fps), "-i", "-",
            "-pix_fmt", "yuv420p", "-vf", "scale=trunc(iw/2)*2:trunc(ih/2)*2", str(target),
        ]  # fmt: skip
        result = subprocess.run(
            command, input=b"".join(f.tobytes() for f in frames), capture_output=True, check=False
        )
        if result.returncode != 0:
            raise ValueError(f"ffmpeg could not encode the video: {result.stderr.decode()[-500:]}")
        return target.read_bytes()
