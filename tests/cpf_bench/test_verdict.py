"""The multi-metric verdict, --reference and --split, on constructed and short real runs."""

from __future__ import annotations

import re

import numpy as np
import pytest

from cpf_bench import verdict as verdicts_module
from cpf_bench.report import CellResult
from cpf_bench.verdict import GUARDED, verdict
from cpf_commands.bench.cli import bench_main
from cpf_commands.bench.run import run_bench
from cpf_env.evaluation.fleet_metrics import COURSE_UNMEASURED, METRICS

SEEDS = tuple(range(10))


def _cell(policy: str, cost: np.ndarray, **changes: np.ndarray) -> CellResult:
    """A cell on hulls with a sway actuator (the course not measured), changes applied."""
    metrics = {name: np.full(len(SEEDS), 0.01) for name in METRICS}
    metrics.update({name: np.full(len(SEEDS), value) for name, value in COURSE_UNMEASURED.items()})
    metrics["progress_window"] = np.full(len(SEEDS), 0.9)
    metrics["terminated"] = np.zeros(len(SEEDS))
    metrics["cost"] = cost
    metrics.update(changes)
    return CellResult(policy, "bench_mild", SEEDS, False, metrics)


BASE_COST = 100.0 + np.arange(10.0)
REFERENCE = _cell("nn_dsc", BASE_COST)
COURSE = {name: np.full(len(SEEDS), 0.01) for name in COURSE_UNMEASURED}
#: The reference on hulls without a sway actuator: its course is measured.
SWAYLESS = _cell("nn_dsc", BASE_COST, **COURSE)


def test_lower_cost_and_no_regression_beats():
    v = verdict(_cell("better", BASE_COST - 5.0), REFERENCE)
    assert v.label == "beats"
    assert v.cost_difference == pytest.approx((-5.0, -5.0, -5.0))
    assert v.p_beats[0] == 1.0 and v.p_beats[1] < 0.75  # Wilson at 10/10


def test_a_heading_regression_makes_it_mixed_and_names_it():
    worse = np.full(10, 0.01 * 30)  # 30x the reference's heading error
    v = verdict(_cell("agent", BASE_COST - 5.0, heading_error_rms_window=worse), REFERENCE)
    assert v.label == "mixed (worse: heading)"
    assert v.regressed == ("heading",)


@pytest.mark.parametrize("metric", sorted(GUARDED))
def test_every_guarded_metric_can_regress(metric):
    _, floor, _ = GUARDED[metric]
    base = REFERENCE.metrics[metric]
    step = max(0.5 * abs(float(base.mean())), 2 * floor, 0.5)
    changed = base + step  # further from any target: the reference's progress is 0.9
    v = verdict(_cell("p", BASE_COST - 5.0, **{metric: changed}), REFERENCE)
    assert v.regressed == (GUARDED[metric][0],)


def test_without_a_sway_actuator_the_direction_is_not_guarded_the_position_is():
    """A crabbing, converging hull's heading and course offsets are how it holds its path."""
    off = np.full(10, 0.01 * 30)
    steering = {"heading_error_rms_window": off, "course_error_rms_window": off}
    held = verdict(_cell("p", BASE_COST - 5.0, **{**COURSE, **steering}), SWAYLESS)
    assert held.label == "beats"
    astray_cell = _cell("p", BASE_COST - 5.0, **{**COURSE, "cross_track_error_rms_window": off})
    assert verdict(astray_cell, SWAYLESS).label == "mixed (worse: cross-track)"
    with_sway = verdict(_cell("p", BASE_COST - 5.0, heading_error_rms_window=off), REFERENCE)
    assert with_sway.label == "mixed (worse: heading)"


def test_progress_is_judged_by_its_distance_from_the_schedule():
    """The reference is 10 % behind (0.9): 30 % ahead is further off, 5 % ahead closer."""
    ahead = verdict(_cell("p", BASE_COST - 5.0, progress_window=np.full(10, 1.3)), REFERENCE)
    assert ahead.label == "mixed (worse: progress)"
    near = verdict(_cell("p", BASE_COST - 5.0, progress_window=np.full(10, 1.05)), REFERENCE)
    assert near.label == "beats"
    worst = verdicts_module.worst_episode("progress_window", np.array([0.6, 1.0, 1.3]))
    assert worst == 0.6


