"""TorchRLFleetEnv's residual form, global state, normalized inputs and seeding."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torchrl")

import torch
from torchrl.envs.utils import check_env_specs

import cpf_env
from baselines import make_policy
from cpf_env import FleetSim, scenarios
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.envs.residual import ResidualConfig, ResidualController
from cpf_env.envs.torchrl_env import GROUP, StateFeatures, TorchRLFleetEnv

pytestmark = pytest.mark.torchrl


def residual_env(name: str, num_fleets: int, **kwargs: object) -> TorchRLFleetEnv:
    scenario = scenarios.get(name).replace(**kwargs.pop("overrides", {}))  # type: ignore[arg-type]
    base = make_policy("nn_dsc", scenario)
    return TorchRLFleetEnv(scenario, num_fleets=num_fleets, base_policy=base, **kwargs)  # type: ignore[arg-type]


def base_alone(scenario_name: str, seed: int, steps: int, **overrides: object) -> dict[str, list]:
    """One fleet under nn_dsc on its own FleetSim, reset by hand when its episode ends."""
    scenario = scenarios.get(scenario_name).replace(**overrides)
    sim = FleetSim(scenario)
    policy = make_policy("nn_dsc", scenario)
    obs = sim.reset(seeds=[seed]).copy()
    record: dict[str, list] = {"next": [], "reward": [], "done": [], "after": []}
    for _ in range(steps):
        obs = sim.step(policy.act_batch(obs)).copy()
        done = bool(sim.arrays.terminated[0] or sim.truncated[0])
        record["next"].append(obs[0].copy())
        record["reward"].append(sim.arrays.reward[0].astype(np.float32))
        record["done"].append(done)
        if done:
            obs = sim.reset(seeds=[None]).copy()
            policy.reset()
        record["after"].append(obs[0].copy())
    return record


@pytest.mark.parametrize(
    ("name", "overrides"),
    [
        ("bench_saturation", {"max_steps": 60}),  # truncations
        ("bench_saturation", {"max_steps": 400, "max_path_error": 3.6}),  # some fleets fail
    ],
)
def test_zero_actions_reproduce_the_base_policy_fleet_for_fleet(name: str, overrides: dict) -> None:
    """300 steps through per-fleet resets: each fleet equals its own nn_dsc run bit for bit."""
    B, seed, steps = 4, 11, 300
    env = residual_env(name, B, overrides=overrides, seed=seed, stagger=False)
    td = env.reset()
    references = [base_alone(name, seed + k, steps, **overrides) for k in range(B)]
    zero = torch.zeros((B, env.n, 3))
    ends, terminated = 0, False
    for t in range(steps):
        step, td = env.step_and_maybe_reset(td.set((GROUP, "action"), zero))
        for k, ref in enumerate(references):
            nxt = step["next"][k]
            assert np.array_equal(nxt[GROUP, "observation"].numpy(), ref["next"][t]), (t, k)
            assert np.array_equal(nxt[GROUP, "reward"][:, 0].numpy(), ref["reward"][t])
            assert bool(nxt["done"]) == ref["done"][t]
            assert np.array_equal(td[GROUP, "observation"][k].numpy(), ref["after"][t]), (t, k)
            ends += ref["done"][t]
        terminated |= bool(step["next", "terminated"].any())
    assert ends >= B
    if "max_path_error" in overrides:
        assert terminated


def test_check_env_specs_with_state_extras_and_normalized_inputs() -> None:
    config = ResidualConfig(mode="force_and_rate", extras=("base_action", "multiscale_errors"))
    env = residual_env(
        "bench_lossy_links",
        3,
        residual=config,
        state=True,
        normalize=True,
        normalization_steps=20,
        info_level="minimal",
        overrides={"max_steps": 40},
        seed=0,
    )
    check_env_specs(env)
    assert env.full_action_spec[GROUP, "action"].shape == (3, 5, 4)
    assert env.observation_spec[GROUP, "observation"].shape == (3, 5, 26 + 4 + 9)
    assert env.observation_spec["state"].shape == (3, 50)


def test_check_env_specs_with_learned_messages_and_full_infos() -> None:
    """The action holds k + L entries; the residual info the k of the correction."""
    config = ResidualConfig(mode="force_and_rate", messages=2)
    env = residual_env(
        "bench_lossy_links", 2, residual=config, info_level="full",
        overrides={"max_steps": 30, "message_size": 3}, seed=0,
    )  # fmt: skip
    check_env_specs(env)
    assert env.full_action_spec[GROUP, "action"].shape == (2, 5, 4 + 2)
    rollout = env.rollout(5)
    assert rollout["next", GROUP, "info", "residual"].shape == (2, 5, 5, 4)  # B, T, n, k


def test_state_is_the_parallel_envs_state_of_each_fleet() -> None:
    env = TorchRLFleetEnv("heterogeneous", num_fleets=2, state=True, seed=5, max_steps=30)
    td = env.reset()
    zero = torch.zeros((2, 5, 5))
    step, _ = env.step_and_maybe_reset(td.set((GROUP, "action"), zero))
    for k in range(2):
        parallel = cpf_env.parallel_env("heterogeneous", max_steps=30)
        parallel.reset(seed=5 + k)
        assert np.array_equal(td["state"][k].numpy(), parallel.state())
        parallel.step({agent: np.zeros(5, np.float32) for agent in parallel.possible_agents})
        assert np.array_equal(step["next", "state"][k].numpy(), parallel.state())


def test_the_extra_state_is_appended_and_read_as_the_fleet_ended_its_step() -> None:
    """[10 n physical | 5 n unobserved]; at a horizon "next" holds the state the fleet ended in."""
    from cpf_env.evaluation.privileged import UNOBSERVED_SIZE, unobserved_state

    settings = {"num_fleets": 3, "seed": 4, "overrides": {"max_steps": 40}}
    features = StateFeatures(UNOBSERVED_SIZE, unobserved_state)
    told_env = {"state": True, "extra_state": features, **settings}
    told = residual_env("bench_current_waves", **told_env)  # type: ignore[arg-type]
    plain = residual_env("bench_current_waves", state=True, **settings)  # type: ignore[arg-type]
    stepped = residual_env("bench_current_waves", **told_env)  # type: ignore[arg-type]
    size = 10 * 5
    assert told.observation_spec["state"].shape == (3, size + UNOBSERVED_SIZE * 5)
    td, td_plain, td_stepped = told.reset(), plain.reset(), stepped.reset()
    action = torch.full((3, 5, 3), 0.3)
    ended = 0
    for _ in range(45):  # the stagger ends fleets at steps 40, 27 and 14, one more at 54
        step, td = told.step_and_maybe_reset(td.set((GROUP, "action"), action))
        step_plain, td_plain = plain.step_and_maybe_reset(td_plain.set((GROUP, "action"), action))
        state = step["next", "state"].numpy()
        assert np.array_equal(state[:, :size], step_plain["next", "state"].numpy())
        # the same step without the reset: the simulator as each fleet ended its step
        after = stepped.step(td_stepped.set((GROUP, "action"), action))["next"]
        truth = unobserved_state(stepped.sim).reshape(3, -1)
        np.testing.assert_array_equal(state[:, size:], truth)
        np.testing.assert_array_equal(state, after["state"].numpy())
        done = step["next", "done"].numpy()[:, 0]
        ended += int(done.sum())
        if done.any():  # the twin resets the same fleets, as the collector did
            td_stepped = stepped.reset(after.set("_reset", step["next", "done"]))
        else:
            td_stepped = after
        v0 = np.array([told.sim.v0_at(float(t)) for t in told.sim.time], dtype=np.float32)
        told_v0 = state[~done, size + 3 :: UNOBSERVED_SIZE]  # (running fleets, n)
        assert told_v0.shape[1] == 5 and (told_v0 == v0[~done, None]).all()
    assert ended == 3
    check_env_specs(told)


def test_the_extra_state_is_checked() -> None:
    from cpf_env.evaluation.privileged import unobserved_state

    features = StateFeatures(5, unobserved_state)
    with pytest.raises(ValueError, match="StateFeatures\\(size, compute\\) and state=True"):
        TorchRLFleetEnv("bench_mild", num_fleets=2, extra_state=features)
    with pytest.raises(ValueError, match="got function"):
        TorchRLFleetEnv("bench_mild", num_fleets=2, state=True, extra_state=unobserved_state)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="size must be an int >= 1"):
        TorchRLFleetEnv("bench_mild", num_fleets=2, state=True, extra_state=StateFeatures(0, len))  # type: ignore[arg-type]
    wrong = TorchRLFleetEnv(
        "bench_mild", num_fleets=2, state=True, extra_state=StateFeatures(4, unobserved_state)
    )
    with pytest.raises(ValueError, match=r"= \(2, 5, 4\) features, got shape \(2, 5, 5\)"):
        wrong.reset()


def test_normalized_inputs_are_the_statistics_applied_to_the_raw_inputs() -> None:
    raw = residual_env("bench_mild", 2, seed=3, overrides={"max_steps": 30})
    scaled = residual_env(
        "bench_mild", 2, seed=3, normalize=True, normalization_steps=30, overrides={"max_steps": 30}
    )
    stats = scaled.input_statistics
    assert isinstance(stats, InputStatistics)
    assert stats.size == raw.core.input_size and np.all(stats.var >= 0)
    torch.manual_seed(0)
    first = raw.rollout(10, break_when_any_done=False)
    torch.manual_seed(0)
    second = scaled.rollout(10, break_when_any_done=False)
    assert torch.equal(first[GROUP, "action"], second[GROUP, "action"])
    expected = stats.apply(first["next", GROUP, "observation"].numpy())
    assert np.array_equal(second["next", GROUP, "observation"].numpy(), expected)
    # the statistics come from a separate simulator: the env's episodes are unchanged
    assert torch.equal(first["next", GROUP, "reward"], second["next", GROUP, "reward"])


def test_statistics_pool_a_base_only_rollout_of_16_fleets_whatever_b() -> None:
    scenario = scenarios.get("bench_mild").replace(max_steps=25)
    envs = [
        TorchRLFleetEnv(
            scenario,
            num_fleets=b,
            base_policy=make_policy("nn_dsc", scenario),
            normalize=True,
            normalization_steps=25,
        )
        for b in (2, 5)
    ]
    sim = FleetSim(scenario, num_fleets=16)
    loop = ResidualController(scenario, make_policy("nn_dsc", scenario), 16)
    inputs = [loop.observe(sim.reset(seeds=list(range(16))))]
    for _ in range(24):
        inputs.append(loop.observe(sim.step(loop.compose(np.zeros((16, 5, 3))))))
    rows = np.concatenate([x.astype(np.float32).reshape(-1, x.shape[-1]) for x in inputs])
    for env in envs:
        stats = env.input_statistics
        assert stats is not None
        assert np.array_equal(stats.mean, rows.astype(np.float64).mean(axis=0))
        assert np.array_equal(stats.var, rows.astype(np.float64).var(axis=0))


def test_same_seed_same_rollout_with_a_residual() -> None:
    def rollout(seed: int) -> object:
        env = residual_env("heterogeneous", 2, seed=seed, overrides={"max_steps": 40})
        torch.manual_seed(0)
        return env.rollout(60, break_when_any_done=False)

    first, again, other = rollout(3), rollout(3), rollout(4)
    assert (first == again).all()  # type: ignore[operator]
    assert not torch.equal(first[GROUP, "observation"], other[GROUP, "observation"])  # type: ignore[index]


def test_outputs_live_on_the_env_device() -> None:
    env = residual_env("bench_mild", 2, seed=0, device="cpu", state=True)
    td = env.reset()
    assert env.device == torch.device("cpu")
    assert all(value.device == env.device for value in td.values(True, True))


def test_bad_residual_input_is_refused_and_leaves_the_state_alone() -> None:
    env = residual_env("bench_mild", 2, seed=0)
    td = env.reset()
    before = env.sim.arrays.eta.copy()
    with pytest.raises(ValueError, match=r"must have shape \(B, n, k\) = \(2, 5, 3\)"):
        env.step(td.clone().set((GROUP, "action"), torch.zeros(2, 5, 5)))
    nan = torch.zeros(2, 5, 3)
    nan[0, 1, 2] = float("nan")
    with pytest.raises(ValueError, match="must be finite"):
        env.step(td.clone().set((GROUP, "action"), nan))
    with pytest.raises(ValueError, match="real numbers"):
        env.step(td.clone().set((GROUP, "action"), torch.zeros(2, 5, 3, dtype=torch.complex64)))
    assert np.array_equal(env.sim.arrays.eta, before)
    with pytest.raises(TypeError, match=r"agents\.marl\.envs\.make_env"):
        TorchRLFleetEnv("bench_mild", num_fleets=2, base_policy="nn_dsc")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="has none: give base_policy="):
        TorchRLFleetEnv("bench_mild", num_fleets=2, normalize=True)
    with pytest.raises(ValueError, match="statistics have 3 dimensions"):
        TorchRLFleetEnv(
            "bench_mild",
            num_fleets=2,
            normalize=InputStatistics(np.zeros(3), np.ones(3)),
        )


def test_stagger_ends_the_first_episodes_at_spread_horizons_then_full_ones() -> None:
    B, max_steps = 4, 40
    staggered = residual_env("bench_mild", B, seed=1, stagger=True, overrides={"max_steps": 40})
    plain = residual_env("bench_mild", B, seed=1, stagger=False, overrides={"max_steps": 40})
    td, td_plain = staggered.reset(), plain.reset()
    zero = torch.zeros((B, 5, 3))
    ends: list[list[int]] = [[] for _ in range(B)]
    for t in range(1, 2 * max_steps + 1):
        step, td = staggered.step_and_maybe_reset(td.set((GROUP, "action"), zero))
        if t < max_steps - (B - 1) * max_steps // B:  # before any fleet ends: same episodes
            step_plain, td_plain = plain.step_and_maybe_reset(td_plain.set((GROUP, "action"), zero))
            assert (step["next"] == step_plain["next"]).all()
        for k in range(B):
            if step["next", "truncated"][k]:
                ends[k].append(t)
        assert not step["next", "terminated"].any()
    assert ends == [[40, 80], [30, 70], [20, 60], [10, 50]]
    with pytest.raises(ValueError, match="stagger must be True or False"):
        TorchRLFleetEnv("bench_mild", num_fleets=2, stagger=1)  # type: ignore[arg-type]
