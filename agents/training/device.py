"""The torch device a learner runs on, from a name the user gives (``--device``).

``cpf-train --device`` and ``cpf-distill --device`` take ``auto`` (a GPU if
torch sees one, else the CPU), ``cpu``, ``cuda`` or ``cuda:N`` (or any other
device string torch knows, e.g. ``mps``). The default everywhere is ``cpu``:
the small networks of this package train as fast there, and the CPU is what
the tests and the committed results use. Agent folders hold float32 tensors
written from the CPU, so a folder trained on any device loads on the CPU.
"""

from __future__ import annotations

import torch

__all__ = ["torch_device"]


def torch_device(name: str) -> torch.device:
    """The torch device of ``name``, checked to be usable here.

    Args:
        name: ``"auto"``, ``"cpu"``, ``"cuda"``, ``"cuda:N"`` or another torch device string.

    Raises:
        ValueError: A name torch does not know, or a GPU this machine (or this torch
            build) does not offer, with what to do instead.
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError) as error:
        raise ValueError(
            f"--device {name!r} is not a torch device ({error}); give auto, cpu, cuda or cuda:N."
        ) from None
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise ValueError(
                f"--device {name!r} asks for a CUDA GPU, but torch {torch.__version__} sees none "
                "(no GPU on this machine, or a CPU-only torch build); run with --device cpu "
                "(or auto), or install a CUDA build of torch on a machine with a GPU."
            )
        index = 0 if device.index is None else device.index
        if index >= torch.cuda.device_count():
            raise ValueError(
                f"--device {name!r}: torch sees {torch.cuda.device_count()} CUDA device(s), "
                f"numbered 0 .. {torch.cuda.device_count() - 1}; pick one of them."
            )
    elif device.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(
            f"--device {name!r} asks for Apple's MPS, which torch does not offer here; "
            "run with --device cpu (or auto)."
        )
    return device
