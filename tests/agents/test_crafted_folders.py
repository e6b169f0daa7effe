"""A corpus of crafted agent folders: each is refused at load with one line naming file and field.

Every case starts from a valid small folder of the repository (a PPO agent and
a MAPPO actor, 64 x 64), changes one thing, and, where the case is about the
content rather than the integrity check, rewrites the manifest so that its
hashes match (what a forger would do). Each test runs under a guard that turns
a hang into a failure after a few seconds and caps the memory the process may
add, so a loader that blocks on a FIFO or reads ``/dev/zero`` fails instead of
stalling or exhausting the machine.
"""

from __future__ import annotations

import hashlib
import json
import os
import resource
import shutil
import signal
from collections.abc import Callable, Iterator
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np
import pytest
import torch
from conftest import ROOT
from safetensors.torch import load as load_tensors
from safetensors.torch import save as save_tensors

from agents import load_policy
from agents.folder.files import MAX_JSON_BYTES, AgentFolderError
from cpf_commands.bench.cli import bench_main
from cpf_commands.run.cli import run_main

AGENT = ROOT / "tests/fixtures/agents/residual_ppo_lossy_links"
MARL = ROOT / "tests/fixtures/agents/mappo_lossy_links"
MARL_ENCODER = ROOT / "tests/fixtures/agents/mappo_encoder_lossy_links"
#: Seconds a load may take before the guard calls it a hang.
DEADLINE = 20.0
#: Memory a load may add to the process (bytes) before allocations fail.
HEADROOM = 1 << 30


def _data_segment() -> int:
    """The process's data segment (bytes), as RLIMIT_DATA counts it."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmData:"):
            return int(line.split()[1]) * 1024
    raise RuntimeError("no VmData in /proc/self/status")


def allow(seconds: float) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Give a test ``seconds`` instead of DEADLINE (one that compiles the simulator's kernels)."""

    def mark(test: Callable[..., None]) -> Callable[..., None]:
        test.deadline = seconds  # type: ignore[attr-defined]
        return test

    return mark


@pytest.fixture(autouse=True)
def guard(request: pytest.FixtureRequest) -> Iterator[None]:
    """Fail, rather than hang or exhaust memory: SIGALRM after the deadline, RLIMIT_DATA capped."""
    seconds = getattr(request.function, "deadline", DEADLINE)

    def expire(signum: int, frame: FrameType | None) -> None:
        raise TimeoutError(f"the loader was still running after {seconds} s (blocked)")

    previous = signal.signal(signal.SIGALRM, expire)
    soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
    cap = _data_segment() + HEADROOM
    resource.setrlimit(
        resource.RLIMIT_DATA, (cap if hard == resource.RLIM_INFINITY else min(cap, hard), hard)
    )
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        resource.setrlimit(resource.RLIMIT_DATA, (soft, hard))


def _copy(source: Path, tmp_path: Path) -> Path:
    folder = tmp_path / source.name
    shutil.copytree(source, folder)
    return folder


def _forge(folder: Path, name: str, data: bytes) -> None:
    """Write ``name`` and update the manifest's hash and size to match it."""
    (folder / name).write_bytes(data)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["files"][name] = {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=2))


def _edit_json(folder: Path, name: str, edit: Callable[[Any], None]) -> None:
    """Edit a JSON file in place (and, but for the manifest itself, forge the manifest)."""
    data = json.loads((folder / name).read_text())
    edit(data)
    if name == "manifest.json":
        (folder / name).write_text(json.dumps(data))
    else:
        _forge(folder, name, json.dumps(data).encode())


def _edit_tensors(folder: Path, edit: Callable[[dict[str, torch.Tensor]], None]) -> None:
    tensors = load_tensors((folder / "policy.safetensors").read_bytes())
    edit(tensors)
    _forge(folder, "policy.safetensors", save_tensors(tensors))


def _set(path: str, value: Any) -> Callable[[Any], None]:
    """An edit that sets ``a.b.c`` to ``value``."""

    def edit(data: Any) -> None:
        *parents, last = path.split(".")
        for key in parents:
            data = data[key]
        data[last] = value

    return edit


