from __future__ import annotations

import ast
import csv
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

import agents
from baselines import POLICIES, SAFE, make_policy
from cpf_bench import report as bench_report
from cpf_bench.episodes import METRICS, run_episodes
from cpf_commands.bench import run as bench_run
from cpf_commands.bench.cli import bench_main
from cpf_commands.bench.run import BASE_SEED, run_bench
from cpf_commands.common.policies import policy_label, resolve_policy
from cpf_commands.run.cli import run_main
from cpf_commands.run.experiment import run_episode
from cpf_env import scenarios
from cpf_env.scenarios import suite
from cpf_env.sim.fleet import FleetSim


class OffPath:
    """Stand-in policy that pushes every vessel sideways off its path at full sway force."""

    name = "off_path"

    def __init__(self, scenario):
        self.scenario = scenario
        self.diagnostics = {}

    def reset(self, seed=None):
        del seed

    def act_batch(self, obs):
        actions = np.zeros((obs.shape[0], self.scenario.n, 4 + self.scenario.message_size))
        actions[..., 1] = self.scenario.tau_max[0][1]
        actions[..., 3] = self.scenario.v0_schedule.values[0]
        return actions


class Recorder:
    """Wraps a policy and keeps the first observation batch it saw."""

    def __init__(self, policy, name):
        self.policy, self.name, self.first = policy, name, None

    @property
    def diagnostics(self):
        return self.policy.diagnostics

    def reset(self, seed=None):
        self.policy.reset(seed)
        self.first = None

    def act_batch(self, obs):
        if self.first is None:
            self.first = np.array(obs)
        return self.policy.act_batch(obs)


def _tight(max_path_error=3.0):
    return scenarios.get("wang2014").replace(name="tight", max_path_error=max_path_error)


# --- the suite -----------------------------------------------------------------------------


def test_suite_scenarios_are_registered_and_random():
    names = scenarios.list_scenarios()
    assert suite.list_suite() == [n for n in names if "bench_" in n and not n.endswith("_shift")]
    assert len(suite.SUITE) == 7
    for name in suite.SUITE:
        scenario = scenarios.get(name)
        assert scenario.name == name and not suite.is_deterministic(scenario)
        sim = FleetSim(scenario, num_fleets=2)
        sim.reset(seeds=[1, 2])
        assert not np.array_equal(sim.arrays.eta[0], sim.arrays.eta[1]), name


@pytest.mark.parametrize(
    ("name", "deterministic"),
    [
        ("wang2014", True),
        ("saturation_heavy", True),
        ("switching_topology", True),
        ("lossy_links", False),
        ("current_and_waves", False),
        ("heterogeneous", False),
    ],
)
def test_is_deterministic(name, deterministic):
    assert suite.is_deterministic(scenarios.get(name)) is deterministic


def test_a_deterministic_scenario_gives_the_same_episode_for_every_seed():
    """What is_deterministic promises, checked on the simulator."""
    scenario = scenarios.get("saturation_heavy")
    metrics = run_episodes(make_policy("nn_dsc", scenario), scenario, [1, 2, 3], max_steps=40)
    for name in METRICS:
        np.testing.assert_array_equal(metrics[name], metrics[name][0], err_msg=name)


# --- episodes ------------------------------------------------------------------------------


def test_batched_episode_equals_single_episode_bit_for_bit():
    scenario = scenarios.get("bench_lossy_links")
    both = run_episodes(make_policy("nn_dsc", scenario), scenario, [5, 6], max_steps=60)
    alone = run_episodes(make_policy("nn_dsc", scenario), scenario, [6], max_steps=60)
    for name in METRICS:
        np.testing.assert_array_equal(both[name][1:], alone[name], err_msg=name)


