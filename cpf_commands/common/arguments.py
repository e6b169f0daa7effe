"""argparse types shared by the commands."""

from __future__ import annotations

import argparse
from typing import Any

from cpf_env import scenarios

__all__ = ["add_scenarios_argument", "positive_int"]


def positive_int(text: str) -> int:
    """Parse an integer >= 1 (argparse type; underscores allowed, e.g. 2_000_000)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {value}")
    return value


def add_scenarios_argument(parser: argparse.ArgumentParser, help: str, **options: Any) -> None:
    """Add ``--scenarios SCENARIO [SCENARIO ...]``, registered names only.

    Args:
        parser: The command's parser.
        help: The option's help text.
        **options: More ``add_argument`` options (``default``, ``required``).
    """
    parser.add_argument(
        "--scenarios",
        nargs="+",
        choices=scenarios.list_scenarios(),
        metavar="SCENARIO",
        help=help,
        **options,
    )
