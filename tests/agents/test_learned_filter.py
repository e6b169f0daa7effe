"""The learned navigation filter (``agents.estimation``): its map, its policy, its folder."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import baselines
from agents import load_policy
from agents.estimation import network
from agents.estimation.correction import (
    STEP_SIZE,
    Correction,
    assemble,
    body_error,
    correct,
    fit,
)
from agents.estimation.fit import fit_filter, gather
from agents.estimation.folder import read_filter, save_filter
from agents.estimation.network import fit_network
from agents.estimation.policy import WINDOW, LearnedFilter
from agents.folder.files import AgentFolderError
from cpf_bench.rollout import rollout
from cpf_commands.curves import curves_main
from cpf_commands.fit_filter import fit_filter_main
from cpf_env.scenarios import make_scenario
from cpf_env.sim.fleet import FleetSim

#: hard_sensing, short: noisy 5 Hz fixes without velocity, over 15 s.
SHORT = make_scenario("hard_sensing").replace(max_steps=300)


def _random_state(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    state = rng.normal(size=(*shape, 9))
    state[..., 2] = rng.uniform(-np.pi, np.pi, size=shape)
    return state


def test_correcting_by_the_true_error_gives_the_true_state() -> None:
    rng = np.random.default_rng(0)
    states = _random_state(rng, (4, 5))
    eta = states[..., :3] + rng.normal(scale=0.05, size=(4, 5, 3))
    eta[..., 2] = np.angle(np.exp(1j * eta[..., 2]))
    nu = states[..., 3:6] + rng.normal(scale=0.01, size=(4, 5, 3))
    corrected = correct(states, body_error(states, eta, nu))
    np.testing.assert_allclose(corrected[..., :2], eta[..., :2], atol=1e-12)
    np.testing.assert_allclose(
        np.angle(np.exp(1j * (corrected[..., 2] - eta[..., 2]))), 0.0, atol=1e-12
    )
    np.testing.assert_allclose(corrected[..., 3:6], nu, atol=1e-12)
    np.testing.assert_array_equal(corrected[..., 6:], states[..., 6:])  # the bias is kept
    np.testing.assert_array_equal(correct(states, np.zeros((4, 5, 6))), states)


def _samples(rng: np.random.Generator, count: int, window: int, members: int) -> tuple:
    history = rng.normal(size=(count, 1, window, STEP_SIZE))
    states = _random_state(rng, (count, 1))
    bank = states[:, :, None, :] + rng.normal(scale=0.01, size=(count, 1, members, 9))
    return history, states, bank


def test_least_squares_recovers_a_linear_map_and_refuses_a_wrong_shape() -> None:
    rng = np.random.default_rng(1)
    window, members = 2, 3
    history, states, bank = _samples(rng, 3000, window, members)
    inputs = assemble(history, states, bank)[:, 0]
    assert inputs.shape == (3000, window * STEP_SIZE + 6 + members * 9)
    truth = rng.normal(size=(inputs.shape[1], 6))
    errors = inputs @ truth + 0.5
    correction = fit(inputs, errors, window, members, ridge=0.0)
    np.testing.assert_allclose(correction.predict(history, states, bank)[:, 0], errors, atol=1e-8)
    arrays = [correction.weights, correction.input_mean, correction.input_scale]
    with pytest.raises(ValueError, match=r"window of 3 steps and 3 filters needs weights of sha"):
        Correction(3, members, *arrays, correction.offset, correction.target_scale)
    layers = ((np.zeros(3), np.zeros(4)), (np.zeros((4, 6)), np.zeros(6)))
    with pytest.raises(ValueError, match=r"needs layers\.0\.weight of shape \(45, 6\), got \(3,\)"):
        Correction(window, members, *arrays, correction.offset, correction.target_scale, layers)
    with pytest.raises(ValueError, match="members must be an integer >= 1"):
        Correction(window, 0, *arrays, correction.offset, correction.target_scale)
    with pytest.raises(ValueError, match="ridge must be >= 0"):
        fit(inputs, errors, window, members, ridge=-1.0)


def test_the_network_learns_what_the_matrix_cannot(monkeypatch: pytest.MonkeyPatch) -> None:
    """An error that is the square of an input: the matrix explains none of it."""
    rng = np.random.default_rng(2)
    window, members = 1, 1
    history, states, bank = _samples(rng, 20000, window, members)
    inputs = assemble(history, states, bank)[:, 0]
    errors = np.zeros((len(inputs), 6))
    errors[:, 0] = inputs[:, 0] ** 2 + 0.3 * inputs[:, 1]
    linear = fit(inputs, errors, window, members, ridge=1e-6)
    learned = fit_network(inputs, errors, linear, hidden=(32,), epochs=20, seed=0)
    left = [np.sqrt(np.mean((errors - c.apply(inputs))[:, 0] ** 2)) for c in (linear, learned)]
    assert left[1] < 0.2 * left[0]
    again = fit_network(inputs, errors, linear, hidden=(32,), epochs=20, seed=0)
    for (w, b), (w2, b2) in zip(learned.layers, again.layers, strict=True):
        np.testing.assert_array_equal(w, w2)  # same data, same seed: the same network
        np.testing.assert_array_equal(b, b2)
    monkeypatch.setattr(network, "CHUNK", 7)  # standardized in blocks: the same bits
    blocks = fit_network(inputs, errors, linear, hidden=(32,), epochs=20, seed=0)
    for (w, b), (w2, b2) in zip(learned.layers, blocks.layers, strict=True):
        np.testing.assert_array_equal(w, w2)
        np.testing.assert_array_equal(b, b2)
    with pytest.raises(ValueError, match="fit the network on a correction without one"):
        fit_network(inputs, errors, learned, hidden=(32,))
    with pytest.raises(ValueError, match="hidden widths >= 1 and epochs >= 1"):
        fit_network(inputs, errors, linear, hidden=())


def test_with_a_correction_of_zeros_it_is_its_base_bit_for_bit() -> None:
    """400 steps of 2 fleets: the rebuilt observation is the filter's own."""
    base = baselines.make_policy("mpc_tuned_mmae", SHORT)
    alone = LearnedFilter(SHORT, Correction.zero(WINDOW, 4))
    sims = [FleetSim(SHORT.replace(max_steps=400), num_fleets=2) for _ in range(2)]
    obs = [sim.reset(seeds=[3, 4]) for sim in sims]
    for _ in range(400):
        actions = [base.act_batch(obs[0]), alone.act_batch(obs[1])]
        np.testing.assert_array_equal(actions[0], actions[1])
        obs = [sim.step(a) for sim, a in zip(sims, actions, strict=True)]


