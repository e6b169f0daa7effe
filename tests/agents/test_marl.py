"""agents.marl: BenchMARL tasks, two MAPPO iterations, the saved actor as a cpf-bench policy."""

from __future__ import annotations

import csv
import doctest
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("torchrl")
if importlib.util.find_spec("benchmarl") is None:  # importing it needs agents.marl.compat first
    pytest.skip("BenchMARL is not installed (docs/marl.md)", allow_module_level=True)

import torch
from safetensors.torch import load_file
from torchrl.envs.utils import ExplorationType, set_exploration_type

from agents import load_policy
from agents.folder.files import AgentFolderError
from agents.marl import envs, policy_folder
from agents.marl.tasks import CONF, CpfTask, CpfTaskClass
from baselines import DEPLOYABLE
from cpf_env import FleetSim, scenarios
from cpf_env.evaluation.privileged import unobserved_state
from cpf_env.scenarios import paper, suite

pytestmark = pytest.mark.benchmarl

#: The BenchMARL training example the tests below run.
SCRIPT = Path(__file__).resolve().parents[2] / "examples" / "marl_residual.py"

#: Two short iterations: 4 fleets x 50 steps per batch, one minibatch pass.
SMALL = {
    "max_n_iters": 2,
    "max_n_frames": None,
    "loggers": [],
    "on_policy_n_envs_per_worker": 4,
    "on_policy_collected_frames_per_batch": 200,
    "on_policy_minibatch_size": 100,
    "on_policy_n_minibatch_iters": 1,
    "evaluation": False,
    "render": False,
    "checkpoint_at_end": False,
    "create_json": False,
}


def small_experiment(  # type: ignore[no-untyped-def]
    algorithm: str, folder: Path, route: type = CpfTask, **task_config: object
):
    from benchmarl.algorithms import IppoConfig, MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig

    config = ExperimentConfig.get_from_yaml()
    for key, value in SMALL.items():
        setattr(config, key, value)
    config.save_folder = str(folder)
    task = route.BENCH_LOSSY_LINKS.get_from_yaml()  # type: ignore[attr-defined]
    task.config.update({"normalization_steps": 20, **task_config})
    algorithm_config = {"mappo": MappoConfig, "ippo": IppoConfig}[algorithm].get_from_yaml()
    model = MlpConfig.get_from_yaml()
    model.num_cells = [32, 32]
    return Experiment(
        task=task,
        algorithm_config=algorithm_config,
        model_config=model,
        critic_model_config=model,
        seed=0,
        config=config,
    )


def test_the_tasks_are_the_training_scenarios_each_with_a_config() -> None:
    names = [task.name.lower() for task in CpfTask]
    assert sorted(names) == sorted([*paper.__all__, *suite.SUITE, *suite.list_suite("hard")])
    for task in CpfTask:
        loaded = task.get_from_yaml()
        assert isinstance(loaded, CpfTaskClass)
        assert loaded.config["scenario"] == task.name.lower()
        # the hard track's tasks play whole episodes (its crossings come after 40 s)
        hard = task.name.lower() in suite.list_suite("hard")
        own = scenarios.get(task.name.lower()).max_steps
        assert loaded.config["max_steps"] == (own if hard else 200)
        assert loaded.config["base_policy"] in DEPLOYABLE
        assert loaded.config["stagger"] is True
    assert (CONF / "config.yaml").is_file()


def test_task_configs_are_checked_and_evaluation_seeds_refused() -> None:
    task = CpfTask.BENCH_MILD.get_task({"scenario": "bench_mild", "max_step": 50})
    with pytest.raises(ValueError, match=r"unknown cpf task config fields \['max_step'\]"):
        task.get_env_fun(2, True, 0, "cpu")
    task = CpfTask.BENCH_MILD.get_from_yaml()
    with pytest.raises(ValueError, match="held-out seeds"):
        task.get_env_fun(4, True, 9_998, "cpu")
    with pytest.raises(ValueError, match="continuous actions only"):
        task.get_env_fun(4, False, 0, "cpu")
    shifted = CpfTask.BENCH_MILD.get_task({"scenario": "bench_mild_shift"})
    with pytest.raises(ValueError, match="held-out shift split"):
        shifted.get_env_fun(4, True, 0, "cpu")