def _refused(folder: Path, *patterns: str) -> str:
    """Load ``folder``; the one-line ``AgentFolderError`` must name every pattern."""
    with pytest.raises(AgentFolderError) as caught:
        load_policy(folder)
    message = str(caught.value)
    assert "\n" not in message, message
    for pattern in patterns:
        assert pattern in message, message
    return message


# ---- files that are not what they claim: FIFO, devices, links, sizes -------------------------


@pytest.mark.parametrize("name", ["manifest.json", "config.json", "policy.safetensors"])
def test_a_fifo_is_refused_without_blocking(tmp_path: Path, name: str) -> None:
    folder = _copy(AGENT, tmp_path)
    (folder / name).unlink()
    os.mkfifo(folder / name)
    _refused(folder, name, "FIFO")


def test_a_fifo_manifest_blocks_neither_cpf_run_nor_cpf_bench(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _copy(MARL, tmp_path)
    (folder / "manifest.json").unlink()
    os.mkfifo(folder / "manifest.json")
    with pytest.raises(SystemExit):
        run_main(["--policy", str(folder), "--max-steps", "2", "--out", str(tmp_path / "r"),
                  "--quiet", "--no-figures"])  # fmt: skip
    assert "FIFO" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        bench_main(["--policies", str(folder), "--scenarios", "bench_lossy_links", "--num-seeds",
                    "1", "--max-steps", "2", "--out", str(tmp_path / "b")])  # fmt: skip
    assert "FIFO" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["manifest.json", "policy.safetensors"])
def test_a_link_to_dev_zero_is_reported_as_what_it_is(tmp_path: Path, name: str) -> None:
    folder = _copy(AGENT, tmp_path)
    (folder / name).unlink()
    (folder / name).symlink_to("/dev/zero")
    message = _refused(folder, name, "/dev/zero", "outside")
    assert "missing" not in message


@pytest.mark.parametrize(("target", "says"), [("manifest.json", "loop"), ("gone", "missing")])
def test_a_link_loop_or_dangling_link_is_named(tmp_path: Path, target: str, says: str) -> None:
    folder = _copy(AGENT, tmp_path)
    (folder / "manifest.json").unlink()
    (folder / "manifest.json").symlink_to(target)
    _refused(folder, "manifest.json", says)


def test_a_link_leaving_the_folder_is_refused_even_to_the_right_bytes(tmp_path: Path) -> None:
    folder = _copy(AGENT, tmp_path)
    outside = tmp_path / "elsewhere.safetensors"
    (folder / "policy.safetensors").rename(outside)
    (folder / "policy.safetensors").symlink_to(outside)
    _refused(folder, "policy.safetensors", "outside")


def test_a_link_inside_the_folder_is_followed(tmp_path: Path) -> None:
    folder = _copy(AGENT, tmp_path)
    (folder / "policy.safetensors").rename(folder / "weights.bin")
    (folder / "policy.safetensors").symlink_to("weights.bin")
    assert load_policy(folder).actor.input_size == 26


def test_an_oversized_manifest_is_refused_before_it_is_read(tmp_path: Path) -> None:
    folder = _copy(AGENT, tmp_path)
    manifest = folder / "manifest.json"
    manifest.write_bytes(manifest.read_bytes() + b" " * MAX_JSON_BYTES)
    _refused(folder, "manifest.json", "bytes")


@pytest.mark.parametrize("name", ["manifest.json", "config.json"])
def test_deeply_nested_json_is_refused_without_recursion(tmp_path: Path, name: str) -> None:
    folder = _copy(AGENT, tmp_path)
    deep = b"[" * 200_000 + b"]" * 200_000
    if name == "manifest.json":
        (folder / name).write_bytes(deep)
    else:
        _forge(folder, name, deep)
    _refused(folder, name, "levels deep")


# ---- shapes and sizes, checked before anything is allocated ------------------------------------


