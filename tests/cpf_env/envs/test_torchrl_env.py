"""TorchRLFleetEnv and the PettingZooWrapper route: specs, bit for bit, resets, bad input."""

from __future__ import annotations

import doctest
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

pytest.importorskip("torchrl")

import torch
from tensordict import TensorDict
from torchrl.data import Unbounded
from torchrl.envs import PettingZooWrapper
from torchrl.envs.utils import check_env_specs

import cpf_env
from cpf_env import FleetSim, scenarios
from cpf_env.envs import torchrl_env
from cpf_env.envs.torchrl_env import GROUP, TorchRLFleetEnv
from cpf_env.sim.arrays import ERROR_KEYS

pytestmark = pytest.mark.torchrl

EXAMPLES = ROOT / "examples"

#: Random models and initial poses, lossy links: every reset draws from the generator.
SCENARIO = "heterogeneous"
SHORT = {"max_steps": 80, "max_path_error": 2.5}


def biased_actions(env: TorchRLFleetEnv, rng: np.random.Generator, bias: np.ndarray) -> np.ndarray:
    """float32 actions (B, n, 4 + m): forces ``tau_max * (bias[b] + 0.3 u)``, small rate/message.

    A larger bias pushes a fleet off its paths sooner, so fleets end at different steps.
    """
    _, tau_max = env.scenario.tau_limits
    unit = rng.uniform(-1.0, 1.0, size=(env.num_fleets, env.n, env.sim.act_dim))
    actions = 0.05 * unit
    actions[..., :3] = tau_max * (bias[:, None, None] + 0.3 * unit[..., :3])
    return actions.astype(np.float32)


def with_action(td: TensorDict, actions: np.ndarray) -> TensorDict:
    td.set((GROUP, "action"), torch.from_numpy(actions))
    return td


@pytest.mark.parametrize("info_level", ["none", "minimal"])
def test_check_env_specs(info_level: str) -> None:
    env = TorchRLFleetEnv(SCENARIO, num_fleets=3, info_level=info_level, **SHORT)
    env.set_seed(0)
    check_env_specs(env)


def test_specs_follow_the_scenario_and_the_parallel_env() -> None:
    env = TorchRLFleetEnv("lossy_links", num_fleets=2, message_size=2)
    parallel = cpf_env.parallel_env("lossy_links", message_size=2)
    action = env.full_action_spec[GROUP, "action"]
    assert action.shape == (2, 5, 6)
    for i, agent in enumerate(parallel.possible_agents):
        space = parallel.action_space(agent)
        for b in range(2):
            assert np.array_equal(action.space.low[b, i].numpy(), space.low)
            assert np.array_equal(action.space.high[b, i].numpy(), space.high)
    observation = env.observation_spec[GROUP, "observation"]
    assert observation.shape == (2, 5, parallel.layout.size)
    assert observation.dtype == torch.float32
    assert isinstance(observation, Unbounded)  # the ParallelEnv's box is +-1.7e38 anyway
    assert env.group_map == {GROUP: parallel.possible_agents}
    assert env.full_done_spec["done"].shape == (2, 1)
    assert env.full_done_spec[GROUP, "terminated"].shape == (2, 5, 1)
    assert env.full_reward_spec[GROUP, "reward"].shape == (2, 5, 1)


def test_bit_identical_to_fleet_sim_through_per_fleet_resets() -> None:
    """300 steps of random actions, fleets ending at different times and reset alone."""
    B, seed = 4, 11
    env = TorchRLFleetEnv(SCENARIO, B, stagger=False, info_level="minimal", **SHORT)
    sim = FleetSim(scenarios.get(SCENARIO).replace(**SHORT), num_fleets=B)
    env.set_seed(seed)
    td = env.reset()
    expected = sim.reset(seeds=[seed + k for k in range(B)])
    assert torch.equal(td[GROUP, "observation"], torch.from_numpy(expected))
    rng = np.random.default_rng(0)
    bias = np.array([1.0, 0.6, 0.3, 0.0])  # fleet 0 leaves its paths soonest
    partial_resets = 0
    for _ in range(300):
        actions = biased_actions(env, rng, bias)
        step, td = env.step_and_maybe_reset(with_action(td, actions))
        obs = sim.step(actions).copy()
        a = sim.arrays
        done = a.terminated | sim.truncated
        nxt = step["next"]
        assert torch.equal(nxt[GROUP, "observation"], torch.from_numpy(obs))
        reward = torch.from_numpy(a.reward.astype(np.float32))
        assert torch.equal(nxt[GROUP, "reward"][..., 0], reward)
        assert torch.equal(nxt["terminated"][:, 0], torch.from_numpy(a.terminated))
        assert torch.equal(nxt["done"][:, 0], torch.from_numpy(done))
        assert torch.equal(nxt[GROUP, "done"][..., 0], torch.from_numpy(done)[:, None].expand(B, 5))
        errors = torch.from_numpy(a.errors.astype(np.float32))
        for key, index in ERROR_KEYS:
            assert torch.equal(nxt[GROUP, "info", key], errors[..., index])
        if done.any():
            partial_resets += int(not done.all())
            obs = sim.reset(fleets=np.flatnonzero(done))
        assert torch.equal(td[GROUP, "observation"], torch.from_numpy(obs))
        assert not td["done"].any()
    assert partial_resets >= 3, "the run must reset some fleets while others go on"


