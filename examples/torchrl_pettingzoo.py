"""The two TorchRL routes: ``PettingZooWrapper`` over the ParallelEnv, and ``TorchRLFleetEnv``.

Both give one group of agents, ``"vessel"``, with the same keys:
``("vessel", "observation")``, ``("vessel", "action")``, ``("vessel", "reward")``
and per-vessel ``done``/``terminated``/``truncated`` next to the root flags.
The wrapper route steps one fleet through Python dicts; the native env steps
B fleets in one simulator call (batch size [B]). The script checks both with
``check_env_specs``, runs a short random rollout on each, and shows that fleet
k of the native env seeded s reproduces the ParallelEnv seeded s + k.

``info_level="none"`` drops the per-step infos (the fastest wrapper route);
``"minimal"`` keeps the four errors per vessel, as ``("vessel", "info", ...)``
on both routes. The ParallelEnv's default, ``"full"``, also wraps, but costs
the wrapper a tensor per entry per vessel per step; the native env offers
only the two cheap levels.

Needs the ``torchrl`` extra (``pip install -e ".[torchrl]"``). Usage::

    python examples/torchrl_pettingzoo.py --steps 50 --info-level minimal
"""

from __future__ import annotations

import argparse
import warnings

try:
    import torch
    from torchrl.envs import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs
except ImportError as error:  # an optional stack: say which extra brings it
    raise SystemExit(
        f"{error}; this example needs the torchrl extra: "
        f'pip install -e ".[torchrl]" (your PyTorch build first)'
    ) from error

import cpf_env
from cpf_commands.common.arguments import positive_int
from cpf_env.envs.torchrl_env import GROUP, TorchRLFleetEnv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--scenario", default="wang2014", choices=cpf_env.scenarios.list_scenarios()
    )
    parser.add_argument(
        "--steps", type=positive_int, default=50, help="rollout length (control steps)"
    )
    parser.add_argument(
        "--fleets", type=positive_int, default=8, help="B of the native env (at least 2)"
    )
    parser.add_argument("--info-level", choices=["none", "minimal"], default="none")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.fleets < 2:
        parser.error("--fleets must be at least 2: the script compares fleet 1 with a ParallelEnv")
    warnings.filterwarnings("ignore", message="PettingZoo in TorchRL is tested")

    # Route 1: TorchRL's wrapper over the PettingZoo ParallelEnv (one fleet).
    parallel = cpf_env.parallel_env(args.scenario, info_level=args.info_level)
    wrapped = PettingZooWrapper(parallel)  # default group map: {"vessel": [vessel_0, ...]}
    print("wrapper group map:", wrapped.group_map)
    check_env_specs(wrapped)
    wrapped.set_seed(args.seed)
    data = wrapped.rollout(args.steps)
    reward = data["next", GROUP, "reward"]
    print(f"wrapper rollout: batch {list(data.batch_size)}, reward {list(reward.shape)}")
    print(f"  mean reward per vessel-step {reward.mean():.4f}")

    # Route 2: the native batched env, B fleets in one FleetSim.
    native = TorchRLFleetEnv(args.scenario, num_fleets=args.fleets, info_level=args.info_level)
    check_env_specs(native)
    native.set_seed(args.seed)  # fleet k draws from seed + k
    data = native.rollout(args.steps, break_when_any_done=False)
    reward = data["next", GROUP, "reward"]
    print(f"native rollout: batch {list(data.batch_size)}, reward {list(reward.shape)}")
    print(f"  mean reward per vessel-step {reward.mean():.4f}")
    if args.info_level == "minimal":
        path_error = data["next", GROUP, "info", "path_error"]
        print(f"  mean path error {path_error.mean():.4f} m")

    # Seeding: fleet 1 of the native env is the ParallelEnv reset with seed + 1.
    native.set_seed(args.seed)
    first = native.reset()[GROUP, "observation"][1]
    observations, _ = cpf_env.parallel_env(args.scenario).reset(seed=args.seed + 1)
    single = torch.stack([torch.from_numpy(observations[a]) for a in parallel.possible_agents])
    print("fleet 1 == ParallelEnv reset(seed + 1):", torch.equal(first, single))


if __name__ == "__main__":
    main()