def test_a_huge_declared_network_is_refused_before_it_is_built(tmp_path: Path) -> None:
    folder = _copy(AGENT, tmp_path)
    _edit_json(folder, "config.json", _set("config.net_arch", [20000, 20000]))
    _refused(folder, "config.json", "[20000, 20000]")


@pytest.mark.parametrize("tensor", ["hidden.0.weight", "hidden.1.weight"])
def test_a_one_dimensional_weight_is_refused(tmp_path: Path, tensor: str) -> None:
    folder = _copy(AGENT, tmp_path)

    def flatten(tensors: dict[str, torch.Tensor]) -> None:
        tensors[tensor] = tensors[tensor].reshape(-1).contiguous()

    _edit_tensors(folder, flatten)
    _refused(folder, "policy.safetensors", tensor)


def test_a_marl_manifest_without_files_is_refused(tmp_path: Path) -> None:
    folder = _copy(MARL, tmp_path)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["files"] = []
    (folder / "manifest.json").write_text(json.dumps(manifest))
    _refused(folder, "manifest.json", "'files'")


@pytest.mark.parametrize("sizes", [[-26, 64, 64, 3], [26, -64, 64, 3], [26, 64, 64, -3], [26, 3]])
def test_marl_layer_sizes_below_one_are_refused(tmp_path: Path, sizes: list[int]) -> None:
    folder = _copy(MARL, tmp_path)
    _edit_json(folder, "config.json", _set("sizes", sizes))
    _refused(folder, "config.json", "'sizes'")


def test_marl_statistics_of_the_wrong_length_are_refused_at_load(tmp_path: Path) -> None:
    folder = _copy(MARL, tmp_path)

    def shorten(data: dict[str, Any]) -> None:
        data["mean"], data["var"] = data["mean"][:-2], data["var"][:-2]

    _edit_json(folder, "normalization.json", shorten)
    _refused(folder, "normalization.json", "24 inputs")


def test_a_marl_encoder_folder_runs_on_more_slots_than_trained() -> None:
    from cpf_env import scenarios
    from cpf_env.sim.fleet import FleetSim

    policy = load_policy(MARL_ENCODER, scenario="bench_switching")  # K = 4; trained on 2
    sim = FleetSim(scenarios.get("bench_switching"), num_fleets=2)
    policy.reset()
    actions = policy.act_batch(sim.reset(seeds=[0, 1]))
    assert actions.shape[:2] == (2, 5) and np.isfinite(actions).all()
    assert load_policy(MARL_ENCODER).scenario.name == "bench_lossy_links"


@pytest.mark.parametrize(
    ("edit", "name", "pattern"),
    [
        (lambda record: record.pop("actor"), "config.json", "lacks the field 'actor'"),
        (_set("actor.slots", 3), "config.json", "'actor.slots'"),
        (_set("task.shared_slot_statistics", "true"), "config.json",
         "'task.shared_slot_statistics'"),
        (_set("task.shared_slot_statistics", False), "config.json", "shared_slot_statistics"),
        (_set("format_version", 1), "manifest.json", "version 1"),
    ],
)  # fmt: skip
def test_a_marl_encoder_folder_that_contradicts_itself_is_refused(
    tmp_path: Path, edit: Callable[[Any], None], name: str, pattern: str
) -> None:
    folder = _copy(MARL_ENCODER, tmp_path)
    _edit_json(folder, name, edit)
    _refused(folder, pattern)


def test_a_marl_encoder_whose_slot_statistics_differ_is_refused(tmp_path: Path) -> None:
    folder = _copy(MARL_ENCODER, tmp_path)

    def unpool(data: dict[str, Any]) -> None:
        data["mean"][18 + 4 + 1] += 0.5  # slot 1's theta difference, not slot 0's

    _edit_json(folder, "normalization.json", unpool)
    _refused(folder, "normalization.json", "differ between slots")


# ---- types, finiteness and dtypes: nothing loaded silently -------------------------------------