def test_within_tolerance_or_below_the_floor_is_not_a_regression():
    # cross-track 5 % worse: within the 10 % tolerance; 0.5 mm worse on 0.1 mm: below 1 mm floor
    slightly = np.full(10, 0.0105)
    v = verdict(_cell("p", BASE_COST - 5.0, cross_track_error_rms_window=slightly), REFERENCE)
    assert v.label == "beats"
    tiny_base = _cell("nn_dsc", BASE_COST, cross_track_error_rms_window=np.full(10, 1e-4))
    tiny = np.full(10, 6e-4)
    v = verdict(_cell("p", BASE_COST - 5.0, cross_track_error_rms_window=tiny), tiny_base)
    assert v.label == "beats"


def test_higher_cost_loses_and_noise_is_no_difference():
    assert verdict(_cell("p", BASE_COST + 3.0), REFERENCE).label == "loses"
    noise = BASE_COST + np.array([3.0, -3.0] * 5)
    assert verdict(_cell("p", noise), REFERENCE).label == "no difference"


def test_suite_cost_difference_is_relative_and_stratified():
    other = CellResult("nn_dsc", "bench_switching", SEEDS, False, dict(REFERENCE.metrics))
    policy_a = _cell("p", BASE_COST * 0.9)
    policy_b = CellResult("p", "bench_switching", SEEDS, False, {**REFERENCE.metrics})
    cells = [REFERENCE, other, policy_a, policy_b]
    mean, low, high = verdicts_module.suite_cost_difference(cells, "p", "nn_dsc")
    assert mean == pytest.approx(-0.05)  # -10 % on one scenario, 0 on the other
    assert low <= mean <= high


def test_reference_must_be_one_of_the_policies():
    with pytest.raises(ValueError, match="--reference backstepping is not among"):
        run_bench(
            ["nn_dsc", "dsc"], ["bench_mild"], num_seeds=1, max_steps=2, reference="backstepping"
        )


