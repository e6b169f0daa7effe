"""The hard track (``cpf_env.scenarios.hard``): its scenarios, mechanisms, splits and version."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cpf_env import scenarios
from cpf_env.scenarios import hard, splits, suite

HARD = suite.list_suite("hard")
ON_CORE = list(hard.BASES)
CROSSING = [name for name in HARD if name not in hard.BASES]


def test_the_tracks_list_their_scenarios_and_an_unknown_track_is_refused() -> None:
    assert suite.list_suite() == suite.list_suite("core") == list(suite.SUITE)
    assert HARD == [factory.__name__ for factory in hard.HARD_FACTORIES]
    assert CROSSING == ["hard_crossing", "hard_large_fleet"]
    assert all(name in scenarios.list_scenarios() for name in HARD)
    with pytest.raises(ValueError, match=r"unknown track 'hardest'; choose one of \['core'"):
        suite.list_suite("hardest")
    assert suite.track_of("hard_sensing_shift") == "hard" and suite.track_of("wang2014") is None


def test_each_mechanism_is_on_at_least_two_scenarios_and_all_on_the_large_fleet() -> None:
    tasks = [scenarios.get(name) for name in HARD]
    assert sum(not task.sensors.ideal for task in tasks) >= 2
    assert sum(not task.thrusters.instant for task in tasks) >= 2
    assert sum(task.separation is not None for task in tasks) >= 2
    assert sum(not task.actuated[:, 1].any() for task in tasks) >= 2
    large = scenarios.get("hard_large_fleet")
    assert large.n >= 10 and not large.sensors.ideal and not large.thrusters.instant
    assert large.separation == hard.CROSSING_SEPARATION and not large.actuated[:, 1].any()
    assert large.v0.at(0.0) == hard.LARGE_FLEET_SPEED
    assert not splits.split_scenario("hard_large_fleet", "shift").actuated[:, 1].any()


@pytest.mark.parametrize("name", CROSSING)
def test_a_crossing_scenario_carries_the_separation_and_room_for_the_safety_broadcast(
    name: str,
) -> None:
    task = scenarios.get(name)
    assert task.separation == hard.CROSSING_SEPARATION
    assert task.message_size == hard.CROSSING_MESSAGE and task.message_max == 100.0
    assert task.max_steps == suite.BENCH_STEPS and task.n % 2 == 0
    shifted = splits.split_scenario(name, "shift")
    assert shifted.initial.position_std > task.initial.position_std
    assert shifted.links.loss_probability == pytest.approx(task.links.loss_probability + 0.2)
    assert shifted.links.delay_steps == 2 * task.links.delay_steps
    assert shifted.paths == task.paths and shifted.separation == task.separation
    if not task.sensors.ideal:
        assert shifted.sensors == hard.SHIFTED_FIX
    if not task.thrusters.instant:
        assert shifted.thrusters == hard.SHIFTED_THRUSTERS


@pytest.mark.parametrize("name", CROSSING)
def test_a_synchronized_crossing_pair_passes_between_the_collision_and_the_keep_out(
    name: str,
) -> None:
    """Partners at a common path variable come offset / sqrt(2) close: 0.57 m, inside 1.5 m."""
    task = scenarios.get(name)
    theta = np.linspace(0.0, 60.0, 600_001)
    for k in range(task.n // 2):
        east, north = (task.paths[2 * k + j].evaluate(theta)[:, 0, :2] for j in (0, 1))
        closest = np.linalg.norm(east - north, axis=1).min()
        assert closest == pytest.approx(hard.CROSSING_OFFSET / np.sqrt(2.0), abs=1e-4)
        assert task.separation.hard_distance < closest < task.separation.safe_distance


@pytest.mark.parametrize("name", ON_CORE)
def test_a_hard_scenario_is_its_core_task_with_the_mechanisms_only(name: str) -> None:
    task, core = scenarios.get(name), scenarios.get(hard.BASES[name])
    if not task.actuated[:, 1].any():  # the hull is a mechanism too
        core = hard.without_sway(core)
    same = dataclasses.replace(
        task, name=core.name, description=core.description,
        sensors=core.sensors, thrusters=core.thrusters,
    )  # fmt: skip
    assert same == core
    assert not (task.sensors.ideal and task.thrusters.instant and task.actuated[:, 1].any())


def test_without_sway_zeroes_the_sway_limits_only() -> None:
    core = suite.bench_saturation()
    hull = hard.without_sway(core)
    (low, high), (core_low, core_high) = hull.tau_limits, core.tau_limits
    assert (low[:, 1] == 0.0).all() and (high[:, 1] == 0.0).all()
    assert (high[:, [0, 2]] == core_high[:, [0, 2]]).all()
    assert (low[:, [0, 2]] == core_low[:, [0, 2]]).all()
    assert core.actuated.all() and not hull.actuated[:, 1].any()
    assert [name for name in HARD if not scenarios.get(name).actuated[:, 1].any()] == [
        "hard_underactuated", "hard_underactuated_sensing", "hard_large_fleet",
    ]  # fmt: skip


@pytest.mark.parametrize("name", ON_CORE)
def test_the_shift_split_shifts_the_core_task_and_the_mechanisms(name: str) -> None:
    task, shifted = scenarios.get(name), splits.split_scenario(name, "shift")
    core_shift = splits.split_scenario(hard.BASES[name], "shift")
    assert shifted.name == f"{name}_shift" and shifted.n == core_shift.n
    assert shifted.paths == core_shift.paths and shifted.links == core_shift.links
    if not task.sensors.ideal:
        assert shifted.sensors == hard.SHIFTED_FIX != task.sensors
    if not task.thrusters.instant:
        assert shifted.thrusters == hard.SHIFTED_THRUSTERS != task.thrusters
    assert shifted.actuated[:, 1].any() == task.actuated[:, 1].any()
    assert splits.suite_version(shifted.name) == suite.HARD_VERSION
    with pytest.raises(ValueError, match="held-out shift split"):
        splits.check_training(shifted.name, range(4))
    with pytest.raises(ValueError, match="held-out seeds"):
        splits.check_training(name, range(splits.EVALUATION_SEED, splits.EVALUATION_SEED + 2))
