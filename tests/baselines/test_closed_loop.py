"""The compiled closed loop steps exactly as ``sim.step(policy.act_batch(obs))`` does."""

from __future__ import annotations

import numpy as np
import pytest

import baselines
from baselines.closed_loop import ClosedLoop
from baselines.policy import AnalyticPolicy
from cpf_env import scenarios
from cpf_env.evaluation.recording import CHUNK, new_record
from cpf_env.sim.fleet import PARALLEL_MIN_FLEETS, FleetSim

#: The compiled analytic policies (``AnalyticPolicy``); the receding-horizon ones step in Python.
EVERY_POLICY = tuple(
    name
    for name, cls in {**baselines.POLICIES, **baselines.PRIVILEGED}.items()
    if issubclass(cls, baselines.AnalyticPolicy)
)


def _pair(names, scenario, per_policy):
    """Two identical simulators and policy sets, reset alike: one per path."""
    task = scenarios.get(scenario)
    seeds = list(range(per_policy)) * len(names)
    sides = []
    for _ in range(2):
        sim = FleetSim(task, num_fleets=len(names) * per_policy)
        sim.reset(seeds=seeds)
        policies = [baselines.make_policy(name, task) for name in names]
        for p, policy in enumerate(policies):
            if policy.privileged:
                policy.bind_simulator(sim, np.arange(p * per_policy, (p + 1) * per_policy))
        sides.append((sim, policies))
    return sides


def _step_in_python(sim, policies, per_policy, steps):
    for _ in range(steps):
        obs = sim.arrays.obs
        sim.step(
            np.concatenate(
                [
                    policy.act_batch(obs[p * per_policy : (p + 1) * per_policy])
                    for p, policy in enumerate(policies)
                ]
            )
        )


def _assert_same(python_side, compiled_side):
    (sim_a, policies_a), (sim_b, policies_b) = python_side, compiled_side
    for name, x, y in zip(sim_a.arrays._fields, sim_a.arrays, sim_b.arrays, strict=True):
        np.testing.assert_array_equal(x, y, err_msg=name)
    for a, b in zip(policies_a, policies_b, strict=True):
        for key, value in a.diagnostics.items():
            np.testing.assert_array_equal(value, b.diagnostics[key], err_msg=f"{a.name} {key}")


@pytest.mark.parametrize(
    "scenario", ["wang2014", "bench_lossy_links", "bench_switching", "bench_large_fleet"]
)
def test_every_policy_steps_bit_for_bit_as_in_python(scenario):
    """All analytic policies side by side, serial (1 fleet each) and threaded (16 fleets in all)."""
    for per_policy in (1, -(-PARALLEL_MIN_FLEETS // len(EVERY_POLICY))):
        python_side, compiled_side = _pair(EVERY_POLICY, scenario, per_policy)
        _step_in_python(*python_side, per_policy, 90)
        loop = ClosedLoop(compiled_side[1], compiled_side[0])
        loop.run(1)
        loop.run(89)  # a run continues where the last one stopped
        _assert_same(python_side, compiled_side)


def test_a_single_policy_acts_on_every_fleet_and_a_reset_starts_it_again():
    python_side, compiled_side = _pair(["nn_dsc"], "bench_mild", 3)
    (sim_a, (policy_a,)), (sim_b, (policy_b,)) = python_side, compiled_side
    loop = ClosedLoop(policy_b, sim_b)
    for _ in range(2):
        _step_in_python(sim_a, [policy_a], 3, 40)
        loop.run(40)
        _assert_same(python_side, compiled_side)
        for sim, policy in (python_side, compiled_side):
            sim.reset(seeds=[7, 8, 9])
            policy[0].reset()


def test_the_record_holds_every_step_of_every_fleet():
    python_side, compiled_side = _pair(["nn_dsc", "backstepping"], "bench_mild", 2)
    sim_a, policies_a = python_side
    sim_b, policies_b = compiled_side
    record = new_record(sim_b.arrays)
    ClosedLoop(policies_b, sim_b).run(CHUNK, record=record)
    for k in range(CHUNK):
        _step_in_python(sim_a, policies_a, 2, 1)
        for name in ("eta", "nu", "theta", "theta_dot", "errors", "reward", "tau_command"):
            np.testing.assert_array_equal(getattr(record, name)[k], getattr(sim_a.arrays, name))
        estimates = [policy.diagnostics["speed_estimate"] for policy in policies_a]
        np.testing.assert_array_equal(record.estimate[k], np.concatenate(estimates))


def test_a_fleet_that_left_its_path_is_held_at_zero_actions():
    task = scenarios.get("bench_mild").replace(name="tight", max_path_error=3.0)
    sim = FleetSim(task, num_fleets=6)
    sim.reset(seeds=list(range(6)))
    policy = baselines.make_policy("nn_dsc", task)
    loop = ClosedLoop(policy, sim)
    loop.run(30, hold_ended=True)
    failed = loop.ended >= 0
    assert failed.any() and not failed.all()  # seeds 3 and 4 leave at once on this scenario
    assert np.array_equal(loop.live, ~failed)
    np.testing.assert_array_equal(sim.arrays.tau_command[failed], 0.0)
    assert (np.abs(sim.arrays.tau_command[~failed]).sum(axis=(1, 2)) > 0).all()


def test_policies_that_read_the_simulator_through_python_are_refused():
    task = scenarios.get("wang2014")
    sim = FleetSim(task, num_fleets=2)

    class PythonKinetics(AnalyticPolicy):
        name = "python_kinetics"

    assert ClosedLoop.supports(baselines.make_policy("nn_dsc_privileged", task))
    assert not ClosedLoop.supports(PythonKinetics(task))
    assert not ClosedLoop.supports(object())
    assert not ClosedLoop.supports(baselines.make_policy("mpc", task))
    with pytest.raises(ValueError, match="whole step is compiled"):
        ClosedLoop(PythonKinetics(task), sim)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda task, sim: ClosedLoop([], sim), "at least one policy"),
        (
            lambda task, sim: ClosedLoop([baselines.make_policy("nn_dsc", task)] * 2, sim),
            "appears twice",
        ),
        (
            lambda task, sim: ClosedLoop(
                [baselines.make_policy("nn_dsc", task) for _ in range(3)], sim
            ),
            "divisible by 3",
        ),
        (
            lambda task, sim: ClosedLoop(baselines.make_policy("nn_dsc", "bench_large_fleet"), sim),
            "does not fit",
        ),
    ],
)
def test_a_loop_that_cannot_be_built_says_why(build, message):
    task = scenarios.get("wang2014")
    with pytest.raises(ValueError, match=message):
        build(task, FleetSim(task, num_fleets=2))


def test_bad_runs_are_refused_and_a_diverged_plant_is_named():
    task = scenarios.get("wang2014")
    sim = FleetSim(task, num_fleets=2)
    loop = ClosedLoop(baselines.make_policy("nn_dsc", task), sim)
    with pytest.raises(RuntimeError, match="reset"):
        loop.run(1)
    sim.reset(seeds=[0, 1])
    with pytest.raises(ValueError, match="steps must be"):
        loop.run(0)
    with pytest.raises(ValueError, match=f"at most {CHUNK}"):
        loop.run(CHUNK + 1, record=new_record(sim.arrays))
    sim.arrays.nu[1] = 1e200  # a state the plant cannot integrate
    with pytest.raises(RuntimeError, match="diverged in fleet 1"):
        loop.run(5)
