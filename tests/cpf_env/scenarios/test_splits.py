"""Held-out splits: every suite scenario's shift lies outside its training ranges."""

from __future__ import annotations

import numpy as np
import pytest

from cpf_env import scenarios
from cpf_env.scenarios import splits, suite


def test_every_suite_scenario_has_both_splits():
    tracks = [*suite.list_suite("core"), *suite.list_suite("hard")]
    assert set(splits.SHIFTS) == set(tracks)
    for name in tracks:
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


def test_training_refuses_held_out_seeds_and_the_shift_split():
    splits.check_training("bench_lossy_links", range(0, 256))
    splits.check_training("bench_lossy_links", range(splits.VALIDATION_SEED - 256, 9_000))
    with pytest.raises(ValueError, match="held-out seeds"):
        splits.check_training("bench_lossy_links", range(9900, 10156))
    with pytest.raises(ValueError, match=r"held-out seeds \(from 9000; seeds 9000-9999 select"):
        splits.check_training("bench_lossy_links", range(8990, 9001))
    with pytest.raises(ValueError, match="held-out shift split"):
        splits.check_training("bench_lossy_links_shift", [0])
    with pytest.raises(ValueError, match="unknown split"):
        splits.split_scenario("bench_mild", "train")
    with pytest.raises(ValueError, match="no held-out splits"):
        splits.split_scenario("wang2014", "shift")


def test_cpf_train_refuses_evaluation_seeds(capsys):
    from cpf_commands.train import train_main

    with pytest.raises(SystemExit):
        train_main(["--scenarios", "bench_mild", "--seed", "10000", "--out", "unused"])
    assert "held-out seeds" in capsys.readouterr().err


@pytest.mark.parametrize("split", splits.SPLITS)
def test_switching_cuts_the_leader_off_while_v0_steps_inside_the_scored_window(split):
    """Both v0 steps fall while no vessel hears the leader, the second in the last 25 %."""
    scenario = splits.split_scenario("bench_switching", split)
    topology, schedule = scenario.topology, scenario.v0_schedule
    steps = scenario.max_steps
    window = range(int(0.75 * steps), steps)  # the bench's final window
    assert len({topology.index_at(step) for step in window}) >= 2  # it switches there
    for time in schedule.times[1:]:
        step = round(time / scenario.dt)
        assert not topology.graph_at(step).leaders, f"v0 steps at {time} s with a leader link"
        assert schedule.at(time) != schedule.at(time - scenario.dt)
    assert round(schedule.times[-1] / scenario.dt) in window
    assert scenario.v0_schedule == scenarios.get("bench_switching").v0_schedule


def test_suite_version_belongs_to_suite_scenarios_and_their_shifts():
    assert splits.suite_version("bench_switching") == suite.SUITE_VERSION
    assert splits.suite_version("bench_switching_shift") == suite.SUITE_VERSION
    assert splits.suite_version("switching_topology") is None