@pytest.mark.parametrize(
    ("name", "path", "value", "field"),
    [
        ("normalization.json", "epsilon", True, "'epsilon'"),
        ("normalization.json", "clip", "10", "'clip'"),
        ("config.json", "config.scale", True, "'config.scale'"),
        ("config.json", "config.net_arch", ["64", "64"], "'config.net_arch'"),
    ],
)
def test_booleans_and_strings_are_not_numbers(
    tmp_path: Path, name: str, path: str, value: Any, field: str
) -> None:
    folder = _copy(AGENT, tmp_path)
    _edit_json(folder, name, _set(path, value))
    _refused(folder, name, field)


@pytest.mark.parametrize(
    ("path", "value", "field"),
    [("task.scale", "10", "'task.scale'"), ("task.normalize", "false", "'task.normalize'")],
)
def test_marl_fields_are_typed_strictly(tmp_path: Path, path: str, value: Any, field: str) -> None:
    folder = _copy(MARL, tmp_path)
    _edit_json(folder, "config.json", _set(path, value))
    _refused(folder, "config.json", field)


def test_marl_task_overrides_make_the_default_scenario_and_a_named_one_leaves_them_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _copy(MARL, tmp_path)
    _edit_json(folder, "config.json", _set("task.overrides", {"max_path_error": 3.5}))
    assert load_policy(folder).scenario.max_path_error == 3.5
    assert load_policy(MARL).scenario.max_path_error == 10.0
    assert load_policy(folder, scenario="bench_lossy_links").scenario.max_path_error == 10.0
    argv = ["--policy", str(folder), "--max-steps", "2", "--out", str(tmp_path / "r"), "--quiet",
            "--no-figures"]  # fmt: skip
    with pytest.raises(SystemExit) as caught:
        run_main(argv)
    assert caught.value.code == 2
    error = capsys.readouterr().err
    assert "with the scenario overrides {'max_path_error': 3.5}" in error
    assert "choose one with --scenario" in error and not (tmp_path / "r").exists()
    assert run_main([*argv, "--scenario", "bench_lossy_links"]) == 0


@pytest.mark.parametrize(
    ("overrides", "pattern"),
    [
        ([1.0], "'task.overrides' must be a JSON object"),
        ({"no_such_field": 1.0}, "'task.overrides' does not apply to scenario 'bench_lossy_links'"),
        ({"max_path_error": "far"}, "'task.overrides' does not apply"),
    ],
)
def test_marl_task_overrides_its_scenario_refuses_are_refused(
    tmp_path: Path, overrides: Any, pattern: str
) -> None:
    folder = _copy(MARL, tmp_path)
    _edit_json(folder, "config.json", _set("task.overrides", overrides))
    _refused(folder, "config.json", pattern)


@pytest.mark.parametrize(("key", "text"), [("epsilon", "Infinity"), ("clip", "1e400")])
def test_infinite_statistics_are_refused(tmp_path: Path, key: str, text: str) -> None:
    folder = _copy(AGENT, tmp_path)
    data = json.loads((folder / "normalization.json").read_text())
    data[key] = "PLACEHOLDER"
    _forge(folder, "normalization.json", json.dumps(data).replace('"PLACEHOLDER"', text).encode())
    _refused(folder, "normalization.json")


def test_marl_statistics_that_are_not_finite_name_their_file(tmp_path: Path) -> None:
    folder = _copy(MARL, tmp_path)
    text = (folder / "normalization.json").read_text()
    data = json.loads(text)
    data["mean"][0] = "PLACEHOLDER"
    _forge(folder, "normalization.json", json.dumps(data).replace('"PLACEHOLDER"', "NaN").encode())
    _refused(folder, "normalization.json")


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.int32, torch.float64])
def test_weights_other_than_float32_are_refused_not_converted(
    tmp_path: Path, dtype: torch.dtype
) -> None:
    folder = _copy(AGENT, tmp_path)

    def convert(tensors: dict[str, torch.Tensor]) -> None:
        for name in tensors:
            tensors[name] = tensors[name].to(dtype)

    _edit_tensors(folder, convert)
    _refused(folder, "policy.safetensors", str(dtype).removeprefix("torch."), "float32")


