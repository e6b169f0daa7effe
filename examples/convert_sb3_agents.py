"""Convert old SB3 agent folders (model.zip + vecnormalize.pkl) to the data-only format.

The old folders are pickles: converting one unpickles it, which runs any code
its author put in it, so convert only folders you made or trust. Each folder
is replaced atomically by one holding ``policy.safetensors``,
``normalization.json``, ``config.json`` and ``manifest.json`` (no pickle), or
written to ``--out`` when one folder is given.

This is how the agents under ``results/`` were converted::

    python examples/convert_sb3_agents.py results/residual_rl/agents/*/
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from agents.legacy import convert_sb3_folder, is_sb3_folder


def main(argv: Sequence[str] | None = None) -> int:
    """Convert each folder given; see ``--help``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    parser.add_argument("folders", nargs="+", type=Path, help="SB3 agent folders you trust")
    parser.add_argument("--out", type=Path, default=None, help="destination (one folder only)")
    args = parser.parse_args(argv)
    if args.out is not None and len(args.folders) != 1:
        parser.error("--out takes one source folder.")
    for folder in args.folders:
        if not is_sb3_folder(folder):
            parser.error(f"{folder} is not an SB3 agent folder (model.zip and config.json).")
        target = convert_sb3_folder(folder, args.out or folder)
        print(f"converted {folder} -> {target}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
