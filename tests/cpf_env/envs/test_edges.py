"""The edges a user touches: conventions, bad input, stiff settings, divergence, latching."""

from __future__ import annotations

import dataclasses
import warnings

import numba
import numpy as np
import pettingzoo
import pytest
from gymnasium.utils.env_checker import check_env

import cpf_env
from cpf_env import scenarios
from cpf_env.envs.gym_envs import PETTINGZOO_ID, CentralizedFleetEnv, CentralizedFleetVectorEnv
from cpf_env.model.disturbances import Disturbances
from cpf_env.model.links import LinkImpairments
from cpf_env.model.vessel import CYBERSHIP2
from cpf_env.sim.fleet import FleetSim, _constants
from cpf_env.sim.observation import OBS_BOUND

# --- PettingZoo and Gymnasium conventions -----------------------------------------------


def test_max_cycles_is_the_episode_length() -> None:
    aec = pettingzoo.make("aec", PETTINGZOO_ID, max_cycles=20)
    assert aec.unwrapped.scenario.max_steps == 20
    par = pettingzoo.make("parallel", PETTINGZOO_ID, max_cycles=3)
    par.reset(seed=0)
    steps = 0
    while par.agents:
        par.step({agent: np.zeros(5) for agent in par.agents})
        steps += 1
    assert steps == 3
    assert cpf_env.parallel_env(max_cycles=7).scenario.max_steps == 7
    with pytest.raises(ValueError, match=r"max_cycles .* or max_steps, not both"):
        cpf_env.env(max_cycles=7, max_steps=8)


def test_the_aec_factory_survives_importing_cpf_env_submodules() -> None:
    # A submodule such as cpf_env.envs.core becomes a package attribute: the factory must
    # not look PettingZoo's wrappers up under such a name.
    import cpf_env.envs.core

    assert cpf_env.env(max_cycles=2).unwrapped.scenario.max_steps == 2