def test_the_task_env_is_the_residual_env_with_state_and_statistics() -> None:
    task = CpfTask.BENCH_LOSSY_LINKS.get_from_yaml()
    task.config["normalization_steps"] = 10
    env = task.get_env_fun(3, True, 7, "cpu")()
    assert env.batch_size == (3,)
    assert env.scenario.max_steps == 200
    assert env.input_statistics is not None and env.state
    assert task.group_map(env) == {"vessel": [f"vessel_{i}" for i in range(5)]}
    assert set(task.observation_spec(env).keys(True, True)) == {("vessel", "observation")}
    assert task.state_spec(env)["state"].shape == (50,)  # type: ignore[index]
    assert task.action_spec(env)["vessel", "action"].shape == (5, 3)


def test_mappos_critic_reads_the_privileged_state_and_the_actor_stays_local(
    tmp_path: Path,
) -> None:
    torch.set_num_threads(1)
    task = CpfTask.BENCH_LOSSY_LINKS.get_from_yaml()
    assert task.config["privileged_state"] is False
    task.config.update({"normalization_steps": 10, "privileged_state": True})
    env = task.get_env_fun(3, True, 7, "cpu")()
    assert env.extra_state is not None and env.extra_state.compute is unobserved_state
    assert task.state_spec(env)["state"].shape == (75,)  # type: ignore[index]  # (10 + 5) x 5
    assert set(task.observation_spec(env).keys(True, True)) == {("vessel", "observation")}
    experiment = small_experiment("mappo", tmp_path, privileged_state=True)
    critic = experiment.losses["vessel"].critic_network
    assert "state" in critic.in_keys
    assert ("vessel", "observation") not in critic.in_keys
    widths = [m.in_features for m in critic.modules() if isinstance(m, torch.nn.Linear)]
    assert widths[0] == 75
    experiment.run()
    assert experiment.n_iters_performed == 2
    folder = policy_folder.save_marl_policy(experiment, tmp_path / "agent", "mappo")
    record = json.loads((folder / "config.json").read_text())
    assert record["sizes"] == [26, 32, 32, 3]  # the actor reads the local observation only


def test_a_task_config_with_the_privileged_state_needs_the_state() -> None:
    task = CpfTask.BENCH_MILD.get_from_yaml()
    task.config.update({"state": False, "privileged_state": True})
    with pytest.raises(ValueError, match="set state: true as well"):
        task.get_env_fun(2, True, 0, "cpu")


def test_the_pettingzoo_route_refuses_the_privileged_state() -> None:
    from agents.marl.pettingzoo_route import CpfPettingZooTask

    task = CpfPettingZooTask.BENCH_MILD.get_from_yaml()
    task.config["privileged_state"] = True
    with pytest.raises(ValueError, match="train on the native task"):
        task.get_env_fun(2, True, 0, "cpu")


def test_make_env_tells_the_state_what_no_vessel_observes_only_with_the_state() -> None:
    env = envs.make_env("bench_mild", 2, state=True, privileged_state=True, max_steps=20)
    assert env.observation_spec["state"].shape == (2, 75)
    with pytest.raises(ValueError, match="pass state=True as well"):
        envs.make_env("bench_mild", 2, privileged_state=True)


def test_make_env_resolves_names_and_refuses_unknown_ones() -> None:
    results = doctest.testmod(envs)
    assert results.attempted > 0 and results.failed == 0
    env = envs.make_env("bench_mild", 2, base_policy="none", max_steps=20)
    assert env.full_action_spec["vessel", "action"].shape == (2, 5, 4)  # forces and rate
    with pytest.raises(ValueError, match="unknown base policy 'nn_dcs'"):
        envs.make_env("bench_mild", 2, base_policy="nn_dcs")


