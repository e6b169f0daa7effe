"""What a learner's own messages carry, and whether its fleet uses them.

A residual learner trained with learned messages (``ResidualConfig.messages``:
``examples/marl_residual.py --messages L``) broadcasts L entries of its own
choosing after its base's. This study plays such an agent on the ``test``
split and answers two questions:

* **Are they used?** The same agent with its learned entries cut (sent as
  zeros, so every receiver hears nothing new; the sender acts as ever),
  against the agent, paired by seed: the cost difference with its bootstrap
  interval.
* **What do they carry?** Every learned entry a vessel sends is paired with
  the sender's true state at that step (``FEATURES``): the Pearson correlation
  with each feature, and the share of the entry's variance a linear fit on
  all features explains (R^2). An entry that never moves (std below 1e-3)
  carries nothing.

Usage::

    python studies/hard_track/messages.py runs/hard/crossing_mappo_msg5_s0 \
        --scenario hard_crossing --num-seeds 20
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents import TrainedPolicy, load_policy
from cpf_bench.rollout import rollout
from cpf_bench.stats import paired_difference
from cpf_env.envs.policy import FleetPolicy
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.scenarios.splits import EVALUATION_SEED
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.observation import SLOT_AGE, SLOT_DTHETA, SLOT_WEIGHT

Array = NDArray[np.float64]

#: The sender's state each learned entry is compared with (true values, at the step it sends).
FEATURES = (
    "sync offset",  # theta_i minus the fleet's mean theta
    "path rate",  # theta_dot_i commanded at this step (1/s)
    "speed estimate",  # message entry 0: the base's v0 estimate (m/s)
    "along-track error",  # z1 x, body frame (m)
    "cross-track error",  # z1 y, body frame (m)
    "heading error",  # z1 psi (rad)
    "surge u",
    "sway v",
    "yaw rate r",
    "nearest vessel",  # distance to the closest other vessel (m)
    "heard offset",  # mean theta_j - theta_i over the linked slots, as received
    "packet age",  # mean age of the linked slots (steps)
    "time",  # s since the start
)
#: Below this standard deviation a learned entry is taken as constant.
CONSTANT = 1e-3


class MessagesCut(FleetPolicy):
    """``policy`` with its last ``learned`` message entries sent as zeros.

    Args:
        policy: A trained agent with learned messages.
        learned: How many message entries it learned (``ResidualConfig.messages``).
    """

    def __init__(self, policy: FleetPolicy, learned: int) -> None:
        self.policy, self.learned = policy, int(learned)
        self.name = f"{getattr(policy, 'name', 'agent')}, messages cut"
        self.n, self.obs_dim, self.act_dim = policy.n, policy.obs_dim, policy.act_dim
        self.agents, self.diagnostics = policy.agents, policy.diagnostics

    def act_batch(self, obs: Any, fleets: Any = None) -> Array:
        """The policy's actions (rows, n, 4 + m), the learned entries zeroed."""
        actions = self.policy.act_batch(obs, fleets)
        actions[..., actions.shape[-1] - self.learned :] = 0.0
        self.diagnostics = self.policy.diagnostics
        return actions

    def reset(self, seed: int | None = None) -> None:
        """Forget the policy's states."""
        self.policy.reset(seed)

    def reset_fleets(self, fleets: Any) -> None:
        """Forget the states of the listed fleets."""
        self.policy.reset_fleets(fleets)


class SenderRecord:
    """A ``StepObserver`` pairing each learned entry sent with its sender's state.

    Attributes:
        messages: (rows, L) the learned entries, one row per vessel and step.
        features: (rows, len(FEATURES)) the sender's state at that step.
    """

    def __init__(self, learned: int) -> None:
        self.learned = learned
        self._messages: list[Array] = []
        self._features: list[Array] = []

    def before(self, sim: FleetSim, actions: Array, policy: FleetPolicy) -> None:
        """Record the alive fleets' learned entries and their senders' state."""
        del policy
        a = sim.arrays
        alive = ~(a.terminated | a.nonfinite)
        if not alive.any():
            return
        layout = sim.layout
        obs = a.obs[alive].astype(np.float64)
        theta = a.theta[alive]
        pose = a.eta[alive, :, :2]
        gaps = np.linalg.norm(pose[:, :, None] - pose[:, None], axis=-1)
        gaps[:, np.arange(sim.scenario.n), np.arange(sim.scenario.n)] = np.inf
        starts = [layout.slot(k).start for k in range(layout.n_slots)]
        weight = np.stack([obs[..., s + SLOT_WEIGHT] for s in starts], axis=-1) != 0.0
        linked = np.maximum(weight.sum(axis=-1), 1)
        heard = np.stack([obs[..., s + SLOT_DTHETA] for s in starts], axis=-1)
        age = np.stack([obs[..., s + SLOT_AGE] for s in starts], axis=-1)
        sent = actions[alive]
        columns = [
            theta - theta.mean(axis=-1, keepdims=True),
            sent[..., 3],
            sent[..., 4],
            obs[..., layout.z1.start],
            obs[..., layout.z1.start + 1],
            obs[..., layout.z1.start + 2],
            obs[..., layout.nu.start],
            obs[..., layout.nu.start + 1],
            obs[..., layout.nu.start + 2],
            gaps.min(axis=-1),
            (heard * weight).sum(axis=-1) / linked,
            (age * weight).sum(axis=-1) / linked,
            np.broadcast_to(a.step[alive, None] * sim.scenario.dt, theta.shape),
        ]
        self._features.append(np.stack(columns, axis=-1).reshape(-1, len(FEATURES)))
        self._messages.append(sent[..., sent.shape[-1] - self.learned :].reshape(-1, self.learned))

    def after(self, sim: FleetSim) -> None:
        """Nothing after the step."""
        del sim

    @property
    def messages(self) -> Array:
        """(rows, L) the learned entries sent."""
        return np.concatenate(self._messages)

    @property
    def features(self) -> Array:
        """(rows, len(FEATURES)) the senders' states."""
        return np.concatenate(self._features)