def test_terminal_prints_the_verdict_against_any_reference(tmp_path, capsys):
    argv = ["--policies", "backstepping", "dsc", "--scenarios", "bench_mild", "--num-seeds", "3"]
    argv += ["--max-steps", "20", "--reference", "backstepping", "--out", str(tmp_path), "--quiet"]
    assert bench_main([*argv, "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert "verdict: against backstepping" in out.replace("\n", " ")
    assert "/ backstepping [95 %]" in out
    ranked = re.findall(r"^  \d  (\S+)", out, flags=re.MULTILINE)
    assert sorted(ranked) == ["backstepping", "dsc"]
    summary = (tmp_path / "summary.md").read_text()
    assert "## Verdict against backstepping" in summary
    assert "--reference backstepping" in summary


def test_shift_split_runs_the_shifted_scenarios():
    cells = run_bench(
        ["nn_dsc"],
        ["bench_lossy_links", "bench_large_fleet"],
        num_seeds=2,
        max_steps=5,
        split="shift",
    )
    assert [c.scenario for c in cells] == ["bench_lossy_links_shift", "bench_large_fleet_shift"]
    with pytest.raises(ValueError, match="no held-out splits"):
        run_bench(["nn_dsc"], ["wang2014"], num_seeds=1, max_steps=2, split="shift")


def test_marl_eval_export_has_the_nested_layout(tmp_path):
    import json

    out = tmp_path / "marl.json"
    argv = ["--policies", "nn_dsc", "dsc", "--scenarios", "bench_mild", "--num-seeds", "2"]
    argv += ["--max-steps", "5", "--out", str(tmp_path / "b"), "--quiet", "--no-figures"]
    assert bench_main([*argv, "--marl-eval", str(out)]) == 0
    data = json.loads(out.read_text())
    runs = data["cpf_env"]["bench_mild"]["dsc"]
    assert sorted(runs) == ["seed_10000", "seed_10001"]
    metrics = runs["seed_10000"]["absolute_metrics"]
    assert metrics["return"] == [-metrics["cost"][0]]
    assert "speed_estimate_error_rms" in metrics and len(metrics["cross_track_error_rms"]) == 1


def test_one_bad_episode_is_named_without_changing_the_verdict():
    from cpf_bench.report import summarize
    from cpf_bench.verdict import worst_episode_regressed
    from cpf_commands.bench.ranking import terminal_report

    formation = np.full(len(SEEDS), 0.005)
    formation[3] = 1.1  # one episode in ten ends a metre off the formation
    cell = _cell("p", BASE_COST - 50.0, formation_error_rms_window=formation)
    assert verdict(cell, REFERENCE).label == "beats"  # the mean's interval reaches below zero
    assert worst_episode_regressed(cell, REFERENCE) == ("formation",)
    text = terminal_report(summarize([REFERENCE, cell], "nn_dsc"), [REFERENCE, cell], "nn_dsc")
    assert (
        "p on bench_mild, worst episode worse than nn_dsc's worst: formation 1.1 m vs 0.01 m"
        in (text)
    )
    assert "p on bench_mild, worse than nn_dsc" not in text
    # within the tolerance, below the floor, or better: not named
    for value in (0.0105, 0.0109, 0.001):
        close = np.full(len(SEEDS), 0.005)
        close[3] = value
        near = _cell("q", BASE_COST - 50.0, cross_track_error_rms_window=close)
        assert worst_episode_regressed(near, REFERENCE) == ()
    progress = np.full(len(SEEDS), 0.9)
    progress[0] = 0.5  # one episode that made half the way: higher is better
    slow = _cell("r", BASE_COST - 50.0, progress_window=progress)
    assert worst_episode_regressed(slow, REFERENCE) == ("progress",)
    failed = _cell("s", BASE_COST - 50.0, terminated=np.eye(len(SEEDS))[0])
    assert "failures" in worst_episode_regressed(failed, REFERENCE)


def test_terminal_names_the_regressed_metrics_with_their_values():
    from cpf_bench.report import summarize
    from cpf_commands.bench.ranking import terminal_report

    def terminal(cells: list[CellResult]) -> str:
        return terminal_report(summarize(cells, "nn_dsc"), cells, "nn_dsc")

    heading = np.full(len(SEEDS), 0.03)
    text = terminal([REFERENCE, _cell("p", BASE_COST - 50.0, heading_error_rms_window=heading)])
    assert "mixed (worse: heading)" in text
    assert "p on bench_mild, worse than nn_dsc: heading 0.03 rad vs 0.01 rad" in text
    assert "worse than" not in terminal([REFERENCE, _cell("q", BASE_COST - 50.0)])


# --- the practical-equivalence margin of the cost ---------------------------------------------


def test_a_difference_inside_the_margin_is_equivalent_whatever_its_sign():
    tiny = BASE_COST * (1.0 - 1e-4)  # 0.01 % lower on every seed: resolved, but immaterial
    assert verdict(_cell("p", tiny), REFERENCE).label == "equivalent"
    assert verdict(_cell("p", BASE_COST * (1.0 + 1e-4)), REFERENCE).label == "equivalent"
    assert verdict(_cell("p", tiny), REFERENCE, margin=0.0).label == "beats"
    v = verdict(_cell("p", BASE_COST * (1.0 + 1e-4)), REFERENCE, margin=0.0)
    assert v.label == "loses" and v.margin == 0.0


def test_the_margin_scales_with_the_reference_cost_and_needs_the_whole_interval_inside():
    v = verdict(_cell("p", BASE_COST - 0.5), REFERENCE)  # 0.48 % of 104.5, zero spread
    assert v.margin == pytest.approx(0.01 * BASE_COST.mean())
    assert v.label == "equivalent"
    assert verdict(_cell("p", BASE_COST - 0.5), REFERENCE, margin=0.004).label == "beats"
    # mean -0.5 but the interval reaches past -1.045 (the margin): resolved as beats, not equivalent
    spread = BASE_COST - 0.5 + np.array([1.5, -2.5] * 5)
    assert verdict(_cell("p", spread), REFERENCE).label == "no difference"


def test_an_equivalent_cost_still_names_a_regressed_guarded_metric():
    worse = np.full(10, 0.01 * 30)
    v = verdict(_cell("p", BASE_COST * (1.0 - 1e-4), heading_error_rms_window=worse), REFERENCE)
    assert v.label == "equivalent (worse: heading)"


def test_a_negative_or_nan_margin_is_refused_before_anything_runs(tmp_path, capsys):
    with pytest.raises(ValueError, match="cost margin"):
        verdict(_cell("p", BASE_COST), REFERENCE, margin=-0.01)
    for bad in ("-0.01", "nan"):
        with pytest.raises(SystemExit):
            bench_main(["--cost-margin", bad, "--out", str(tmp_path / "out"), "--quiet"])
        assert "--cost-margin" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_help_states_the_default_margin(capsys):
    with pytest.raises(SystemExit):
        bench_main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--cost-margin FRACTION" in text and "(default: 0.01, i.e. 1%; 0 turns it off)" in text