def test_episode_metrics_agree_with_the_recorded_trajectory():
    scenario = scenarios.get("bench_mild")
    metrics = run_episodes(make_policy("dsc", scenario), scenario, [3], max_steps=80)
    trajectory = run_episode(scenario, "dsc", seed=3, max_steps=80)
    assert metrics["return"][0] == pytest.approx(trajectory.reward.mean(axis=1).sum(), rel=1e-12)
    assert metrics["path_error_max"][0] == pytest.approx(
        max(trajectory.errors[1:, :, 0].max(), metrics["path_error_max"][0]), rel=1e-12
    )
    applied = trajectory.tau_applied
    saturated = (trajectory.tau_command != applied).any(axis=2).mean()
    assert metrics["saturated_fraction"][0] == pytest.approx(saturated, rel=1e-12)
    theta = trajectory.theta  # before each step; the bench measures after it
    assert metrics["theta_spread_rms"][0] > 0.0
    assert metrics["theta_spread_end"][0] <= theta.max(axis=1).max() - theta.min()
    # cpf-run reports the bench's numbers: one rollout, one set of metrics
    for name in METRICS:
        np.testing.assert_equal(trajectory.fleet_metrics[name], metrics[name][0], err_msg=name)


def test_cost_split_by_reward_term_adds_up():
    scenario = scenarios.get("bench_current_waves")
    metrics = run_episodes(make_policy("nn_dsc", scenario), scenario, [0, 1], max_steps=50)
    for suffix in ("", "_window"):
        terms = sum(metrics[f"cost_{term}{suffix}"] for term in ("position", "heading", "sync"))
        terms = terms + metrics[f"cost_speed{suffix}"] + metrics[f"cost_effort{suffix}"]
        np.testing.assert_allclose(terms, metrics[f"cost{suffix}"], rtol=1e-12)
        np.testing.assert_array_equal(metrics[f"return{suffix}"], -metrics[f"cost{suffix}"])


def test_a_failing_policy_is_masked_after_it_leaves_the_path():
    scenario = _tight()
    metrics = run_episodes(OffPath(scenario), scenario, [0], max_steps=300)
    assert metrics["terminated"][0] == 1.0
    assert 1 < metrics["steps"][0] < 300
    assert metrics["path_error_max"][0] > scenario.max_path_error
    # The final window starts after the failure: it is the failure step itself.
    assert metrics["path_error_max_window"][0] == metrics["path_error_max"][0]
    assert np.isnan(metrics["speed_estimate_error_rms"][0])  # no estimator


def test_terminating_on_the_last_step_is_a_failure():
    scenario = _tight()
    steps = int(run_episodes(OffPath(scenario), scenario, [0], max_steps=300)["steps"][0])
    metrics = run_episodes(OffPath(scenario), scenario, [0], max_steps=steps)
    assert metrics["terminated"][0] == 1.0 and metrics["steps"][0] == steps


# --- the bench -----------------------------------------------------------------------------


def test_seeds_are_paired_across_policies():
    recorders = {
        label: Recorder(make_policy(name, "bench_mild"), label)
        for label, name in (("a", "nn_dsc"), ("b", "backstepping"))
    }
    cells = run_bench(recorders, ["bench_mild"], num_seeds=3, max_steps=5)
    assert cells[0].seeds == cells[1].seeds == (BASE_SEED, BASE_SEED + 1, BASE_SEED + 2)
    np.testing.assert_array_equal(recorders["a"].first, recorders["b"].first)
    assert not np.array_equal(recorders["a"].first[0], recorders["a"].first[1])


def test_a_deterministic_scenario_runs_one_episode():
    (cell,) = run_bench(["nn_dsc"], ["wang2014"], num_seeds=5, max_steps=5)
    assert cell.deterministic and cell.seeds == (BASE_SEED,)
    assert cell.metrics["cost"].shape == (1,)


def test_identical_arguments_give_identical_files(tmp_path):
    argv = ["--policies", "nn_dsc", "backstepping", "--scenarios", "bench_mild", "wang2014"]
    argv += ["--num-seeds", "3", "--max-steps", "15", "--quiet"]
    for run in ("one", "two"):
        assert bench_main([*argv, "--out", str(tmp_path / run)]) == 0
    names = sorted(path.name for path in (tmp_path / "one").iterdir())
    assert {"episodes.csv", "summary.csv", "summary.md", "cost.png"} <= set(names)
    pictures = [n for n in names if n.endswith(".png")]
    assert len(pictures) == len(bench_report.HEADLINE) + 2  # + the two rliable-style figures
    assert {"performance_profile.png", "probability_of_improvement.png"} <= set(pictures)
    for name in names:
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes()
    summary = (tmp_path / "one" / "summary.md").read_text()
    assert "`cpf-bench --policies nn_dsc backstepping --scenarios bench_mild wang2014" in summary
    assert "wang2014 (deterministic" in summary and str(tmp_path) not in summary
    assert f"benchmark suite version {suite.SUITE_VERSION} " in summary
    with open(tmp_path / "one" / "summary.csv") as file:
        versions = {(r["scenario"], r["suite_version"]) for r in csv.DictReader(file)}
    assert versions == {("bench_mild", str(suite.SUITE_VERSION)), ("wang2014", ""), ("all", "")}