@pytest.mark.parametrize(("tensor", "value"), [("output.bias", float("inf")),
                                               ("hidden.0.weight", float("nan"))])  # fmt: skip
def test_non_finite_weights_are_refused_at_load(tmp_path: Path, tensor: str, value: float) -> None:
    for source in (AGENT, MARL):
        folder = _copy(source, tmp_path / source.parent.parent.name)

        def spoil(tensors: dict[str, torch.Tensor]) -> None:
            tensors[tensor].view(-1)[0] = value

        _edit_tensors(folder, spoil)
        _refused(folder, "policy.safetensors", tensor)


# ---- messages that name the file and the field ------------------------------------------------


def test_statistics_that_are_not_json_name_their_file(tmp_path: Path) -> None:
    folder = _copy(AGENT, tmp_path)
    _forge(folder, "normalization.json", b"not json")
    _refused(folder, "normalization.json", "JSON")


def test_a_manifest_with_a_bad_file_list_says_so_not_format_version(tmp_path: Path) -> None:
    folder = _copy(AGENT, tmp_path)
    _edit_json(folder, "manifest.json", _set("files", "policy.safetensors"))
    message = _refused(folder, "manifest.json", "'files'")
    assert "version" not in message


# ---- the commands ------------------------------------------------------------------------------


def test_cpf_run_refuses_an_empty_folder_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit) as caught:
        run_main(["--policy", str(tmp_path / "empty"), "--max-steps", "2", "--out",
                  str(tmp_path / "r"), "--quiet", "--no-figures"])  # fmt: skip
    assert caught.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert "empty" in error and "manifest.json" in error


@allow(600)  # a cold numba cache compiles the simulator's kernels first
def test_cpf_run_runs_the_marl_folders_cpf_bench_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for algorithm in ("mappo", "ippo"):
        folder = ROOT / f"tests/fixtures/agents/{algorithm}_lossy_links"
        assert run_main(["--policy", str(folder), "--max-steps", "2", "--out",
                         str(tmp_path / algorithm), "--quiet", "--no-figures"]) == 0  # fmt: skip
        assert "bench_lossy_links with" in capsys.readouterr().out
        assert (tmp_path / algorithm / f"bench_lossy_links_{folder.name}/metrics.json").is_file()


# ---- cpf-export files: sealed by their own SHA-256, interface checked ---------------------------


@pytest.fixture
def onnx_file(tmp_path: Path) -> Callable[..., Path]:
    """Write a small graph (inputs (B, n, 26) @ W -> action (B, n, 3)) with cpf-export's metadata.

    Keyword args: ``shape`` of the input (default ``["B", n, 26]``), ``record`` (the
    ``cpf_config`` text; default the PPO agent's ``config.json``), ``seal`` (default True),
    ``weight`` (the value of every entry of W).
    """
    onnx = pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    from onnx import TensorProto, helper, numpy_helper

    from agents.folder.onnx_policy import seal_onnx
    from cpf_env import scenarios

    n = scenarios.get("bench_lossy_links").n
    count = iter(range(1000))

    def write(
        shape: list[Any] | None = None,
        record: str | None = None,
        seal: bool = True,
        weight: float = 0.01,
    ) -> Path:
        import numpy as np

        shape = ["B", n, 26] if shape is None else shape
        inputs = helper.make_tensor_value_info("inputs", TensorProto.FLOAT, shape)
        action = helper.make_tensor_value_info("action", TensorProto.FLOAT, [*shape[:-1], 3])
        matrix = numpy_helper.from_array(np.full((26, 3), weight, np.float32), "W")
        node = helper.make_node("MatMul", ["inputs", "W"], ["action"])
        graph = helper.make_graph([node], "actor", [inputs], [action], [matrix])
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
        model.ir_version = 9
        text = (AGENT / "config.json").read_text() if record is None else record
        metadata = [("cpf_config", text)] + ([("cpf_sha256", "0" * 64)] if seal else [])
        for key, value in metadata:
            entry = model.metadata_props.add()
            entry.key, entry.value = key, value
        onnx.checker.check_model(model)
        data = model.SerializeToString()
        path = tmp_path / f"agent{next(count)}.onnx"
        path.write_bytes(seal_onnx(data) if seal else data)
        return path

    return write


