"""``load_policy``: a ``cpf-train`` output folder as a policy like the analytic ones.

The loaded policy runs the base policy (rebuilt by name for the evaluation
scenario) and the trained network on the same local inputs it was trained
on, normalized with the saved statistics, and acts on the mean action
(deterministic). It offers ``reset``, ``reset_fleets``, ``act``, ``act_batch``,
``predict``, ``diagnostics`` and ``name``, so ``cpf-bench``, ``cpf-run`` and
SB3's ``evaluate_policy`` treat it as any analytic policy.

Example (with a folder written by ``cpf-train --out runs/ppo``)::

    from agents import load_policy
    policy = load_policy("runs/ppo", scenario="bench_lossy_links")
    actions = policy.act_batch(obs)  # (B, n, obs_dim) -> (B, n, 4 + m)
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray
from stable_baselines3.common.base_class import BaseAlgorithm

from agents.training import ALGORITHMS, TrainConfig
from agents.vec_env import resolve_base_policy
from baselines.interface import PolicyInterface
from cpf_env.envs.parallel import make_scenario
from cpf_env.envs.residual import ResidualConfig, ResidualController
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import observation_layout

__all__ = ["TrainedPolicy", "load_policy"]

Array = NDArray[np.float64]


def load_policy(path: str | Path, scenario: str | Scenario | None = None) -> TrainedPolicy:
    """Load a trained agent from the folder ``cpf-train --out`` wrote.

    Args:
        path: The folder (with ``model.zip`` and ``config.json``).
        scenario: Evaluation scenario (name or ``Scenario``); default: the training
            scenario with the training run's overrides. Its observation layout
            must match the training one (the network's input size).

    Raises:
        FileNotFoundError: ``path`` is not a ``cpf-train`` output folder.
        ValueError: The scenario's observations do not fit the network.
    """
    folder = Path(path)
    missing = [name for name in ("model.zip", "config.json") if not (folder / name).is_file()]
    if missing:
        raise FileNotFoundError(
            f"{folder} is not a cpf-train output folder: missing {missing}. "
            "Train one with `cpf-train --out DIR`, or give a baseline name."
        )
    record = json.loads((folder / "config.json").read_text())
    config = TrainConfig.from_json(record["config"])
    model = ALGORITHMS[config.algo].load(folder / "model.zip", device="cpu")
    statistics = None
    if (folder / "vecnormalize.pkl").is_file():
        with open(folder / "vecnormalize.pkl", "rb") as handle:
            statistics = pickle.load(handle)  # SB3's own format (VecNormalize.save)
    if scenario is None:
        resolved = make_scenario(config.scenario, **config.scenario_overrides())
    else:
        resolved = make_scenario(scenario)
    return TrainedPolicy(folder.name, config, model, statistics, resolved)


class TrainedPolicy(PolicyInterface):
    """Base policy plus a trained network, with the analytic policies' interface.

    The network runs on one thread: torch's multi-threaded matrix products sum
    in an order that depends on the thread count, so its outputs would
    otherwise differ in the last bits between a laptop, a Ray worker (one
    thread) and a cluster node. For the batch sizes of an evaluation one
    thread is also the fastest.

    Args:
        name: Label (the folder name).
        config: The training run's configuration.
        model: The SB3 model.
        statistics: The saved ``VecNormalize`` (its ``obs_rms``, ``clip_obs`` and
            ``epsilon`` are used), or None.
        scenario: The evaluation scenario.
    """

    def __init__(
        self,
        name: str,
        config: TrainConfig,
        model: BaseAlgorithm,
        statistics: Any,
        scenario: Scenario,
    ) -> None:
        self.name = name
        self.config = config
        self.model = model
        self.scenario = scenario
        self.layout = observation_layout(scenario)
        self.n, self.obs_dim = scenario.n, self.layout.size
        self.act_dim = 4 + scenario.message_size
        self.agents = [f"vessel_{i}" for i in range(self.n)]
        self.diagnostics: dict[str, Array] = {}
        base = None if config.base == "none" else config.base
        self._base = resolve_base_policy(base, scenario)
        self._residual = (
            ResidualConfig(mode="force_and_rate", scale=1.0)
            if base is None
            else config.residual_config()
        )
        self._statistics = statistics
        self._controller: ResidualController | None = None
        size = self._residual.input_size(self.layout)
        expected = model.observation_space.shape
        if expected != (size,):
            raise ValueError(
                f"scenario {scenario.name!r} gives inputs of size {size} but the "
                f"network of {name!r} takes {expected}: evaluate it on a scenario with the "
                f"training scenario's neighbour slots and message size ({config.scenario!r})."
            )

    def reset(self, seed: int | None = None) -> None:
        """Forget all internal states (the base's and the last residuals)."""
        del seed
        self._controller = None
        if self._base is not None:
            self._base.reset()
        self.diagnostics = {}

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Forget the internal states of the fleets in a (B,) mask."""
        if self._controller is not None:
            mask = np.asarray(fleets)
            if mask.dtype != bool:
                index = mask
                mask = np.zeros(self._controller.num_fleets, dtype=bool)
                mask[index] = True
            self._controller.reset_fleets(mask)

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """Base action plus the trained correction, (B, n, 4 + m) float64.

        The network runs with one torch thread, so that the actions have the
        same bits whatever the caller's thread setting; torch's thread count is
        process-wide, so this sets it and restores it around the forward pass,
        and calling it from several Python threads at once is not safe.

        Args:
            obs: (B, n, obs_dim) local observations.
            fleets: Must be None (a trained policy acts on whole batches).
        """
        if fleets is not None:
            raise ValueError(
                f"{self.name!r} acts on whole batches only; call act_batch(obs) on all fleets."
            )
        batch = np.asarray(obs, dtype=np.float64)
        if batch.ndim != 3 or batch.shape[1:] != (self.n, self.obs_dim):
            raise ValueError(
                f"observations must have shape (B, {self.n}, {self.obs_dim}), got {batch.shape}."
            )
        if self._controller is None:
            self._controller = ResidualController(
                self.scenario, self._base, batch.shape[0], self._residual
            )
        elif self._controller.num_fleets != batch.shape[0]:
            raise ValueError(
                f"this policy holds states for B = {self._controller.num_fleets} fleets but got "
                f"B = {batch.shape[0]}; call reset() before changing the number of fleets."
            )
        inputs = self._controller.observe(batch)
        rows = inputs.reshape(-1, inputs.shape[-1]).astype(np.float32)
        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # the same bits whatever the process's thread setting
        try:
            action, _ = self.model.predict(self._normalize(rows), deterministic=True)
        finally:
            torch.set_num_threads(threads)
        command = self._controller.compose(np.asarray(action).reshape(*batch.shape[:2], -1))
        base_diagnostics = getattr(self._base, "diagnostics", {}) if self._base else {}
        self.diagnostics = {**base_diagnostics, "residual": self._controller.residual.copy()}
        return command

    def _normalize(self, rows: NDArray[np.float32]) -> NDArray[np.float32]:
        """Apply the saved observation statistics as ``VecNormalize`` does at evaluation."""
        if self._statistics is None:
            return rows
        rms = self._statistics.obs_rms
        scaled = (rows - rms.mean) / np.sqrt(rms.var + self._statistics.epsilon)
        clip = self._statistics.clip_obs
        return np.clip(scaled, -clip, clip).astype(np.float32)