def test_failures_are_counted_not_dropped(tmp_path):
    policies = {"nn_dsc": "nn_dsc", "off_path": OffPath}
    cells = run_bench(policies, [_tight()], num_seeds=2, max_steps=250, out=tmp_path, figures=False)
    assert cells[1].metrics["terminated"].tolist() == [1.0]  # deterministic: one episode
    with open(tmp_path / "summary.csv") as file:
        rows = {(r["policy"], r["metric"]): r for r in csv.DictReader(file)}
    assert rows[("off_path", "cost")]["failures"] == "1"
    assert rows[("off_path", "cost")]["n_episodes"] == "1"
    assert rows[("nn_dsc", "cost")]["failures"] == "0"
    assert rows[("off_path", "terminated")]["mean"] == "1.0"
    assert ("off_path", "speed_estimate_error_rms") not in rows  # no estimator, no row
    with open(tmp_path / "episodes.csv") as file:
        episodes = list(csv.DictReader(file))
    assert [(e["policy"], e["terminated"]) for e in episodes] == [
        ("nn_dsc", "0.0"),
        ("off_path", "1.0"),
    ]
    assert "| off_path |" in (tmp_path / "summary.md").read_text()
    assert "| 1/1 |" in (tmp_path / "summary.md").read_text()


def test_summary_has_the_required_columns_and_reference_scores():
    cells = run_bench(
        ["nn_dsc", "dsc"], ["bench_mild", "bench_switching"], num_seeds=4, max_steps=30
    )
    rows = bench_report.summarize(cells)
    assert set(bench_report.SUMMARY_COLUMNS) >= {
        "policy", "scenario", "metric", "mean", "iqm", "ci_low", "ci_high",
        "n_episodes", "failures",
    }  # fmt: skip
    index = {(r["policy"], r["scenario"], r["metric"]): r for r in rows}
    own = index[("nn_dsc", "bench_mild", "cost")]
    assert own["normalized"] == 1.0 and own["p_beats_reference"] is None
    other = index[("dsc", "bench_mild", "cost")]
    ours = cells[2].metrics["cost"]  # policies outermost: nn_dsc's two cells, then dsc's
    reference = cells[0].metrics["cost"]
    assert other["normalized"] == pytest.approx(ours.mean() / reference.mean())
    assert other["p_beats_reference"] == pytest.approx(np.mean(ours < reference))
    assert other["ci_low"] <= other["mean"] <= other["ci_high"]
    suite_row = index[("dsc", "all", "cost_normalized")]
    assert suite_row["n_episodes"] == 8
    assert suite_row["mean"] == pytest.approx(
        np.mean(
            np.r_[
                ours / reference.mean(), cells[3].metrics["cost"] / cells[1].metrics["cost"].mean()
            ]
        )
    )


def test_switching_is_scored_while_the_fleet_re_synchronizes():
    """bench_switching's final window is not bench_mild's (as it was in suite version 1)."""
    cells = run_bench(["nn_dsc"], ["bench_mild", "bench_switching"], num_seeds=2)
    mild, switching = (cell.metrics["cost_window"] for cell in cells)
    assert np.all(switching > 10 * mild)


def _picky(scenario):
    """A stand-in for a trained agent that fits only some observation layouts."""
    if scenario.name == "bench_switching":
        raise ValueError("inputs of size 34 do not fit the network")
    return make_policy("dsc", scenario)


