"""Which reward form tells controllers apart? The measurement behind the default.

Runs ``nn_dsc`` and ``backstepping`` on a scenario under both reward forms of
``cpf_env.sim.reward`` (``log``, the default, and ``quadratic``) and prints, per
form and policy: the episodic cost, the share of it paid in the first 10 s,
each term's share of the cost over the last quarter, and the tail RMS path
error. A good learning signal ranks the policies as their steady-state
accuracy does and is not dominated by the first seconds.

Usage::

    python studies/residual_rl/reward_forms.py --scenario saturation_heavy
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Sequence

import numpy as np


def measure(scenario_name: str, policy_name: str, form: str, seeds: Sequence[int]) -> dict:
    """Cost split of ``policy_name`` on ``scenario_name`` under ``form``, averaged over seeds."""
    from baselines import make_policy
    from cpf_env import FleetSim, scenarios
    from cpf_env.scenarios.reward_weights import REWARD_TERMS

    base = scenarios.get(scenario_name)
    scenario = base.replace(reward=dataclasses.replace(base.reward, form=form))
    sim = FleetSim(scenario, num_fleets=len(seeds))
    policy = make_policy(policy_name, scenario)
    obs = sim.reset(seeds=list(seeds))
    steps = scenario.max_steps
    terms = np.zeros((steps, len(seeds), len(REWARD_TERMS)))
    path = np.zeros((steps, len(seeds), scenario.n))
    for t in range(steps):
        obs = sim.step(policy.act_batch(obs))
        terms[t] = -sim.arrays.reward_terms.sum(axis=1)
        path[t] = sim.arrays.errors[..., 0]
    cost = terms.sum(axis=(0, 2))
    early = terms[: round(10.0 / scenario.dt)].sum(axis=(0, 2))
    tail = terms[-steps // 4 :].sum(axis=0)
    return {
        "cost": float(cost.mean()),
        "first_10s_share": float((early / cost).mean()),
        "tail_shares": dict(
            zip(REWARD_TERMS, (tail / tail.sum(axis=1, keepdims=True)).mean(0), strict=True)
        ),
        "tail_path_rms": float(np.sqrt((path[-steps // 4 :] ** 2).mean())),
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="reward_forms.py",
        description="Cost of nn_dsc and backstepping under the log and quadratic reward forms.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--scenario", default="saturation_heavy", help="scenario name")
    parser.add_argument("--num-seeds", type=int, default=1, help="episodes (seeds 0 .. N-1)")
    args = parser.parse_args(argv)
    seeds = range(args.num_seeds)
    print(f"{args.scenario}, {args.num_seeds} episode(s); tail = last quarter")
    print("form       policy        cost      first 10 s  tail path RMS  tail cost shares")
    for form in ("log", "quadratic"):
        for policy in ("nn_dsc", "backstepping"):
            m = measure(args.scenario, policy, form, seeds)
            shares = " ".join(f"{k} {v:.0%}" for k, v in m["tail_shares"].items())
            print(
                f"{form:10s} {policy:12s} {m['cost']:9.3f}  {m['first_10s_share']:9.0%}  "
                f"{m['tail_path_rms']:13.2e}  {shares}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