def _onnx_refused(path: Path, *patterns: str) -> str:
    from agents.folder.onnx_policy import load_onnx_policy

    with pytest.raises(AgentFolderError) as caught:
        load_onnx_policy(path)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message, message
    for pattern in patterns:
        assert pattern in message, message
    return message


def test_a_sealed_graph_loads_and_acts(onnx_file: Callable[..., Path]) -> None:
    import numpy as np

    from agents.folder.onnx_policy import load_onnx_policy

    policy = load_onnx_policy(onnx_file())
    obs = np.zeros((2, policy.n, policy.obs_dim))
    assert policy.act_batch(obs).shape == (2, policy.n, policy.act_dim)


def test_a_graph_without_seal_is_refused(onnx_file: Callable[..., Path]) -> None:
    _onnx_refused(onnx_file(seal=False), "cpf_sha256", "cpf-export")


def test_a_swapped_graph_is_refused(onnx_file: Callable[..., Path], tmp_path: Path) -> None:
    import onnx
    from onnx import numpy_helper

    sealed = onnx_file()
    model = onnx.load_from_string(sealed.read_bytes())
    weight = numpy_helper.to_array(model.graph.initializer[0]) * 100
    model.graph.initializer[0].CopyFrom(numpy_helper.from_array(weight, "W"))
    swapped = tmp_path / "swapped.onnx"
    swapped.write_bytes(model.SerializeToString())  # the metadata, seal included, unchanged
    _onnx_refused(swapped, "does not match", "cpf_sha256")


@pytest.mark.parametrize(
    ("record", "field"), [("{}", "'config'"), ("[1, 2]", "object"), ("{", "JSON")]
)
def test_metadata_without_a_config_is_refused(
    onnx_file: Callable[..., Path], record: str, field: str
) -> None:
    _onnx_refused(onnx_file(record=record), "cpf_config", field)


def test_a_rank_two_input_is_refused(onnx_file: Callable[..., Path]) -> None:
    _onnx_refused(onnx_file(shape=["B", 26]), "'inputs'", "(B, n, size)")


@pytest.mark.parametrize("kind", ["fifo", "dev_zero"])
def test_an_onnx_path_that_is_no_regular_file_is_refused(
    onnx_file: Callable[..., Path], tmp_path: Path, kind: str
) -> None:
    path = tmp_path / f"{kind}.onnx"
    if kind == "fifo":
        os.mkfifo(path)
    else:
        path.symlink_to("/dev/zero")
    _onnx_refused(path, "FIFO" if kind == "fifo" else "/dev/zero) is a character device")


def test_an_onnx_link_to_a_sealed_file_is_followed(
    onnx_file: Callable[..., Path], tmp_path: Path
) -> None:
    from agents.folder.onnx_policy import load_onnx_policy

    link = tmp_path / "link.onnx"
    link.symlink_to(onnx_file())
    assert load_onnx_policy(link).actor.input_size == 26


# ---- the actor field: the encoder's layout and tensors, checked against each other -----------


def _encoder_folder(tmp_path: Path) -> Path:
    from test_agent_folder import write_encoder_agent

    folder = tmp_path / "encoder"
    write_encoder_agent(folder)
    return folder


def _bump_slot_mean(data: Any) -> None:
    data["mean"][18 + 1] += 1.0  # slot 0's theta difference only: the slots no longer pooled


def _bump_weight_mean(data: Any) -> None:
    for k in range(6):
        data["mean"][18 + 4 * k] = 0.5  # every slot's a_ij: an empty slot is no longer 0


