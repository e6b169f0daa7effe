"""Compose your own cooperative path-following task from parts and run it.

Three vessels follow three different paths (a circle, a straight line and a
figure-eight), talk over a custom graph with lossy, delayed links, hear a
leader speed that changes at t = 5 s, sail in a current with wave forces, and
one of them is heavier than the others. The policy is deliberately naive and
open loop (thrust that balances drag at the leader's speed, no steering), so
the summary shows what the task asks of a real controller.

Usage::

    python examples/custom_scenario.py
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

import cpf_env
from cpf_env.model.disturbances import Disturbances, GaussMarkov, OceanCurrent
from cpf_env.model.graph import Graph
from cpf_env.model.links import LinkImpairments
from cpf_env.model.paths import Circle, Lemniscate, StraightLine
from cpf_env.model.vessel import CYBERSHIP2, damping_matrix
from cpf_env.scenarios import InitialState, Scenario, SpeedSchedule
from cpf_env.scenarios.reward_weights import RewardWeights


def build_scenario() -> Scenario:
    """A three-vessel task assembled from the package's building blocks."""
    paths = (
        Circle(cx=0.0, cy=25.0, radius=15.0, phase=-np.pi / 2),  # starts at (0, 10), heading +x
        StraightLine(x0=0.0, y0=0.0, heading=0.0),
        Lemniscate(cx=0.0, cy=-15.0, half_width=12.0),
    )
    # Start every vessel 1 m to the left of its path's first point, aligned with it.
    poses = []
    for path in paths:
        x, y, psi = path.evaluate(0.0)[0]
        poses.append((x - np.sin(psi), y + np.cos(psi), psi))
    heavy = dataclasses.replace(CYBERSHIP2, mass=27.5, X_uu=-1.6)  # loaded, draggier
    return Scenario(
        name="three_shapes",
        paths=paths,
        # 0 -- 1 -- 2, the second link half as trusted; only the middle vessel hears v0.
        topology=Graph.from_edges(3, [(0, 1), (1, 2, 0.5)], leaders=(1,)),
        initial=InitialState(eta=tuple(poses), position_std=0.2, heading_std=0.05),
        vessels=(CYBERSHIP2, heavy, CYBERSHIP2),
        v0=SpeedSchedule(times=(0.0, 5.0), values=(0.15, 0.25)),
        tau_max=((9.2, 4.5, 3.0), (12.0, 4.5, 3.0), (9.2, 4.5, 3.0)),  # vessel 1: bigger thruster
        disturbances=Disturbances(
            current=OceanCurrent(velocity=(0.03, -0.02)),
            waves=GaussMarkov(std=(0.2, 0.2, 0.05), time_constant=3.0),
        ),
        links=LinkImpairments(loss_probability=0.2, delay_steps=2),
        reward=RewardWeights(position=2.0, sync=0.5, effort=0.05, team=True),
        max_steps=2000,
        description="Circle, line and lemniscate; lossy links; current and waves.",
    )


def cruise_action(speed: float, message_size: int) -> np.ndarray:
    """Open-loop action: surge thrust equal to the drag at ``speed``, path rate ``speed``."""
    drag = damping_matrix(CYBERSHIP2.to_params(), np.array([speed, 0.0, 0.0]))[0, 0] * speed
    return np.array([drag, 0.0, 0.0, speed] + [speed] * message_size, dtype=np.float32)


def main(steps: int = 200) -> dict[str, Any]:
    """Run ``steps`` control steps of the custom scenario and print a summary.

    Returns:
        The summary: steps run, episode end flags, mean reward per vessel, final
        path errors (m), mean |theta_i - theta_j| over links and the fraction of
        vessel-steps with a saturated axis.
    """
    scenario = build_scenario()
    env = cpf_env.parallel_env(scenario, info_level="full")
    observations, infos = env.reset(seed=0)
    layout = env.layout
    print(f"{scenario.name}: {scenario.description}")
    print(
        f"agents {env.possible_agents}, observation {layout.size} floats, "
        f"action {env.action_space('vessel_0').shape[0]} floats"
    )
    rewards_sum = dict.fromkeys(env.possible_agents, 0.0)
    saturated = run = 0
    terminated = truncated = False
    while run < steps and not (terminated or truncated):
        actions = {}
        for agent in env.agents:
            # Vessels that hear v0 use it; the others use the speed a neighbour broadcast.
            obs = observations[agent]
            if obs[layout.leader][0] > 0:
                speed = float(obs[layout.v0][0])
            else:
                slots = layout.slots(obs)
                linked = slots[slots[:, 0] > 0]
                speed = float(linked[0, 3]) if len(linked) else 0.15
            actions[agent] = cruise_action(speed, scenario.message_size)
        observations, rewards, terminations, truncations, infos = env.step(actions)
        run += 1
        for agent, reward in rewards.items():
            rewards_sum[agent] += reward
        saturated += sum(bool(np.any(info["saturated"])) for info in infos.values())
        terminated, truncated = any(terminations.values()), any(truncations.values())
    theta = np.array([infos[agent]["theta"] for agent in env.possible_agents])
    edges = np.argwhere(np.triu(scenario.switching.graphs[0].adjacency) > 0)
    summary = {
        "steps": run,
        "terminated": terminated,
        "truncated": truncated,
        "mean_reward": {agent: total / run for agent, total in rewards_sum.items()},
        "final_path_error": {agent: infos[agent]["path_error"] for agent in env.possible_agents},
        "coordination_error": float(np.mean([abs(theta[i] - theta[j]) for i, j in edges])),
        "saturated_fraction": saturated / (run * scenario.n),
    }
    print(
        f"ran {run} steps ({run * scenario.dt:.1f} s), "
        f"terminated={terminated}, truncated={truncated}"
    )
    for agent in env.possible_agents:
        print(
            f"  {agent}: mean reward {summary['mean_reward'][agent]: .5f}, "
            f"final path error {summary['final_path_error'][agent]:.3f} m"
        )
    print(f"  mean |theta_i - theta_j| over links: {summary['coordination_error']:.4f}")
    print(f"  vessel-steps with a saturated axis: {summary['saturated_fraction']:.1%}")
    env.close()
    return summary


if __name__ == "__main__":
    main()
