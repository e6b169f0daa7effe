"""FleetSim.reset checks every seed before it resets any fleet: a refused call changes nothing."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from cpf_env import scenarios
from cpf_env.sim.fleet import FleetSim


def _state(sim: FleetSim) -> dict[str, Any]:
    """Every array (copied) and every fleet generator's state."""
    arrays = {name: np.array(value, copy=True) for name, value in sim.arrays._asdict().items()}
    return {"arrays": arrays, "rngs": [rng.bit_generator.state for rng in sim.rngs]}


@pytest.fixture(scope="module")
def sim() -> FleetSim:
    sim = FleetSim(scenarios.get("bench_mild"), num_fleets=3)
    sim.reset(seeds=[0, 1, 2])
    sim.step(np.zeros((3, sim.n, sim.act_dim)))
    return sim


@pytest.mark.parametrize(
    "seeds",
    [[7, -1, 2], [7, 1.5, 2], [7, "x", 2], [7, True, 2], [7, 2], 1.5, "x", True, 7, "abc"],
)
def test_a_refused_reset_leaves_every_array_and_generator_as_it_was(
    sim: FleetSim, seeds: Any
) -> None:
    before = _state(sim)
    with pytest.raises(ValueError, match="seed"):
        sim.reset(seeds=seeds)
    after = _state(sim)
    assert after["rngs"] == before["rngs"]
    for name, value in before["arrays"].items():
        np.testing.assert_array_equal(after["arrays"][name], value, err_msg=name, strict=True)
        assert after["arrays"][name].tobytes() == value.tobytes(), name


def test_numpy_integers_and_none_are_seeds(sim: FleetSim) -> None:
    first = sim.reset(seeds=[np.int64(3), None, np.uint32(5)]).copy()
    again = sim.reset(seeds=np.array([3, 4, 5])).copy()
    np.testing.assert_array_equal(first[[0, 2]], again[[0, 2]])
