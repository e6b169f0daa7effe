"""Held-out splits: every suite scenario's shift lies outside its training ranges."""

from __future__ import annotations

import numpy as np
import pytest

from cpf_env import scenarios
from cpf_env.scenarios import splits, suite


def test_every_suite_scenario_has_both_splits():
    assert set(splits.SHIFTS) == set(suite.SUITE)
    for name in suite.SUITE:
        assert splits.split_scenario(name, "test") == scenarios.get(name)
        assert splits.split_scenario(name, "shift").name == f"{name}_shift"
        assert not suite.is_deterministic(splits.split_scenario(name, "shift"))


def _shift(name):
    return scenarios.get(name), scenarios.get(f"{name}_shift")


def test_shifted_conditions_are_outside_the_training_ranges():
    train, shift = _shift("bench_lossy_links")
    assert shift.links.loss_probability > train.links.loss_probability
    assert shift.links.delay_steps > train.links.delay_steps
    train, shift = _shift("bench_current_waves")
    speed = np.hypot(*shift.disturbances.current.velocity)
    assert speed > 1.9 * np.hypot(*train.disturbances.current.velocity)
    assert shift.disturbances.current.std > train.disturbances.current.std
    assert np.all(
        np.array(shift.disturbances.waves.std) >= 2 * np.array(train.disturbances.waves.std)
    )
    assert shift.model_spread > train.model_spread
    train, shift = _shift("bench_heterogeneous")
    assert shift.model_spread > train.model_spread
    train, shift = _shift("bench_saturation")
    assert shift.v0_schedule.values[0] > train.v0_schedule.values[0]
    assert np.all(np.array(shift.tau_max) < np.array(train.tau_max))
    train, shift = _shift("bench_large_fleet")
    assert shift.n != train.n
    train, shift = _shift("bench_mild")
    assert shift.paths != train.paths
    train, shift = _shift("bench_switching")
    assert shift.topology.period < train.topology.period


def test_training_refuses_evaluation_seeds_and_the_shift_split():
    splits.check_training("bench_lossy_links", range(0, 256))
    with pytest.raises(ValueError, match="evaluation seeds"):
        splits.check_training("bench_lossy_links", range(9900, 10156))
    with pytest.raises(ValueError, match="held-out shift split"):
        splits.check_training("bench_lossy_links_shift", [0])
    with pytest.raises(ValueError, match="unknown split"):
        splits.split_scenario("bench_mild", "train")
    with pytest.raises(ValueError, match="no held-out splits"):
        splits.split_scenario("wang2014", "shift")


def test_cpf_train_refuses_evaluation_seeds(capsys):
    from cpf_commands.train import train_main

    with pytest.raises(SystemExit):
        train_main(["--scenario", "bench_mild", "--seed", "10000", "--out", "unused"])
    assert "evaluation seeds" in capsys.readouterr().err
