"""``cpf-precompile``: compile every simulator and policy kernel once per machine or image.

Run it after installing (in a container image: as a build step), with the
``NUMBA_CACHE_DIR`` the workers will use, so that Ray trials, RLlib env
runners and test workers load the compiled kernels (about 0.35 s) instead of
each compiling them (15-30 s). See ``cpf_env.sim.precompile`` and ``docs/scaling.md``.

Example::

    NUMBA_CACHE_DIR=/shared/numba-cache cpf-precompile
"""

from __future__ import annotations

import argparse
import time
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
    policies_seconds = _warm_policy_kernels()
    print(
        f"cpf-precompile: {report.compiled} signatures compiled and cached, "
        f"{report.loaded} loaded from the cache, over {len(report.scenarios)} scenarios "
        f"in {report.seconds:.1f} s; the analytic policies' kernels in {policies_seconds:.1f} s; "
        f"cache: {report.cache_directory}"
    )
    return 0


def _warm_policy_kernels() -> float:
    """Run the compiled analytic policies once, serial and threaded; their wall time (s).

    Alone, and in the compiled closed loop (``baselines.closed_loop``) with and
    without a record.
    """
    from baselines import make_policy
    from baselines.closed_loop import ClosedLoop
    from cpf_env import FleetSim, scenarios
    from cpf_env.evaluation.recording import new_record
    from cpf_env.sim.threads import PARALLEL_MIN_FLEETS

    start = time.perf_counter()
    task = scenarios.get("wang2014")
    for num_fleets in (2, PARALLEL_MIN_FLEETS):
        sim = FleetSim(task, num_fleets=num_fleets)
        obs = sim.reset(seeds=list(range(num_fleets)))
        for name in ("nn_dsc", "backstepping"):
            make_policy(name, task).act_batch(obs)
        loop = ClosedLoop([make_policy("nn_dsc", task), make_policy("nn_dsc_privileged", sim)], sim)
        loop.run(1)
        loop.run(1, hold_ended=True, record=new_record(sim.arrays))
    return time.perf_counter() - start


if __name__ == "__main__":
    raise SystemExit(precompile_main())
