"""A trained agent as an ONNX graph: export, and a policy that runs it with onnxruntime.

``export_onnx(folder, out)`` writes one graph holding everything between the
learner's raw inputs and its correction:

- input ``inputs`` (B, n, k) float32: the learner's inputs in their own units
  (what ``ResidualController.observe`` gives), n the fleet size of the
  scenario it is exported for (``scenario=``, default the training
  scenario's; the residual range is per vessel);
- the saved normalization (``(x - mean) / sqrt(var + eps)``, clipped);
- the actor (``agents.folder.actor.PolicyNetwork``);
- output ``action`` (B, n, a) float32 in [-1, 1] (clipped or tanh-squashed),
  a = k + the learned message entries (``ResidualConfig.messages``);
- output ``residual`` (B, n, k) float32: the correction in physical units, the
  action's first k entries times the residual range (``residual_range``:
  ``scale`` x each vessel's force limits (N, N, N m) and, in
  ``force_and_rate`` mode, ``scale`` x theta_dot_max (1/s)), which the base's
  command is added to (learned messages are sent as they are).

The training configuration (``config.json``) is stored in the graph's
metadata (key ``cpf_config``), and the file's own SHA-256 in key ``cpf_sha256``
(computed with those 64 digits written as zeros), so a ``.onnx`` file is a
policy on its own, sealed as an agent folder's manifest seals its files: a
graph swapped or edited after export is refused on load, before onnxruntime
parses it. The loader reads the file as it reads an agent folder
(``agents.folder.files``: a regular file of at most 256 MiB, strict JSON), and
checks the graph's interface (one rank-3 float input ``inputs`` (B, n, k), a
rank-3 output ``action``) before running it. ``load_onnx_policy(path,
scenario)`` rebuilds the base policy and runs the graph with onnxruntime, and
``cpf-bench --policies nn_dsc agent.onnx`` takes it. Deploying needs
onnxruntime and the base controller, not torch. ONNX holds data only
(protobuf), so loading one runs no code.

An agent with a neighbour encoder (format version 2) is exported for a
static number K' of neighbour slots (``export_onnx(..., slots=K')``,
``cpf-export --slots K'``; default its training K): tracing freezes the
input's length, so the graph takes exactly K' slots, and runs every
scenario whose graph has degree <= K' (fewer neighbours: empty slots,
masked). The saved statistics are given to every slot
(``agents.folder.encoder.statistics_for_slots``). An agent trained with a history
takes it as part of its input, and the graph keeps no state: the caller
appends each vessel's history (``agents.envs.history.OwnHistory``, as
``load_onnx_policy``'s policy does). The input layout, per vessel, in order:

- the 18 own-vessel features (``cpf_env.sim.observation``);
- K' neighbour slots of 3 + m floats ``[a_ij, theta_j - theta_i, age, msg]``
  (the scenario's, then empty all-zero slots);
- the extras of the ``TrainConfig`` (``cpf_env.envs.residual.EXTRAS``);
- H history entries, newest first, each ``[own 18 features, action (a),
  valid]`` (H = ``TrainConfig.history``; none when 0).

Needs the optional extra: ``pip install -e ".[onnx]"``.
"""

from __future__ import annotations

import json
import re
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from numpy.typing import NDArray

from agents.folder.actor import PolicyNetwork
from agents.folder.encoder import statistics_for_slots
from agents.folder.files import (
    MAX_WEIGHT_BYTES,
    AgentFolderError,
    field,
    parse_json,
    read_file,
    sha256,
)
from agents.folder.format import Normalization, read_agent, training_config
from agents.folder.loading import TrainedPolicy, load_policy
from agents.training.config import TrainConfig, upgrade_record
from cpf_env.infra import atomic
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.sim.observation import SLOTS

__all__ = ["OnnxActor", "export_onnx", "load_onnx_policy", "residual_range", "seal_onnx"]

_INSTALL = 'this needs the optional ONNX extra: pip install -e ".[onnx]" (onnx and onnxruntime)'
#: Metadata keys of an exported graph: the training record, and the file's own SHA-256.
CONFIG_KEY, HASH_KEY = "cpf_config", "cpf_sha256"
#: The SHA-256's place while the file is hashed.
_UNSEALED = b"0" * 64
#: The serialized metadata entry of the hash (protobuf: key field 1, value field 2, 64 bytes).
_SEAL = re.compile(rb"\x0a\x0a" + HASH_KEY.encode() + rb"\x12\x40([0-9a-f]{64})")


