"""Import BenchMARL 1.5 beside TorchRL 0.14, which renamed one class it imports.

BenchMARL 1.5.x declares ``torchrl>=0.10,<0.12``; this package uses TorchRL
0.14 (``torchrl`` extra), whose ``torchrl.collectors`` calls the synchronous
collector ``Collector`` (0.11 called it ``SyncDataCollector``). BenchMARL
imports the old name once, in ``benchmarl.experiment.experiment``; its one
call runs unchanged on the new class (``tests/agents/test_marl.py``).
``import_benchmarl`` adds the old name as an alias of the new class, only if
it is missing and only for BenchMARL 1.5, then imports BenchMARL. Nothing
else of TorchRL is touched.
"""

from __future__ import annotations

import importlib
from importlib import metadata
from types import ModuleType

__all__ = ["BENCHMARL_VERSIONS", "INSTALL", "import_benchmarl"]

#: The BenchMARL releases the alias is known to fit.
BENCHMARL_VERSIONS = ("1.5.",)

#: How to install BenchMARL beside this package (BenchMARL's own pins would
#: downgrade TorchRL and, through torchvision, replace the CPU build of torch).
INSTALL = 'pip install -e ".[benchmarl]" && pip install --no-deps benchmarl==1.5.2'


def import_benchmarl() -> ModuleType:
    """BenchMARL, imported with the one alias TorchRL 0.14 needs (see the module docstring).

    Raises:
        ImportError: BenchMARL is not installed, or is a release the alias was not
            checked with (the message gives the install line).
    """
    try:
        version = metadata.version("benchmarl")
    except metadata.PackageNotFoundError:
        raise ImportError(f"BenchMARL is not installed; install it with: {INSTALL}") from None
    if not version.startswith(BENCHMARL_VERSIONS):
        raise ImportError(
            f"BenchMARL {version} is installed; cpf_env's tasks are tested with BenchMARL "
            f"{' '.join(v + 'x' for v in BENCHMARL_VERSIONS)} on TorchRL 0.14. Install: {INSTALL}"
        )
    collectors = importlib.import_module("torchrl.collectors")
    if not hasattr(collectors, "SyncDataCollector"):
        collectors.SyncDataCollector = collectors.Collector  # type: ignore[attr-defined]
    return importlib.import_module("benchmarl")
