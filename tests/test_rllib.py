"""RLlib example (examples/rllib_ppo.py): wrapper, shared module, one training iteration.

Needs the ``rllib`` extra; run with ``python -m pytest -m ray tests/test_rllib.py``.
"""

from __future__ import annotations

import importlib.util
import math
import sys

import numpy as np
import pytest

pytestmark = pytest.mark.ray
pytest.importorskip("ray.rllib")

import ray  # noqa: E402
import torch  # noqa: E402
from conftest import ROOT  # noqa: E402
from ray.rllib.core.rl_module.rl_module import RLModule  # noqa: E402
from ray.rllib.utils.spaces.space_utils import unsquash_action  # noqa: E402


def _load_example():
    spec = importlib.util.spec_from_file_location("rllib_ppo", ROOT / "examples" / "rllib_ppo.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["rllib_ppo"] = module
    spec.loader.exec_module(module)
    # Ray's workers cannot import examples/: ship the env creator by value, as for a script.
    ray.cloudpickle.register_pickle_by_value(module)
    return module


example = _load_example()

TINY = {
    "max_steps": 50,
    "train_batch_size_per_learner": 200,
    "minibatch_size": 200,
    "num_epochs": 2,
    "hidden": (16,),
}


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray on 2 CPUs for the module, shut down at the end."""
    torch.set_num_threads(1)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def trained(local_ray):
    """A PPO algorithm (local sampling) after one tiny iteration, and that iteration's result."""
    algo = example.build_config("lossy_links", seed=3, **TINY).build_algo()
    before = {k: v.clone() for k, v in algo.get_module(example.SHARED_MODULE).state_dict().items()}
    result = algo.train()
    yield algo, result, before
    algo.stop()


def test_wrapper_reset_step_and_render_with_rllibs_positional_mode():
    config = {"scenario": "wang2014", "max_steps": 3, "render_mode": "rgb_array"}
    env = example.make_rllib_env({**config, "info_level": "minimal"})
    agents = [f"vessel_{i}" for i in range(5)]
    observations, infos = env.reset(seed=0)
    assert sorted(observations) == agents and sorted(infos) == agents
    assert all(env.observation_space[a].contains(observations[a]) for a in agents)
    actions = {a: np.zeros(5, np.float32) for a in agents}
    for step in range(3):
        observations, rewards, terminated, truncated, infos = env.step(actions)
        assert sorted(rewards) == agents and not terminated["__all__"]
        assert truncated["__all__"] == (step == 2)
    assert set(infos["vessel_0"]) == {"path_error", "heading_error", "sync_error", "speed_error"}
    frame = env.render()  # RLlib's wrapper calls par_env.render(self.render_mode): None here
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    env.render_mode = "rgb_array"  # the wrapper passing the env's own mode positionally
    assert np.array_equal(env.render(), frame)
    env.render_mode = "human"
    with pytest.raises(ValueError, match="render_mode='human'"):
        env.render()
    env.close()


def test_every_vessel_maps_to_the_one_shared_module(trained):
    algo, result, _ = trained
    assert set(algo.env_runner.module.keys()) == {example.SHARED_MODULE}  # sampling side
    calls = algo.learner_group.foreach_learner(lambda learner: set(learner.module.keys()))
    assert [call.get() for call in calls] == [{example.SHARED_MODULE}]  # training side
    mapping = algo.config.policy_mapping_fn
    assert {mapping(f"vessel_{i}", None) for i in range(5)} == {example.SHARED_MODULE}
    runners = result["env_runners"]
    assert set(runners["num_module_steps_sampled"]) == {example.SHARED_MODULE}
    env_steps = runners["num_env_steps_sampled"]
    assert runners["num_module_steps_sampled"][example.SHARED_MODULE] == 5 * env_steps
    assert set(result["learners"]) == {"__all_modules__", example.SHARED_MODULE}


def test_one_iteration_trains_the_shared_module(trained):
    algo, result, before = trained
    learner = result["learners"][example.SHARED_MODULE]
    assert math.isfinite(learner["total_loss"]) and math.isfinite(learner["policy_loss"])
    runners = result["env_runners"]
    assert runners["num_env_steps_sampled"] >= TINY["train_batch_size_per_learner"]
    assert runners["num_episodes"] >= 1 and runners["episode_len_mean"] == TINY["max_steps"]
    assert math.isfinite(runners["episode_return_mean"])
    after = algo.get_module(example.SHARED_MODULE).state_dict()
    assert any(not torch.equal(before[k], after[k]) for k in before)


def test_checkpoint_reloads_the_shared_module(trained, tmp_path):
    algo, _, _ = trained
    checkpoint = algo.save_to_path(str(tmp_path))
    reloaded = RLModule.from_checkpoint(example.shared_module_path(checkpoint))
    module = algo.get_module(example.SHARED_MODULE)
    batch = {"obs": torch.randn(7, *module.observation_space.shape)}
    with torch.no_grad():
        expected = module.forward_inference(batch)["action_dist_inputs"]
        got = reloaded.forward_inference(batch)["action_dist_inputs"]
    assert torch.equal(expected, got)
    env = example.make_rllib_env({"scenario": "lossy_links", "max_steps": 20})
    observations, _ = env.reset(seed=1)
    for _ in range(3):
        actions = example.greedy_actions(reloaded, observations, env)
        assert sorted(actions) == sorted(observations)
        assert all(env.action_space[a].contains(actions[a]) for a in actions)
        again = example.greedy_actions(module, observations, env)
        assert all(np.array_equal(actions[a], again[a]) for a in actions)
        observations, *_ = env.step(actions)


def test_greedy_actions_are_rllibs_deterministic_actions(trained):
    algo, _, _ = trained
    module = algo.get_module(example.SHARED_MODULE)
    env = example.make_rllib_env({"scenario": "lossy_links", "max_steps": 50})
    (episode, *_) = algo.env_runner.sample(num_timesteps=4, explore=False)
    for t in range(3):
        observations = episode.get_observations(indices=t)
        normalized = episode.get_actions(indices=t)  # RLlib's own, in [-1, 1] units
        actions = example.greedy_actions(module, observations, env)
        for agent, action in actions.items():
            expected = unsquash_action(normalized[agent], env.action_space[agent])
            np.testing.assert_allclose(action, expected, rtol=1e-5, atol=1e-6)


def test_example_main_with_a_remote_runner_measures_and_checkpoints(local_ray, tmp_path, capsys):
    argv = ["--scenario", "lossy_links", "--iterations", "1", "--env-runners", "1"]
    argv += ["--max-steps", "50", "--train-batch-size-per-learner", "100"]
    argv += ["--minibatch-size", "100", "--num-epochs", "1"]
    assert example.main([*argv, "--measure", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "RLlib sampling only" in out and "wrapped env alone" in out
    assert "peak during training" in out
    assert example.shared_module_path(tmp_path).is_dir()
    assert ray.is_initialized()  # main leaves the caller's Ray session running