def test_observation_bounds_are_one_finite_rule() -> None:
    par = cpf_env.parallel_env("large_fleet")
    gym_env = CentralizedFleetEnv("large_fleet")
    vec = CentralizedFleetVectorEnv("large_fleet", 2)
    boxes = [par.observation_space("vessel_0"), par.state_space, gym_env.observation_space]
    boxes.append(vec.single_observation_space)
    for box in boxes:
        assert box.dtype == np.float32
        assert np.all(box.low == -OBS_BOUND) and np.all(box.high == OBS_BOUND)
        # SuperSuit's normalize_obs: finite bounds, and (obs - low) / (high - low) in float32.
        width = box.high - box.low
        assert np.all(np.isfinite(box.low)) and np.all(np.isfinite(width))
    observations, _ = par.reset(seed=0)
    box = par.observation_space("vessel_0")
    with np.errstate(all="raise"):
        scaled = (observations["vessel_0"] - box.low) / (box.high - box.low)
    assert np.all((scaled >= 0.0) & (scaled <= 1.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(CentralizedFleetEnv(max_steps=5), skip_render_check=True)
    assert not [str(w.message) for w in caught if "observation" in str(w.message).lower()]


# --- AEC: a bad action is rejected at its turn ------------------------------------------


@pytest.mark.parametrize("bad", [np.full(5, np.nan), np.zeros(4), np.zeros(5) + 1j, None])
def test_aec_rejects_a_bad_action_at_its_turn_and_stays_usable(bad: object) -> None:
    aec = cpf_env.env("wang2014", max_cycles=4)
    aec.reset(seed=0)
    aec.step(np.zeros(5))  # vessel_0
    assert aec.agent_selection == "vessel_1"
    with pytest.raises(ValueError, match="action of vessel_1"):
        aec.step(bad)
    assert aec.agent_selection == "vessel_1"  # the same agent acts again
    for _ in range(4):
        aec.step(np.zeros(5))
    assert aec.unwrapped.sim.arrays.step[0] == 1  # the fleet stepped after vessel_4
    aec.step(np.zeros(5))  # and the next cycle starts normally


# --- Bad input to reset, step, render and the scenario ----------------------------------


def test_reset_options_are_not_silently_ignored() -> None:
    par = cpf_env.parallel_env(max_steps=5)
    with pytest.warns(UserWarning, match=r"reset ignores options \['bogus'\]"):
        par.reset(seed=0, options={"bogus": 1})
    with pytest.raises(ValueError, match=r"reset takes no options, got \['bogus'\]"):
        CentralizedFleetEnv(max_steps=5).reset(seed=0, options={"bogus": 1})


def test_render_before_reset_raises() -> None:
    for env in (
        cpf_env.parallel_env(render_mode="rgb_array"),
        CentralizedFleetEnv(render_mode="rgb_array"),
    ):
        with pytest.raises(RuntimeError, match=r"render\(\) before reset\(\)"):
            env.render()
    with pytest.raises(RuntimeError, match=r"render\(\) before reset\(\)"):
        CentralizedFleetVectorEnv(num_envs=2, render_mode="rgb_array").render()


def test_complex_actions_are_rejected() -> None:
    par = cpf_env.parallel_env(max_steps=5)
    par.reset(seed=0)
    actions = {agent: np.zeros(5, dtype=complex) for agent in par.agents}
    with pytest.raises(ValueError, match=r"action of vessel_0 must be real numbers.*complex"):
        par.step(actions)
    assert par.sim.arrays.step[0] == 0
    sim = FleetSim(scenarios.get("wang2014"))
    sim.reset(seeds=[0])
    with pytest.raises(ValueError, match=r"real numbers.*complex"):
        sim.step(np.zeros((1, 5, 5), dtype=complex))
    gym_env = CentralizedFleetEnv(max_steps=5)
    gym_env.reset(seed=0)
    with pytest.raises(ValueError, match=r"real numbers.*complex"):
        gym_env.step(np.zeros(25, dtype=complex))


def test_numpy_integers_are_integers_and_strings_are_not_numbers() -> None:
    par = cpf_env.parallel_env(max_steps=np.int64(100))
    assert par.scenario.max_steps == 100 and type(par.scenario.max_steps) is int
    first, _ = par.reset(seed=np.int64(3))
    second, _ = par.reset(seed=3)
    assert all(np.array_equal(first[a], second[a]) for a in first)
    gym_env = CentralizedFleetEnv(max_steps=5, substeps=np.int32(5), dt=np.float32(0.05))
    obs_numpy, _ = gym_env.reset(seed=np.uint8(3))
    obs_int, _ = gym_env.reset(seed=3)
    assert np.array_equal(obs_numpy, obs_int)
    with pytest.raises(ValueError, match=r"Scenario.dt must be a real number \(s\), got '0.05'"):
        cpf_env.parallel_env(dt="0.05")
    with pytest.raises(ValueError, match=r"Scenario\.max_steps must be an integer, got True"):
        cpf_env.parallel_env(max_steps=True)


def test_delay_steps_are_checked_against_the_episode_length() -> None:
    with pytest.raises(ValueError, match="delay_steps = 3000 is not shorter than the episode"):
        cpf_env.parallel_env(links=LinkImpairments(delay_steps=3000))
    with pytest.raises(ValueError, match="delay_steps = 100000000 is not shorter"):
        cpf_env.parallel_env(links=LinkImpairments(delay_steps=10**8))
    assert cpf_env.parallel_env(links=LinkImpairments(delay_steps=2999)).scenario.max_steps == 3000


# --- Stiff settings: caught at construction, with the fix -------------------------------


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"dt": 1e3}, r"dt / substeps = 1000 / 5 = 200 s is too long.*Use substeps >= \d+"),
        ({"dt": float("inf")}, r"Scenario.dt = inf is invalid: dt must be > 0 and finite"),
        (
            {"vessels": dataclasses.replace(CYBERSHIP2, mass=1e-6, X_udot=0.0)},
            r"too long for vessel 0: its fastest linear mode.*Use substeps >= \d+",
        ),
        (
            {"disturbances": Disturbances(unmodeled_scale=1e6)},
            r"unmodeled_scale = 1e\+06.*smaller unmodeled_scale",
        ),
    ],
)
def test_stiff_scenarios_fail_at_construction_with_the_fix(overrides: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        cpf_env.parallel_env("wang2014", **overrides)


def test_the_suggested_substeps_are_accepted() -> None:
    with pytest.raises(ValueError, match=r"Use substeps >= (\d+)") as error:
        cpf_env.parallel_env(dt=50.0)
    needed = int(str(error.value).split("substeps >= ")[1].split()[0])
    assert cpf_env.parallel_env(dt=50.0, substeps=needed).scenario.substeps == needed


# --- Divergence at run time: say where and what to change; no live agents on NaN --------


def _diverging(**overrides: object) -> cpf_env.CooperativePathFollowingEnv:
    """Passes construction (the linear modes are slow) but a yaw rate of ~1e3 rad/s follows."""
    base = scenarios.get("wang2014")
    initial = dataclasses.replace(base.initial, nu=((0.0, 1.0, 0.0),) * 5)
    return cpf_env.parallel_env(
        base.replace(initial=initial, disturbances=Disturbances(unmodeled_scale=1e3)), **overrides
    )


def test_divergence_says_where_and_what_to_change_and_ends_the_episode() -> None:
    env = _diverging()
    env.reset(seed=0)
    with pytest.raises(RuntimeError) as error:
        for _ in range(50):
            env.step({agent: np.zeros(5) for agent in env.agents})
    message = str(error.value)
    assert "fleet 0" in message and "vessel_" in message and "non-finite" in message
    assert "substeps" in message and "unmodeled_scale = 1000" in message
    assert "bug" not in message
    assert env.agents == []  # no live agents over a NaN state
    with pytest.raises(RuntimeError, match="episode is over"):
        env.step({})
    observations, _ = env.reset(seed=0)
    assert all(np.all(np.isfinite(obs)) for obs in observations.values())


def test_a_diverged_fleet_must_be_reset_before_the_sim_steps_again() -> None:
    sim = FleetSim(_diverging().scenario, num_fleets=2)
    sim.reset(seeds=[0, 1])
    with pytest.raises(RuntimeError, match="the plant diverged in fleet 0"):
        for _ in range(50):
            sim.step(np.zeros((2, 5, 5)))
    steps = sim.arrays.step.copy()
    with pytest.raises(RuntimeError, match=r"fleet\(s\) \[0, 1\] diverged and have not been reset"):
        sim.step(np.zeros((2, 5, 5)))
    assert np.array_equal(sim.arrays.step, steps)  # nothing moved
    sim.reset(seeds=[0, 1])
    sim.step(np.zeros((2, 5, 5)))


# --- Termination is latched until reset --------------------------------------------------


def test_terminated_is_latched_until_reset() -> None:
    # Vessel 0 starts 1.41 m from theta = 0; moving theta away and back crosses 1.5 m twice.
    sim = FleetSim(scenarios.get("wang2014").replace(max_path_error=1.5))
    sim.reset(seeds=[0])
    assert not sim.arrays.terminated[0]
    actions = np.zeros((1, 5, 5))
    actions[..., 3] = 1.0
    for _ in range(10):
        sim.step(actions)
    assert sim.arrays.terminated[0] and sim.arrays.errors[0, 0, 0] > 1.5
    actions[..., 3] = -1.0
    for _ in range(10):
        sim.step(actions)
    assert sim.arrays.errors[0, :, 0].max() < 1.5  # back within the bound ...
    assert sim.arrays.terminated[0]  # ... and still terminated
    sim.reset(seeds=[0])
    assert not sim.arrays.terminated[0]


# --- One compilation serves every scenario and fleet size --------------------------------


def test_one_kernel_type_for_every_scenario_and_fleet_size() -> None:
    types = set()
    for name in scenarios.list_scenarios():
        scenario = scenarios.get(name)
        for fleets in (1, 3):
            sim = FleetSim(scenario, num_fleets=fleets)
            types.add((numba.typeof(sim.constants), numba.typeof(sim.arrays)))
        types.add((numba.typeof(_constants(scenario.replace(message_size=0))), None))
    assert len({constants for constants, _ in types}) == 1
    assert len({arrays for _, arrays in types if arrays is not None}) == 1