@pytest.mark.parametrize(
    ("name", "edit", "patterns"),
    [
        ("config.json", _set("actor.hidden", 64), ["hidden.0.weight reads 95", "gives 127"]),
        ("config.json", _set("actor.slot_size", 5), ["'actor.slot_size' is 5", "has 4"]),
        ("config.json", _set("actor.tail", 40), ["'actor.tail' is 40", "has 44"]),
        ("config.json", _set("actor.slots", 7), ["'actor.slots' is 7", "has 6"]),
        ("config.json", _set("actor.pooling", "max"), ["'actor'", "'max'"]),
        ("config.json", _set("actor.history", 3), ["'actor'", "history 3"]),
        ("config.json", _set("actor.encoder", None), ["'actor'", "encoder None"]),
        ("config.json", _set("actor.hidden", "32"), ["'actor.hidden' must be an integer"]),
        ("config.json", _set("actor.extra", 1), ["unknown field(s) ['extra']"]),
        ("config.json", lambda data: data.pop("actor"), ["lacks the field 'actor'"]),
        ("config.json", _set("config.history", 0), ["'actor'", "history 2"]),
        ("normalization.json", _bump_slot_mean, ["differ between slots"]),
        ("normalization.json", _bump_weight_mean, ["empty slot's a_ij becomes", "masks slots at"]),
        ("manifest.json", _set("format_version", 1), ["format version 1, an MLP without"]),
        ("manifest.json", _set("format_version", 4), ["format version 4", "version(s) 1, 2, 3"]),
        ("config.json", _set("config.residual.scale", True), ["'config.residual.scale'"]),
        ("config.json", _set("config.residual.pace", 1), ["residual has unknown", "'pace'"]),
        ("config.json", _set("config.mode", "force"), ["unknown TrainConfig field(s) ['mode']"]),
        ("manifest.json", _set("trainer", "torchrl"), ["'trainer' is 'torchrl'", "'benchmarl'"]),
        ("manifest.json", lambda data: data.pop("trainer"), ["lacks the field 'trainer'"]),
        ("manifest.json", _set("format", "cpf-marl-agent"), ["version 3", "version(s) 1, 2"]),
        ("manifest.json", _set("format", "cpf-policy"), ["'cpf-policy'", "cpf-agent and"]),
    ],
)
def test_a_tampered_encoder_folder_is_refused_naming_what(
    tmp_path: Path, name: str, edit: Callable[[Any], None], patterns: list[str]
) -> None:
    folder = _encoder_folder(tmp_path)
    load_policy(folder)  # valid before the edit
    _edit_json(folder, name, edit)
    _refused(folder, *patterns)


@pytest.mark.parametrize(
    ("edit", "patterns"),
    [
        (lambda t: t.pop("encoder.phi.2.bias"), ["safetensors holds tensors", "phi.2.bias"]),
        (
            lambda t: t.__setitem__("encoder.tolerance", torch.tensor(-1.0)),
            ["safetensors: tensor encoder.tolerance is negative"],
        ),
        (
            lambda t: t.__setitem__("encoder.empty_weight", torch.tensor(0.5)),
            ["normalization.json", "masks slots at 0.5"],
        ),
        (
            lambda t: t.__setitem__("encoder.phi.0.weight", t["encoder.phi.0.weight"].double()),
            ["encoder.phi.0.weight is float64"],
        ),
        (
            lambda t: t["encoder.phi.2.weight"].__setitem__((0, 0), float("nan")),
            ["encoder.phi.2.weight holds a NaN"],
        ),
    ],
)
def test_an_encoder_folder_with_forged_encoder_tensors_is_refused(
    tmp_path: Path, edit: Callable[[dict[str, torch.Tensor]], None], patterns: list[str]
) -> None:
    folder = _encoder_folder(tmp_path)
    _edit_tensors(folder, edit)
    _refused(folder, *patterns)


def test_an_encoder_weights_file_edited_without_the_manifest_is_refused(tmp_path: Path) -> None:
    folder = _encoder_folder(tmp_path)
    data = bytearray((folder / "policy.safetensors").read_bytes())
    data[-1] ^= 1
    (folder / "policy.safetensors").write_bytes(bytes(data))
    _refused(folder, "policy.safetensors does not match its SHA-256")