def carried(messages: Array, features: Array) -> tuple[Array, Array, Array]:
    """Per learned entry: its std, its correlation with each feature, and R^2 of a linear fit.

    Args:
        messages: (rows, L) entries sent.
        features: (rows, F) the senders' states.

    Returns:
        std (L,); correlation (L, F), NaN where either side is constant; R^2 (L,)
        of the least-squares fit of the entry on all features and a constant, NaN
        for a constant entry.
    """
    std = messages.std(axis=0)
    centred_m = messages - messages.mean(axis=0)
    centred_f = features - features.mean(axis=0)
    scale_f = features.std(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = (centred_m.T @ centred_f) / len(messages) / np.outer(std, scale_f)
    correlation[:, scale_f < 1e-12] = np.nan
    correlation[std < CONSTANT] = np.nan
    design = np.column_stack([features[:, scale_f >= 1e-12], np.ones(len(features))])
    fit, *_ = np.linalg.lstsq(design, messages, rcond=None)
    residual = messages - design @ fit
    with np.errstate(invalid="ignore", divide="ignore"):
        r2 = 1.0 - residual.var(axis=0) / messages.var(axis=0)
    r2[std < CONSTANT] = np.nan
    return std, correlation, r2


def study(folder: Path, scenario: Scenario, num_seeds: int, base: str | None) -> list[str]:
    """The report's lines (markdown) for the agent in ``folder`` on ``scenario``."""
    seeds = [EVALUATION_SEED + k for k in range(num_seeds)]
    agent = load_policy(folder, scenario)
    if not isinstance(agent, TrainedPolicy):
        raise SystemExit(f"{folder} holds a learned filter, which sends no messages.")
    learned = agent.config.residual.messages
    if learned < 1:
        raise SystemExit(f"{folder} learned no messages (its residual.messages is 0).")
    record = SenderRecord(learned)
    costs = {"agent": rollout(agent, scenario, seeds, observer=record)["cost"]}
    costs["messages cut"] = rollout(
        MessagesCut(load_policy(folder, scenario), learned), scenario, seeds
    )["cost"]
    if base is not None:
        from baselines import make_policy

        costs[base] = rollout(make_policy(base, scenario), scenario, seeds)["cost"]
    lines = [
        f"{folder} on {scenario.name}, test split, {num_seeds} seeds; {learned} learned entries",
        "",
        "| policy | mean cost | minus the agent's (95 % interval) |",
        "|---|---|---|",
    ]
    for label, cost in costs.items():
        mean, low, high = paired_difference(cost, costs["agent"])
        lines.append(f"| {label} | {cost.mean():.2f} | {mean:+.2f} ({low:+.2f} to {high:+.2f}) |")
    std, correlation, r2 = carried(record.messages, record.features)
    lines += [
        "",
        "| entry | std | R^2 (all features) | strongest correlations |",
        "|---|---|---|---|",
    ]
    first = scenario.message_size - learned
    for j in range(learned):
        if std[j] < CONSTANT:
            lines.append(f"| {first + j} | {std[j]:.2g} | - | constant |")
            continue
        order = np.argsort(-np.nan_to_num(np.abs(correlation[j]), nan=-1.0))[:3]
        named = ", ".join(f"{FEATURES[f]} {correlation[j, f]:+.2f}" for f in order)
        lines.append(f"| {first + j} | {std[j]:.3f} | {r2[j]:.2f} | {named} |")
    return lines


def main() -> None:
    """Parse the arguments and print the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("agent", type=Path, help="an agent folder trained with learned messages")
    parser.add_argument("--scenario", default="hard_crossing")
    parser.add_argument("--num-seeds", type=int, default=20)
    parser.add_argument("--base", default="mpc_tuned", help="a design to compare, or 'none'")
    args = parser.parse_args()
    base = None if args.base == "none" else args.base
    print("\n".join(study(args.agent, make_scenario(args.scenario), args.num_seeds, base)))


if __name__ == "__main__":
    main()
