"""The simulator's entry kernels: tuple dispatch, checks inside the kernel, read-only arrays."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_unchanged, random_actions, snapshot

from cpf_env import scenarios
from cpf_env.sim import kernels
from cpf_env.sim.fleet import PARALLEL_MIN_FLEETS, FleetSim


def _twins(name: str, num_fleets: int) -> tuple[FleetSim, FleetSim]:
    sims = FleetSim(scenarios.get(name), num_fleets), FleetSim(scenarios.get(name), num_fleets)
    for sim in sims:
        sim.reset(seeds=list(range(num_fleets)))
    return sims


@pytest.mark.parametrize("num_fleets", [2, PARALLEL_MIN_FLEETS])
def test_the_entry_kernels_step_as_the_per_fleet_step_bit_for_bit(num_fleets: int) -> None:
    """FleetSim.step (tuples in, serial or parallel) equals step_fleet on the named tuples."""
    sim, reference = _twins("lossy_links", num_fleets)
    rng = np.random.default_rng(3)
    for _ in range(20):
        actions = random_actions(rng, sim)
        sim.step(actions)
        for b in range(num_fleets):
            kernels.step_fleet(reference.arrays, reference.constants, actions, b)
    assert sim.arrays.step[0] == 20
    for name, value in reference.arrays._asdict().items():
        assert np.array_equal(getattr(sim.arrays, name), value), f"arrays.{name} differs"


@pytest.mark.parametrize("num_fleets", [2, PARALLEL_MIN_FLEETS])
def test_a_non_finite_action_changes_nothing_in_either_kernel(num_fleets: int) -> None:
    sim = FleetSim(scenarios.get("wang2014"), num_fleets)
    sim.reset(seeds=list(range(num_fleets)))
    actions = random_actions(np.random.default_rng(0), sim)
    sim.step(actions)
    actions[num_fleets - 1, 4, 0] = np.nan  # the last entry the kernel's check reaches
    before = snapshot(sim)
    with pytest.raises(ValueError, match=rf"fleet {num_fleets - 1}, vessel_4, component 0 is nan"):
        sim.step(actions)
    assert_unchanged(before, sim)


def test_a_diverged_fleet_is_reported_before_a_bad_action() -> None:
    """The order of the checks is the one FleetSim.step always had: diverged fleets first."""
    sim = FleetSim(scenarios.get("wang2014"), 2)
    sim.reset(seeds=[0, 1])
    sim.arrays.nonfinite[1] = True  # as a divergence the caller ignored leaves it
    for bad in (np.zeros((2, 5, 6)), np.full((2, 5, 5), np.nan), np.zeros((2, 5, 5), complex)):
        with pytest.raises(RuntimeError, match=r"fleet\(s\) \[1\] diverged"):
            sim.step(bad)
    assert sim.arrays.step.tolist() == [0, 0]


def test_arrays_and_constants_are_the_kernels_own_and_cannot_be_replaced() -> None:
    """The kernels get tuples of these very arrays, so replacing them would go unseen."""
    sim = FleetSim(scenarios.get("wang2014"), 2)
    with pytest.raises(AttributeError):
        sim.arrays = sim.arrays._replace(eta=np.zeros_like(sim.arrays.eta))  # type: ignore[misc]
    with pytest.raises(AttributeError):
        sim.constants = sim.constants._replace(dt=1.0)  # type: ignore[misc]
    sim.reset(seeds=[0, 1])
    eta = sim.arrays.eta
    sim.step(np.zeros((2, 5, 5)))
    assert sim.arrays.eta is eta and not np.array_equal(eta, np.zeros_like(eta))


def test_the_thread_threshold_is_read_from_the_environment_and_checked() -> None:
    from cpf_env.sim.threads import DEFAULT_PARALLEL_MIN_FLEETS, parallel_min_fleets

    assert parallel_min_fleets({}) == DEFAULT_PARALLEL_MIN_FLEETS
    assert parallel_min_fleets({"CPF_PARALLEL_MIN_FLEETS": "8"}) == 8
    for bad in ("0", "-3", "many", "2.5"):
        with pytest.raises(ValueError, match="CPF_PARALLEL_MIN_FLEETS must be an integer >= 1"):
            parallel_min_fleets({"CPF_PARALLEL_MIN_FLEETS": bad})
