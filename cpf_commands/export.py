"""``cpf-export``: a trained agent folder as one ONNX graph, checked against torch.

The graph holds the normalization, the network, the action bounds and the
residual scaling (``agents.folder.onnx_policy``, which documents the input layout);
``cpf-bench --policies nn_dsc agent.onnx`` runs it through onnxruntime. An
agent with a neighbour encoder is exported for ``--slots K`` neighbour slots
(default its training K; at most n - 1). The graph is tied to one fleet size
n: the training scenario's, or with ``--scenario NAME`` that scenario's (and its
force limits), so an encoder agent runs on a larger fleet than it trained on.
Needs the ``onnx`` extra.

Example::

    cpf-export results/agents/residual_ppo_s0 agent.onnx
"""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

from cpf_env.infra import atomic

__all__ = ["export_main"]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cpf-export",
        description="Export a cpf-train agent folder to ONNX (normalization, network, action "
        "bounds and residual scaling in the graph; the training config in its metadata) and "
        "report the largest difference from the torch policy on random inputs.",
        allow_abbrev=False,
    )
    parser.add_argument("folder", help="a cpf-train --out folder (data-only format)")
    parser.add_argument("out", help="the .onnx file to write")
    parser.add_argument(
        "--checks", type=int, default=1000, help="random inputs compared with torch (default 1000)"
    )
    parser.add_argument(
        "--slots",
        type=int,
        default=None,
        help="neighbour slots of the graph's input, for an agent with a neighbour encoder "
        "(default: its training K), from 1 to n - 1 (n: the fleet size of --scenario); "
        "the graph then runs graphs of degree <= K",
    )
    parser.add_argument(
        "--scenario",
        default=None,
        help="the registered scenario whose fleet the graph is built for: its size n and "
        "force limits (default: the training scenario)",
    )
    return parser


def _check_paths(folder: Path, out: Path) -> None:
    """Raise ValueError if the agent folder or the output's folder is missing, before loading."""
    from agents.folder.format import MANIFEST

    if not folder.exists():
        raise ValueError(
            f"the agent folder {str(folder)!r} does not exist; give a cpf-train --out folder."
        )
    if not folder.is_dir() or not (folder / MANIFEST).is_file():
        raise ValueError(
            f"{str(folder)!r} is not an agent folder (no {MANIFEST}); give a cpf-train --out "
            "folder."
        )
    if not out.parent.is_dir():
        raise ValueError(
            f"the folder of the output, {str(out.parent)!r}, does not exist; create it first "
            f"(mkdir -p {shlex.quote(str(out.parent))})."
        )


def export_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-export``: see ``cpf-export --help``."""
    parser = _parser()
    args = parser.parse_args(argv)
    if not args.out.endswith(".onnx"):
        parser.error(f"the output {args.out!r} must end in .onnx.")
    if args.checks < 1:
        parser.error(f"--checks must be >= 1, got {args.checks}.")
    if args.slots is not None and args.slots < 1:
        parser.error(f"--slots must be >= 1, got {args.slots}.")
    try:
        _check_paths(Path(args.folder), Path(args.out))
        from agents.folder.onnx_policy import export_onnx

        # before the work: writable, not a link, room for about twice the weights
        weights = Path(args.folder) / "policy.safetensors"
        needed = 2 * weights.stat().st_size + 2**20 if weights.is_file() else 0
        atomic.check_writable(args.out, needed)
        with atomic.FolderLock(args.out, "another cpf-export"):
            difference = export_onnx(
                args.folder, args.out, checks=args.checks, slots=args.slots, scenario=args.scenario
            )
    except (ImportError, ValueError, OSError, atomic.FolderLockedError) as error:
        parser.error(str(error))
    print(
        f"cpf-export: wrote {args.out}; max |ONNX - torch| over {args.checks} inputs: "
        f"{difference:.3g}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(export_main())
