"""Counter-based random numbers for the compiled simulator kernel.

Every draw is a pure function of ``(key, counter, stream, index)``: a fleet's
key (drawn once per episode from the env's ``np_random``), the control step,
a stream id (waves, wind, current, packet loss, sensor noise and dropouts)
and an element index. Draws therefore do not depend on the number of
fleets, the order in which threads run, or what other streams consumed: the
single env and fleet k of the batched simulator see the same numbers, bit
for bit.

The mixer is SplitMix64 (Steele, Lea & Flood, OOPSLA 2014), chained once per
coordinate; uniforms take the top 53 bits.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "STREAM_CURRENT",
    "STREAM_DROPOUT",
    "STREAM_FIX",
    "STREAM_LOSS",
    "STREAM_WAVES",
    "STREAM_WIND",
    "normal",
    "uniform",
]

STREAM_WAVES, STREAM_WIND, STREAM_CURRENT, STREAM_LOSS = 1, 2, 3, 4
#: The sensors' noise on each fix, and whether a scheduled fix is lost (``cpf_env.model.sensors``).
STREAM_FIX, STREAM_DROPOUT = 5, 6

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MUL1 = np.uint64(0xBF58476D1CE4E5B9)
_MUL2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TWO_POW_M53 = 1.0 / 9007199254740992.0


@numba.njit(cache=True, inline="always")
def _splitmix(x: np.uint64) -> np.uint64:
    z = x + _GOLDEN
    z = (z ^ (z >> _S30)) * _MUL1
    z = (z ^ (z >> _S27)) * _MUL2
    return z ^ (z >> _S31)


@numba.njit(cache=True)
def uniform(key: np.uint64, counter: int, stream: int, index: int) -> float:
    """Return a uniform draw in [0, 1) determined by its four coordinates."""
    h = _splitmix(key ^ np.uint64(counter))
    h = _splitmix(h ^ np.uint64(stream))
    h = _splitmix(h ^ np.uint64(index))
    return float(h >> _S11) * _TWO_POW_M53


@numba.njit(cache=True)
def normal(key: np.uint64, counter: int, stream: int, index: int) -> float:
    """Return a standard normal draw (Box-Muller on two coordinates' uniforms)."""
    u1 = 1.0 - uniform(key, counter, stream, 2 * index)
    u2 = uniform(key, counter, stream, 2 * index + 1)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)
