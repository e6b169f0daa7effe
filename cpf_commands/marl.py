"""``cpf-marl``: BenchMARL's Hydra command line, with cpf_env's tasks registered.

BenchMARL's own ``benchmarl/run.py`` looks tasks up in its installed registry
and config folder, which know nothing of this package. This command is that
script with ``agents.marl.tasks`` imported first (it registers ``cpf/<task>``)
and ``agents/marl/conf`` as the primary config folder, which puts BenchMARL's
configs (algorithms, models, experiment) on Hydra's search path. Every
BenchMARL override works as documented there::

    cpf-marl algorithm=mappo task=cpf/bench_lossy_links experiment.max_n_iters=20
    cpf-marl algorithm=ippo task=cpf/bench_mild "experiment.loggers=[csv]" task.max_steps=100

Needs BenchMARL (``docs/marl.md`` gives the install lines).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from cpf_commands.common.extras import missing_extra

try:  # the benchmarl extra; on the base install, a message instead of a traceback
    import torch

    import agents.marl
    from agents.marl.compat import import_benchmarl
except ModuleNotFoundError as error:
    raise SystemExit(missing_extra("cpf-marl", error, "benchmarl")) from None

__all__ = ["marl_main"]

CONF = Path(agents.marl.__file__).parent / "conf"


def _arguments_parser() -> argparse.ArgumentParser:
    """Hydra's own parser (its options, then overrides), abbreviations refused.

    Without Hydra installed, a parser of overrides only, so that ``--help``
    still answers and the missing install is reported after parsing.
    """
    try:
        from hydra._internal.utils import get_args_parser
    except ImportError:
        parser = argparse.ArgumentParser(prog="cpf-marl", description=__doc__.splitlines()[0])
        parser.add_argument("overrides", nargs="*", help="Hydra overrides, key=value")
    else:
        parser = get_args_parser()
    parser.prog, parser.allow_abbrev = "cpf-marl", False
    return parser


def marl_main(argv: Sequence[str] | None = None) -> None:
    """Parse Hydra overrides from the command line and run the BenchMARL experiment.

    Args:
        argv: The arguments (default: ``sys.argv[1:]``): Hydra's options and
            overrides, checked first by Hydra's own parser with abbreviations
            refused (``--multi`` is not ``--multirun``), as every command here.

    Raises:
        ImportError: BenchMARL or Hydra is missing (the message gives the install lines).
    """
    arguments = list(sys.argv[1:] if argv is None else argv)
    _arguments_parser().parse_args(arguments)
    import_benchmarl()
    import hydra
    from benchmarl.hydra_config import load_experiment_from_hydra
    from hydra.core.hydra_config import HydraConfig
    from omegaconf import DictConfig, OmegaConf

    import agents.marl.tasks  # noqa: F401  (registers the cpf/<task> tasks)

    @hydra.main(version_base=None, config_path=str(CONF), config_name="config")
    def run(cfg: DictConfig) -> None:
        choices = HydraConfig.get().runtime.choices
        print(f"\nAlgorithm: {choices['algorithm']}, Task: {choices['task']}\n")
        print(OmegaConf.to_yaml(cfg))
        load_experiment_from_hydra(cfg, task_name=choices["task"]).run()

    torch.set_num_threads(1)  # small networks, a shared machine: one thread is faster
    sys.argv = [sys.argv[0], *arguments]  # Hydra reads its overrides from sys.argv
    run()


if __name__ == "__main__":
    marl_main()