def test_fleet_k_reproduces_the_parallel_env_seeded_seed_plus_k() -> None:
    env = TorchRLFleetEnv(SCENARIO, num_fleets=3, **SHORT)
    env.set_seed(5)
    td = env.reset()
    zero = np.zeros((3, 5, 5), dtype=np.float32)
    step, _ = env.step_and_maybe_reset(with_action(td, zero))
    for k in range(3):
        parallel = cpf_env.parallel_env(SCENARIO, **SHORT)
        observations, _ = parallel.reset(seed=5 + k)
        first = np.stack([observations[agent] for agent in parallel.possible_agents])
        assert np.array_equal(td[GROUP, "observation"][k].numpy(), first)
        observations, *_ = parallel.step(
            {agent: zero[k, i] for i, agent in enumerate(parallel.possible_agents)}
        )
        second = np.stack([observations[agent] for agent in parallel.possible_agents])
        assert np.array_equal(step["next", GROUP, "observation"][k].numpy(), second)


def test_same_seed_same_rollout_other_seed_other_rollout() -> None:
    def rollout(seed: int) -> TensorDict:
        env = TorchRLFleetEnv(SCENARIO, num_fleets=2, **SHORT)
        env.set_seed(seed)
        torch.manual_seed(0)  # the random policy samples with torch
        return env.rollout(80, break_when_any_done=False)

    first, again, other = rollout(3), rollout(3), rollout(4)
    assert (first == again).all()
    assert not torch.equal(first[GROUP, "observation"], other[GROUP, "observation"])


def test_rollout_with_a_random_policy() -> None:
    env = TorchRLFleetEnv(SCENARIO, num_fleets=3, **SHORT)
    env.set_seed(1)
    data = env.rollout(130, break_when_any_done=False)
    assert data.batch_size == (3, 130)
    obs = data["next", GROUP, "observation"]
    assert obs.shape == (3, 130, 5, env.sim.obs_dim)
    assert torch.isfinite(obs).all()
    assert torch.isfinite(data["next", GROUP, "reward"]).all()
    done = data["next", "done"]
    assert done.any(), "130 steps must end at least one episode of max_steps = 80"
    assert torch.equal(data["next", GROUP, "done"], done.unsqueeze(2).expand(-1, -1, 5, -1))
    ended = data["next", "truncated"] | data["next", "terminated"]
    assert torch.equal(ended, done)


@pytest.mark.parametrize("key", ["_reset", (GROUP, "_reset")])
def test_partial_reset_leaves_other_fleets_untouched(key: str | tuple[str, str]) -> None:
    B = 3
    env = TorchRLFleetEnv(SCENARIO, num_fleets=B, **SHORT)
    env.set_seed(2)
    td = env.reset()
    zero = np.zeros((B, 5, 5), dtype=np.float32)
    for _ in range(5):
        _, td = env.step_and_maybe_reset(with_action(td, zero))
    before = {name: getattr(env.sim.arrays, name).copy() for name in ("eta", "nu", "step", "obs")}
    shape = (B, 1) if key == "_reset" else (B, 5, 1)
    mask = torch.zeros(shape, dtype=torch.bool)
    mask[1] = True
    td.set(key, mask)
    out = env.reset(td)
    for name, value in before.items():
        now = getattr(env.sim.arrays, name)
        assert np.array_equal(now[[0, 2]], value[[0, 2]]), name
    assert env.sim.arrays.step[1] == 0
    reference = FleetSim(env.scenario, num_fleets=B)
    reference.reset(seeds=[2, 3, 4])
    reference.reset(fleets=[1])  # fleet 1's second episode: its generator continued
    assert np.array_equal(out[GROUP, "observation"][1].numpy(), reference.arrays.obs[1])
    assert np.array_equal(out[GROUP, "observation"][0].numpy(), before["obs"][0])


