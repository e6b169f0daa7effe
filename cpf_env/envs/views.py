"""Render plumbing shared by the envs: mode checks and lazily created renderers.

The envs import this module, not ``cpf_env.envs.render``: matplotlib is imported
only when a frame is first drawn.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import gymnasium
import numpy as np
from numpy.typing import NDArray

from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import FleetSim

if TYPE_CHECKING:
    from cpf_env.envs.render import FleetRenderer

__all__ = ["FleetViews", "check_render_mode"]


def check_render_mode(render_mode: str | None, modes: list[str]) -> None:
    """Raise ``ValueError`` unless ``render_mode`` is None or one of ``modes``."""
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"render_mode must be one of {modes} or None, got {render_mode!r}.")


class FleetViews:
    """One ``FleetRenderer`` per rendered fleet of a simulator, created on first use.

    Args:
        scenario: The scenario drawn.
        render_mode: ``"human"``, ``"rgb_array"`` or None (then ``draw`` warns).
    """

    def __init__(self, scenario: Scenario, render_mode: str | None) -> None:
        self.scenario = scenario
        self.render_mode = render_mode
        self._renderers: dict[int, FleetRenderer] = {}

    def draw(self, sim: FleetSim, fleet: int = 0) -> NDArray[np.uint8] | None:
        """Draw fleet ``fleet``: an (H, W, 3) frame in rgb_array mode, None otherwise.

        Raises:
            RuntimeError: Before the simulator's first reset (there is no fleet yet).
        """
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without render_mode; pass render_mode=...")
            return None
        if not sim.started:
            raise RuntimeError("render() before reset(): there is no fleet to draw; call reset().")
        if fleet not in self._renderers:
            from cpf_env.envs.render import FleetRenderer

            self._renderers[fleet] = FleetRenderer(self.scenario, mode=self.render_mode)
        return self._renderers[fleet].draw(sim, fleet=fleet)

    def close(self) -> None:
        """Close every renderer (idempotent)."""
        for renderer in self._renderers.values():
            renderer.close()
        self._renderers.clear()
