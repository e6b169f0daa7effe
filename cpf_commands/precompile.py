"""``cpf-precompile``: compile every simulator kernel once per machine or image.

Run it after installing (in a container image: as a build step), with the
``NUMBA_CACHE_DIR`` the workers will use, so that Ray trials, RLlib env
runners and test workers load the compiled kernels (about 0.35 s) instead of
each compiling them (15-30 s). See ``cpf_env.sim.precompile`` and ``docs/scaling.md``.

Example::

    NUMBA_CACHE_DIR=/shared/numba-cache cpf-precompile
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from cpf_commands.common.arguments import add_scenarios_argument

__all__ = ["precompile_main"]


def precompile_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-precompile``: see ``cpf-precompile --help``."""
    parser = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="cpf-precompile",
        description="Compile (or load from the cache) every numba kernel of the simulator, "
        "so that later processes start without compiling. Set NUMBA_CACHE_DIR to the "
        "directory your workers share; by default numba caches next to the sources.",
    )
    add_scenarios_argument(parser, "scenarios to exercise (default: all registered ones)")
    args = parser.parse_args(argv)
    from cpf_env.sim.precompile import precompile

    print(
        "cpf-precompile: loading the kernels, or compiling them if the cache is cold "
        "(about a minute on 2 cores)...",
        flush=True,
    )
    try:
        report = precompile(args.scenarios)
    except ValueError as error:
        parser.error(str(error))
    print(
        f"cpf-precompile: {report.compiled} signatures compiled and cached, "
        f"{report.loaded} loaded from the cache, over {len(report.scenarios)} scenarios "
        f"in {report.seconds:.1f} s; "
        f"cache: {report.cache_directory}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(precompile_main())
