"""The DeepSets neighbour encoder: permutation invariance, empty slots, any K, in SB3."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

from agents import FleetVecEnv
from agents.folder.encoder import NeighbourSetEncoder, empty_weight_after
from agents.training.algorithms import DeepSetsExtractor
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.sim.observation import SLOTS, observation_box

SLOT = 4  # 3 + m with m = 1
TAIL = 3


def _rows(k: int, linked: int, count: int = 16, seed: int = 0) -> torch.Tensor:
    """Random inputs with ``linked`` linked slots first and K - linked empty (all-zero) ones."""
    rng = np.random.default_rng(seed)
    rows = rng.standard_normal((count, SLOTS + k * SLOT + TAIL)).astype(np.float32)
    slots = rows[:, SLOTS : SLOTS + k * SLOT].reshape(count, k, SLOT)
    slots[:, :linked, 0] = rng.uniform(0.5, 2.0, (count, linked))
    slots[:, linked:] = 0.0
    return torch.from_numpy(rows)


def _permuted(rows: torch.Tensor, k: int, order: list[int]) -> torch.Tensor:
    out = rows.clone()
    slots = out[:, SLOTS : SLOTS + k * SLOT].reshape(-1, k, SLOT)
    out[:, SLOTS : SLOTS + k * SLOT] = slots[:, order].reshape(-1, k * SLOT)
    return out


@pytest.mark.parametrize("pooling", ["mean", "sum"])
def test_slot_order_does_not_matter(pooling: str) -> None:
    torch.manual_seed(0)
    encoder = NeighbourSetEncoder(SLOT, tail=TAIL, pooling=pooling)
    rows = _rows(5, linked=4)
    base = encoder(rows)
    for order in ([4, 3, 2, 1, 0], [2, 0, 4, 1, 3]):
        # float sums in another order differ by rounding only: atol 1e-6 on O(1) features
        torch.testing.assert_close(encoder(_permuted(rows, 5, order)), base, atol=1e-6, rtol=0)
    # a network that is not invariant fails this check: the flat input changes
    assert not torch.equal(_permuted(rows, 5, [1, 0, 2, 3, 4]), rows)


def test_empty_slots_are_ignored_and_more_slots_give_the_same_features() -> None:
    torch.manual_seed(1)
    encoder = NeighbourSetEncoder(SLOT, tail=TAIL)
    small = _rows(3, linked=3)
    # the same vessel seen with 9 slots (6 more empty ones), as a larger graph pads it
    large = torch.zeros(small.shape[0], SLOTS + 9 * SLOT + TAIL)
    large[:, : SLOTS + 3 * SLOT] = small[:, : SLOTS + 3 * SLOT]
    large[:, -TAIL:] = small[:, -TAIL:]
    # empty slots add exact zeros, but the slot MLP runs on (B K) rows: BLAS may pick
    # another kernel for another row count, so allow float rounding only
    torch.testing.assert_close(encoder(large), encoder(small), rtol=1e-6, atol=1e-7)
    # garbage in an empty slot's other fields is ignored (a_ij = 0 marks it empty)
    noisy = large.clone()
    noisy[:, SLOTS + 5 * SLOT + 1 : SLOTS + 6 * SLOT] = 7.0
    assert torch.equal(encoder(noisy), encoder(large))
    # the degree feature counts the links
    degree = encoder(small)[:, SLOTS + encoder.hidden]
    assert torch.equal(degree, torch.full_like(degree, 3.0))
    # a linked slot does change the features
    linked = large.clone()
    linked[:, SLOTS + 5 * SLOT] = 1.0
    assert not torch.allclose(encoder(linked), encoder(large))


def test_bad_layouts_are_refused() -> None:
    encoder = NeighbourSetEncoder(SLOT, tail=TAIL)
    with pytest.raises(ValueError, match="not 18 \\+ K x 4 \\+ 3"):
        encoder(torch.zeros(2, SLOTS + 2 * SLOT + TAIL + 1))
    with pytest.raises(ValueError, match="pooling"):
        NeighbourSetEncoder(SLOT, pooling="max")


def test_empty_weight_after_normalization() -> None:
    k = 3
    size = SLOTS + k * SLOT + TAIL
    mean, var = np.zeros(size), np.ones(size)
    mean[SLOTS : SLOTS + k * SLOT : SLOT] = 0.6
    var[SLOTS : SLOTS + k * SLOT : SLOT] = 0.24
    stats = InputStatistics(mean, var, epsilon=1e-8, clip=10.0)
    empty = empty_weight_after(stats, k, SLOT)
    assert empty == pytest.approx(-0.6 / np.sqrt(0.24 + 1e-8))
    normalized = torch.from_numpy(stats.apply(_rows(k, linked=2).numpy()).astype(np.float32))
    encoder = NeighbourSetEncoder(SLOT, tail=TAIL, empty_weight=empty, tolerance=1e-4)
    degree = encoder(normalized)[:, SLOTS + encoder.hidden]
    assert torch.equal(degree, torch.full_like(degree, 2.0))
    mean[SLOTS + SLOT] = 0.1  # slot 1's weight has other statistics: not pooled
    with pytest.raises(ValueError, match="pool them first"):
        empty_weight_after(InputStatistics(mean, var), k, SLOT)


def test_ppo_trained_on_few_slots_runs_a_ten_vessel_star() -> None:
    env = FleetVecEnv("wang2014", num_fleets=1, max_steps=16)
    kwargs = {"features_extractor_class": DeepSetsExtractor, "features_extractor_kwargs": {}}
    model = PPO(
        "MlpPolicy",
        env,
        n_steps=8,
        batch_size=8,
        n_epochs=1,
        device="cpu",
        seed=0,
        policy_kwargs=kwargs,
    )
    model.learn(16)
    k_star = 9  # the centre of a 10-vessel star
    big = PPO(
        "MlpPolicy",
        FleetVecEnv("wang2014", num_fleets=1, max_steps=16),
        device="cpu",
        policy_kwargs=kwargs,
    )
    big.policy.observation_space = observation_box(SLOTS + k_star * SLOT)
    big.policy.load_state_dict(model.policy.state_dict(), strict=True)
    obs = env.reset()
    padded = np.zeros((obs.shape[0], SLOTS + k_star * SLOT), dtype=np.float32)
    padded[:, : obs.shape[1]] = obs
    small_actions, _ = model.predict(obs, deterministic=True)
    big_actions, _ = big.predict(padded, deterministic=True)
    # Padding adds masked zeros only, but the slot MLP then runs on more rows, for which
    # BLAS may pick another kernel (by shape and thread count): float rounding only.
    np.testing.assert_allclose(big_actions, small_actions, rtol=1e-6, atol=1e-7)
    star = np.zeros((1, SLOTS + k_star * SLOT), dtype=np.float32)
    star[0, SLOTS : SLOTS + k_star * SLOT : SLOT] = 1.0  # nine linked neighbours
    action, _ = big.predict(star, deterministic=True)
    assert action.shape == (1, small_actions.shape[1]) and np.all(np.isfinite(action))
