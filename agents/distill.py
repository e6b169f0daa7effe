"""Teacher and student: DAgger of a local residual student from a teacher policy.

The teacher is any policy of ``baselines``: a deployable one of
``baselines.POLICIES`` (e.g. ``mpc``, receding-horizon control per vessel)
or a privileged reference of ``baselines.PRIVILEGED`` (e.g. ``oracle``,
centralized, told the true model and the coming disturbances; default
``nn_dsc_privileged``). It acts on the fleet's true observations (a
privileged one is bound to the simulator it reads). The student is the
deployable actor of the agent-folder format (``agents.agent_folder.PolicyNetwork``:
an MLP with tanh hidden layers and a clipped output, built by ``student_actor``)
on the vessel's local input, in the residual parameterization of
``cpf_env.envs.residual``: the command applied is ``base + scale * limit * a``.
The teacher's command is turned into the residual that would reproduce it,

    a*_f = (tau_T - tau_base) / (scale * tau_limit)             (force axes, N),
    a*_r = (theta_dot_T - theta_dot_base) / (scale * theta_dot_max)
                                               (``force_and_rate`` mode only, 1/s),

and clipped to [-1, 1]: the student learns what the teacher would add to the
base it runs on; where the teacher's correction is beyond the residual's
reach the label is clipped (``DistillReport.clipped`` says how often; raise
``TrainConfig.scale`` if it is large). In ``force`` mode the path-variable
rate stays the base's, so a teacher that plans its own rate (``mpc``,
``oracle``) is imitated in force only; ``force_and_rate`` imitates both.

Data: one scenario, or a mixture (``TrainConfig.scenario`` a tuple, e.g. the
suite's training distributions; ``agents.mixture_env.MixtureVecEnv``),
optionally joined by procedural training fleets
(``DistillConfig.procedural`` draws of ``cpf_env.scenarios.sampler``, seeds
0, 1, ...). Held-out scenarios and seeds are refused
(``splits.check_training``, ``sampler.check_not_held_out``).

DAgger (Ross et al. 2011): round 0 rolls out the teacher's residual (plain
behaviour cloning data); every later round rolls out the student and labels
the states it visits with the teacher's residual; the student is refit on
all the data so far. The rounds continue the episodes under way (the env is
reset once, at the start; fleets restart when their episode ends), so with
rounds x steps beyond the horizon the data covers whole episodes. The
teacher acts on every step of the rollout (its states follow the commands
actually applied), and restarts with the fleets the vector env restarts.

The result is an ordinary agent folder (``agents.load_policy``,
``cpf-bench --policies FOLDER``): the ``TrainConfig`` it was distilled for,
the input statistics of round 0's data, the actor, and a ``distillation``
record (settings, per-round losses, clipped share, wall time).
``cpf-distill`` (``cpf_commands.distill``) runs it from a TOML file.

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

from agents.agent_folder import PolicyNetwork, build_actor, write_agent
from agents.mixture_env import MixtureVecEnv, split_fleets
from agents.train_config import TrainConfig
from agents.vec_env import FleetVecEnv
from baselines import ALL_POLICIES, make_policy
from cpf_env import scenarios
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.envs.policy import FleetPolicy
from cpf_env.infra import atomic
from cpf_env.scenarios import Scenario
from cpf_env.scenarios.sampler import ScenarioDistribution
from cpf_env.scenarios.splits import check_training

__all__ = [
    "TEACHERS",
    "DistillConfig",
    "DistillReport",
    "check_distillation",
    "distill",
    "student_actor",
]

#: Residual modes a student can be distilled in (the teacher's command maps onto them).
LABEL_MODES = ("force", "force_and_rate")
#: Bases that act for every row they are given (no ``act_batch(obs, fleets)``): the
#: rollouts run them fleet by fleet (``FleetwiseBase``), as the env restarts single fleets.
WHOLE_BATCH_BASES = ("mpc",)


#: Names a teacher may have: ``baselines.POLICIES`` and ``baselines.PRIVILEGED``.
TEACHERS = tuple(sorted(ALL_POLICIES))


@dataclass(frozen=True)
class DistillConfig:
    """The teacher, the data and the DAgger budget.

    Attributes:
        teacher: A policy name of ``TEACHERS`` (deployable or privileged).
        rounds: DAgger rounds (round 0 is behaviour cloning on the teacher's rollouts).
        steps: Vector-env steps per round (samples: steps x fleets x n per round).
        epochs: Passes over the aggregated data after each round.
        batch_size: Samples per gradient step.
        learning_rate: Adam step size.
        procedural: Procedural training fleets added to the scenarios, draws
            0 .. procedural - 1 of ``ScenarioDistribution(max_degree=K)`` (K: the
            student's neighbour slots); 0 for none. Each takes one group of fleets.
    """

    teacher: str = "nn_dsc_privileged"
    rounds: int = 3
    steps: int = 500
    epochs: int = 10
    batch_size: int = 4096
    learning_rate: float = 1e-3
    procedural: int = 0

    def __post_init__(self) -> None:
        if self.teacher not in TEACHERS:
            raise ValueError(
                f"teacher must be a policy of baselines.POLICIES or baselines.PRIVILEGED, one of "
                f"{list(TEACHERS)}; got {self.teacher!r}."
            )
        for name in ("rounds", "steps", "epochs", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"DistillConfig.{name} must be an integer >= 1, got {value!r}.")
        if (
            isinstance(self.procedural, bool)
            or not isinstance(self.procedural, int)
            or self.procedural < 0
        ):
            raise ValueError(
                f"DistillConfig.procedural must be an integer >= 0 (procedural training fleets), "
                f"got {self.procedural!r}."
            )
        if not (
            isinstance(self.learning_rate, int | float)
            and not isinstance(self.learning_rate, bool)
            and self.learning_rate > 0.0
        ):
            raise ValueError(f"learning_rate must be a number > 0, got {self.learning_rate!r}.")


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
        rounds: Per round: ``round``, ``samples`` (data so far), ``loss``,
            ``zero_loss`` and ``clipped`` (on the data so far), ``seconds`` (since start).
    """

    folder: Path
    samples: int
    losses: tuple[float, ...]
    zero_loss: float
    clipped: float
    seconds: float
    rounds: tuple[dict[str, float], ...]


def student_actor(config: TrainConfig, input_size: int, action_size: int) -> PolicyNetwork:
    """The student's actor: the agent-folder actor of ``config``, its output at zero.

    Args:
        config: The run (``net_arch``, ``algo`` for the actor format).
        input_size: Learner input length per vessel.
        action_size: k, the residual's size (3 or 4).

    Returns:
        The network; with zero output weights and bias the student starts as the base.
    """
    network = build_actor(config, input_size, action_size)
    with torch.no_grad():
        network.output.weight.zero_()
        network.output.bias.zero_()
    return network


class FleetwiseBase(FleetPolicy):
    """A base policy that acts on whole batches only, run as one instance per fleet.

    The vector env restarts single fleets and then asks the base to act for
    them alone (``act_batch(obs, fleets)``); ``mpc`` acts for all the rows it is
    given. Each fleet here has its own instance (B = 1); ``mpc``'s plans depend
    on the fleet's own episode alone, so the actions are those of one batched
    instance. Slower than one batched call (B calls a step); for training only.

    Args:
        name: A policy name of ``baselines.POLICIES``.
        scenario: The scenario the fleets run.
        num_fleets: B.
    """

    def __init__(self, name: str, scenario: Scenario, num_fleets: int) -> None:
        self.policies = [make_policy(name, scenario) for _ in range(num_fleets)]
        first = self.policies[0]
        self.name, self.n, self.obs_dim = name, first.n, first.obs_dim
        self.act_dim, self.agents = first.act_dim, first.agents
        self.diagnostics: dict[str, NDArray[np.float64]] = {}

    def act_batch(self, obs: Any, fleets: Any = None) -> NDArray[np.float64]:
        """Actions (rows, n, 4 + m) of all fleets, or of the listed ``fleets`` (index array)."""
        given = np.asarray(obs, dtype=np.float64)
        rows = range(len(self.policies)) if fleets is None else np.asarray(fleets).tolist()
        actions = [self.policies[k].act_batch(given[i : i + 1]) for i, k in enumerate(rows)]
        keys = self.policies[0].diagnostics.keys()
        self.diagnostics = {
            key: np.concatenate([self.policies[k].diagnostics[key] for k in rows]) for key in keys
        }
        return np.concatenate(actions)

    def reset(self, seed: int | None = None) -> None:
        """Forget every fleet's states."""
        for policy in self.policies:
            policy.reset(seed)

    def reset_fleets(self, fleets: Any) -> None:
        """Forget the states of the fleets in a (B,) mask or index list."""
        for k in np.arange(len(self.policies))[np.asarray(fleets)]:
            self.policies[int(k)].reset()


def _groups(env: FleetVecEnv | MixtureVecEnv) -> list[FleetVecEnv]:
    """The env's ``FleetVecEnv``s: itself, or a mixture's groups, in slot order."""
    return [env] if isinstance(env, FleetVecEnv) else list(env.groups)


def _labels(env: FleetVecEnv, teacher: FleetPolicy) -> NDArray[np.float64]:
    """The teacher's command as a residual on the env's base, (B, n, k), unclipped.

    The teacher acts once (its states advance one step) on the fleets' true
    observations.
    """
    command = np.asarray(teacher.act_batch(env.sim.arrays.obs), dtype=np.float64)
    controller = env.controller
    tau_min, tau_max = env.scenario.tau_limits
    reach = controller.config.scale * np.maximum(np.abs(tau_min), np.abs(tau_max))
    force = (command[..., :3] - controller.base_actions[..., :3]) / reach
    if controller.config.mode == "force":
        return force
    rate_reach = controller.config.scale * float(env.scenario.theta_dot_max)
    rate = (command[..., 3] - controller.base_actions[..., 3]) / rate_reach
    return np.concatenate([force, rate[..., None]], axis=-1)


def _rollout(
    env: FleetVecEnv | MixtureVecEnv,
    obs: NDArray[np.float32],
    teachers: list[FleetPolicy],
    student: PolicyNetwork | None,
    stats: InputStatistics | None,
    steps: int,
) -> tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.float32]]:
    """Run ``steps`` env steps from the inputs ``obs``, continuing the episodes under way.

    Returns:
        The inputs (S, d) and raw labels (S, k) seen, and the last inputs (num_envs, d).
    """
    inputs, labels = [], []
    groups = _groups(env)
    for _ in range(steps):
        label = np.concatenate(
            [
                _labels(group, teacher).reshape(-1, group.controller.action_size)
                for group, teacher in zip(groups, teachers, strict=True)
            ]
        )
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
        start = 0
        for group, teacher in zip(groups, teachers, strict=True):
            ended = np.asarray(dones[start : start + group.num_envs]).reshape(-1, group.n)[:, 0]
            start += group.num_envs
            if ended.any():
                teacher.reset_fleets(ended)
    return np.concatenate(inputs), np.concatenate(labels), obs


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