def test_bad_actions_raise_and_leave_the_state_untouched() -> None:
    env = TorchRLFleetEnv(SCENARIO, num_fleets=2, **SHORT)
    env.set_seed(0)
    td = env.reset()
    before = env.sim.arrays.eta.copy(), env.sim.arrays.step.copy()
    cases = [
        (torch.zeros(2, 5, 4), r"must have shape \(B, n, 4 \+ m\) = \(2, 5, 5\), got \(2, 5, 4\)"),
        (torch.zeros(2, 5, 5, 1), r"got \(2, 5, 5, 1\)"),
    ]
    nan = torch.zeros(2, 5, 5)
    nan[1, 3, 2] = float("nan")
    cases.append((nan, "fleet 1, vessel_3, component 2 is nan: actions must be finite"))
    complex_action = torch.zeros(2, 5, 5, dtype=torch.complex64)
    cases.append((complex_action, r"must be real numbers, got dtype complex64 \(complex values\)"))
    bools = torch.ones(2, 5, 5, dtype=torch.bool)
    cases.append((bools, r"must be real numbers, got dtype bool \(bools are not commands\)"))
    for action, message in cases:
        with pytest.raises(ValueError, match=message):
            env.step(td.clone().set((GROUP, "action"), action))
        assert np.array_equal(env.sim.arrays.eta, before[0])
        assert np.array_equal(env.sim.arrays.step, before[1])
    with pytest.raises(ValueError, match=r"no \('vessel', 'action'\) entry"):
        env.step(td.clone())
    with pytest.raises(ValueError, match="info_level must be one of"):
        TorchRLFleetEnv(SCENARIO, num_fleets=2, info_level="verbose")
    with pytest.raises(ValueError, match="num_fleets must be an integer >= 1"):
        TorchRLFleetEnv(SCENARIO, num_fleets=0)


@pytest.mark.parametrize("info_level", ["none", "minimal"])
def test_pettingzoo_wrapper_route_passes_check_env_specs(info_level: str) -> None:
    env = PettingZooWrapper(cpf_env.parallel_env(SCENARIO, info_level=info_level, **SHORT))
    assert env.group_map == {GROUP: [f"vessel_{i}" for i in range(5)]}
    env.set_seed(0)
    check_env_specs(env)
    native = TorchRLFleetEnv(SCENARIO, num_fleets=1, info_level=info_level, **SHORT)
    wrapper_keys = set(env.full_observation_spec.keys(True, True))
    assert wrapper_keys == set(native.full_observation_spec.keys(True, True))


def test_importing_cpf_env_does_not_import_torch() -> None:
    code = "import sys, cpf_env; print('torch' in sys.modules, 'torchrl' in sys.modules)"
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.split() == ["False", "False"]


def test_module_example_runs() -> None:
    """The module's doctest (pyproject's addopts leave the module out of doctest collection)."""
    results = doctest.testmod(torchrl_env)
    assert results.attempted > 0
    assert results.failed == 0


def run_example(name: str, *args: str, folder: Path = EXAMPLES) -> str:
    command = [sys.executable, str(folder / name), *args]
    return subprocess.run(command, capture_output=True, text=True, check=True).stdout


def test_pettingzoo_example_runs() -> None:
    out = run_example(
        "torchrl_pettingzoo.py", "--steps", "5", "--fleets", "2", "--info-level", "minimal"
    )
    assert "wrapper rollout: batch [5], reward [5, 5, 1]" in out
    assert "native rollout: batch [2, 5], reward [2, 5, 5, 1]" in out
    assert "fleet 1 == ParallelEnv reset(seed + 1): True" in out


def test_throughput_example_prints_its_table() -> None:
    out = run_example(
        "torchrl_throughput.py", "--seconds", "0.3", "--fleets", "2", "256", "--rollout-steps", "0",
        folder=EXAMPLES.parent / "benchmarks",
    )  # fmt: skip
    assert "PettingZooWrapper, info_level=none" in out
    assert "native B = 256 / PettingZooWrapper, info_level=none:" in out
    rows = [line for line in out.splitlines() if line.startswith("TorchRLFleetEnv")]
    assert [line.split()[1] for line in rows] == ["2", "256"]


def test_observations_are_not_aliased() -> None:
    """A kept observation tensor is unchanged after the next steps."""
    env = TorchRLFleetEnv("wang2014", num_fleets=2)
    td = env.reset()
    kept = td[GROUP, "observation"]
    snapshot = kept.clone()
    actions = np.full((2, env.n, env.sim.act_dim), 0.5, np.float32)
    for _ in range(3):
        step, td = env.step_and_maybe_reset(with_action(td, actions))
    assert torch.equal(kept, snapshot)
    assert not torch.equal(step["next", GROUP, "observation"], snapshot)


def test_a_float_reset_mask_is_refused_before_any_fleet_resets() -> None:
    env = TorchRLFleetEnv("bench_mild", num_fleets=3)
    env.set_seed(0)
    env.reset()
    before = env.sim.arrays.eta.copy()
    with pytest.raises(ValueError, match="must be a bool tensor"):
        env.reset(TensorDict({"_reset": torch.tensor([[1.0], [0.0], [0.0]])}, batch_size=[3]))
    np.testing.assert_array_equal(env.sim.arrays.eta, before)


@pytest.mark.skipif(torch.cuda.is_available(), reason="the machine has CUDA")
def test_an_unavailable_device_is_refused_with_what_to_do() -> None:
    with pytest.raises(ValueError, match="device='cuda' is not usable here"):
        TorchRLFleetEnv("wang2014", num_fleets=2, device="cuda")


def test_a_fractional_seed_is_refused() -> None:
    env = TorchRLFleetEnv("bench_mild", num_fleets=2)
    with pytest.raises(ValueError, match="seed must be an integer"):
        env.set_seed(1.5)  # type: ignore[arg-type]