def residual_range(config: TrainConfig, scenario: Scenario) -> NDArray[np.float32]:
    """(n, k) correction per unit of action, per vessel, as ``ResidualController.compose``.

    Forces in N, N, N m (``scale`` x each vessel's force limits) and, in
    ``force_and_rate`` mode, the rate in 1/s (``scale`` x theta_dot_max); in
    ``kinematic`` mode the offsets in m, m, rad.
    """
    from cpf_env.envs.residual import ResidualController, learner_config

    residual = config.residual
    if config.base_policy == "none":  # the learner's own composition, without the base object
        residual = learner_config(None, residual)
    if residual.mode == "kinematic":
        offsets = np.asarray(residual.kinematic_scale, dtype=np.float64)
        return np.tile(offsets, (scenario.n, 1)).astype(np.float32)
    # only its limits are read: any neighbour slots do (an encoder's graph takes any K')
    controller = ResidualController(scenario, None, 1, replace(residual, neighbour_slots=None))
    limits = np.asarray(controller._tau_scale, dtype=np.float64)  # (n, 3)
    if residual.mode == "force_and_rate":
        rate = np.full((scenario.n, 1), controller._theta_dot_max)
        limits = np.concatenate([limits, rate], axis=1)
    return (residual.scale * limits).astype(np.float32)


