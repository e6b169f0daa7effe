"""The data-only agent folder: no code runs on load, every file checked, no pickle is read."""

from __future__ import annotations

import base64
import dataclasses
import json
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import ROOT

from agents import TrainConfig, load_policy
from agents.folder.actor import PolicyNetwork, build_actor
from agents.folder.files import AgentFolderError
from agents.folder.format import Normalization, read_agent, write_agent
from cpf_commands.bench.cli import bench_main
from cpf_commands.run.cli import run_main
from cpf_env.envs.residual import ResidualConfig

AGENT = ROOT / "tests/fixtures/agents/residual_ppo_lossy_links"


class _Payload:
    """Unpickling this creates the marker file: the proof that a pickle ran code."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[object, tuple[str, str]]:
        return (open, (str(self.marker), "w"))


def _malicious_folder(root: Path, marker: Path, which: str) -> Path:
    """An old-style SB3 folder whose ``which`` file ("pkl" or "zip") runs the payload."""
    folder = root / f"evil_{which}"
    folder.mkdir()
    shutil.copy(AGENT / "config.json", folder / "config.json")
    (folder / "vecnormalize.pkl").write_bytes(pickle.dumps(_Payload(marker)))
    serialized = base64.b64encode(pickle.dumps(_Payload(marker))).decode()
    data = {"policy_class": {":type:": "<class 'type'>", ":serialized:": serialized}}
    with zipfile.ZipFile(folder / "model.zip", "w") as archive:
        archive.writestr("data", json.dumps(data))
    if which == "zip":
        (folder / "vecnormalize.pkl").unlink()
    return folder


@pytest.mark.parametrize("which", ["pkl", "zip"])
def test_a_malicious_sb3_save_runs_no_code_on_any_route(
    tmp_path: Path, which: str, capsys: pytest.CaptureFixture[str]
) -> None:
    marker = tmp_path / "payload_ran"
    folder = _malicious_folder(tmp_path, marker, which)
    with pytest.raises(AgentFolderError, match=r"plain SB3 save.*pickles.*cpf-train --out"):
        load_policy(folder)
    with pytest.raises(SystemExit):
        bench_main(["--policies", "nn_dsc", str(folder), "--scenarios", "bench_lossy_links",
                    "--num-seeds", "1", "--max-steps", "2",
                    "--out", str(tmp_path / "b")])  # fmt: skip
    assert "plain SB3 save" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        run_main(["--scenario", "bench_lossy_links", "--policy", str(folder), "--max-steps", "2",
                  "--out", str(tmp_path / "r"), "--quiet", "--no-figures"])  # fmt: skip
    assert "plain SB3 save" in capsys.readouterr().err
    assert not marker.exists()
    if which == "pkl":  # the payload is real: unpickling it makes the marker
        pickle.loads((folder / "vecnormalize.pkl").read_bytes())
        assert marker.exists()


def _copy(tmp_path: Path) -> Path:
    folder = tmp_path / "agent"
    shutil.copytree(AGENT, folder)
    return folder


@pytest.mark.parametrize(
    ("name", "edit"),
    [
        ("config.json", lambda text: text.replace('"scale": 0.2', '"scale": 0.3')),
        ("config.json", lambda text: text.replace('"mode": "force"', '"mode": "force_and_rate"')),
        ("normalization.json", lambda text: text.replace("[", "[1.0, ", 1)),
        ("policy.safetensors", None),
    ],
)
def test_an_edited_file_is_an_error_naming_it(tmp_path: Path, name: str, edit: object) -> None:
    folder = _copy(tmp_path)
    path = folder / name
    if edit is None:
        path.write_bytes(path.read_bytes()[:-10])  # truncated
    else:
        path.write_text(edit(path.read_text()))  # type: ignore[operator]
    with pytest.raises(AgentFolderError, match=name.replace(".", r"\.")):
        load_policy(folder)


def test_a_missing_file_is_an_error_naming_it(tmp_path: Path) -> None:
    folder = _copy(tmp_path)
    (folder / "normalization.json").unlink()
    with pytest.raises(AgentFolderError, match=r"normalization\.json is missing"):
        load_policy(folder)


def test_a_consistent_forgery_of_the_statistics_is_caught(tmp_path: Path) -> None:
    """Statistics of another size, with the manifest's hash and size updated to match."""
    import hashlib

    folder = _copy(tmp_path)
    statistics = json.loads((folder / "normalization.json").read_text())
    statistics["mean"], statistics["var"] = statistics["mean"][:-1], statistics["var"][:-1]
    data = (json.dumps(statistics) + "\n").encode()
    (folder / "normalization.json").write_bytes(data)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["files"]["normalization.json"]["sha256"] = hashlib.sha256(data).hexdigest()
    manifest["files"]["normalization.json"]["bytes"] = len(data)
    (folder / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(AgentFolderError, match="statistics for 25 inputs"):
        load_policy(folder)


def test_the_loaded_agent_acts_as_sb3_predicts(tmp_path: Path) -> None:
    """The fixture agent's weights in an SB3 model: SB3's predict gives the same bits.

    The SB3 model is rebuilt from the converted weights (no pickle is read), run through
    SB3's own ``predict`` on inputs normalized by VecNormalize's formula written out here.
    """
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    from agents.training.algorithms import build_model, make_env
    from agents.training.config import TrainConfig

    policy = load_policy(AGENT)
    record, _, _ = read_agent(AGENT)  # a version-1 folder: its config in today's layout
    config = TrainConfig.from_json({**record["config"], "fleets": 1, "batch_size": 160})
    model = build_model(config, VecMonitor(make_env(config)))
    assert isinstance(model, PPO)
    network = policy.actor.network  # type: ignore[attr-defined]
    layers = [m for m in model.policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for mine, theirs in zip(network.hidden, layers, strict=True):
            theirs.weight.copy_(mine.weight)
            theirs.bias.copy_(mine.bias)
        model.policy.action_net.weight.copy_(network.output.weight)
        model.policy.action_net.bias.copy_(network.output.bias)
    statistics = json.loads((AGENT / "normalization.json").read_text())
    rows = np.random.default_rng(3).normal(size=(1000, network.input_size)) * 3
    rows = (np.array(statistics["mean"]) + rows * np.sqrt(statistics["var"])).astype(np.float32)
    normalized = (rows - np.array(statistics["mean"])) / np.sqrt(np.array(statistics["var"]) + 1e-8)
    expected, _ = model.predict(np.clip(normalized, -10, 10).astype(np.float32), deterministic=True)
    np.testing.assert_array_equal(policy.actor(rows), expected)  # type: ignore[attr-defined]


# ---- the neighbour encoder and the own history (the actor field, since version 2) ---------

ENCODER_CONFIG = TrainConfig(
    scenario="bench_mild",
    fleets=2,
    net_arch=(16,),
    encoder="deepsets",
    history=2,
    residual=ResidualConfig(neighbour_slots=6),
    shared_slot_statistics=True,
)
#: own 18 + 6 slots of 4 + 2 history entries of (18 + 3 actions + 1 valid)
ENCODER_INPUTS = 18 + 6 * 4 + 2 * 22


def write_encoder_agent(folder: Path) -> PolicyNetwork:
    """A version-2 folder of an untrained encoder actor (seeded), with slot-pooled statistics."""
    torch.manual_seed(0)
    network = build_actor(ENCODER_CONFIG, ENCODER_INPUTS, 3)
    with torch.no_grad():
        network.output.weight.normal_()  # not zero: the actions depend on every input
    rng = np.random.default_rng(0)
    mean, var = rng.normal(size=ENCODER_INPUTS), rng.uniform(0.5, 2.0, size=ENCODER_INPUTS)
    slot = (
        np.concatenate([[0.0], rng.normal(size=3)]),
        np.concatenate([[1.0], rng.uniform(1, 2, 3)]),
    )
    mean[18:42], var[18:42] = np.tile(slot[0], 6), np.tile(slot[1], 6)  # pooled; a_ij raw
    folder.mkdir()
    write_agent(folder, {"config": ENCODER_CONFIG.to_json()}, network, Normalization(mean, var))
    return network


def test_an_encoder_folder_round_trips_the_encoder_and_its_layout(tmp_path: Path) -> None:
    folder = tmp_path / "encoder"
    network = write_encoder_agent(folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    assert (manifest["format"], manifest["format_version"], manifest["trainer"]) == (
        "cpf-agent",
        3,
        "sb3",
    )
    record, loaded, normalization = read_agent(folder)
    assert record["actor"] == {"encoder": "deepsets", "history": 2, "pooling": "mean",
                               "hidden": 32, "slot_size": 4, "tail": 44, "slots": 6}  # fmt: skip
    assert loaded.input_size is None and loaded.encoder is not None
    saved = network.state_dict()
    assert sorted(loaded.state_dict()) == sorted(saved)
    for name, tensor in loaded.state_dict().items():
        assert torch.equal(tensor, saved[name]), name
    assert normalization is not None and normalization.mean.size == ENCODER_INPUTS
    rows = torch.from_numpy(np.random.default_rng(1).normal(size=(50, ENCODER_INPUTS)))
    with torch.no_grad():
        assert torch.equal(loaded(rows.float()), network(rows.float()))


def test_a_version_1_folder_is_read_and_written_again_as_version_3(tmp_path: Path) -> None:
    """The fixture is version 1: read, its configuration is today's layout (``base_policy``,
    the ``residual`` object) with the same values; written again, the weights and statistics
    are the same bytes, the manifest is version 3 (with the trainer), without an 'actor'."""
    old = json.loads((AGENT / "config.json").read_text())["config"]
    assert "base" in old and "mode" in old  # the layout of version 1
    record, network, normalization = read_agent(AGENT)
    assert json.loads((AGENT / "manifest.json").read_text())["format_version"] == 1
    config = TrainConfig.from_json(record["config"])
    assert (config.base_policy, config.residual.mode, config.residual.scale) == (
        old["base"],
        old["mode"],
        old["scale"],
    )
    folder = tmp_path / "mlp"
    folder.mkdir()
    write_agent(folder, record, network, normalization)
    for name in ("policy.safetensors", "normalization.json"):
        assert (folder / name).read_bytes() == (AGENT / name).read_bytes(), name
    manifest = json.loads((folder / "manifest.json").read_text())
    assert (manifest["format_version"], manifest["trainer"]) == (3, "sb3")
    again, _, _ = read_agent(folder)
    assert "actor" not in again and TrainConfig.from_json(again["config"]) == config


@pytest.mark.parametrize("encoder", [None, "deepsets"])
def test_build_actor_has_the_layers_sb3_trains(encoder: str | None) -> None:
    """The untrained actor (for other learners) has the tensors ``cpf-train`` writes."""
    from stable_baselines3.common.vec_env import VecMonitor

    from agents.envs.history_env import HistoryVecEnv
    from agents.folder.actor import actor_tensors
    from agents.training.algorithms import build_model, make_env

    config = dataclasses.replace(ENCODER_CONFIG, encoder=encoder, batch_size=32)
    env = VecMonitor(HistoryVecEnv(make_env(config), config.history))
    tensors = actor_tensors(build_model(config, env), config.algo)
    size = int(env.observation_space.shape[0])  # type: ignore[index]
    assert size == ENCODER_INPUTS
    network = build_actor(config, size, 3)
    shapes = {name: tuple(value.shape) for name, value in network.state_dict().items()}
    assert shapes == {name: tuple(value.shape) for name, value in tensors.items()}
    assert (network.encoder is None) == (encoder is None)


#: An MLP (no encoder) with 2 history entries, on bench_mild's chain (K = 2 slots of 4).
HISTORY_CONFIG = TrainConfig(scenario="bench_mild", fleets=2, net_arch=(16,), history=2)
#: own 18 + 2 slots of 4 + 2 history entries of (18 + 3 actions + 1 valid)
HISTORY_INPUTS = 18 + 2 * 4 + 2 * 22


def write_history_mlp(folder: Path) -> PolicyNetwork:
    """A folder of an untrained MLP with a history (seeded), with statistics."""
    torch.manual_seed(0)
    network = build_actor(HISTORY_CONFIG, HISTORY_INPUTS, 3)
    with torch.no_grad():
        network.output.weight.normal_()  # not zero: the actions depend on every input
    rng = np.random.default_rng(0)
    mean, var = rng.normal(size=HISTORY_INPUTS), rng.uniform(0.5, 2.0, size=HISTORY_INPUTS)
    folder.mkdir()
    write_agent(folder, {"config": HISTORY_CONFIG.to_json()}, network, Normalization(mean, var))
    return network


def test_an_mlp_with_history_round_trips(tmp_path: Path) -> None:
    folder = tmp_path / "mlp"
    network = write_history_mlp(folder)
    assert HISTORY_CONFIG.learner_input_size() == HISTORY_INPUTS
    assert json.loads((folder / "manifest.json").read_text())["format_version"] == 3
    record, loaded, normalization = read_agent(folder)
    assert record["actor"] == {"encoder": None, "history": 2}
    assert record["config"]["encoder"] is None and record["config"]["history"] == 2
    assert loaded.encoder is None and loaded.input_size == HISTORY_INPUTS
    saved = network.state_dict()
    assert sorted(loaded.state_dict()) == sorted(saved)
    for name, tensor in loaded.state_dict().items():
        assert torch.equal(tensor, saved[name]), name
    assert normalization is not None and normalization.mean.size == HISTORY_INPUTS
    rows = torch.from_numpy(np.random.default_rng(1).normal(size=(50, HISTORY_INPUTS))).float()
    with torch.no_grad():
        assert torch.equal(loaded(rows), network(rows))


def test_a_fresh_mlp_config_holds_every_field_and_no_actor_record(tmp_path: Path) -> None:
    """Every ``TrainConfig`` field, the residual's as an object, and no 'actor' field."""
    config = dataclasses.replace(HISTORY_CONFIG, history=0)
    folder = tmp_path / "mlp"
    folder.mkdir()
    network = build_actor(config, 26, 3)
    write_agent(
        folder, {"config": config.to_json()}, network, Normalization(np.zeros(26), np.ones(26))
    )
    record = json.loads((folder / "config.json").read_text())
    assert set(record) == {"config"}
    assert set(record["config"]) == {f.name for f in dataclasses.fields(TrainConfig)}
    assert set(record["config"]["residual"]) == {f.name for f in dataclasses.fields(ResidualConfig)}
    assert TrainConfig.from_json(record["config"]) == config
    assert json.loads((folder / "manifest.json").read_text())["format_version"] == 3
    assert read_agent(folder)[1].input_size == 26
    yielding = dataclasses.replace(config, residual=ResidualConfig(yield_at_limit=True))
    for other in (HISTORY_CONFIG, ENCODER_CONFIG, yielding):  # set: written, and read back
        assert TrainConfig.from_json(json.loads(json.dumps(other.to_json()))) == other
    assert yielding.to_json()["residual"]["yield_at_limit"] is True
    assert ENCODER_CONFIG.to_json()["history"] == 2
