"""A BenchMARL actor that reads the neighbour slots through the DeepSets encoder.

BenchMARL's ``MlpConfig`` actor reads each vessel's flat local input of K
neighbour slots, so it is tied to K and to the slots' order. ``NeighbourSetMlp``
runs ``agents.folder.encoder.NeighbourSetEncoder`` over the slots (one shared slot MLP,
mean or sum over the linked slots) and an MLP over the encoder's features: the
actor of ``agents.folder.actor.PolicyNetwork``, the one the SB3 learner and
``cpf-distill`` train, with the same tensor names. One network runs on any
degree; ``agents.marl.policy_folder.save_marl_policy`` saves it, and
``cpf-bench`` runs the folder on scenarios with more neighbours than trained.

Its inputs need one set of statistics for every slot, with the links' weights
a_ij left raw (an empty slot reads exactly 0): train on a task with
``shared_slot_statistics: true`` (``CpfTaskConfig``). The actor is parameter-
shared and decentralised (each vessel's own input): use it as the model of
MAPPO or IPPO, with any critic (e.g. ``MlpConfig`` on the global state)::

    from agents.marl.models import NeighbourSetMlpConfig

    task = CpfTask.BENCH_LOSSY_LINKS.get_from_yaml()
    task.config["shared_slot_statistics"] = True
    model = NeighbourSetMlpConfig.for_task(task.config)
    Experiment(task=task, model_config=model, critic_model_config=MlpConfig.get_from_yaml(), ...)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from tensordict import TensorDictBase

from agents.folder.actor import PolicyNetwork
from agents.folder.encoder import POOLINGS, NeighbourSetEncoder
from agents.marl.compat import import_benchmarl
from agents.marl.tasks import CpfTaskConfig, checked_config
from cpf_env.envs.residual import EXTRAS
from cpf_env.scenarios import make_scenario
from cpf_env.sim.fleet import observation_layout

import_benchmarl()

from benchmarl.models.common import Model, ModelConfig  # noqa: E402

__all__ = ["NeighbourSetMlp", "NeighbourSetMlpConfig"]


class NeighbourSetMlp(Model):
    """BenchMARL model: ``PolicyNetwork`` with a ``NeighbourSetEncoder``, shared by the vessels.

    Keyword args (``NeighbourSetMlpConfig``'s fields, then BenchMARL's model arguments):
        num_cells: Hidden widths of the MLP after the encoder.
        hidden: Width of the encoder's slot MLP.
        pooling: ``"mean"`` or ``"sum"`` over the linked slots.
        slot_size: Floats per neighbour slot, 3 + m.
        tail: Floats after the slots (the residual's extras).

    Attributes:
        network: The ``PolicyNetwork``; the model's output is its ``unbounded`` values.
    """

    def __init__(self, **kwargs: Any) -> None:
        num_cells = list(kwargs.pop("num_cells"))
        hidden, pooling = int(kwargs.pop("hidden")), str(kwargs.pop("pooling"))
        slot_size, tail = int(kwargs.pop("slot_size")), int(kwargs.pop("tail"))
        super().__init__(**kwargs)
        encoder = NeighbourSetEncoder(slot_size, tail, hidden, pooling)
        (spec,) = self.input_spec.values(True, True)
        encoder.slots_in(int(spec.shape[-1]))  # the input is 18 + K slots + tail
        outputs = int(self.output_leaf_spec.shape[-1])
        self.network = PolicyNetwork(
            [encoder.features_dim, *num_cells, outputs], "tanh", "tanh", encoder
        ).to(self.device)

    def _perform_checks(self) -> None:
        """One input with the vessel dimension, parameters shared, decentralised."""
        super()._perform_checks()
        if len(self.in_keys) != 1 or not self.input_has_agent_dim:
            raise ValueError(
                "NeighbourSetMlp reads one per-vessel input (the local observation); use it as "
                f"the actor, not as a critic on the global state. Inputs: {self.in_keys}."
            )
        if self.centralised or not self.share_params:
            raise ValueError(
                "NeighbourSetMlp is one network for every vessel on its own input: "
                "share_policy_params=True and a decentralised actor (MAPPO, IPPO)."
            )

    def _forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """The output layer's values [..., n, outputs] of each vessel's input [..., n, d]."""
        tensordict.set(self.out_key, self.network.unbounded(tensordict.get(self.in_keys[0])))
        return tensordict


@dataclass
class NeighbourSetMlpConfig(ModelConfig):
    """Config of ``NeighbourSetMlp`` (``for_task`` fills the slot layout from a task)."""

    slot_size: int
    tail: int = 0
    num_cells: list[int] = field(default_factory=lambda: [64, 64])
    hidden: int = 32
    pooling: str = "mean"

    def __post_init__(self) -> None:
        if self.pooling not in POOLINGS:
            raise ValueError(f"pooling must be one of {POOLINGS}, got {self.pooling!r}.")

    @classmethod
    def for_task(
        cls, config: CpfTaskConfig | dict[str, Any], **fields: Any
    ) -> NeighbourSetMlpConfig:
        """The config whose slot size (3 + m) and tail (extras) are the task's inputs'.

        Raises:
            ValueError: A task whose inputs are not normalized with shared slot statistics.
        """
        task = config if isinstance(config, CpfTaskConfig) else checked_config(dict(config))
        if task.normalize and not task.shared_slot_statistics:
            raise ValueError(
                "the encoder runs one set of weights on every slot, so the slots need one set "
                "of statistics: set the task's shared_slot_statistics: true."
            )
        layout = observation_layout(make_scenario(task.scenario, **task.overrides))
        tail = sum(EXTRAS[name] for name in task.extras)
        return cls(slot_size=layout.slot_size, tail=tail, **fields)

    @staticmethod
    def associated_class() -> type[Model]:
        """``NeighbourSetMlp``."""
        return NeighbourSetMlp
