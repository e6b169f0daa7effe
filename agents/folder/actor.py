"""The deterministic actor of an agent folder: its network, and how it is built.

``PolicyNetwork`` maps (R, k) float32 inputs to (R, a) actions in [-1, 1]:
an MLP with ``tanh`` (PPO) or ``ReLU`` (SAC) hidden layers (``ACTORS``),
optionally behind a DeepSets neighbour encoder (``agents.folder.encoder``), whose
deterministic action is the output clipped to [-1, 1] (PPO, as SB3's
``predict`` clips) or squashed by ``tanh`` and unscaled as SB3 does (SAC), in
float32, so it has the bits of SB3's ``predict``. ``build_actor`` builds the
one ``cpf-train`` trains for a ``TrainConfig`` (untrained, for other learners
such as ``agents.distill.dagger``); ``actor_tensors`` and ``sb3_actor_layers`` take
it out of a trained SB3 model; ``actor_record`` and ``encoder_layout`` are
the layout that ``agents.folder.format`` writes beside the weights.
"""

from __future__ import annotations

import itertools
from typing import Any

import torch

from agents.folder.encoder import NeighbourSetEncoder
from agents.training.config import TrainConfig
from cpf_env.sim.observation import SLOTS

__all__ = [
    "ACTORS",
    "ENCODER_HIDDEN",
    "ENCODER_POOLING",
    "PolicyNetwork",
    "actor_record",
    "actor_tensors",
    "build_actor",
    "encoder_layout",
    "sb3_actor_layers",
]

#: Hidden-layer activation and output transform of each algorithm's actor.
ACTORS = {"ppo": ("tanh", "clip"), "sac": ("relu", "tanh")}
#: Width of the encoder's per-slot MLP and its pooling, for ``TrainConfig(encoder="deepsets")``.
ENCODER_HIDDEN, ENCODER_POOLING = 32, "mean"


class PolicyNetwork(torch.nn.Module):
    """The deterministic actor: (R, k) float32 inputs -> (R, a) actions in [-1, 1].

    Without an encoder the input has the training layout's k floats
    (``input_size``). With one, the MLP reads the encoder's features, and the
    input may have any number K of neighbour slots (``18 + K (3 + m) + tail``
    floats; ``input_size`` is None).

    Args:
        sizes: Layer widths, input first (the encoder's ``features_dim`` with an
            encoder) and action size last.
        activation: ``"tanh"`` or ``"relu"`` between hidden layers.
        output: ``"clip"`` (clip to [-1, 1]) or ``"tanh"`` (squash, then SB3's unscaling).
        encoder: A ``NeighbourSetEncoder`` in front of the MLP, or None.
    """

    input_size: int | None

    def __init__(
        self,
        sizes: list[int],
        activation: str,
        output: str,
        encoder: NeighbourSetEncoder | None = None,
    ) -> None:
        super().__init__()
        if encoder is not None and encoder.features_dim != sizes[0]:
            raise ValueError(
                f"the encoder gives {encoder.features_dim} features but the MLP's layer sizes "
                f"{sizes} start at {sizes[0]}."
            )
        self.activation, self.output_transform = activation, output
        self.encoder = encoder
        self.hidden = torch.nn.ModuleList(
            torch.nn.Linear(a, b) for a, b in itertools.pairwise(sizes[:-1])
        )
        self.output = torch.nn.Linear(sizes[-2], sizes[-1])
        self.input_size = sizes[0] if encoder is None else None
        self.action_size = sizes[-1]

    def unbounded(self, rows: torch.Tensor) -> torch.Tensor:
        """The output layer's values (R, a), before the output transform bounds them."""
        act = torch.tanh if self.activation == "tanh" else torch.relu
        latent = rows if self.encoder is None else self.encoder(rows)
        for layer in self.hidden:
            latent = act(layer(latent))
        return self.output(latent)

    def forward(self, rows: torch.Tensor) -> torch.Tensor:
        """Deterministic actions (R, a) in [-1, 1]."""
        action = self.unbounded(rows)
        if self.output_transform == "clip":
            return torch.clamp(action, -1.0, 1.0)
        return -1.0 + 0.5 * (torch.tanh(action) + 1.0) * 2.0  # SB3's unscale_action on [-1, 1]