@pytest.mark.parametrize("algorithm", ["mappo", "ippo"])
def test_two_iterations_then_the_saved_actor_acts_as_benchmarls(
    algorithm: str, tmp_path: Path
) -> None:
    torch.set_num_threads(1)
    experiment = small_experiment(algorithm, tmp_path)
    experiment.run()
    assert experiment.n_iters_performed == 2
    assert experiment.total_frames == 400
    folder = policy_folder.save_marl_policy(experiment, tmp_path / "agent", algorithm)
    record = json.loads((folder / "config.json").read_text())
    assert record["algorithm"] == algorithm and record["sizes"] == [26, 32, 32, 3]
    assert not list(folder.glob("*.pkl")) and not list(folder.glob("*.pt"))
    policy = load_policy(folder, scenario="bench_lossy_links")
    env = experiment.test_env
    td = env.reset()
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        expected = experiment.policy(td.clone())["vessel", "action"].numpy()
    raw = env.base_env.sim.arrays.obs.copy()
    policy.reset()
    policy.act_batch(raw)
    controller = policy._controller
    assert controller is not None
    residual = policy.diagnostics["residual"] / (0.2 * controller._tau_scale)
    np.testing.assert_allclose(residual, expected, atol=2e-6)


def test_an_edited_weight_file_is_refused(tmp_path: Path) -> None:
    experiment = small_experiment("mappo", tmp_path)
    folder = policy_folder.save_marl_policy(experiment, tmp_path / "agent", "mappo")
    weights = folder / "policy.safetensors"
    weights.write_bytes(weights.read_bytes()[:-4] + b"\0\0\0\0")
    with pytest.raises(AgentFolderError, match="does not match its SHA-256"):
        load_policy(folder)