def check_distillation(config: TrainConfig, settings: DistillConfig) -> None:
    """Refuse what ``distill`` cannot do, before anything runs (see ``distill``)."""
    for name in config.scenarios:
        check_training(name, range(config.seed, config.seed + config.fleets))
    if config.mode not in LABEL_MODES or config.algo != "ppo" or not config.normalize_observations:
        raise ValueError(
            "distill needs a force or force_and_rate residual (or base='none') with the PPO "
            f"actor format and normalized inputs (mode in {list(LABEL_MODES)}, algo='ppo', "
            f"normalize_observations); got mode={config.mode!r}, algo={config.algo!r}, "
            f"normalize_observations={config.normalize_observations}."
        )
    if config.encoder is not None or config.history:
        raise ValueError(
            "distill trains an MLP student on the vessel's present input; leave out encoder "
            f"and history (got encoder={config.encoder!r}, history={config.history}), or "
            "train them with cpf-train."
        )
    groups = len(config.scenarios) + settings.procedural
    if config.fleets < groups:
        raise ValueError(
            f"distill over {groups} scenarios (training scenarios and procedural draws) needs "
            f"at least one fleet each; got fleets={config.fleets}. Raise fleets."
        )


def _environment(config: TrainConfig, settings: DistillConfig) -> FleetVecEnv | MixtureVecEnv:
    """The rollout env: one scenario, or the mixture of the scenarios and procedural draws."""
    residual = config.residual_config()
    if len(config.scenarios) == 1 and settings.procedural == 0:
        scenario = scenarios.make_scenario(config.home_scenario, **config.scenario_overrides())
        base = None if config.base == "none" else _base(config.base, scenario, config.fleets)
        return FleetVecEnv(scenario, num_fleets=config.fleets, base_policy=base, residual=residual)
    slots = residual.neighbour_slots
    if slots is None:  # one named scenario: its own degree
        slots = config.learner_slots()[0]
        residual = dataclasses.replace(residual, neighbour_slots=slots)
    draws = [
        ScenarioDistribution(max_degree=max(2, slots)).sample(seed)
        for seed in range(settings.procedural)
    ]
    named = [
        scenarios.make_scenario(name, **config.scenario_overrides(name))
        for name in config.scenarios
    ]
    groups: list[Scenario] = [*named, *draws]
    if config.base == "none":
        return MixtureVecEnv(groups, num_fleets=config.fleets, base_policy=None, residual=residual)
    bases = [
        _base(config.base, scenario, fleets)
        for scenario, fleets in zip(groups, split_fleets(config.fleets, len(groups)), strict=True)
    ]
    return MixtureVecEnv(groups, num_fleets=config.fleets, base_policy=bases, residual=residual)


