"""The rollout's compiled path measures exactly what its Python path measures."""

from __future__ import annotations

import numpy as np
import pytest

import baselines
from cpf_bench.rollout import rollout_group
from cpf_env import scenarios


class InPython:
    """A compiled baseline behind the bare policy contract, so the rollout steps it from Python."""

    def __init__(self, policy):
        self.policy = policy
        self.name = policy.name
        bind = getattr(policy, "bind_simulator", None)
        if bind is not None:
            self.bind_simulator = bind

    @property
    def diagnostics(self):
        return self.policy.diagnostics

    def act_batch(self, obs, fleets=None):
        return self.policy.act_batch(obs, fleets)

    def reset(self, seed=None):
        self.policy.reset(seed)


def _both_paths(names, task, seeds, max_steps):
    compiled = rollout_group(
        [baselines.make_policy(n, task) for n in names], task, seeds, max_steps
    )
    stepped = rollout_group(
        [InPython(baselines.make_policy(n, task)) for n in names], task, seeds, max_steps
    )
    return compiled, stepped


def _assert_equal(compiled, stepped):
    for a, b in zip(compiled, stepped, strict=True):
        assert a.keys() == b.keys()
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)


@pytest.mark.parametrize("scenario", ["bench_lossy_links", "bench_switching"])
def test_compiled_and_python_rollouts_give_the_same_metrics(scenario):
    names = ["nn_dsc", "backstepping_delay_comp", "nn_dsc_privileged"]
    task = scenarios.get(scenario)
    _assert_equal(*_both_paths(names, task, [0, 1, 2], max_steps=150))  # chunks of 64, 64, 22


def test_fleets_that_leave_their_path_are_masked_alike_on_both_paths():
    task = scenarios.get("bench_mild").replace(name="tight", max_path_error=3.0)
    compiled, stepped = _both_paths(["nn_dsc", "dsc"], task, list(range(6)), max_steps=100)
    assert 0 < compiled[0]["terminated"].sum() < 6
    _assert_equal(compiled, stepped)


def test_a_rollout_in_which_every_fleet_fails_stops_alike_on_both_paths():
    task = scenarios.get("bench_mild").replace(name="tight", max_path_error=1.0)
    compiled, stepped = _both_paths(["nn_dsc"], task, [0, 1], max_steps=200)
    assert compiled[0]["terminated"].all()
    _assert_equal(compiled, stepped)


def test_compiled_and_python_policies_mix_in_one_call_and_keep_their_order():
    task = scenarios.get("bench_mild")
    policies = [
        InPython(baselines.make_policy("dsc", task)),
        baselines.make_policy("nn_dsc", task),
        InPython(baselines.make_policy("nn_dsc", task)),
        baselines.make_policy("dsc", task),
    ]
    dsc_python, nn_compiled, nn_python, dsc_compiled = rollout_group(policies, task, [3, 4], 80)
    _assert_equal([nn_compiled, dsc_compiled], [nn_python, dsc_python])
    assert not np.array_equal(nn_compiled["cost"], dsc_compiled["cost"])
