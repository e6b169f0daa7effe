"""Teacher and student: DAgger of a local residual student from a privileged teacher.

The teacher is a privileged reference of ``baselines`` (default
``nn_dsc_privileged``: ``nn_dsc`` told the true lumped force, on ideal links),
cheap to run batched. The student is the deployable actor of the agent-folder
format (``agents.agent_folder.PolicyNetwork``: an MLP with tanh hidden layers
and a clipped output) on the vessel's local input, in the residual
parameterization of ``cpf_env.envs.residual``: the force applied is
``base + scale * limit * a``. The teacher's command tau_T is turned into the
residual that would reproduce it,

    a* = clip((tau_T - tau_base) / (scale * limit), -1, 1)      (force axes),

so the student learns what the teacher would add to the base it runs on;
where the teacher's correction is larger than the residual's reach the label
is clipped (``DistillReport.clipped`` says how often).

DAgger (Ross et al. 2011): round 0 rolls out the teacher's residual (plain
behaviour cloning data); every later round rolls out the student and labels
the states it visits with the teacher's residual; the student is refit on
all the data so far. The teacher acts on every step of the rollout (its
auxiliary states follow the forces actually applied), and restarts with the
fleets the vector env restarts.

The result is an ordinary agent folder (``agents.load_policy``,
``cpf-bench --policy``): the ``TrainConfig`` it was distilled for, the
input statistics of round 0's data, the actor, and a ``distillation`` record.
PPO can fine-tune from it by loading the actor's weights.

Example (a tiny budget):
    >>> import tempfile
    >>> from agents.train_config import TrainConfig
    >>> config = TrainConfig(scenario="wang2014", fleets=2, net_arch=(16,))
    >>> out = tempfile.mkdtemp() + "/student"
    >>> report = distill(config, DistillConfig(rounds=2, steps=20, epochs=2), out)
    >>> report.samples
    400
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from agents.agent_folder import ACTORS, PolicyNetwork, write_agent
from agents.algorithms import make_env
from agents.train_config import TrainConfig
from agents.vec_env import FleetVecEnv
from baselines import PRIVILEGED, make_policy
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.infra import atomic
from cpf_env.scenarios.splits import check_training

__all__ = ["DistillConfig", "DistillReport", "distill"]


@dataclass(frozen=True)
class DistillConfig:
    """The teacher and the DAgger budget.

    Attributes:
        teacher: A privileged reference of ``baselines.PRIVILEGED``.
        rounds: DAgger rounds (round 0 is behaviour cloning on the teacher's rollouts).
        steps: Vector-env steps per round (samples: steps x fleets x n).
        epochs: Passes over the aggregated data after each round.
        batch_size: Samples per gradient step.
        learning_rate: Adam step size.
    """

    teacher: str = "nn_dsc_privileged"
    rounds: int = 3
    steps: int = 500
    epochs: int = 10
    batch_size: int = 4096
    learning_rate: float = 1e-3

    def __post_init__(self) -> None:
        if self.teacher not in PRIVILEGED:
            raise ValueError(
                f"teacher must be a privileged reference, one of {sorted(PRIVILEGED)}; "
                f"got {self.teacher!r}."
            )
        for name in ("rounds", "steps", "epochs", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"DistillConfig.{name} must be an integer >= 1, got {value!r}.")
        if not self.learning_rate > 0.0:
            raise ValueError(f"learning_rate must be > 0, got {self.learning_rate}.")


@dataclass(frozen=True)
class DistillReport:
    """What a distillation did.

    Attributes:
        folder: The agent folder written.
        samples: Labelled vessel-steps in the final data set.
        losses: Mean squared error of the student on all data after each round.
        zero_loss: The same error of the base alone (a = 0) on the final data.
        clipped: Fraction of the labels' components clipped to [-1, 1].
        seconds: Wall time (s).
    """

    folder: Path
    samples: int
    losses: tuple[float, ...]
    zero_loss: float
    clipped: float
    seconds: float


def _labels(env: FleetVecEnv, teacher: Any) -> NDArray[np.float64]:
    """The teacher's command as a residual on the env's base, (B, n, 3), unclipped."""
    command = np.asarray(teacher.act_batch(env.sim.arrays.obs), dtype=np.float64)
    tau_min, tau_max = env.scenario.tau_limits
    reach = env.controller.config.scale * np.maximum(np.abs(tau_min), np.abs(tau_max))
    return (command[..., :3] - env.controller.base_actions[..., :3]) / reach


def _rollout(
    env: FleetVecEnv,
    teacher: Any,
    student: PolicyNetwork | None,
    stats: InputStatistics | None,
    steps: int,
) -> tuple[NDArray[np.float32], NDArray[np.float64]]:
    """Run ``steps`` env steps; return the inputs (S, d) and raw labels (S, 3) seen."""
    inputs, labels = [], []
    obs = env.reset()
    teacher.reset()
    for _ in range(steps):
        label = _labels(env, teacher).reshape(-1, 3)
        inputs.append(obs)
        labels.append(label)
        if student is None:
            action = np.clip(label, -1.0, 1.0)
        else:
            assert stats is not None
            with torch.no_grad():
                rows = torch.from_numpy(stats.apply(obs).astype(np.float32))
                action = student(rows).numpy()
        stepped, _, dones, _ = env.step(action.astype(np.float32))
        obs = np.asarray(stepped, dtype=np.float32)
        ended = np.asarray(dones).reshape(env.num_fleets, env.n)[:, 0]
        if ended.any():
            teacher.reset_fleets(ended)
    return np.concatenate(inputs), np.concatenate(labels)


def _fit(
    network: PolicyNetwork,
    rows: torch.Tensor,
    targets: torch.Tensor,
    config: DistillConfig,
    generator: torch.Generator,
) -> float:
    """Fit the actor's pre-clip output to ``targets`` (in [-1, 1]); return the final MSE."""
    optimizer = torch.optim.Adam(network.parameters(), lr=config.learning_rate)

    def raw(batch: torch.Tensor) -> torch.Tensor:
        latent = batch
        for layer in network.hidden:
            latent = torch.tanh(layer(latent))
        return network.output(latent)

    for _ in range(config.epochs):
        order = torch.randperm(rows.shape[0], generator=generator)
        for start in range(0, rows.shape[0], config.batch_size):
            index = order[start : start + config.batch_size]
            loss = torch.mean((raw(rows[index]) - targets[index]) ** 2)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    with torch.no_grad():
        return float(torch.mean((network(rows) - targets) ** 2))


def distill(config: TrainConfig, settings: DistillConfig, out: str | Path) -> DistillReport:
    """Distill a privileged teacher into a local residual student; write its agent folder.

    Args:
        config: The student's run: scenario, base, residual (``mode="force"``),
            ``fleets``, ``seed``, ``net_arch`` (``algo`` must be ``ppo``, whose actor
            format the student takes).
        settings: Teacher and budget.
        out: The agent folder to write (replaced whole if it exists).

    Raises:
        ValueError: A held-out scenario or seed (``splits.check_training``), a
            mixture of scenarios, a residual mode other than ``force``, ``sac``, no
            base, or ``normalize_observations=False``.
    """
    started = time.perf_counter()
    for name in config.scenarios:
        check_training(name, range(config.seed, config.seed + config.fleets))
    if (
        config.mode != "force"
        or config.algo != "ppo"
        or config.base == "none"
        or not config.normalize_observations
    ):
        raise ValueError(
            "distill needs a force residual on a base policy with the PPO actor format and "
            "normalized inputs (mode='force', algo='ppo', a base, normalize_observations); "
            f"got mode={config.mode!r}, algo={config.algo!r}, base={config.base!r}, "
            f"normalize_observations={config.normalize_observations}."
        )
    env = make_env(config)
    if not isinstance(env, FleetVecEnv):
        raise ValueError("distill takes one training scenario, not a mixture.")
    env.seed(config.seed)
    teacher = make_policy(settings.teacher, env.sim)
    torch.manual_seed(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    size = env.observation_space.shape[0]  # type: ignore[index]
    activation, output = ACTORS[config.algo]
    network = PolicyNetwork([size, *config.net_arch, 3], activation, output)
    with torch.no_grad():  # the residual starts at zero: the student starts as the base
        network.output.weight.zero_()
        network.output.bias.zero_()
    stats: InputStatistics | None = None
    data: list[tuple[NDArray[np.float32], NDArray[np.float64]]] = []
    losses = []
    for round_ in range(settings.rounds):
        data.append(_rollout(env, teacher, None if round_ == 0 else network, stats, settings.steps))
        if stats is None:
            first = data[0][0].astype(np.float64)
            stats = InputStatistics(first.mean(axis=0), first.var(axis=0))
        inputs = np.concatenate([d[0] for d in data])
        labels = np.concatenate([d[1] for d in data])
        rows = torch.from_numpy(stats.apply(inputs).astype(np.float32))
        targets = torch.from_numpy(np.clip(labels, -1.0, 1.0).astype(np.float32))
        losses.append(_fit(network, rows, targets, settings, generator))
    clipped = float(np.mean(np.abs(labels) > 1.0))
    zero_loss = float(np.mean(np.clip(labels, -1.0, 1.0) ** 2))
    seconds = time.perf_counter() - started
    record = {
        "config": config.to_json(),
        "distillation": {
            **dataclasses.asdict(settings),
            "samples": int(labels.shape[0]),
            "losses": losses,
            "zero_loss": zero_loss,
            "clipped": clipped,
            "seconds": seconds,
        },
        "timesteps_done": int(labels.shape[0]),
        "interrupted": False,
    }
    with atomic.staged_folder(out) as staging:
        write_agent(staging, record, network, stats)
    return DistillReport(
        Path(out), int(labels.shape[0]), tuple(losses), zero_loss, clipped, seconds
    )
