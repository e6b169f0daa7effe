"""A hull without a sway actuator (sway limits 0 and 0): accepted, and no sway force ever acts."""

from __future__ import annotations

import numpy as np
import pytest

import baselines
from cpf_env import scenarios
from cpf_env.sim.fleet import FleetSim

#: bench_mild's vessels with no sway force: a propeller and a rudder.
UNDERACTUATED = scenarios.get("bench_mild").replace(
    tau_max=(9.2, 0.0, 3.0), tau_min=(-9.2, 0.0, -3.0)
)


@pytest.mark.parametrize("policy", ["nn_dsc", "ilos", "backstepping"])
def test_no_sway_force_acts_whatever_the_policy_commands(policy: str) -> None:
    sim = FleetSim(UNDERACTUATED, num_fleets=2)
    controller = baselines.make_policy(policy, UNDERACTUATED)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(300):
        actions = controller.act_batch(obs)
        obs = sim.step(actions)
        assert np.all(sim.arrays.tau_applied[..., 1] == 0.0)
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(sim.arrays.reward))
    assert UNDERACTUATED.tau_scale[0].tolist() == [9.2, 1.0, 3.0]  # 1 where there is no actuator
    assert UNDERACTUATED.actuated[0].tolist() == [True, False, True]


def test_an_axis_limited_on_one_side_only_is_refused_saying_what_to_give() -> None:
    with pytest.raises(ValueError, match="tau_min = tau_max = 0 on an axis without an actuator"):
        scenarios.get("bench_mild").replace(tau_max=(9.2, 0.0, 3.0), tau_min=(-9.2, -1.0, -3.0))


def test_the_action_space_gives_an_axis_without_an_actuator_its_unit_scale() -> None:
    """+-1 N (``tau_scale``), not a Box of equal bounds; a command there applies nothing."""
    import cpf_env

    env = cpf_env.parallel_env(UNDERACTUATED)
    space = env.action_space(env.possible_agents[0])
    np.testing.assert_array_equal(space.low[:3], np.float32([-9.2, -1.0, -3.0]))
    np.testing.assert_array_equal(space.high[:3], np.float32([9.2, 1.0, 3.0]))
    env.reset(seed=0)
    env.step({agent: space.high.copy() for agent in env.agents})
    assert np.all(env.core.sim.arrays.tau_applied[..., 1] == 0.0)