def test_under_the_safety_filter_too_a_correction_of_zeros_is_its_base() -> None:
    task = make_scenario("hard_large_fleet").replace(max_steps=60)
    base = baselines.make_policy("mpc_tuned_ekf_safe", task)
    alone = LearnedFilter(task, Correction.zero(WINDOW, 1), base="mpc_tuned_ekf_safe")
    sims = [FleetSim(task, num_fleets=1) for _ in range(2)]
    obs = [sim.reset(seeds=[7]) for sim in sims]
    for _ in range(60):
        actions = [base.act_batch(obs[0]), alone.act_batch(obs[1])]
        np.testing.assert_array_equal(actions[0], actions[1])
        obs = [sim.step(a) for sim, a in zip(sims, actions, strict=True)]


def test_it_refuses_ideal_sensors_a_design_without_a_filter_and_another_bank() -> None:
    zero = Correction.zero(4, 4)
    with pytest.raises(ValueError, match="ideal sensors: its vessels observe their true state"):
        LearnedFilter("hard_crossing", zero)
    with pytest.raises(ValueError, match="base must be one of"):
        LearnedFilter(SHORT, zero, base="mpc_tuned")
    with pytest.raises(ValueError, match="a bank of 4 filters, and 'mpc_tuned_ekf' runs 1"):
        LearnedFilter(SHORT, zero, base="mpc_tuned_ekf")


def test_training_refuses_the_held_out_seeds() -> None:
    with pytest.raises(ValueError, match="held-out seeds"):
        gather(SHORT, [9000], "mpc_tuned_mmae", Correction.zero(4, 4))
    with pytest.raises(ValueError, match="held-out seeds"):
        fit_filter(["hard_sensing"], 3000, rounds=4, max_steps=100)
    with pytest.raises(ValueError, match="episodes of 30 steps end before the window of 40"):
        fit_filter(["hard_sensing"], 1, max_steps=30)
    with pytest.raises(ValueError, match=r"hidden widths must be >= 1, got \[256, 0\]"):
        fit_filter(["hard_sensing"], 1, hidden=(256, 0))


@pytest.fixture(scope="module")
def fitted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Correction, dict]:
    correction, record, _ = fit_filter(
        ["hard_sensing"], 3, window=8, rounds=2, hidden=(32,), epochs=3, eval_num_seeds=2,
        max_steps=300,
    )  # fmt: skip
    folder = tmp_path_factory.mktemp("filters") / "learned"
    save_filter(folder, correction, record)
    return folder, correction, record


