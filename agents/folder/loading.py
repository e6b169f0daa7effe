"""``load_policy``: a ``cpf-train`` output folder as a policy like the analytic ones.

The loaded policy runs the base policy (rebuilt by name for the evaluation
scenario) and the trained network on the same local inputs it was trained
on, normalized with the saved statistics, and acts on the mean action
(deterministic). An agent with a neighbour encoder (``TrainConfig(encoder=...)``)
gets as many neighbour slots as the evaluation scenario needs (at least its
training K), and an agent trained with a history (``TrainConfig(history=H)``)
keeps each vessel's own history itself (``agents.envs.history.OwnHistory``, as
``HistoryVecEnv`` kept it in training), cleared by ``reset`` and
``reset_fleets``. It offers ``reset``, ``reset_fleets``, ``act``, ``act_batch``,
``predict``, ``diagnostics`` and ``name``, so ``cpf-bench``, ``cpf-run`` and
SB3's ``evaluate_policy`` treat it as any analytic policy.

Example (with a folder written by ``cpf-train --out runs/ppo``)::

    from agents import load_policy
    policy = load_policy("runs/ppo", scenario="bench_lossy_links")  # no pickle is read
    actions = policy.act_batch(obs)  # (B, n, obs_dim) -> (B, n, 4 + m)
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

from agents.envs.history import OwnHistory
from agents.envs.resolve import resolve_base_policy
from agents.estimation.policy import LearnedFilter
from agents.folder.actor import PolicyNetwork
from agents.folder.encoder import statistics_for_slots
from agents.folder.files import AgentFolderError, field
from agents.folder.format import (
    CONFIG,
    Normalization,
    read_agent,
    read_agent_manifest,
    read_json,
    read_record,
    training_config,
)
from agents.marl.policy_folder import marl_config, read_marl_agent
from agents.training.config import TrainConfig
from cpf_env.envs.policy import FleetPolicy, fleet_mask
from cpf_env.envs.residual import ResidualController, learner_config
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.sim.fleet import observation_layout
from cpf_env.sim.observation import SLOTS

__all__ = [
    "Actor",
    "TorchActor",
    "TrainedPolicy",
    "load_policy",
    "read_config",
    "read_scenario_overrides",
]

Array = NDArray[np.float64]


def load_policy(
    path: str | Path, scenario: str | Scenario | None = None
) -> TrainedPolicy | LearnedFilter:
    """Load a trained agent from the folder ``cpf-train --out`` (or ``save_marl_policy``) wrote.

    A learned navigation filter's folder (``cpf-fit-filter --out``) loads as its
    ``agents.estimation.LearnedFilter``.

    Reads the data-only formats (``agents.folder.format``, and a BenchMARL actor's
    ``agents.marl.policy_folder``: safetensors and JSON, every file checked
    against the manifest, read with ``agents.folder.files``' limits); nothing in
    the folder can run code. Pickles are never read: a plain SB3 save
    (``model.zip``, ``vecnormalize.pkl``) is refused.

    Args:
        path: The folder.
        scenario: Evaluation scenario (name or ``Scenario``); default: the training
            scenario with the training run's overrides (a MARL task's ``overrides``;
            not its training ``max_steps``: the scenario's own episode). Its observation layout
            must match the training one (the network's input size).

    Raises:
        AgentFolderError: (a ValueError) ``path`` is not an agent folder, a file is
            missing, altered or inconsistent with the others (named), or a plain
            SB3 save.
        ValueError: The scenario's observations do not fit the network.
    """
    folder = Path(path)
    trainer, _ = read_agent_manifest(folder)
    if trainer == "filter":  # a learned navigation filter (agents.estimation)
        from agents.estimation.folder import load_filter

        return load_filter(folder, scenario)
    overrides: dict[str, Any] = {}  # a MARL task's Scenario field overrides
    if trainer == "benchmarl":  # a BenchMARL actor (agents.marl.policy_folder)
        config, network, normalization, overrides = read_marl_agent(folder)
    else:
        record, network, normalization = read_agent(folder)
        config = training_config(record["config"], folder / CONFIG)
    if scenario is None:
        resolved = make_scenario(config.home_scenario, **config.scenario_overrides(), **overrides)
    else:
        resolved = make_scenario(scenario)
    return TrainedPolicy(folder.name, config, TorchActor(network, normalization), resolved)


def read_config(path: str | Path) -> TrainConfig:
    """The training configuration of an agent folder ``load_policy`` reads, without its weights.

    Raises:
        AgentFolderError: Not an agent folder, or an unreadable or invalid configuration.
    """
    folder = Path(path)
    trainer, manifest = read_agent_manifest(folder)
    if trainer == "benchmarl":
        return _marl_record(folder, manifest)[0]
    record = read_record(folder, manifest)
    return training_config(field(record, "config", folder / CONFIG), folder / CONFIG)


def read_scenario_overrides(path: str | Path) -> dict[str, Any]:
    """The ``Scenario`` field overrides of a MARL folder's task (``{}`` for other agent folders).

    ``load_policy`` applies them when it is given no scenario; a named scenario
    leaves them out.

    Raises:
        AgentFolderError: Not an agent folder, or an unreadable or invalid configuration.
    """
    folder = Path(path)
    trainer, manifest = read_agent_manifest(folder)
    return _marl_record(folder, manifest)[2] if trainer == "benchmarl" else {}


def _marl_record(
    folder: Path, manifest: dict[str, Any]
) -> tuple[TrainConfig, list[int], dict[str, Any]]:
    """``marl_config`` of a MARL folder's ``config.json``, checked against its manifest."""
    return marl_config(read_json(folder, CONFIG, manifest), folder / CONFIG)


class Actor(Protocol):
    """The learned part of a policy: raw learner inputs -> actions in [-1, 1].

    ``input_size`` is None for an actor that takes any number of neighbour slots
    (a neighbour encoder run by torch).
    """

    @property
    def input_size(self) -> int | None:
        """Floats per input row."""

    @property
    def action_size(self) -> int:
        """Floats per action."""

    def __call__(self, rows: NDArray[np.float32]) -> NDArray[np.float32]:
        """(R, input_size) float32 inputs -> (R, action_size) float32 actions."""


@contextlib.contextmanager
def one_torch_thread() -> Iterator[None]:
    """Run the block on one torch thread, then restore the process's thread count.

    torch's multi-threaded matrix products sum in an order that depends on the
    thread count; on one thread a network's outputs are the same bits whatever
    the process's setting. The count is process-wide: not safe to use from
    several Python threads at once.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


class TorchActor:
    """``PolicyNetwork`` behind the saved normalization, on one torch thread.

    One thread (``one_torch_thread``) so that the outputs do not differ in the
    last bits between a laptop, a Ray worker (one thread) and a cluster node;
    it is set and restored around each forward pass, so calling it from
    several Python threads at once is not safe.

    With a neighbour encoder the inputs may have any number K' of slots: the
    statistics (saved for the training K, slots pooled) are given to every
    slot (``agents.folder.encoder.statistics_for_slots``).

    Args:
        network: The deterministic actor.
        normalization: The observation statistics, or None.
    """

    def __init__(self, network: PolicyNetwork, normalization: Normalization | None) -> None:
        self.network, self.normalization = network, normalization
        self.input_size, self.action_size = network.input_size, network.action_size
        self._statistics: dict[int, Normalization] = {}

    def _normalization(self, size: int) -> Normalization | None:
        """The statistics for inputs of ``size`` floats."""
        encoder = self.network.encoder
        if encoder is None or self.normalization is None:
            return self.normalization
        slots = encoder.slots_in(size)
        if slots not in self._statistics:
            trained = encoder.slots_in(self.normalization.mean.size)
            self._statistics[slots] = statistics_for_slots(
                self.normalization, trained, encoder.slot_size, slots
            )
        return self._statistics[slots]

    def __call__(self, rows: NDArray[np.float32]) -> NDArray[np.float32]:
        """(R, k) float32 inputs -> (R, a) float32 actions, bit-identical to SB3's predict."""
        normalization = self._normalization(rows.shape[-1])
        if normalization is not None:
            rows = normalization.apply(rows)
        with one_torch_thread(), torch.no_grad():
            return self.network(torch.from_numpy(rows)).numpy()


class TrainedPolicy(FleetPolicy):
    """Base policy plus a trained network, with the analytic policies' interface.

    Args:
        name: Label (the folder name).
        config: The training run's configuration.
        actor: The learned part (``TorchActor``, or ``agents.folder.onnx_policy.OnnxActor``).
        scenario: The evaluation scenario.
    """

    def __init__(
        self,
        name: str,
        config: TrainConfig,
        actor: Actor,
        scenario: Scenario,
    ) -> None:
        self.name = name
        self.config = config
        self.actor = actor
        self.scenario = scenario
        self.layout = observation_layout(scenario)
        self.n, self.obs_dim = scenario.n, self.layout.size
        self.act_dim = 4 + scenario.message_size
        self.agents = [f"vessel_{i}" for i in range(self.n)]
        self.diagnostics: dict[str, Array] = {}
        self._base = resolve_base_policy(config.base_policy, scenario)
        residual = config.residual
        if config.encoder is not None:
            slots = self._encoder_slots(config, actor)
            residual = dataclasses.replace(residual, neighbour_slots=slots)
        self._residual = learner_config(self._base, residual)
        # the entries a learner over this agent may not write (FleetPolicy.message_entries):
        # all m once it writes learned messages (they end the message), else its base's
        if self._residual.messages:
            self.message_entries = self.act_dim - 4
        elif self._base is None:
            self.message_entries = 0
        elif hasattr(self._base, "message_entries"):
            self.message_entries = self._base.message_entries
        self._controller: ResidualController | None = None
        self._history: OwnHistory | None = None
        size = self._residual.learner_layout(self.layout).size + config.learner_tail()
        if isinstance(actor, TorchActor) and actor.network.encoder is not None:
            self._check_encoder(actor.network.encoder.slot_size, actor.network.encoder.tail)
        if actor.input_size is not None and actor.input_size != size:
            raise ValueError(
                f"scenario {scenario.name!r} gives inputs of size {size} but the "
                f"network of {name!r} takes {actor.input_size}: evaluate it on a scenario with "
                f"the training scenarios' neighbour slots and message size "
                f"({config.home_scenario!r}), or train with --set "
                f"residual.neighbour_slots=K to run on "
                "graphs of higher degree."
            )
        if actor.action_size != self._residual.action_size:
            raise AgentFolderError(
                f"the network of {name!r} gives {actor.action_size} actions but its "
                f"config.json (mode {self._residual.mode!r}) asks for "
                f"{self._residual.action_size}."
            )

    def _check_encoder(self, slot_size: int, tail: int) -> None:
        """Refuse an encoder whose slots or tail are not this scenario's inputs'.

        Raises:
            ValueError: Slots of another message size (the scenario's ``3 + m``).
            AgentFolderError: A tail (extras and history) other than the configuration's.
        """
        if slot_size != self.layout.slot_size:
            raise ValueError(
                f"the encoder of {self.name!r} reads neighbour slots of {slot_size} floats but "
                f"scenario {self.scenario.name!r} gives {self.layout.slot_size} (3 + message "
                "size): evaluate it on a scenario with the training message size."
            )
        expected = self.config.learner_tail()
        if tail != expected:
            raise AgentFolderError(
                f"the encoder of {self.name!r} reads {tail} floats after the slots but its "
                f"config.json's extras and history give {expected}."
            )

    def _encoder_slots(self, config: TrainConfig, actor: Actor) -> int:
        """Neighbour slots an encoder actor gets on the evaluation scenario.

        Any number (``actor.input_size`` None): the training K or the scenario's
        degree, whichever is larger. A fixed input (an exported graph): the K' its
        size holds, which must cover the scenario's degree.

        Raises:
            ValueError: A fixed input size that holds no whole number of slots, or
                fewer slots than the scenario's degree (re-export with more).
        """
        trained, slot_size = config.learner_slots()
        if actor.input_size is None:
            return max(trained, self.layout.n_slots)
        tail = config.learner_tail()
        body = actor.input_size - SLOTS - tail
        if body < 0 or body % slot_size:
            raise ValueError(
                f"the network of {self.name!r} takes {actor.input_size} floats, not 18 + K' x "
                f"{slot_size} + {tail} (extras and history) for any K'."
            )
        slots = body // slot_size
        if slots < self.layout.n_slots:
            raise ValueError(
                f"{self.name!r} was exported for {slots} neighbour slots but scenario "
                f"{self.scenario.name!r} gives a vessel {self.layout.n_slots} neighbours: "
                "re-export the agent folder with cpf-export FOLDER OUT.onnx --slots K, K >= "
                f"{self.layout.n_slots}."
            )
        return slots

    def reset(self, seed: int | None = None) -> None:
        """Forget all internal states (the base's, the last residuals and the own histories)."""
        del seed
        self._controller = None
        self._history = None
        if self._base is not None:
            self._base.reset()
        self.diagnostics = {}

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Forget the internal states (own histories too) of the fleets in a (B,) mask."""
        if self._controller is not None:
            mask = fleet_mask(fleets, self._controller.num_fleets)
            self._controller.reset_fleets(mask)
            if self._history is not None:
                self._history.clear(np.repeat(mask, self.n))

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """Base action plus the trained correction, (B, n, 4 + m) float64.

        A ``TorchActor`` runs with one torch thread (see there): the actions have
        the same bits whatever the caller's thread setting. With a history, each
        call records the inputs and actions (``agents.envs.history.OwnHistory``).

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
            if self.config.history:
                self._history = OwnHistory(
                    batch.shape[0] * self.n, self.config.history, SLOTS, self._residual.action_size
                )
        elif self._controller.num_fleets != batch.shape[0]:
            raise ValueError(
                f"this policy holds states for B = {self._controller.num_fleets} fleets but got "
                f"B = {batch.shape[0]}; call reset() before changing the number of fleets."
            )
        inputs = self._controller.observe(batch)
        rows = inputs.reshape(-1, inputs.shape[-1]).astype(np.float32)
        if self._history is None:
            action = self.actor(rows)
        else:  # as HistoryVecEnv: act on the input and the history, then record both
            action = self.actor(self._history.append_to(rows))
            self._history.push(rows, action)
        command = self._controller.compose(np.asarray(action).reshape(*batch.shape[:2], -1))
        base_diagnostics = getattr(self._base, "diagnostics", {}) if self._base else {}
        self.diagnostics = {**base_diagnostics, "residual": self._controller.residual.copy()}
        return command
