from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from baselines import POLICIES
from cpf_bench.evaluate import policy_label
from cpf_commands.run.experiment import run_episode
from cpf_commands.speed import busy_competitor, measure, speed_main
from cpf_env import scenarios
from cpf_env.evaluation.metrics import episode_metrics

ROOT = Path(__file__).resolve().parents[1]


def _load_example(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_speed_measure_reports_every_component():
    rows = measure("wang2014", fleets=(2,), min_seconds=0.01, max_steps=20)
    components = {row["component"] for row in rows}
    assert components == {
        "FleetSim.step",
        "nn_dsc.act_batch",
        "nn_dsc + FleetSim.step",
        "nn_dsc + FleetSim, ClosedLoop.run(1)",
        "ParallelEnv.step",
        "FleetVecEnv.step (residual on nn_dsc)",
        "wang2014 episode (20 steps), nn_dsc, stepped",
        "wang2014 episode (20 steps), nn_dsc, ClosedLoop.run",
    }
    for episode in rows[-2:]:
        assert episode["steps_per_s"] == pytest.approx(20 / episode["seconds"], rel=1e-3)
    for row in rows:  # both rates are rounded to 0.1: steps_per_s's rounding, times B n
        assert row["vessel_steps_per_s"] == pytest.approx(
            row["steps_per_s"] * row["B"] * 5, abs=0.05 * row["B"] * 5 + 0.05
        )
        assert row["steps_per_s"] > 0


def test_speed_times_a_python_design_and_an_agent_folder_without_the_compiled_loop():
    """The navigation-filtered designs and the learned filter step in Python: no ClosedLoop rows."""
    folder = str(ROOT / "results" / "agents" / "hard_sensing_learned_filter_s0")
    for policy in ("mpc_tuned_mmae", folder):
        rows = measure("hard_sensing", fleets=(2,), policy=policy, min_seconds=0.01, max_steps=5)
        label = policy_label(policy)
        assert [row["component"] for row in rows] == [
            "FleetSim.step",
            f"{label}.act_batch",
            f"{label} + FleetSim.step",
            "ParallelEnv.step",
            *([f"FleetVecEnv.step (residual on {label})"] if policy == "mpc_tuned_mmae" else []),
            f"hard_sensing episode (5 steps), {label}, stepped",
        ]


def test_speed_starts_the_policy_again_with_the_episode():
    """A stateful design (a filter's estimate) must not carry one episode's state into the next."""
    from cpf_commands.speed import _step_or_reset
    from cpf_env import FleetSim

    class Counting:
        resets = 0

        def reset(self, seed=None):
            self.resets += 1

    sim, policy = (
        FleetSim(scenarios.make_scenario("wang2014", max_steps=3), num_fleets=2),
        Counting(),
    )
    sim.reset(seeds=[0, 1])
    for _ in range(3):
        _step_or_reset(sim, np.zeros((2, sim.n, sim.act_dim)), policy)
    assert policy.resets == 1 and sim.arrays.step.max() == 0


def test_speed_refuses_a_policy_it_cannot_build(capsys):
    with pytest.raises(SystemExit):
        speed_main(["--policy", "no_such_design", "--quiet"])
    assert "--policy no_such_design" in capsys.readouterr().err
    folder = str(ROOT / "results" / "agents" / "hard_sensing_learned_filter_s0")
    with pytest.raises(SystemExit):  # a learned filter where there is no fix to correct
        speed_main(["--scenario", "wang2014", "--policy", folder, "--quiet"])
    assert "sensors" in capsys.readouterr().err


def test_speed_contention_rows_and_the_competitor_is_gone():
    with busy_competitor() as competitor:
        assert competitor.poll() is None  # spinning
    assert competitor.poll() is not None  # ended with the block
    rows = measure("wang2014", fleets=(), min_seconds=0.01, max_steps=5, contention=(2,))
    labels = [row["component"] for row in rows if row["B"] == 2]
    assert labels == [
        "FleetSim.step, alone",
        "FleetSim.step, 1 busy competitor",
        "FleetVecEnv.step (residual on nn_dsc), alone",
        "FleetVecEnv.step (residual on nn_dsc), 1 busy competitor",
    ]


def test_speed_times_the_default_bench(monkeypatch):
    import types

    from cpf_commands.bench import run as bench_run

    calls = []

    def fake_run_bench(policies, scenarios, num_seeds, out, figures):
        calls.append((tuple(policies), tuple(scenarios), num_seeds, out, figures))
        return [types.SimpleNamespace(seeds=(0,) * num_seeds) for _ in range(3)]

    monkeypatch.setattr(bench_run, "run_bench", fake_run_bench)
    rows = measure("wang2014", fleets=(), min_seconds=0.01, max_steps=5, bench_num_seeds=4)
    ((policies, scenarios, seeds, out, figures),) = calls
    assert seeds == 4 and out is None and not figures and "nn_dsc" in policies
    assert scenarios[0] == "bench_mild"
    (bench,) = [row for row in rows if str(row["component"]).startswith("cpf-bench")]
    assert bench["component"] == "cpf-bench default (12 episodes)"
    assert bench["steps_per_s"] == pytest.approx(12 / bench["seconds"], rel=1e-2)


def test_speed_command_prints_json(capsys):
    argv = ["--fleets", "1", "--seconds", "0.01", "--max-steps", "5", "--json", "--quiet"]
    assert speed_main(argv) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {row["B"] for row in rows} == {1}
    assert [row["component"] for row in rows][-2:] == [
        "wang2014 episode (5 steps), nn_dsc, stepped",
        "wang2014 episode (5 steps), nn_dsc, ClosedLoop.run",
    ]
    for row in rows:
        assert {"component", "B", "n", "steps_per_s", "vessel_steps_per_s"} <= set(row)


@pytest.mark.slow
@pytest.mark.parametrize("policy", sorted(POLICIES))
@pytest.mark.parametrize("name", scenarios.list_scenarios())
def test_full_episode_of_every_policy_on_every_scenario(name, policy):
    """Whole episodes: nobody leaves its path, forces respect the limits, path errors settle."""
    trajectory = run_episode(name, policy, seed=0)
    scenario = scenarios.get(name)
    assert trajectory.time.shape[0] == scenario.max_steps, "episode terminated early"
    metrics = episode_metrics(trajectory)
    assert metrics["force_within_limits"]
    # Steady state within 5 cm of every path (measured: <= 2.6 cm on every pair).
    assert max(metrics["path_error_max"]) < 0.05


def test_compare_policies_example_runs_the_bench_with_a_custom_policy(tmp_path, capsys):
    example = _load_example("compare_policies")
    argv = [
        "--scenarios",
        "bench_mild",
        "--num-seeds",
        "2",
        "--max-steps",
        "20",
        "--out",
        str(tmp_path),
    ]
    cells = example.main(argv)
    assert [cell.policy for cell in cells] == ["nn_dsc", "backstepping", "nn_dsc_soft"]
    assert cells[0].seeds == cells[2].seeds
    assert cells[0].metrics["cost"].tolist() != cells[2].metrics["cost"].tolist()
    assert "| nn_dsc_soft |" in capsys.readouterr().out


def test_train_residual_ppo_example_trains_evaluates_and_reports(tmp_path, capsys):
    """Its three phases on a tiny budget: a run folder, both rewards' benches, the summary."""
    example = _load_example("train_residual_ppo")
    runs, results = tmp_path / "runs", tmp_path / "results"
    common = ["--runs", str(runs), "--results", str(results), "--scenarios", "bench_lossy_links"]
    train = ["train", *common, "--timesteps", "2000", "--fleets", "2", "--num-seeds", "1"]
    assert example.main([*train, "--seed", "3", "--agents", "residual_ppo"]) == 0
    run = runs / "residual_ppo_bench_lossy_links_s3"
    assert (run / "config.json").is_file() and (run / "manifest.json").is_file()
    evaluate = ["evaluate", *common, "--eval-num-seeds", "2", "--eval-max-steps", "40"]
    assert example.main(evaluate) == 0
    for label in ("training_reward", "quadratic_reward"):
        rows = (results / f"bench_lossy_links_{label}" / "episodes.csv").read_text().splitlines()
        assert len(rows) == 1 + 3 * 2  # nn_dsc, backstepping and the run, two seeds each
    summary = (results / "summary.md").read_text()
    assert "--eval-num-seeds 2 --eval-max-steps 40" in summary and run.name in summary
    capsys.readouterr()


def test_hard_track_step_benchmark_times_both_sides():
    spec = importlib.util.spec_from_file_location(
        "hard_track_step", ROOT / "benchmarks" / "hard_track_step.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    argv = ["--fleets", "4", "--rounds", "1", "--seconds", "0.05", "--scenarios", "hard_sensing"]
    [(name, hard_rate, core_rate)] = module.main(argv)
    assert name == "hard_sensing" and hard_rate > 0 and core_rate > 0
