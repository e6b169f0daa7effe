"""The hard-track studies: the told-state variant and the bound's tightness check."""

from __future__ import annotations

import dataclasses

import numpy as np
from conftest import ROOT, load_script

from cpf_bench.report import METRICS, CellResult, episodes_csv
from cpf_env import scenarios
from cpf_env.model.sensors import Sensors


def test_the_told_state_variant_is_the_hard_scenario_with_ideal_sensors() -> None:
    script = load_script(ROOT / "studies/hard_track/told_state.py")
    task, told = scenarios.get("hard_heterogeneous"), script.told_state("hard_heterogeneous")
    assert told.sensors == Sensors() and not task.sensors.ideal
    assert told.thrusters == task.thrusters  # the thrusters stay: only the observation changes
    assert dataclasses.replace(told, name=task.name, sensors=task.sensors) == task


def test_the_hard_bench_is_read_as_mean_costs_per_policy_and_scenario(tmp_path) -> None:
    script = load_script(ROOT / "studies/hard_track/told_state.py")
    cells = [
        CellResult(policy, "hard_sensing", (10000, 10002), False,
                   {m: np.array([cost, cost + 2.0]) for m in METRICS})
        for policy, cost in (("mpc_tuned_ekf", 100.0), ("oracle", 60.0))
    ]  # fmt: skip
    (tmp_path / "episodes.csv").write_text(episodes_csv(cells))
    assert script._hard_costs(tmp_path) == {  # the mean over the two seeds
        ("mpc_tuned_ekf", "hard_sensing"): 101.0, ("oracle", "hard_sensing"): 61.0
    }  # fmt: skip


def test_the_tightness_check_compares_the_oracle_with_more_samples(capsys) -> None:
    script = load_script(ROOT / "studies/hard_track/bound_tightness.py")
    argv = ["--num-seeds", "1", "--max-steps", "20", "--scenarios", "hard_sensing"]
    [(name, base, more)] = script.main(argv)
    assert name == "hard_sensing" and base > 0 and more > 0
    assert "oracle_48_samples" in capsys.readouterr().out
