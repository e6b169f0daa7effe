"""From how many fleets per call the compiled kernels use numba's threads.

The simulator's step (``cpf_env.sim.fleet``), the analytic policies'
``act_batch`` and their compiled closed loop (``baselines``) run a call on
the calling thread below ``PARALLEL_MIN_FLEETS`` fleets and on numba's
threads from there on. The results are the same bits either way: fleets
never interact.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

__all__ = ["DEFAULT_PARALLEL_MIN_FLEETS", "PARALLEL_MIN_FLEETS", "parallel_min_fleets"]

#: Fleets per call from which the parallel kernels run, unless ``CPF_PARALLEL_MIN_FLEETS``
#: says otherwise.
DEFAULT_PARALLEL_MIN_FLEETS = 48


def parallel_min_fleets(environ: Mapping[str, str] = os.environ) -> int:
    """Fleets per call from which the simulator's and the policies' kernels use threads.

    Below it one call runs on the calling thread: waking numba's threads, which
    wait passively (``OMP_WAIT_POLICY=PASSIVE``, set by ``import cpf_env``),
    costs more than they give. On the development machine (a 2-core VM) a
    passive wake-up took about 100-150 us, and the serial and parallel step
    broke even between 32 and 64 fleets (``docs/scaling.md``, "Threads").
    ``CPF_PARALLEL_MIN_FLEETS`` moves it (lower on a machine of many cores or
    with ``OMP_WAIT_POLICY=ACTIVE``).

    Raises:
        ValueError: ``CPF_PARALLEL_MIN_FLEETS`` is not an integer >= 1.
    """
    text = environ.get("CPF_PARALLEL_MIN_FLEETS")
    if text is None:
        return DEFAULT_PARALLEL_MIN_FLEETS
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise ValueError(
            f"CPF_PARALLEL_MIN_FLEETS must be an integer >= 1 (fleets per call from which "
            f"the kernels use threads), got {text!r}; unset it for the default "
            f"{DEFAULT_PARALLEL_MIN_FLEETS}."
        )
    return value


#: Below this many fleets per call the serial kernels run (``parallel_min_fleets``).
PARALLEL_MIN_FLEETS = parallel_min_fleets()
