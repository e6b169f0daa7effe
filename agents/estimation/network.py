"""The network of a ``Correction``: what the ridge regression's matrix leaves, fitted by PyTorch.

The matrix (``correction.fit``) is fitted first; the network then learns,
on the same standardized inputs, the errors the matrix leaves, each over its
spread (``Correction.target_scale``): mean squared error, Adam, minibatches,
a fixed number of epochs, the last layer starting at zero (so an untrained
network adds nothing). On ``hard_sensing`` the matrix alone takes the
validation cost from the bank's 118.3 to 106.4-106.9, the network on the
same inputs to 88.0-89.7 (docs/findings, "Learned filters"). Training draws its
minibatches and initial weights from ``seed``: same data, same seed, same
network, on one machine, device and thread count. ``device`` trains it on a
GPU (``cuda``); the correction it returns acts on the CPU, in NumPy.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from numpy.typing import NDArray

from agents.estimation.correction import CHUNK, TARGET_SIZE, Correction

__all__ = ["BATCH", "EPOCHS", "HIDDEN", "LEARNING_RATE", "WEIGHT_DECAY", "fit_network"]

#: Hidden layer widths.
HIDDEN = (256, 256)
#: Passes over the data per fit.
EPOCHS = 6
#: Samples per minibatch.
BATCH = 512
#: Adam's step size.
LEARNING_RATE = 1e-3
#: Adam's weight decay (an L2 penalty on every weight).
WEIGHT_DECAY = 1e-4


def fit_network(
    inputs: NDArray[np.float64],
    errors: NDArray[np.float64],
    linear: Correction,
    hidden: tuple[int, ...] = HIDDEN,
    epochs: int = EPOCHS,
    seed: int = 0,
    device: str = "cpu",
) -> Correction:
    """``linear`` with a network fitted on the errors it leaves (module docstring).

    Args:
        inputs: (N, D) samples (``correction.assemble``).
        errors: (N, ``TARGET_SIZE``) the estimate's errors.
        linear: The matrix fitted on the same samples (``correction.fit``), without a network.
        hidden: The hidden layers' widths (at least one).
        epochs: Passes over the samples (>= 1).
        seed: Seeds the initial weights and the minibatches.
        device: The torch device that trains it (``agents.training.device.torch_device``).

    Raises:
        ValueError: No hidden layer, a width or ``epochs`` below 1, or ``linear`` has a network.
    """
    if not hidden or min(hidden) < 1 or epochs < 1:
        raise ValueError(
            f"a network needs hidden widths >= 1 and epochs >= 1, got {hidden} and {epochs}."
        )
    if linear.layers:
        raise ValueError("fit the network on a correction without one (correction.fit).")
    target = (errors - linear.apply(inputs)) / linear.target_scale
    generator = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    widths = (inputs.shape[1], *hidden, TARGET_SIZE)
    modules: list[torch.nn.Module] = []
    for k in range(len(widths) - 1):
        modules.append(torch.nn.Linear(widths[k], widths[k + 1], dtype=torch.float32))
        if k < len(widths) - 2:
            modules.append(torch.nn.SiLU())
    network = torch.nn.Sequential(*modules).to(device)
    last = modules[-1]
    assert isinstance(last, torch.nn.Linear)
    torch.nn.init.zeros_(last.weight)
    torch.nn.init.zeros_(last.bias)
    x = torch.empty(inputs.shape, dtype=torch.float32)  # standardized a block at a time
    for k in range(0, len(inputs), CHUNK):
        block = (inputs[k : k + CHUNK] - linear.input_mean) / linear.input_scale
        x[k : k + CHUNK] = torch.from_numpy(block.astype(np.float32))
    x = x.to(device)
    y = torch.as_tensor(target, dtype=torch.float32, device=device)
    optimizer = torch.optim.Adam(network.parameters(), lr=LEARNING_RATE, weight_decay=WEIGHT_DECAY)
    for _ in range(epochs):
        order = torch.randperm(len(x), generator=generator).to(device)
        for start in range(0, len(x), BATCH):
            batch = order[start : start + BATCH]
            loss = torch.mean((network(x[batch]) - y[batch]) ** 2)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    layers = tuple(
        (
            np.ascontiguousarray(module.weight.detach().cpu().numpy().T, dtype=np.float64),
            module.bias.detach().cpu().numpy().astype(np.float64),
        )
        for module in modules
        if isinstance(module, torch.nn.Linear)
    )
    return dataclasses.replace(linear, layers=layers)
