"""``cpf-train --config``: TOML hyperparameters, flags override them, the resolved file is saved."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import ROOT

from agents import TrainConfig
from agents.training.evaluation import DEFAULT_EVAL_NUM_SEEDS
from cpf_commands.hyperparameters import hyperparameters_toml, parse_settings, read_hyperparameters
from cpf_commands.train import DEFAULT_CHECKPOINT_EVERY, DEFAULT_EVAL_EVERY, train_main
from cpf_env.envs.residual import ResidualConfig

EXAMPLES = ROOT / "examples" / "hyperparameters"
TINY = """
scenario = "bench_mild"
fleets = 2
timesteps = 160
n_steps = 16
batch_size = 80
n_epochs = 1
net_arch = [8]
gamma = 0.95
eval_every = 0
"""


def test_the_example_files_are_the_defaults() -> None:
    defaults = TrainConfig()
    schedule = {"eval_every": DEFAULT_EVAL_EVERY, "eval_num_seeds": DEFAULT_EVAL_NUM_SEEDS,
                "checkpoint_every": DEFAULT_CHECKPOINT_EVERY}  # fmt: skip
    ppo = read_hyperparameters(EXAMPLES / "ppo_residual.toml")
    assert TrainConfig(**{k: v for k, v in ppo.items() if k not in schedule}) == defaults
    assert {k: ppo[k] for k in schedule} == schedule
    sac = read_hyperparameters(EXAMPLES / "sac_residual.toml")
    config = TrainConfig(**{k: v for k, v in sac.items() if k not in schedule})
    assert config == TrainConfig(algo="sac")


def test_written_hyperparameters_read_back_exactly(tmp_path: Path) -> None:
    config = TrainConfig(learning_rate=1e-20, residual=ResidualConfig(extras=("base_action",)),
                         reward_form="log",
                         net_arch=(3, 5), torch_threads=None)  # fmt: skip
    text = hyperparameters_toml(config.to_json(), {"eval_every": 7})
    (tmp_path / "h.toml").write_text(text)
    values = read_hyperparameters(tmp_path / "h.toml")
    assert values.pop("eval_every") == 7
    assert TrainConfig(**values) == config
    # a mapping-valued setting is an inline table, its keys quoted
    mapping = hyperparameters_toml({"n_steps": 3}, {"eval_num_seeds": {"a b": 1.5, "c": [1, 2]}})
    (tmp_path / "m.toml").write_text(mapping)
    assert read_hyperparameters(tmp_path / "m.toml")["eval_num_seeds"] == {"a b": 1.5, "c": [1, 2]}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("learning_rate = ", "not valid TOML"),
        ("[ppo]\nn_steps = 3", "unknown keys ['ppo']"),
        ("n_step = 3", "unknown keys ['n_step']; valid keys"),
    ],
)
def test_a_bad_file_is_refused_with_what_is_wrong(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, message: str
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SystemExit):
        train_main(["--config", str(path), "--out", str(tmp_path / "run")])
    assert message in capsys.readouterr().err
    assert not (tmp_path / "run").exists()  # nothing created


def test_flags_override_the_file_and_the_resolved_file_is_saved(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "h.toml"
    path.write_text(TINY)
    out = tmp_path / "run"
    assert train_main(["--config", str(path), "--seed", "4", "--set", "n_epochs=2",
                       "--out", str(out), "--quiet"]) == 0  # fmt: skip
    config = TrainConfig.from_json(json.loads((out / "run.json").read_text())["config"])
    assert (config.seed, config.n_epochs, config.gamma, config.net_arch) == (4, 2, 0.95, (8,))
    assert config.scenario == "bench_mild" and config.learning_rate == 3e-4  # file, default
    saved = out / "hyperparameters.toml"
    again = tmp_path / "again"
    assert train_main(["--config", str(saved), "--out", str(again), "--quiet"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert json.loads((again / "run.json").read_text()) == run
    assert (again / "policy.safetensors").read_bytes() == (out / "policy.safetensors").read_bytes()
    with pytest.raises(SystemExit):
        train_main(["--config", str(path), "--out", str(tmp_path / "x"), "--quiet",
                    "--set", "learning_rate=-1"])  # fmt: skip
    assert "learning_rate must be a number > 0" in capsys.readouterr().err


def test_a_mixture_and_reward_overrides_round_trip_through_the_file(tmp_path: Path) -> None:
    """The scenario list and the reward-overrides table read back as written."""
    config = TrainConfig(
        scenario=("bench_mild", "bench_switching"), reward_overrides={"heading": 1.0}
    )
    file = tmp_path / "h.toml"
    file.write_text(hyperparameters_toml(config.to_json(), {}))
    values = read_hyperparameters(file)
    assert TrainConfig(**values) == config
    file.write_text("[policy]\nnet_arch = [8]\n")
    with pytest.raises(ValueError, match="unknown keys \\['policy'\\]"):
        read_hyperparameters(file)


def test_encoder_none_overrides_the_files_encoder(tmp_path: Path) -> None:
    """``--set encoder=none``: an MLP, whatever the file says; its folder has no actor field."""
    path = tmp_path / "h.toml"
    path.write_text(TINY + 'encoder = "deepsets"\nshared_slot_statistics = true\n')
    out = tmp_path / "run"
    assert train_main(["--config", str(path), "--set", "encoder=none", "--out", str(out),
                       "--quiet"]) == 0  # fmt: skip
    record = json.loads((out / "config.json").read_text())
    assert record["config"]["encoder"] is None and "actor" not in record
    assert TrainConfig.from_json(record["config"]).shared_slot_statistics  # the file's
    assert json.loads((out / "manifest.json").read_text())["format_version"] == 3
    assert "encoder" not in (out / "hyperparameters.toml").read_text()


def test_a_file_extends_another_and_set_overrides_both(tmp_path: Path) -> None:
    """``extends``: the base file first, the extending file's keys over it; --set over both."""
    (tmp_path / "base.toml").write_text(TINY.replace("n_epochs = 1", "n_epochs = 3"))
    (tmp_path / "child.toml").write_text('extends = "base.toml"\ngamma = 0.97\n')
    values = read_hyperparameters(tmp_path / "child.toml")
    assert values["gamma"] == 0.97 and values["n_epochs"] == 3 and "extends" not in values
    out = tmp_path / "run"
    argv = ["--config", str(tmp_path / "child.toml"), "--set", "n_epochs=2", "net_arch=[4, 4]"]
    argv += ["--set", "residual.mode=force_and_rate"]
    assert train_main([*argv, "--out", str(out), "--quiet"]) == 0
    config = TrainConfig.from_json(json.loads((out / "run.json").read_text())["config"])
    assert (config.gamma, config.n_epochs, config.net_arch) == (0.97, 2, (4, 4))
    assert config.residual.mode == "force_and_rate"
    (tmp_path / "base.toml").write_text('extends = "child.toml"\n')
    with pytest.raises(ValueError, match="comes back to a file of its chain"):
        read_hyperparameters(tmp_path / "child.toml")
    (tmp_path / "odd.toml").write_text("extends = 3\n")
    with pytest.raises(ValueError, match="extends must be a file name"):
        read_hyperparameters(tmp_path / "odd.toml")


