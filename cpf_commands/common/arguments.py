"""argparse types shared by the commands."""

from __future__ import annotations

import argparse
from typing import Any

from cpf_env import scenarios

__all__ = ["add_scenarios_argument", "non_negative_int", "positive_int"]


def _integer_at_least(text: str, low: int) -> int:
    """Parse an integer >= ``low`` (underscores allowed, e.g. 2_000_000)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {text!r}") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {value}")
    return value


def positive_int(text: str) -> int:
    """Parse an integer >= 1 (argparse type; underscores allowed, e.g. 2_000_000)."""
    return _integer_at_least(text, 1)


def non_negative_int(text: str) -> int:
    """Parse an integer >= 0 (argparse type; 0 turns a periodic action off)."""
    return _integer_at_least(text, 0)


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