def test_the_hydra_command_runs_a_cpf_task(tmp_path: Path) -> None:
    overrides = [
        "algorithm=ippo",
        "task=cpf/bench_mild",
        "task.normalization_steps=10",
        *(f"experiment.{key}={value}" for key, value in SMALL.items() if key != "max_n_frames"),
        "experiment.max_n_frames=null",
        "experiment.max_n_iters=1",
        f"hydra.run.dir={tmp_path}",
    ]
    overrides = [o.replace("=False", "=false").replace("=[]", "=[]") for o in overrides]
    command = [sys.executable, "-m", "cpf_commands.marl", *overrides]
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    result = subprocess.run(command, capture_output=True, text=True, env=env, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "Algorithm: ippo, Task: cpf/bench_mild" in result.stdout


def test_two_mappo_iterations_on_the_pettingzoo_route_with_distinct_worker_seeds(
    tmp_path: Path,
) -> None:
    from agents.marl.pettingzoo_route import CpfPettingZooTask

    torch.set_num_threads(1)
    task = CpfPettingZooTask.BENCH_MILD.get_from_yaml()
    make = task.get_env_fun(3, True, 4, "cpu")
    first = [make().reset()["vessel", "observation"] for _ in range(3)]
    assert not torch.equal(first[0], first[1]) and not torch.equal(first[1], first[2])
    again = task.get_env_fun(3, True, 4, "cpu")
    assert torch.equal(again().reset()["vessel", "observation"], first[0])  # seed 4 + 0
    experiment = small_experiment("mappo", tmp_path, route=CpfPettingZooTask)
    experiment.run()
    assert experiment.n_iters_performed == 2
    assert experiment.total_frames == 400


def test_a_learner_with_messages_saves_them_and_its_fleet_broadcasts_them(tmp_path: Path) -> None:
    """hard_crossing over mpc_tuned: five free entries, learned, saved and sent on loading."""
    out = tmp_path / "run"
    command = [sys.executable, str(SCRIPT), "--task", "hard_crossing", "--iterations", "1",
               "--mode", "force_and_rate", "--messages", "5", "--encoder", "--out", str(out),
               "--eval-fleets", "1", "--eval-max-steps", "20"]  # fmt: skip
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    result = subprocess.run(command, capture_output=True, text=True, env=env, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    record = json.loads((out / "config.json").read_text())
    assert record["task"]["messages"] == 5 and record["sizes"][-1] == 4 + 5
    policy = load_policy(out)
    assert policy.config.residual.messages == 5 and policy.message_entries == 6
    sim = FleetSim(policy.scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    policy.reset()
    for _ in range(3):
        actions = policy.act_batch(obs)
        obs = sim.step(actions)
    sent = actions[..., 5:]  # entries 1-5, the learner's
    assert np.all(np.abs(sent) <= 1.0) and np.any(sent != 0.0)
    assert np.array_equal(sim.arrays.message[..., 1:], sent)


@pytest.mark.parametrize(
    "actor", [[], ["--encoder"], ["--privileged-state"]], ids=["mlp", "encoder", "told_critic"]
)
def test_the_training_example_writes_a_curve_and_a_policy(tmp_path: Path, actor: list[str]) -> None:
    out = tmp_path / "run"
    command = [sys.executable, str(SCRIPT), "--iterations", "1", "--out", str(out),
               "--eval-fleets", "2", "--eval-max-steps", "20", *actor]  # fmt: skip
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    result = subprocess.run(command, capture_output=True, text=True, env=env, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "vessel-steps/s" in result.stdout
    with (out / "curve.csv").open() as text:
        rows = list(csv.DictReader(text))
    assert len(rows) == 1 and rows[0]["vessel_steps"] == str(64 * 100 * 5)
    assert float(rows[0]["eval_return"]) < 0 and float(rows[0]["eval_return_sync"]) < 0
    run = json.loads((out / "run.json").read_text())
    assert run["vessel_steps"] == 64 * 100 * 5
    assert run["stagger"] is True and run["evaluation"]["max_steps"] == 20
    assert run["privileged_state"] is ("--privileged-state" in actor)
    assert run["evaluation"]["at_start"] == run["evaluation"]["base"]  # the zeroed actor
    record = json.loads((out / "config.json").read_text())
    assert record["task"]["stagger"] is True
    encoder = "--encoder" in actor
    assert record["task"]["shared_slot_statistics"] is encoder and ("actor" in record) is encoder
    assert record["task"]["privileged_state"] is ("--privileged-state" in actor)
    policy = load_policy(out, scenario="bench_lossy_links")
    assert policy.name == "run"
    assert [path.name for path in tmp_path.iterdir()] == ["run"]  # nothing of BenchMARL's left


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--algorithm", "ippo", "--privileged-state"], "use --algorithm mappo"),
        (["--keep-best", "--eval-fleets", "0"], "give --eval-fleets >= 1"),
    ],
    ids=["told_critic_for_ippo", "keep_best_without_evaluation"],
)
def test_the_training_example_refuses_options_that_do_not_fit(
    tmp_path: Path, options: list[str], message: str
) -> None:
    command = [sys.executable, str(SCRIPT), *options, "--out", str(tmp_path / "run")]
    result = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 2 and message in result.stderr
    assert not (tmp_path / "run").exists()


def constant_actor(value: float):  # type: ignore[no-untyped-def]
    """A TorchRL policy writing the same residual for every vessel."""
    from tensordict.nn import TensorDictModule

    def act(observation: torch.Tensor) -> torch.Tensor:
        return torch.full((*observation.shape[:-1], 3), value)

    keys = {"in_keys": [("vessel", "observation")], "out_keys": [("vessel", "action")]}
    return TensorDictModule(act, **keys)


def test_the_fixed_seed_evaluation_is_the_base_at_zero_and_repeats_itself() -> None:
    from agents.marl.fixed_seeds import EVALUATION_FIELDS, FixedSeedEvaluation
    from cpf_env.scenarios.reward_weights import REWARD_TERMS

    config = {**CpfTask.BENCH_LOSSY_LINKS.get_from_yaml().config, "normalization_steps": 20}
    evaluation = FixedSeedEvaluation(config, fleets=3, seed=2, max_steps=40)
    assert list(evaluation.base) == list(EVALUATION_FIELDS)
    assert evaluation.evaluate(constant_actor(0.0)) == evaluation.base
    assert evaluation.base["return_minus_base"] == 0.0
    pushed = evaluation.evaluate(constant_actor(0.5))
    assert pushed == evaluation.evaluate(constant_actor(0.5))
    assert pushed["return_minus_base"] != 0.0 and pushed["late_reward_minus_base"] != 0.0
    assert pushed["return_minus_base"] == pytest.approx(
        pushed["return"] - evaluation.base["return"], abs=1e-9
    )
    terms = sum(pushed[f"return_{term}"] for term in REWARD_TERMS)
    assert terms == pytest.approx(pushed["return"], rel=1e-12)
    # the same seeds played by the env itself: the base's rewards, second half per vessel-step
    env = evaluation.env
    env.set_seed(2)
    rewards = env.rollout(40, constant_actor(0.0))["next", "vessel", "reward"].double()
    assert evaluation.base["late_reward"] == pytest.approx(float(rewards[:, 20:].mean()), rel=1e-5)
    assert evaluation.base["return"] == pytest.approx(float(rewards.sum(1).mean()), rel=1e-5)


def test_the_fixed_seed_evaluation_plays_the_scenarios_own_length_by_default() -> None:
    from agents.marl.fixed_seeds import FixedSeedEvaluation
    from cpf_env import scenarios

    config = {**CpfTask.BENCH_MILD.get_from_yaml().config, "normalization_steps": 20}
    evaluation = FixedSeedEvaluation(config, fleets=1)
    assert evaluation.max_steps == scenarios.get("bench_mild").max_steps != config["max_steps"]
    with pytest.raises(ValueError, match="evaluation"):
        FixedSeedEvaluation(config, fleets=1, seed=10_000, max_steps=10)


def test_a_neighbour_encoder_actor_trains_saves_and_runs_on_a_higher_degree(
    tmp_path: Path,
) -> None:
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig

    from agents.marl.models import NeighbourSetMlp, NeighbourSetMlpConfig
    from cpf_env import scenarios
    from cpf_env.sim.fleet import FleetSim, observation_layout

    torch.set_num_threads(1)
    config = ExperimentConfig.get_from_yaml()
    for key, value in SMALL.items():
        setattr(config, key, value)
    config.save_folder = str(tmp_path)
    task = CpfTask.BENCH_LOSSY_LINKS.get_from_yaml()
    task.config.update(normalization_steps=20, shared_slot_statistics=True)
    model = NeighbourSetMlpConfig.for_task(task.config, num_cells=[16], hidden=8)
    assert (model.slot_size, model.tail) == (4, 0)
    critic = MlpConfig.get_from_yaml()
    critic.num_cells = [16]
    experiment = Experiment(task=task, algorithm_config=MappoConfig.get_from_yaml(),
                            model_config=model, critic_model_config=critic, seed=0,
                            config=config)  # fmt: skip
    actor = experiment.algorithm.get_policy_for_loss("vessel")
    assert any(isinstance(module, NeighbourSetMlp) for module in actor.modules())
    statistics = experiment.test_env.base_env.input_statistics
    slots = statistics.mean[18:26].reshape(2, 4)
    assert np.array_equal(slots[0], slots[1]) and slots[0, 0] == 0.0  # pooled, a_ij raw
    experiment.run()
    assert experiment.n_iters_performed == 2
    folder = policy_folder.save_marl_policy(experiment, tmp_path / "agent", "mappo")
    manifest = json.loads((folder / "manifest.json").read_text())
    record = json.loads((folder / "config.json").read_text())
    assert (manifest["format"], manifest["format_version"], manifest["trainer"]) == (
        "cpf-agent",
        3,
        "benchmarl",
    )
    assert record["sizes"] == [18 + 8 + 1, 16, 3]
    assert record["actor"] == {"encoder": "deepsets", "history": 0, "pooling": "mean",
                               "hidden": 8, "slot_size": 4, "slots": 2, "tail": 0}  # fmt: skip
    # the saved actor acts as BenchMARL's deterministic policy on the training task
    policy = load_policy(folder, scenario="bench_lossy_links")
    env = experiment.test_env
    td = env.reset()
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        expected = experiment.policy(td.clone())["vessel", "action"].numpy()
    policy.reset()
    policy.act_batch(env.base_env.sim.arrays.obs.copy())
    controller = policy._controller
    assert controller is not None
    residual = policy.diagnostics["residual"] / (0.2 * controller._tau_scale)
    np.testing.assert_allclose(residual, expected, atol=2e-6)
    # and runs on a star of degree 4 (trained on 2 slots): one episode start of cpf-run's
    assert observation_layout(scenarios.get("bench_switching")).n_slots == 4
    star = load_policy(folder, scenario="bench_switching")
    sim = FleetSim(scenarios.get("bench_switching"), num_fleets=2)
    observation = sim.reset(seeds=[0, 1])
    star.reset()
    actions = star.act_batch(observation)
    assert actions.shape[:2] == (2, 5) and np.isfinite(actions).all()


def test_keeping_the_best_puts_the_noted_actor_back() -> None:
    spec = importlib.util.spec_from_file_location("marl_residual", SCRIPT)
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    actor = torch.nn.Linear(3, 2)
    curve = example.Curve(n=5, evaluation=None, every=1, iterations=3)
    algorithm = SimpleNamespace(get_policy_for_loss=lambda _: actor)
    curve.experiment = SimpleNamespace(algorithm=algorithm)
    curve.rows = [{}, {}, {}]
    assert curve.restore_best() == {"rule": "last", "iteration": 3}  # no selection: untouched
    curve.note(2, 41.5)
    noted = {key: value.clone() for key, value in actor.state_dict().items()}
    with torch.no_grad():
        actor.weight.add_(1.0)  # training goes on past the best
    assert curve.restore_best() == {"rule": "best", "iteration": 2, "eval_return_minus_base": 41.5}
    for key, value in actor.state_dict().items():
        assert torch.equal(value, noted[key])


def test_the_training_example_keeps_the_best_evaluated_actor(tmp_path: Path) -> None:
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    common = [sys.executable, str(SCRIPT), "--iterations", "3", "--eval-every", "1",
              "--eval-fleets", "2", "--eval-max-steps", "20"]  # fmt: skip
    folders = {}
    for name, extra in (("last", []), ("best", ["--keep-best"])):
        folders[name] = tmp_path / name
        command = [*common, "--out", str(folders[name]), *extra]
        result = subprocess.run(command, capture_output=True, text=True, env=env, cwd=tmp_path)
        assert result.returncode == 0, result.stderr[-2000:]
    with (folders["best"] / "curve.csv").open() as text:
        gains = [0.0] + [float(row["eval_return_minus_base"]) for row in csv.DictReader(text)]
    run = json.loads((folders["best"] / "run.json").read_text())
    best = max(range(len(gains)), key=gains.__getitem__)
    assert run["kept"] == {"rule": "best", "iteration": best, "eval_return_minus_base": gains[best]}
    last = json.loads((folders["last"] / "run.json").read_text())["kept"]
    assert last == {"rule": "last", "iteration": 3}
    kept = load_file(folders["best"] / "policy.safetensors")
    if best == 0:  # the actor before training: its mean output zeroed
        assert not kept["output.weight"].any() and not kept["output.bias"].any()
    else:  # the same seed trains the same actors: a run stopped there saved the same one
        if best < 3:
            folders["stopped"] = tmp_path / "stopped"
            command = [*common[:3], str(best), *common[4:], "--out", str(folders["stopped"])]
            result = subprocess.run(command, capture_output=True, text=True, env=env, cwd=tmp_path)
            assert result.returncode == 0, result.stderr[-2000:]
        same = folders["last" if best == 3 else "stopped"] / "policy.safetensors"
        assert same.read_bytes() == (folders["best"] / "policy.safetensors").read_bytes()
    assert sorted(path.name for path in tmp_path.iterdir()) == sorted(folders)
    policy = load_policy(folders["best"], scenario="bench_lossy_links")
    assert policy.name == "best"
