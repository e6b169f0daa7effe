"""The episode core: seeding, stagger, per-fleet resets, the residual rule, inert refusals."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import cpf_env
from baselines import make_policy
from cpf_env import scenarios
from cpf_env.envs.core import EpisodeCore
from cpf_env.envs.gym_envs import CentralizedFleetEnv, CentralizedFleetVectorEnv
from cpf_env.envs.residual import ResidualConfig, learner_config
from cpf_env.sim.fleet import FleetSim

SCENARIO = scenarios.get("bench_lossy_links").replace(max_steps=40)


def snapshot(env: Any) -> dict[str, Any]:
    """Every array of the simulator (``env``, or an env's) and every fleet's generator state."""
    if isinstance(env, FleetSim):
        sim = env
    else:
        sim = env.core.sim if hasattr(env, "core") else env.sim
    arrays = {key: value.copy() for key, value in sim.arrays._asdict().items()}
    return {"arrays": arrays, "rngs": [rng.bit_generator.state for rng in sim.rngs]}


def assert_same(before: dict[str, Any], after: dict[str, Any]) -> None:
    assert before["rngs"] == after["rngs"]
    for key, value in before["arrays"].items():
        assert value.tobytes() == after["arrays"][key].tobytes(), key


def test_fleet_k_gets_seed_plus_k_and_stagger_spreads_every_full_reset() -> None:
    core = EpisodeCore(SCENARIO, num_fleets=4)
    first = core.reset(seeds=5).copy()
    single = EpisodeCore(SCENARIO, num_fleets=1)
    for k in range(4):
        assert np.array_equal(single.reset(seeds=[5 + k])[0], first[k])
    assert core.horizon.tolist() == [40, 30, 20, 10]
    core.reset(fleets=[1])
    assert core.horizon.tolist() == [40, 40, 20, 10]  # a fleet reset alone runs max_steps
    core.reset()
    assert core.horizon.tolist() == [40, 30, 20, 10]  # every reset of all fleets staggers
    flat = EpisodeCore(SCENARIO, num_fleets=4, stagger=False)
    flat.reset()
    assert set(flat.horizon.tolist()) == {40}


def test_ended_fleets_restart_with_their_terminal_inputs() -> None:
    core = EpisodeCore(SCENARIO, num_fleets=3, base_policy=make_policy("nn_dsc", SCENARIO))
    core.reset(seeds=0)
    zero = np.zeros((3, SCENARIO.n, core.action_size))
    for _ in range(int(core.horizon[2]) - 1):
        core.step(zero)
        assert core.reset_ended()[0].size == 0
    core.step(zero)
    last = core.inputs[2].copy()
    fleets, terminal = core.reset_ended()
    assert fleets.tolist() == [2] and np.array_equal(terminal[0], last)
    assert core.sim.arrays.step.tolist()[2] == 0 and core.horizon[2] == 40


def test_no_base_policy_means_the_learner_commands_forces_and_rate() -> None:
    rule = learner_config(None, ResidualConfig(scale=0.3, neighbour_slots=6))
    assert rule == ResidualConfig(mode="force_and_rate", scale=1.0, neighbour_slots=6)
    base = make_policy("nn_dsc", SCENARIO)
    assert learner_config(base, None) == ResidualConfig()
    assert EpisodeCore(SCENARIO).controller is None  # neither: the raw command


@pytest.mark.parametrize("seed", [True, -1, 1.5, "x", [7, -1, 2]])
def test_bad_seeds_change_nothing_on_any_route(seed: object) -> None:
    envs: list[Any] = [
        cpf_env.parallel_env(SCENARIO),
        CentralizedFleetEnv(SCENARIO),
        CentralizedFleetVectorEnv(SCENARIO, 3),
    ]
    for env in envs:
        env.reset(seed=3)
        before = snapshot(env)
        with pytest.raises(ValueError, match="seed"):
            env.reset(seed=seed)
        assert_same(before, snapshot(env))


def test_the_vector_view_checks_every_seed_before_resetting_any() -> None:
    envs = CentralizedFleetVectorEnv(SCENARIO, 3)
    envs.reset(seed=1)
    envs.step(np.zeros(envs.action_space.shape))
    before = snapshot(envs)
    with pytest.raises(ValueError, match="seed of fleet 1"):
        envs.reset(seed=[7, -1, 2])
    assert_same(before, snapshot(envs))


@pytest.mark.parametrize(
    "bad",
    [
        lambda a: a.astype(bool),
        lambda a: a.astype(complex),
        lambda a: np.where(a == a.flat[0], np.nan, a),
        lambda a: a[:-1],
    ],
)
def test_bad_actions_change_nothing_on_any_route(bad: Any) -> None:
    par = cpf_env.parallel_env(SCENARIO)
    par.reset(seed=0)
    before = snapshot(par)
    actions = {agent: bad(np.ones(5)) for agent in par.agents}
    with pytest.raises(ValueError, match="action"):
        par.step(actions)
    assert_same(before, snapshot(par))
    core = EpisodeCore(SCENARIO, 2, make_policy("nn_dsc", SCENARIO))
    core.reset(seeds=0)
    before = snapshot(core)
    with pytest.raises(ValueError, match="action"):
        core.step(bad(np.ones((2, SCENARIO.n, 3))))
    assert_same(before, snapshot(core))


def test_bool_actions_are_refused_by_fleet_sim_and_every_route_changing_nothing() -> None:
    """A force of ``True`` is never meant: FleetSim refuses bools as every env route does.

    The SB3 route is in ``tests/agents/test_vec_env.py``, TorchRL's in
    ``tests/cpf_env/envs/test_torchrl_env.py`` (the same ``EpisodeCore.check_actions``).
    """
    message = r"real numbers, got dtype bool \(bools are not commands\)"
    sim = FleetSim(SCENARIO, num_fleets=2)
    sim.reset(seeds=[0, 1])
    before = snapshot(sim)
    with pytest.raises(ValueError, match=message):
        sim.step(np.ones((2, SCENARIO.n, 5), dtype=bool))
    assert_same(before, snapshot(sim))
    sim.step(np.ones((2, SCENARIO.n, 5), dtype=np.int64))  # integers are numbers
    assert sim.arrays.step.tolist() == [1, 1]
    par = cpf_env.parallel_env(SCENARIO)
    par.reset(seed=0)
    before = snapshot(par)
    with pytest.raises(ValueError, match=r"action of vessel_0 .*bools are not commands"):
        par.step({agent: np.ones(5, dtype=bool) for agent in par.agents})
    assert_same(before, snapshot(par))
    aec = cpf_env.env(scenario=SCENARIO)
    aec.reset(seed=0)
    before = snapshot(aec.unwrapped)
    with pytest.raises(ValueError, match="bools are not commands"):
        aec.step(np.ones(5, dtype=bool))
    assert_same(before, snapshot(aec.unwrapped))
    assert aec.agent_selection == "vessel_0"
    single = CentralizedFleetEnv(SCENARIO)
    single.reset(seed=0)
    before = snapshot(single)
    with pytest.raises(ValueError, match=message):
        single.step(np.ones(single.action_space.shape, dtype=bool))
    assert_same(before, snapshot(single))
    vector = CentralizedFleetVectorEnv(SCENARIO, 3)
    vector.reset(seed=0)
    before = snapshot(vector)
    with pytest.raises(ValueError, match=message):
        vector.step(np.ones(vector.action_space.shape, dtype=bool))
    assert_same(before, snapshot(vector))