def test_a_policy_that_does_not_fit_a_scenario_skips_it_and_says_so(tmp_path):
    policies = {"nn_dsc": "nn_dsc", "picky": _picky}
    names = ["bench_mild", "bench_switching"]
    cells = run_bench(policies, names, num_seeds=2, max_steps=5, out=tmp_path, figures=False)
    assert [(c.policy, c.scenario) for c in cells] == [
        ("nn_dsc", "bench_mild"),
        ("nn_dsc", "bench_switching"),
        ("picky", "bench_mild"),
    ]
    summary = (tmp_path / "summary.md").read_text()
    assert "- picky on bench_switching: inputs of size 34 do not fit the network" in summary
    with open(tmp_path / "summary.csv") as file:
        rows = list(csv.DictReader(file))
    assert {r["policy"] for r in rows if r["scenario"] == "all"} == {"nn_dsc"}
    with pytest.raises(ValueError, match="do not fit"):
        run_bench({"picky": _picky}, ["bench_switching"], num_seeds=1, max_steps=2)


def test_two_policies_with_one_label_are_refused():
    with pytest.raises(ValueError, match="'nn_dsc' is listed twice; duplicates are not allowed"):
        run_bench(["nn_dsc", "nn_dsc"], ["bench_mild"], num_seeds=1, max_steps=2)
    scenario = scenarios.get("bench_mild")
    with pytest.raises(ValueError, match="two policies are labelled 'off_path'"):
        run_bench([OffPath(scenario), OffPath(scenario)], [scenario], num_seeds=1, max_steps=2)


# --- one resolver for every command ---------------------------------------------------------


def test_resolver_builds_baselines_and_passes_objects_and_factories():
    scenario = scenarios.get("bench_mild")
    assert resolve_policy("dsc", scenario).name == "dsc"
    ready = OffPath(scenario)
    assert resolve_policy(ready, scenario) is ready
    assert isinstance(resolve_policy(OffPath, "bench_mild"), OffPath)
    assert policy_label("runs/agent/") == "runs/agent" and policy_label(ready) == "off_path"


@pytest.mark.parametrize(
    ("spec", "options", "message"),
    [
        ("no_such_policy", {}, "neither a baseline"),
        (OffPath, {"K1": 1.0}, "apply to baselines only"),
        (3, {}, "cannot use int as a policy"),
    ],
)
def test_resolver_rejects_what_it_cannot_use(spec, options, message):
    with pytest.raises(ValueError, match=message):
        resolve_policy(spec, "bench_mild", **options)


@pytest.fixture
def trained_agent(tmp_path, monkeypatch):
    """A cpf-train folder loaded by a stand-in agents.load_policy that returns nn_dsc."""
    calls = []

    def load_policy(path, scenario=None):
        calls.append((Path(path), scenario.name))
        return make_policy("nn_dsc", scenario)

    monkeypatch.setattr(agents, "load_policy", load_policy, raising=False)
    folder = tmp_path / "agent"
    folder.mkdir()
    return folder, calls


def test_a_trained_agent_goes_through_the_bench_like_a_baseline(trained_agent):
    folder, calls = trained_agent
    cells = run_bench(["nn_dsc", str(folder)], ["bench_mild"], num_seeds=2, max_steps=20)
    assert calls == [(folder, "bench_mild")]
    assert cells[1].policy == str(folder)
    for name in METRICS:  # the stand-in is nn_dsc: same seeds, same code, same numbers
        np.testing.assert_array_equal(cells[0].metrics[name], cells[1].metrics[name])


def test_cpf_run_takes_a_trained_agent_path(trained_agent, tmp_path, capsys):
    folder, calls = trained_agent
    argv = ["--policy", str(folder), "--scenario", "wang2014", "--max-steps", "10"]
    argv += ["--out", str(tmp_path / "out")]
    assert run_main([*argv, "--no-figures", "--quiet"]) == 0
    assert calls == [(folder, "wang2014")]
    assert (tmp_path / "out" / "wang2014_agent" / "metrics.json").exists()


class _InlineRay:
    """Stands in for Ray: each remote call runs at once, here, and its arguments are kept."""

    def __init__(self):
        self.calls = []
        self.shut_down = False

    def remote(self, num_cpus):
        assert num_cpus == 1

        def wrap(function):
            calls = self.calls

            class Remote:
                @staticmethod
                def remote(*args):
                    calls.append(args)
                    return function(*args)

            return Remote

        return wrap

    def wait(self, pending, num_returns):
        return pending[:num_returns], pending[num_returns:]

    def get(self, futures):
        return futures

    def shutdown(self):
        self.shut_down = True