class _Graph(torch.nn.Module):
    """Normalization, actor and residual scaling as one module to trace."""

    def __init__(
        self, network: PolicyNetwork, normalization: Normalization | None, scale: NDArray[Any]
    ) -> None:
        super().__init__()
        self.network = network
        self.normalize = normalization is not None
        self.mean = torch.zeros(0, dtype=torch.float64)
        self.std = torch.ones(0, dtype=torch.float64)
        self.clip = 0.0
        if normalization is not None:
            self.mean = torch.tensor(normalization.mean, dtype=torch.float64)
            self.std = torch.sqrt(torch.tensor(normalization.var + normalization.epsilon))
            self.clip = float(normalization.clip)
        self.scale = torch.tensor(scale, dtype=torch.float32)

    def forward(self, rows: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        latent = rows
        if self.normalize:  # in float64 like VecNormalize, then back to float32
            scaled = (rows.to(torch.float64) - self.mean) / self.std
            latent = torch.clamp(scaled, -self.clip, self.clip).to(torch.float32)
        action = self.network(latent)
        return action, action[..., : self.scale.shape[-1]] * self.scale


def export_onnx(
    folder: str | Path,
    out: str | Path,
    checks: int = 1000,
    slots: int | None = None,
    scenario: str | Scenario | None = None,
) -> float:
    """Export an agent folder to ONNX and check it against the torch policy.

    Args:
        folder: A data-only agent folder (``cpf-train`` output).
        out: The ``.onnx`` file to write (atomically).
        checks: Random inputs (drawn around the saved statistics) on which the
            ONNX actions are compared with torch's.
        slots: Neighbour slots K' of the graph's input, for an agent with a
            neighbour encoder (default: its training K); None for an MLP.
        scenario: The fleet the graph is built for, a registered name or a
            ``Scenario``: its size n (the graph's vessel axis) and each vessel's force
            limits (the ``residual`` output's scaling). Default: the training
            scenario. An encoder agent exported for a larger fleet runs there.

    Returns:
        The largest absolute difference between the ONNX and torch actions.

    Raises:
        ImportError: onnx or onnxruntime is missing.
        AgentFolderError: The folder is not a valid agent folder.
        ValueError: ``slots`` for an agent without an encoder, < 1, or more than the
            n - 1 neighbours a vessel of the fleet of n can have; an unknown scenario.
    """
    try:
        import onnx
    except ImportError as error:
        raise ImportError(_INSTALL) from error
    source = Path(folder)
    record, network, normalization = read_agent(source)
    config = training_config(record["config"], source / "config.json")
    if scenario is None:
        fleet = make_scenario(config.home_scenario, **config.scenario_overrides())
    else:
        fleet = make_scenario(scenario)
        load_policy(source, scenario=fleet)  # the folder must run there (an MLP: degree <= K)
    size, normalization = _static_input(network, normalization, record, slots, fleet.n)
    graph = _Graph(network, normalization, residual_range(config, fleet)).eval()
    example = torch.zeros(1, fleet.n, size, dtype=torch.float32)
    target = Path(out)
    with tempfile.TemporaryDirectory() as scratch:  # its own: no name to collide or link
        exported = Path(scratch) / "graph.onnx"
        with warnings.catch_warnings():
            # the TorchScript exporter: the torch.export one needs onnxscript, not a dependency
            warnings.simplefilter("ignore", DeprecationWarning)
            # the encoder reads K from the input's length: a constant of the traced graph
            warnings.simplefilter("ignore", torch.jit.TracerWarning)
            torch.onnx.export(
                graph,
                (example,),
                str(exported),
                input_names=["inputs"],
                output_names=["action", "residual"],
                dynamic_axes={"inputs": {0: "B"}, "action": {0: "B"}, "residual": {0: "B"}},
                dynamo=False,
            )
        model = onnx.load(str(exported))
    for key, value in ((CONFIG_KEY, json.dumps(record)), (HASH_KEY, _UNSEALED.decode())):
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(model)
    atomic.write_bytes(target, seal_onnx(model.SerializeToString()))
    rows = _check_inputs(size, normalization, checks)
    with torch.no_grad():
        expected = network(torch.from_numpy(_normalized(rows, normalization))).numpy()
    padded = np.resize(rows, (-(-checks // fleet.n) * fleet.n, size))  # whole fleets of n
    got = OnnxActor(target)(padded)[:checks]
    return float(np.max(np.abs(got - expected)))


def _static_input(
    network: PolicyNetwork,
    normalization: Normalization | None,
    record: dict[str, Any],
    slots: int | None,
    n: int,
) -> tuple[int, Normalization | None]:
    """The graph's input length per vessel, and the statistics for it.

    Args:
        network: The actor.
        normalization: Its statistics (for the training K), or None.
        record: The ``config.json`` record (``actor.slots``: the training K).
        slots: K' for an encoder actor, or None (the training K, which may exceed n - 1).
        n: The fleet size the graph is tied to: a vessel has at most n - 1 neighbours.

    Raises:
        ValueError: ``slots`` given for an MLP (its K is fixed), < 1, or > n - 1.
    """
    encoder = network.encoder
    if encoder is None:
        if slots is not None:
            raise ValueError(
                "--slots is for an agent with a neighbour encoder; this agent is an MLP over "
                f"its training K slots ({network.input_size} inputs). Leave --slots out."
            )
        return cast(int, network.input_size), normalization
    trained = int(record["actor"]["slots"])
    if slots is not None and not 1 <= slots <= n - 1:
        raise ValueError(
            f"--slots must be in [1, {n - 1}]: the graph runs fleets of n = {n} vessels, whose "
            f"vessels have at most n - 1 = {n - 1} neighbours; got {slots}. For a larger "
            "fleet, export for it (--scenario NAME)."
        )
    count = trained if slots is None else slots
    if normalization is not None:
        normalization = statistics_for_slots(normalization, trained, encoder.slot_size, count)
    return SLOTS + count * encoder.slot_size + encoder.tail, normalization


def _normalized(rows: NDArray[np.float32], normalization: Normalization | None) -> NDArray[Any]:
    """The torch policy's normalization (``TorchActor``), the reference of the check."""
    return rows if normalization is None else normalization.apply(rows)


def _check_inputs(size: int, normalization: Normalization | None, count: int) -> NDArray[Any]:
    """(count, size) float32 inputs spread over twice the saved standard deviations."""
    rng = np.random.default_rng(0)
    noise = rng.normal(size=(count, size))
    if normalization is None:
        return noise.astype(np.float32)
    spread = 2.0 * np.sqrt(normalization.var + normalization.epsilon)
    return (normalization.mean + spread * noise).astype(np.float32)


def seal_onnx(data: bytes) -> bytes:
    """A serialized graph with its SHA-256 in place of its ``cpf_sha256`` metadata's zeros.

    Args:
        data: The serialized ``ModelProto``, whose metadata holds ``cpf_sha256`` = 64 zeros.

    Returns:
        The same bytes with the zeros replaced by the SHA-256 of ``data``.
    """
    if len(_SEAL.findall(data)) != 1 or data.count(_UNSEALED) != 1:
        raise RuntimeError("the exported graph holds the hash placeholder more than once.")
    return data.replace(_UNSEALED, sha256(data).encode())


def _check_seal(data: bytes, path: Path) -> None:
    """Refuse a file whose embedded SHA-256 is missing or not its own."""
    found = _SEAL.findall(data)
    if len(found) != 1:
        raise AgentFolderError(
            f"{path} holds no {HASH_KEY} metadata (or several): it was not sealed by "
            "cpf-export. Export the agent folder again (cpf-export FOLDER OUT.onnx)."
        )
    digest = found[0]
    if data.count(digest) != 1 or sha256(data.replace(digest, _UNSEALED)) != digest.decode():
        raise AgentFolderError(
            f"{path} does not match the SHA-256 in its {HASH_KEY} metadata: the graph or its "
            "metadata was changed after cpf-export wrote it. Export the agent folder again."
        )


class OnnxActor:
    """The ``action`` output of an exported graph, run by onnxruntime on one thread.

    Rows are grouped by fleet, n at a time (n: the graph's fleet size), as
    ``TrainedPolicy`` orders them. The file is read once (bounded, a regular
    file), its seal checked, and onnxruntime given those same bytes.

    Args:
        path: The ``.onnx`` file.

    Raises:
        ImportError: onnxruntime is missing.
        AgentFolderError: Not a file cpf-export sealed, altered since, metadata without
            a valid ``config``, or a graph without the exported interface.
    """

    def __init__(self, path: str | Path) -> None:
        try:
            import onnxruntime
        except ImportError as error:
            raise ImportError(_INSTALL) from error
        source = Path(path)
        data = read_file(source, MAX_WEIGHT_BYTES)
        _check_seal(data, source)
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        try:
            self.session = onnxruntime.InferenceSession(
                data, options, providers=["CPUExecutionProvider"]
            )
        except Exception as error:  # onnxruntime raises its own error types
            message = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise AgentFolderError(f"{source} is not a loadable ONNX model: {message}") from None
        metadata = self.session.get_modelmeta().custom_metadata_map
        where = f"{source} (metadata {CONFIG_KEY})"
        if CONFIG_KEY not in metadata:
            raise AgentFolderError(f"{source} was not written by cpf-export (no {CONFIG_KEY}).")
        self.record: dict[str, Any] = parse_json(metadata[CONFIG_KEY].encode(), where)
        config = field(self.record, "config", where)
        if isinstance(config, dict) and "base" in config:  # exported before folder format 3
            config = upgrade_record(config)
        self.config = training_config(config, where)
        self.n, self.input_size, self.action_size = _interface(self.session, source)

    def __call__(self, rows: NDArray[np.float32]) -> NDArray[np.float32]:
        """(R, k) float32 raw inputs, R a multiple of n -> (R, a) float32 actions in [-1, 1]."""
        fleets = np.ascontiguousarray(rows, dtype=np.float32).reshape(-1, self.n, self.input_size)
        (action,) = self.session.run(["action"], {"inputs": fleets})
        return np.asarray(action, dtype=np.float32).reshape(-1, self.action_size)


def _interface(session: Any, source: Path) -> tuple[int, int, int]:
    """(n, k, a) of the exported interface: input ``inputs`` (B, n, k), output ``action``.

    Raises:
        AgentFolderError: Another input or output, another rank, or a symbolic n, k or a.
    """
    inputs = session.get_inputs()
    actions = [output for output in session.get_outputs() if output.name == "action"]
    if len(inputs) != 1 or inputs[0].name != "inputs" or not actions:
        raise AgentFolderError(
            f"{source} is not a cpf-export graph: it must take one input 'inputs' and give "
            f"'action'; it takes {[i.name for i in inputs]}."
        )
    for node in (inputs[0], actions[0]):
        shape = list(node.shape)
        sizes_known = len(shape) == 3 and all(isinstance(d, int) and d >= 1 for d in shape[1:])
        if node.type != "tensor(float)" or not sizes_known:
            raise AgentFolderError(
                f"{source}: graph {'input' if node is inputs[0] else 'output'} {node.name!r} is "
                f"{node.type} of shape {shape}; cpf-export's is float (B, n, size), n and "
                "size fixed."
            )
    _, n, k = inputs[0].shape
    return int(n), int(k), int(actions[0].shape[2])


def load_onnx_policy(path: str | Path, scenario: str | Scenario | None = None) -> TrainedPolicy:
    """A policy from a ``cpf-export`` file: the base policy plus the graph's correction.

    Args:
        path: The ``.onnx`` file.
        scenario: Evaluation scenario; default: the training scenario.

    Raises:
        ImportError: onnxruntime is missing.
        AgentFolderError: Not a ``cpf-export`` file.
        ValueError: The scenario's observations do not fit the network.
    """
    actor = OnnxActor(path)
    config = actor.config
    if scenario is None:
        resolved = make_scenario(config.home_scenario, **config.scenario_overrides())
    else:
        resolved = make_scenario(scenario)
    if resolved.n != actor.n:
        raise ValueError(
            f"{path} was exported for fleets of {actor.n} vessels but scenario "
            f"{resolved.name!r} has {resolved.n}; evaluate the agent folder instead."
        )
    return TrainedPolicy(Path(path).name, config, actor, resolved)