def build_actor(config: TrainConfig, input_size: int, action_size: int) -> PolicyNetwork:
    """The untrained actor of a run: an MLP, or the neighbour encoder and an MLP.

    The layers are those SB3 builds for ``config`` (``net_arch``, the algorithm's
    activation and output transform; ``agents.training.algorithms.build_model``), with
    torch's default initialization (seed torch first for the same weights).
    ``agents.distill.dagger`` builds its student with it, for learners other than SB3.

    Args:
        config: The run (``algo``, ``net_arch``, ``encoder``, ``history``, slots).
        input_size: The learner's input length per vessel with the training
            layout's K slots, the extras and the history.
        action_size: Floats per action.

    Raises:
        ValueError: With an encoder, an ``input_size`` shorter than the own features
            and K slots of ``config``.
    """
    encoder = None
    first = input_size
    if config.encoder is not None:
        slots, slot_size = config.learner_slots()
        tail = input_size - SLOTS - slots * slot_size
        if tail < 0:
            raise ValueError(
                f"an input of {input_size} floats is shorter than the own features and "
                f"{slots} slots of {slot_size} floats ({SLOTS + slots * slot_size}) this run has."
            )
        encoder = NeighbourSetEncoder(
            slot_size, tail=tail, hidden=ENCODER_HIDDEN, pooling=ENCODER_POOLING
        )
        first = encoder.features_dim
    return PolicyNetwork([first, *config.net_arch, action_size], *ACTORS[config.algo], encoder)


def actor_record(network: PolicyNetwork, config: TrainConfig) -> dict[str, Any] | None:
    """``config.json``'s ``actor`` field (format version 2), or None for version 1.

    Raises:
        ValueError: The network has an encoder and ``config`` none, or the reverse.
    """
    if (network.encoder is None) != (config.encoder is None):
        raise ValueError(
            f"the network {'has no' if network.encoder is None else 'has an'} encoder but the "
            f"configuration's encoder is {config.encoder!r}."
        )
    if network.encoder is None and config.history == 0:
        return None
    record: dict[str, Any] = {"encoder": config.encoder, "history": config.history}
    if network.encoder is not None:
        record.update(encoder_layout(network.encoder), slots=config.learner_slots()[0])
    return record


def encoder_layout(encoder: NeighbourSetEncoder) -> dict[str, Any]:
    """The encoder's pooling, hidden width, slot size and tail (``network_from_tensors``)."""
    return {
        "pooling": encoder.pooling,
        "hidden": encoder.hidden,
        "slot_size": encoder.slot_size,
        "tail": encoder.tail,
    }


def sb3_actor_layers(
    model: Any, algo: str
) -> tuple[NeighbourSetEncoder | None, list[torch.nn.Linear], torch.nn.Linear]:
    """The deterministic actor's modules in an SB3 PPO or SAC model (``PolicyNetwork``'s parts).

    Returns:
        The PPO actor's neighbour encoder (of its ``DeepSetsExtractor``) or None,
        the hidden linear layers in order, and the output layer.
    """
    extractor = getattr(model.policy, "pi_features_extractor", None) if algo == "ppo" else None
    encoder = getattr(extractor, "encoder", None)
    if algo == "ppo":
        hidden = model.policy.mlp_extractor.policy_net
        output = model.policy.action_net
    else:
        hidden = model.actor.latent_pi
        output = model.actor.mu
    layers = [module for module in hidden if isinstance(module, torch.nn.Linear)]
    return (encoder if isinstance(encoder, NeighbourSetEncoder) else None), layers, output


def actor_tensors(model: Any, algo: str) -> dict[str, torch.Tensor]:
    """The deterministic actor's layers of an SB3 PPO or SAC model, as ``PolicyNetwork`` names.

    A PPO model whose actor reads a ``DeepSetsExtractor`` gives its encoder's
    tensors too (``encoder.*``). The tensors are copies on the CPU, whatever
    device the model trains on, so the folder written loads on the CPU.
    """
    tensors: dict[str, torch.Tensor] = {}
    encoder, layers, output = sb3_actor_layers(model, algo)
    if encoder is not None:
        for name, value in encoder.state_dict().items():
            tensors[f"encoder.{name}"] = value.detach().cpu().clone()
    for i, layer in enumerate(layers):
        tensors[f"hidden.{i}.weight"] = layer.weight.detach().cpu().clone()
        tensors[f"hidden.{i}.bias"] = layer.bias.detach().cpu().clone()
    tensors["output.weight"] = output.weight.detach().cpu().clone()
    tensors["output.bias"] = output.bias.detach().cpu().clone()
    return tensors