def test_bench_ray_sends_each_cell_to_ray_with_agent_folders_made_absolute(
    trained_agent, tmp_path, monkeypatch
):
    folder, _ = trained_agent
    ray, started = _InlineRay(), []

    def start_ray(address, cpus_per_task, quiet):
        started.append((address, cpus_per_task))
        return ray

    monkeypatch.setattr(bench_run, "start_ray", start_ray)
    monkeypatch.chdir(folder.parent)  # the agent is given relative to here
    argv = ["--policies", "nn_dsc", folder.name, "--scenarios", "bench_mild", "bench_saturation"]
    argv += ["--num-seeds", "2", "--max-steps", "20", "--no-figures", "--quiet"]
    assert bench_main([*argv, "--out", "here"]) == 0
    assert not started
    assert bench_main([*argv, "--out", "cluster", "--address", "10.0.0.7:6379"]) == 0
    assert started == [("10.0.0.7:6379", 1)] and ray.shut_down
    sent = [(args[0], args[1], args[2].name) for args in ray.calls]
    assert sent == [
        ("nn_dsc", "nn_dsc", "bench_mild"),
        ("nn_dsc", "nn_dsc", "bench_saturation"),
        (folder.name, folder, "bench_mild"),  # absolute: a worker's directory may differ
        (folder.name, folder, "bench_saturation"),
    ]
    for name in ("episodes.csv", "summary.csv"):
        assert (tmp_path / "cluster" / name).read_bytes() == (tmp_path / "here" / name).read_bytes()
    assert bench_main([*argv, "--out", "local_ray", "--ray"]) == 0
    assert started[-1] == (None, 1)


def test_bench_refuses_an_out_that_is_a_file_before_running(tmp_path, capsys):
    taken = tmp_path / "taken"
    taken.write_text("")
    with pytest.raises(SystemExit) as exit_info:
        bench_main(["--policies", "nn_dsc", "--scenarios", "bench_mild", "--out", str(taken)])
    assert exit_info.value.code == 2
    assert f"--out {taken} is a file; give a folder" in capsys.readouterr().err


def test_commands_reject_an_unknown_policy(capsys):
    for main, flag in ((run_main, "--policy"), (bench_main, "--policies")):
        with pytest.raises(SystemExit):
            main([flag, "no_such_policy"])
        assert "neither a baseline" in capsys.readouterr().err


def test_default_bench_is_every_baseline_and_the_headroom_reference_on_the_suite():
    from baselines import HEADROOM_REFERENCE, PRIVILEGED
    from cpf_commands.bench.cli import _arguments, _parser

    args = _arguments(_parser(), [])
    assert args.policies == [*POLICIES, HEADROOM_REFERENCE]
    assert HEADROOM_REFERENCE in PRIVILEGED and args.scenarios == suite.list_suite()
    hard = _arguments(_parser(), ["--track", "hard"])
    assert hard.scenarios == suite.list_suite("hard")
    assert hard.policies == [
        *POLICIES,
        "ilos",
        "nn_dsc_ekf",
        "mpc_tuned_ekf",
        "mpc_tuned_mmae",
        "ilos_ekf",
        *SAFE,
        HEADROOM_REFERENCE,
    ]
    assert args.num_seeds == 10


# --- layering -------------------------------------------------------------------------------

FORBIDDEN = {
    "cpf_env": {"baselines", "agents", "cpf_commands"},
    "baselines": {"agents", "cpf_commands"},
    "agents": {"cpf_commands"},
}


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_layering_no_import_runs_back_up(package):
    """Every import statement of a layer, also inside functions, stays at or below it."""
    offenders = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            offenders += [
                f"{path.relative_to(ROOT)}:{node.lineno} imports {name}"
                for name in names
                if name.split(".")[0] in FORBIDDEN[package]
            ]
    assert not offenders, offenders


def test_the_terminal_says_when_cells_did_not_run(tmp_path, capsys):
    agent = str(ROOT / "tests/fixtures/agents/residual_ppo_lossy_links")
    argv = ["--policies", "nn_dsc", agent, "--scenarios", "bench_lossy_links", "bench_switching"]
    argv += ["--num-seeds", "2", "--max-steps", "5", "--out", str(tmp_path / "b"), "--quiet"]
    assert bench_main([*argv, "--no-figures"]) == 0
    assert "1 of 4 (policy, scenario) cells did not run" in capsys.readouterr().out