def test_the_fit_explains_part_of_the_filter_s_error(fitted: tuple[Path, Correction, dict]) -> None:
    """Measured on 2 rounds of 3 episodes of 15 s, the filters still settling: x 10.9 -> 8.5
    mm, surge 11.9 -> 9.1 mm/s (training data); the validation seeds' cost 79.9 -> 77.8 ->
    77.1 (the base, then each round)."""
    _, _, record = fitted
    before, after = np.array(record["error_rms"]), np.array(record["error_rms_fitted"])
    assert np.all(after < 0.95 * before)
    assert after[3] < 0.9 * before[3]  # surge
    assert record["samples"] == 2 * 3 * 5 * (300 - 8)  # two rounds of 3 episodes
    assert [r["seeds"] for r in record["rounds"]] == [[0, 1, 2], [3, 4, 5]]
    assert [r["vessel_steps"] for r in record["rounds"]] == [3 * 5 * 300, 6 * 5 * 300]
    assert set(record["validation"]["hard_sensing"]) == {"base", "filter"}


def test_the_base_row_is_the_base_s_cost(fitted: tuple[Path, Correction, dict]) -> None:
    """The evaluations start at 0 vessel-steps with the base itself, on the same seeds."""
    _, _, record = fitted
    base = rollout(baselines.make_policy("mpc_tuned_mmae", SHORT), SHORT, [9000, 9001])
    assert record["validation"]["hard_sensing"]["base"] == float(np.mean(base["cost"]))


def test_the_folder_loads_as_the_same_policy_and_is_checked(
    fitted: tuple[Path, Correction, dict], tmp_path: Path
) -> None:
    folder, correction, _ = fitted
    loaded = load_policy(folder, SHORT)
    assert isinstance(loaded, LearnedFilter)
    assert loaded.name == "learned"
    read, _ = read_filter(folder)
    for name, array in correction.arrays.items():
        np.testing.assert_array_equal(read.arrays[name], array)
    assert len(read.layers) == 2
    fresh = LearnedFilter(SHORT, correction)
    sims = [FleetSim(SHORT, num_fleets=2) for _ in range(2)]
    obs = [sim.reset(seeds=[5, 6]) for sim in sims]
    for _ in range(300):
        actions = [loaded.act_batch(obs[0]), fresh.act_batch(obs[1])]
        np.testing.assert_array_equal(actions[0], actions[1])
        obs = [sim.step(a) for sim, a in zip(sims, actions, strict=True)]
    altered = tmp_path / "altered"
    altered.mkdir()
    for path in folder.iterdir():
        (altered / path.name).write_bytes(path.read_bytes())
    config = json.loads((altered / "config.json").read_text())
    config["filter"]["window"] = 9
    (altered / "config.json").write_text(json.dumps(config))
    with pytest.raises(AgentFolderError, match=r"config\.json"):
        load_policy(altered, SHORT)


def test_the_command_refuses_an_existing_folder(
    fitted: tuple[Path, Correction, dict], capsys: pytest.CaptureFixture[str]
) -> None:
    folder, _, _ = fitted
    with pytest.raises(SystemExit):
        fit_filter_main(["--scenarios", "hard_sensing", "--out", str(folder)])
    assert "exists; give another --out, or --force" in capsys.readouterr().err


def test_the_command_writes_a_curve_cpf_curves_draws(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "filter"
    arguments = ["--scenarios", "hard_sensing", "--num-seeds", "1", "--rounds", "2", "--window"]
    fit_filter_main([*arguments, "8", "--hidden", "--eval-num-seeds", "1", "--max-steps", "200",
                     "--out", str(out)])  # fmt: skip
    printed = capsys.readouterr().out
    assert "fitted in 2 rounds on 1,920 samples from 2,000 vessel-steps" in printed
    run = json.loads((out / "run.json").read_text())
    assert run["filter"]["hidden"] == [] and run["evaluation"]["max_steps"] == 200
    rows = (out / "evaluations.csv").read_text().splitlines()
    assert rows[0].startswith("vessel_steps,wall_clock_seconds,evaluation_seconds,mean_cost")
    assert [row.split(",")[0] for row in rows[1:]] == ["0", "1000", "2000"]
    assert isinstance(load_policy(out, "hard_sensing"), LearnedFilter)
    assert curves_main([str(out), "--out", str(tmp_path / "curves")]) == 0
    assert (tmp_path / "curves" / "curves.csv").is_file()
    assert "base policy" in capsys.readouterr().out


def test_the_command_refuses_a_gpu_it_does_not_have(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    with pytest.raises(SystemExit):
        fit_filter_main(["--scenarios", "hard_sensing", "--device", "cuda", "--out",
                         str(tmp_path / "f")])  # fmt: skip
    assert "asks for a CUDA GPU, but torch" in capsys.readouterr().err
    assert not (tmp_path / "f").exists()