def _exported_refused(folder: Path, tmp_path: Path, *patterns: str) -> str:
    """``_refused``; ``export_onnx`` (cpf-export) refuses the folder with the same message."""
    message = _refused(folder, *patterns)
    pytest.importorskip("onnx")
    from agents.folder.onnx_policy import export_onnx

    out = tmp_path / "refused.onnx"
    with pytest.raises(AgentFolderError) as caught:
        export_onnx(folder, out, checks=1)
    assert str(caught.value) == message
    assert not out.exists()
    return message


def _drop_statistics(folder: Path) -> None:
    """Make the folder an unnormalized run's: normalize_observations false, statistics null."""
    _edit_json(folder, "config.json", _set("config.normalize_observations", False))
    _forge(folder, "normalization.json", b"null\n")


@pytest.mark.parametrize(
    ("edits", "patterns"),
    [
        # an extra added: the encoder's tail (the history's 44 floats) no longer fits
        ([("config.residual.extras", ["base_action"])], ["'actor.tail' is 44", "has 48"]),
        # the history lengthened in both places: the tail still says 2 entries
        ([("config.history", 3), ("actor.history", 3)], ["'actor.tail' is 44", "has 66"]),
        ([("actor.slots", 10**12)], ["'actor.slots' is 1000000000000", "has 6"]),
        ([("actor.slot_size", 10**6)], ["'actor.slot_size' is 1000000", "has 4"]),
        ([("config.residual.neighbour_slots", 9)], ["'actor.slots' is 6", "has 9"]),
    ],
)
@pytest.mark.parametrize("normalized", [True, False])
def test_the_actor_record_is_checked_against_the_config_on_every_load_path(
    tmp_path: Path, edits: list[tuple[str, Any]], patterns: list[str], normalized: bool
) -> None:
    """load_policy and export_onnx (cpf-export) both refuse it, naming config.json.

    Without statistics nothing else ties ``actor.slots`` to the weights: 10**12 slots
    loaded, and cpf-export then allocated 18 + 4 x 10**12 floats per vessel.
    """
    folder = _encoder_folder(tmp_path)
    if not normalized:
        _drop_statistics(folder)
    load_policy(folder)  # valid before the edit
    for path, value in edits:
        _edit_json(folder, "config.json", _set(path, value))
    _exported_refused(folder, tmp_path, "config.json", *patterns)


@pytest.mark.parametrize(
    ("path", "value", "inputs"),
    [("config.extras", ["base_action"], 30), ("config.neighbour_slots", 3, 30)],
)
def test_an_mlp_whose_input_is_not_the_configurations_is_refused(
    tmp_path: Path, path: str, value: Any, inputs: int
) -> None:
    """The committed MLP reads 18 + 2 x 4 = 26 inputs; config.json edited to give another size."""
    folder = _copy(AGENT, tmp_path)
    _edit_json(folder, "config.json", _set(path, value))
    _exported_refused(
        folder, tmp_path, "config.json", "hidden.0.weight reads 26 inputs", f"learner {inputs}"
    )


def test_an_mlp_with_history_whose_input_is_not_the_configurations_is_refused(
    tmp_path: Path,
) -> None:
    """A version-2 MLP with 2 history entries, config and actor saying 3: one entry short."""
    from test_agent_folder import write_history_mlp

    folder = tmp_path / "mlp"
    write_history_mlp(folder)
    load_policy(folder)
    for path in ("config.history", "actor.history"):
        _edit_json(folder, "config.json", _set(path, 3))
    _exported_refused(folder, tmp_path, "config.json", "reads 70 inputs", "learner 92")


def test_a_huge_encoder_is_refused_naming_its_fields(tmp_path: Path) -> None:
    """actor.hidden = 10**5: 4 x 10**10 bytes of encoder weights, refused before any is built."""
    folder = _encoder_folder(tmp_path)
    _edit_json(folder, "config.json", _set("actor.hidden", 10**5))
    _exported_refused(
        folder, tmp_path, "actor.hidden = 100000", "actor.slot_size = 4", "config.json"
    )