@pytest.mark.parametrize(
    ("items", "message"),
    [(["n_epochs"], "takes KEY=VALUE"), (["epochs=2"], "unknown key 'epochs'")],
)
def test_set_refuses_what_it_cannot_read(items: list[str], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_settings(items)
    assert parse_settings(["encoder=none", "reward_form=tracking", "residual.scale=0.3"]) == {
        "encoder": None,
        "reward_form": "tracking",
        "residual": {"scale": 0.3},
    }


def test_a_file_of_the_earlier_layout_is_refused_saying_where_each_key_went(
    tmp_path: Path,
) -> None:
    """``base`` and a top-level ``mode``: refused, naming ``base_policy`` and ``[residual]``."""
    path = tmp_path / "old.toml"
    path.write_text('base = "nn_dsc"\nmode = "force"\neval_seeds = 3\n')
    with pytest.raises(ValueError) as caught:
        read_hyperparameters(path)
    message = str(caught.value)
    assert "base is now base_policy" in message and "mode is now [residual] mode" in message
    assert "eval_seeds is now eval_num_seeds" in message
    with pytest.raises(ValueError, match=r"scale is now \[residual\] scale"):
        parse_settings(["scale=0.3"])
    path.write_text("[residual]\npace = 1\n")
    with pytest.raises(ValueError, match=r"\[residual\] has unknown keys \['pace'\]"):
        read_hyperparameters(path)


def test_an_extending_file_overrides_the_residual_table_key_by_key(tmp_path: Path) -> None:
    (tmp_path / "base.toml").write_text('[residual]\nmode = "force_and_rate"\nscale = 0.5\n')
    (tmp_path / "child.toml").write_text('extends = "base.toml"\n[residual]\nscale = 0.3\n')
    values = read_hyperparameters(tmp_path / "child.toml")
    assert values == {"residual": {"mode": "force_and_rate", "scale": 0.3}}
    config = TrainConfig(**values)
    assert (config.residual.mode, config.residual.scale) == ("force_and_rate", 0.3)
    text = hyperparameters_toml(config.to_json(), {})
    (tmp_path / "written.toml").write_text(text)
    assert TrainConfig(**read_hyperparameters(tmp_path / "written.toml")) == config


def test_a_run_record_of_the_earlier_layout_is_read_in_todays(tmp_path: Path) -> None:
    """run.json of a run before the residual table: ``base``, flat fields, ``seeds``."""
    from agents.training.run_folder import read_run_record

    old = {"base": "dsc", "mode": "force_and_rate", "scale": 0.4, "scenario": "bench_mild"}
    record = {"config": old, "schedule": {"eval_every": 0, "checkpoint_every": 0},
              "evaluation": {"split": "test", "scenarios": ["bench_mild"], "seeds": 3}}  # fmt: skip
    (tmp_path / "run.json").write_text(json.dumps(record))
    config, _, evaluation = read_run_record(tmp_path)
    assert (config.base_policy, config.residual.mode, config.residual.scale) == (
        "dsc",
        "force_and_rate",
        0.4,
    )
    assert evaluation["num_seeds"] == 3 and "seeds" not in evaluation
