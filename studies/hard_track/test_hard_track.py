"""The hard-track studies: the room's decomposition and the bound's tightness check."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import ROOT, load_script

from cpf_bench.report import METRICS, CellResult, episodes_csv
from cpf_env import FleetSim, scenarios
from cpf_env.model.links import LinkImpairments
from cpf_env.model.sensors import Sensors


def test_the_told_variants_replace_only_what_the_scenario_impairs() -> None:
    script = load_script(ROOT / "studies/hard_track/decomposition.py")
    task = scenarios.get("hard_heterogeneous")  # sensors, ideal links
    assert set(script.variants("hard_heterogeneous")) == {"state"}
    told = script.variants("hard_heterogeneous")["state"]
    assert told.sensors == Sensors() and told.thrusters == task.thrusters
    assert dataclasses.replace(told, name=task.name, sensors=task.sensors) == task
    large = scenarios.get("hard_large_fleet")  # sensors and a lossy ring
    both = script.variants("hard_large_fleet")["both"]
    assert both.links == LinkImpairments() and both.sensors == Sensors()
    assert dataclasses.replace(both, name=large.name, sensors=large.sensors,
                               links=large.links) == large  # fmt: skip
    assert script.variants("hard_underactuated") == {}  # nothing a vessel lacks but the future


def test_the_decomposition_reads_the_best_design_and_the_bound_on_the_same_seeds(
    tmp_path, capsys
) -> None:
    script = load_script(ROOT / "studies/hard_track/decomposition.py")
    cells = [
        CellResult(policy, "hard_underactuated", (10000, 10001, 10002), False,
                   {m: np.array([cost, cost + 2.0, cost + 100.0]) for m in METRICS})
        for policy, cost in (("nn_dsc", 300.0), ("mpc_tuned", 100.0), ("oracle", 60.0))
    ]  # fmt: skip
    (tmp_path / "episodes.csv").write_text(episodes_csv(cells))
    argv = ["--hard", str(tmp_path), "--num-seeds", "2", "--scenarios", "hard_underactuated"]
    [row] = script.main(argv)
    assert row["best"] == "mpc_tuned" and row["J_best"] == 101.0 and row["oracle"] == 61.0
    assert "| hard_underactuated | mpc_tuned | 101.0 | - | - | - | 61.0 | 100% |" in (
        capsys.readouterr().out
    )


def test_the_tightness_check_compares_the_oracle_with_more_samples(capsys) -> None:
    script = load_script(ROOT / "studies/hard_track/bound_tightness.py")
    argv = ["--num-seeds", "1", "--max-steps", "20", "--scenarios", "hard_sensing"]
    [(name, base, more)] = script.main(argv)
    assert name == "hard_sensing" and base > 0 and more > 0
    assert "oracle_48_samples" in capsys.readouterr().out


def test_the_crossing_bound_study_runs_its_oracle_variants(capsys) -> None:
    script = load_script(ROOT / "studies/hard_track/crossing_bound.py")
    costs = script.main(["--num-seeds", "1", "--max-steps", "20", "--scenarios", "hard_crossing"])
    assert set(costs) == {(label, "hard_crossing") for label in script.VARIANTS}
    assert all(cost > 0 for cost in costs.values())
    assert "| the oracle | hard_crossing |" in capsys.readouterr().out


def test_the_safety_tuning_study_sweeps_distance_and_gain(capsys) -> None:
    script = load_script(ROOT / "studies/hard_track/safety_tuning.py")
    argv = ["--num-seeds", "1", "--max-steps", "20", "--distances", "0.7", "--gains", "1.0"]
    [(distance, gain, cost)] = script.main(argv)
    assert (distance, gain) == (0.7, 1.0) and cost > 0
    assert "| 0.7 | 1.0 |" in capsys.readouterr().out


def test_the_filter_tuning_study_compares_one_filter_per_factor_with_the_bank(capsys) -> None:
    script = load_script(ROOT / "studies/hard_track/filter_tuning.py")
    table = script.main(["--num-seeds", "1", "--max-steps", "40", "--factors", "1", "0.01"])
    assert set(table) == {"x1", "x0.01", "bank (0.001, 0.03, 1.0, 30.0)"}
    assert all(set(costs) == set(script.SENSING) for costs in table.values())
    assert "| x0.01 |" in capsys.readouterr().out


def test_the_crossing_geometry_study_moves_only_the_formation(capsys) -> None:
    script = load_script(ROOT / "studies/hard_track/crossing_geometry.py")
    task, moved = scenarios.get("hard_crossing"), script.with_offset(1.2)
    assert moved.paths != task.paths and moved.initial.eta != task.initial.eta
    same = dataclasses.replace(moved, name=task.name, paths=task.paths, initial=task.initial)
    assert same == task
    costs = script.main(["--num-seeds", "1", "--max-steps", "20", "--offsets", "1.2"])
    assert set(costs[1.2]) == {"oracle", "mpc_tuned", "mpc_tuned_safe"}
    assert "| 1.2 | 0.85 |" in capsys.readouterr().out
    assert not list((ROOT / "results/bench_cache").glob("*offset*"))


def test_the_learners_study_groups_runs_by_method_and_pools_their_episodes(tmp_path) -> None:
    script = load_script(ROOT / "studies/hard_track/learners.py")
    for name in ("ppo_s0", "ppo_s1", "student_s2", "notes"):
        (tmp_path / name).mkdir()
    (tmp_path / "ppo_s1.log").touch()
    for name in ("ppo_s0", "ppo_s1", "student_s2"):
        (tmp_path / name / "manifest.json").write_text("{}")
    runs = script.methods(tmp_path)
    assert runs == {"ppo": [str(tmp_path / "ppo_s0"), str(tmp_path / "ppo_s1")],
                    "student": [str(tmp_path / "student_s2")]}  # fmt: skip
    seeds = (10000, 10001)

    def cell(policy, costs):
        return CellResult(policy, "hard_sensing", seeds, True,
                          {m: np.array(costs, dtype=float) for m in METRICS})  # fmt: skip

    cells = [cell("mpc_tuned_ekf", [100.0, 100.0]), cell("oracle", [60.0, 60.0]),
             cell(runs["ppo"][0], [80.0, 90.0]), cell(runs["ppo"][1], [100.0, 110.0]),
             cell(runs["student"][0], [60.0, 60.0])]  # fmt: skip
    lines = script.summary(cells, runs, "mpc_tuned_ekf")
    # scores 0.5, 0.25, 0, -0.25: the IQM of four drops one at each end
    assert any("ppo: room closed, IQM over 2 seeds x 2 episodes 0.125" in line for line in lines)
    assert any("student: room closed, IQM over 1 seeds x 2 episodes 1.000" in x for x in lines)


def test_the_messages_study_finds_what_a_known_message_carries() -> None:
    """A design that sends its path rate in entry 2: correlation 1 with the path rate."""
    from baselines import make_policy
    from cpf_bench.rollout import rollout

    script = load_script(ROOT / "studies/hard_track/messages.py")
    scenario = scenarios.make_scenario("bench_lossy_links", message_size=3, max_steps=60)
    design = make_policy("nn_dsc", scenario)

    class SendsRate:  # nn_dsc, its path rate in entry 2, a constant in entry 1
        name, n, obs_dim, act_dim = "rate", design.n, design.obs_dim, design.act_dim
        agents, diagnostics = design.agents, design.diagnostics

        def act_batch(self, obs, fleets=None):
            actions = design.act_batch(obs, fleets)
            actions[..., 5], actions[..., 6] = 0.5, actions[..., 3]
            return actions

        def reset(self, seed=None):
            design.reset(seed)

        def reset_fleets(self, fleets):
            design.reset_fleets(fleets)

    record = script.SenderRecord(learned=2)
    rollout(SendsRate(), scenario, [0, 1], observer=record)
    assert record.messages.shape == (2 * 60 * scenario.n, 2)
    assert record.features.shape == (2 * 60 * scenario.n, len(script.FEATURES))
    std, correlation, r2 = script.carried(record.messages, record.features)
    rate = script.FEATURES.index("path rate")
    assert std[0] == 0.0 and np.isnan(correlation[0]).all() and np.isnan(r2[0])
    assert correlation[1, rate] == pytest.approx(1.0) and r2[1] == pytest.approx(1.0)
    assert np.nanmax(np.abs(np.delete(correlation[1], rate))) < 0.999

    cut = script.MessagesCut(SendsRate(), learned=2)
    cut.reset()
    obs = FleetSim(scenario).reset(seeds=[0])
    assert np.all(cut.act_batch(obs)[..., 5:] == 0.0)


def test_the_hand_designed_messages_study_runs_on_validation_seeds(capsys) -> None:
    script = load_script(ROOT / "studies/hard_track/hand_messages.py")
    scenario = scenarios.get("hard_crossing")
    rate = script.Rate(scenario)
    obs = FleetSim(scenario).reset(seeds=[0])
    actions = rate.act_batch(obs)
    assert np.array_equal(actions[..., 5], actions[..., 3])  # the path rate, sent in entry 1
    assert rate.message_entries == 2
    import sys

    argv, sys.argv = sys.argv, ["hand_messages.py", "--num-seeds", "1", "--max-steps", "30"]
    try:
        script.main()
    finally:
        sys.argv = argv
    printed = capsys.readouterr().out
    assert "validation seeds 9000-9000" in printed
    assert "| mpc_tuned | " in printed and "+0.0 (+0.0 to +0.0)" in printed
    assert "path rate in entry 1" in printed and "age compensated twice" in printed


def test_the_filter_information_study_tells_the_bank_the_hull_and_nothing_else(capsys) -> None:
    script = load_script(ROOT / "studies/hard_track/filter_information.py")
    task = scenarios.make_scenario("hard_heterogeneous", max_steps=60)
    exact = task.replace(model_spread=0.0)
    # With no model spread the true models are the nominal ones: told the hull is the bank.
    exact_costs = script.told_costs(exact, [200])
    assert len(exact_costs) == 4 and len(set(exact_costs.values())) == 1
    told = script.told_costs(task, [200])
    assert told["mpc_tuned_mmae"] != told["mpc_tuned_mmae_told_hull"]
    found = script.main(
        ["--num-seeds", "2", "--held-out", "1", "--cost-seeds", "1", "--max-steps", "60"]
    )
    assert set(found["maps"]) == {
        "hard_heterogeneous",
        "without the model spread",
        "without the thruster lag",
    }
    assert list(script.variants("hard_sensing")) == ["hard_sensing"]  # no spread, no lag
    for rows in found["maps"].values():
        assert set(rows) == {"the bank", "the map", "the map, told the hull"}
        assert all(np.isfinite(rows["the map"]))
    assert "| hard_heterogeneous | the bank |" in capsys.readouterr().out
