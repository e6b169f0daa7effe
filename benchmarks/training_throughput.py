"""End-to-end training throughput: PPO on FleetVecEnv, on a zero-cost VecEnv, and via SuperSuit.

Three routes with the same PPO settings (``agents.TrainConfig`` defaults) and the
same number of vessel slots, timed over whole rollouts + updates after one
warm-up rollout:

1. ``FleetVecEnv``: residual on ``nn_dsc``, one batched ``FleetSim`` (the package's route);
2. a zero-cost ``VecEnv`` of the same sizes (returns zeros): SB3's own ceiling
   on this machine, the most any env could reach;
3. SuperSuit: residual ParallelEnvs concatenated by
   ``pettingzoo_env_to_vec_env_v1`` + ``concat_vec_envs_v1`` (the route a user
   would reach for; needs ``pip install supersuit``), with fewer fleets since
   it is one Python env per fleet.

Prints vessel-steps per second (collection + updates) for each. Usage::

    python benchmarks/training_throughput.py --fleets 1024 --rollouts 3
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecEnv


class ZeroCostVecEnv(VecEnv):
    """A VecEnv that computes nothing: zero observations and rewards, never done."""

    render_mode = None

    def __init__(self, num_envs: int, obs_size: int, action_size: int) -> None:
        observation = spaces.Box(-1.0, 1.0, (obs_size,), dtype=np.float32)
        action = spaces.Box(-1.0, 1.0, (action_size,), dtype=np.float32)
        super().__init__(num_envs, observation, action)
        self._obs = np.zeros((num_envs, obs_size), np.float32)
        self._rewards = np.zeros(num_envs, np.float32)
        self._dones = np.zeros(num_envs, bool)

    def reset(self) -> np.ndarray:
        """Zeros."""
        return self._obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        """Ignore the actions."""
        del actions

    def step_wait(self) -> Any:
        """Zeros, never done."""
        return self._obs.copy(), self._rewards.copy(), self._dones.copy(), [{}] * self.num_envs

    def close(self) -> None:
        """Nothing to close."""

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """The attribute, per slot."""
        return [getattr(self, attr_name)] * self.num_envs

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Set the attribute."""
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list:
        """Call the method, per slot."""
        return [getattr(self, method_name)(*args, **kwargs)] * self.num_envs

    def env_is_wrapped(self, wrapper_class: Any, indices: Any = None) -> list[bool]:
        """Nothing is wrapped."""
        return [False] * self.num_envs


def timed_ppo(
    make_env: Callable[[], VecEnv],
    rollouts: int,
    seed: int | None = 0,
    n_epochs: int | None = None,
    batch_size: int | None = None,
) -> float:
    """Vessel-steps/s of PPO (TrainConfig defaults) over ``rollouts`` rollouts after a warm-up.

    ``seed=None`` for SuperSuit's vector env, which has no ``seed()``; ``n_epochs`` and
    ``batch_size`` override the defaults.
    """
    from agents.training.config import TrainConfig

    config = TrainConfig()
    env = make_env()
    model = PPO(
        "MlpPolicy",
        env,
        n_steps=config.n_steps,
        batch_size=min(batch_size or config.batch_size, config.n_steps * env.num_envs),
        n_epochs=n_epochs or config.n_epochs,
        device="cpu",
        policy_kwargs={"net_arch": list(config.net_arch)},
        seed=seed,
    )
    per_rollout = config.n_steps * env.num_envs
    model.learn(per_rollout)  # warm-up: compilation, allocation
    start = time.perf_counter()
    model.learn(rollouts * per_rollout, reset_num_timesteps=False)
    return rollouts * per_rollout / (time.perf_counter() - start)


def supersuit_env(fleets: int) -> VecEnv:
    """``fleets`` residual ParallelEnvs as one SB3 VecEnv through SuperSuit."""
    import supersuit

    import cpf_env
    from baselines import make_policy

    def one() -> Any:
        base = make_policy("nn_dsc", "bench_saturation")
        return cpf_env.parallel_env("bench_saturation", base_policy=base)

    vec = supersuit.pettingzoo_env_to_vec_env_v1(one())
    return supersuit.concat_vec_envs_v1(vec, fleets, num_cpus=0, base_class="stable_baselines3")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="training_throughput.py",
        description="PPO vessel-steps/s on FleetVecEnv, a zero-cost VecEnv and SuperSuit.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--fleets", type=int, default=1024, help="fleets (5 vessels each)")
    parser.add_argument("--rollouts", type=int, default=3, help="timed rollouts per route")
    parser.add_argument("--supersuit-fleets", type=int, default=64, help="fleets, SuperSuit")
    parser.add_argument("--torch-threads", type=int, default=1, help="torch intra-op threads")
    parser.add_argument(
        "--n-epochs", type=int, default=None, help="PPO epochs (default: TrainConfig)"
    )
    parser.add_argument(
        "--batch-size", type=int, default=None, help="minibatch (default: TrainConfig)"
    )
    args = parser.parse_args(argv)
    import torch

    from agents import FleetVecEnv

    torch.set_num_threads(args.torch_threads)
    fleet_env = FleetVecEnv("bench_saturation", num_fleets=args.fleets, base_policy="nn_dsc")
    obs_size = fleet_env.observation_space.shape[0]
    routes: dict[str, tuple[Callable[[], VecEnv], int, int | None]] = {
        "FleetVecEnv (residual on nn_dsc)": (lambda: fleet_env, args.fleets, 0),
        "zero-cost VecEnv (SB3 ceiling)": (
            lambda: ZeroCostVecEnv(args.fleets * 5, obs_size, 3),
            args.fleets,
            0,
        ),
    }
    try:
        import supersuit  # noqa: F401

        routes["SuperSuit + residual ParallelEnv"] = (
            lambda: supersuit_env(args.supersuit_fleets),
            args.supersuit_fleets,
            None,
        )
    except ImportError:
        print("SuperSuit not installed (pip install supersuit): its route is skipped.")
    print(f"{'route':36s} {'fleets':>7s} {'vessel-steps/s':>15s}")
    for name, (factory, fleets, seed) in routes.items():
        rate = timed_ppo(factory, args.rollouts, seed, args.n_epochs, args.batch_size)
        print(f"{name:36s} {fleets:7d} {rate:15,.0f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