def _base(name: str, scenario: Scenario, num_fleets: int) -> FleetPolicy:
    """The base policy of one group of fleets; ``WHOLE_BATCH_BASES`` fleet by fleet."""
    if name in WHOLE_BATCH_BASES:
        return FleetwiseBase(name, scenario, num_fleets)
    return make_policy(name, scenario)


def distill(config: TrainConfig, settings: DistillConfig, out: str | Path) -> DistillReport:
    """Distill a teacher into a local residual student; write its agent folder.

    Args:
        config: The student's run: scenario (one, or a tuple: a mixture), base,
            residual (``mode`` ``"force"`` or ``"force_and_rate"``, ``scale``),
            ``fleets``, ``seed``, ``net_arch`` (``algo`` must be ``ppo``, whose
            actor format the student takes).
        settings: Teacher, procedural draws and budget.
        out: The agent folder to write (replaced whole if it exists).

    Raises:
        ValueError: A held-out scenario or seed (``splits.check_training``), a
            residual mode other than ``force`` or ``force_and_rate``, ``sac``, no
            base, ``normalize_observations=False``, or fewer fleets than scenarios.
    """
    started = time.perf_counter()
    check_distillation(config, settings)
    env = _environment(config, settings)
    env.seed(config.seed)
    teachers = [make_policy(settings.teacher, group.sim) for group in _groups(env)]
    torch.manual_seed(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    size = env.observation_space.shape[0]  # type: ignore[index]
    action_size = _groups(env)[0].controller.action_size
    network = student_actor(config, size, action_size)
    stats: InputStatistics | None = None
    data: list[tuple[NDArray[np.float32], NDArray[np.float64]]] = []
    rounds: list[dict[str, float]] = []
    obs = env.reset()
    for teacher in teachers:
        teacher.reset()
    for round_ in range(settings.rounds):
        student = None if round_ == 0 else network
        inputs, labels, obs = _rollout(env, obs, teachers, student, stats, settings.steps)
        data.append((inputs, labels))
        if stats is None:
            first = data[0][0].astype(np.float64)
            stats = InputStatistics(first.mean(axis=0), first.var(axis=0))
        inputs = np.concatenate([d[0] for d in data])
        labels = np.concatenate([d[1] for d in data])
        rows = torch.from_numpy(stats.apply(inputs).astype(np.float32))
        targets = torch.from_numpy(np.clip(labels, -1.0, 1.0).astype(np.float32))
        loss = _fit(network, rows, targets, settings, generator)
        rounds.append(
            {
                "round": round_,
                "samples": int(labels.shape[0]),
                "loss": loss,
                "zero_loss": float(np.mean(np.clip(labels, -1.0, 1.0) ** 2)),
                "clipped": float(np.mean(np.abs(labels) > 1.0)),
                "seconds": time.perf_counter() - started,
            }
        )
    final = rounds[-1]
    losses = [r["loss"] for r in rounds]
    seconds = time.perf_counter() - started
    record = {
        "config": config.to_json(),
        "distillation": {
            **dataclasses.asdict(settings),
            "samples": int(final["samples"]),
            "losses": losses,
            "zero_loss": final["zero_loss"],
            "clipped": final["clipped"],
            "seconds": seconds,
        },
        "timesteps_done": int(final["samples"]),
        "interrupted": False,
    }
    with atomic.staged_folder(out) as staging:
        write_agent(staging, record, network, stats)
    return DistillReport(
        Path(out),
        int(final["samples"]),
        tuple(losses),
        final["zero_loss"],
        final["clipped"],
        seconds,
        tuple(rounds),
    )
