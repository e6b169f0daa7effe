"""Teacher and student: DAgger of a local residual student from a teacher policy.

The teacher is any policy of ``baselines``: a deployable one of
``baselines.DEPLOYABLE`` (e.g. ``mpc``, receding-horizon control per vessel)
or a privileged reference of ``baselines.PRIVILEGED`` (e.g. ``oracle``,
centralized, told the true model and the coming disturbances; default
``nn_dsc_privileged``). It acts on the fleet's true observations (a
privileged one is bound to the simulator it reads). The student is the
deployable actor of the agent-folder format (``agents.folder.actor.PolicyNetwork``,
built by ``student_actor`` with ``build_actor``, the actor ``cpf-train`` builds
for the same ``TrainConfig``: an MLP with tanh hidden layers and a clipped
output, behind a DeepSets neighbour encoder with ``encoder="deepsets"``, so
one network runs any degree) on the vessel's local input, in the residual
parameterization of
``cpf_env.envs.residual``: the command applied is ``base + scale * limit * a``.
The teacher's command is turned into the residual that would reproduce it,

    a*_f = (tau_T - tau_base) / (scale * tau_limit)             (force axes, N),
    a*_r = (theta_dot_T - theta_dot_base) / (scale * theta_dot_max)
                                               (``force_and_rate`` mode only, 1/s),

and clipped to [-1, 1]: the student learns what the teacher would add to the
base it runs on; where the teacher's correction is beyond the residual's
reach the label is clipped (``DistillReport.clipped`` says how often; raise
``TrainConfig.residual.scale`` if it is large).

Which base the label is taken on: ``DistillConfig.label_base``
(``agents.distill.config``).

The loss. By default it is the mean squared error between the student's
pre-clip output u and the clipped label. With ``DistillConfig.fit_applied``
it is taken on the force the vessel receives. The plant saturates the
command per axis, so a residual acts only within the bounds

    lo = (tau_min - tau_base) / (scale * tau_limit),
    hi = (tau_max - tau_base) / (scale * tau_limit)       (each clipped to [-1, 1]),

and the label becomes t = clip(a*, lo, hi). Where t = hi (the teacher at the
upper limit, or at the residual's reach) every u >= hi applies the same force,
so the loss there is one-sided, (min(u, hi) - t)^2; likewise (max(u, lo) - t)^2
where t = lo; elsewhere it is (u - t)^2. A student fitted with the plain loss
scatters around a label at the limit, and the plant cuts off only the half of
that scatter that points past the limit: the other half is lost force. The
one-sided loss lets it aim past the limit instead. The path-variable rate's
bounds are the output's [-1, 1]. ``DistillReport.at_limit`` is the share of
force labels at a bound either way. In ``force`` mode the path-variable
rate stays the base's, so a teacher that plans its own rate (``mpc``,
``oracle``) is imitated in force only; ``force_and_rate`` imitates both.

Data: one scenario, or a mixture (``TrainConfig.scenario`` a tuple, e.g. the
suite's training distributions), optionally joined by procedural training
fleets (``DistillConfig.procedural`` draws of ``cpf_env.scenarios.sampler``,
seeds 0, 1, ...; with ``redraw`` fresh draws every round, ``draw_seeds``;
``DistillConfig.distribution`` widens or narrows the sampler's ranges, e.g.
faster leaders and weaker actuators).
Each scenario is a group of fleets (``split_fleets``, seeded as
``MixtureVecEnv`` seeds them), stepped one after the other. Held-out
scenarios and seeds are refused (``splits.check_training``,
``sampler.check_not_held_out``).

Inputs. The student reads what ``agents.load_policy`` would give it: the
learner's local input with, for ``TrainConfig(history=H)``, its own last H
(own features, action, valid) entries stacked by ``HistoryVecEnv`` (the
``OwnHistory`` the loaded policy keeps), normalized with the statistics of
round 0's data (``input_statistics``: with ``shared_slot_statistics`` the
slots share pooled statistics and, with an encoder, their weights stay raw, as
``cpf-train`` normalizes). The labels come from the teacher on the fleet's
true present observation.

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
record (settings, per-round losses, clipped share, wall time). With an
evaluator (``distill(..., evaluate=)``, ``cpf-distill --eval-num-seeds``) the
student is also evaluated before round 0 and after each round, into the
rows of ``evaluations.csv`` (``DistillReport.evaluations``).
``cpf-distill`` (``cpf_commands.distill``) runs it from a TOML file.

Example (a tiny budget):
    >>> import tempfile
    >>> from agents.training.config import TrainConfig
    >>> config = TrainConfig(scenario="wang2014", fleets=2, net_arch=(16,))
    >>> out = tempfile.mkdtemp() + "/student"
    >>> report = distill(config, DistillConfig(rounds=2, steps=20, epochs=2), out)
    >>> report.samples
    400
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from agents.distill.config import DistillConfig, DistillReport, check_distillation, draw_seeds
from agents.envs.history_env import HistoryVecEnv
from agents.envs.mixture_env import split_fleets
from agents.envs.slot_statistics import shared_slot_statistics
from agents.envs.vec_env import FleetVecEnv
from agents.folder.actor import PolicyNetwork, build_actor
from agents.folder.format import write_agent
from agents.folder.loading import one_torch_thread
from agents.training.config import TrainConfig
from agents.training.device import torch_device
from agents.training.schedule import EvaluationLog, Evaluator
from baselines import make_policy
from cpf_env import scenarios
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig
from cpf_env.infra import atomic
from cpf_env.scenarios import Scenario
from cpf_env.scenarios.sampler import ScenarioDistribution

__all__ = ["distill", "input_statistics", "student_actions", "student_actor"]


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


@dataclass
class _Group:
    """One scenario's fleets in the rollouts: their env, the student's view of it, the teacher.

    Attributes:
        env: The group's ``FleetVecEnv`` (its simulator, base and residual controller).
        view: What the student reads: ``env``, or ``HistoryVecEnv(env, H)`` with a history.
        teacher: The teacher, bound to ``env.sim`` (a privileged one reads it).
        twin: With ``label_base="twin"``, the copy of ``env``'s base shown the whole
            applied force (the labels' base); None: the labels are taken on
            ``env``'s base.
        obs: The student's last inputs (B n, d) of this group.
        draw: The procedural draw seed, or None for a named scenario.
    """

    env: FleetVecEnv
    view: FleetVecEnv | HistoryVecEnv
    teacher: FleetPolicy
    twin: FleetPolicy | None
    obs: NDArray[np.float32]
    draw: int | None


def _labels(
    env: FleetVecEnv, teacher: FleetPolicy, twin: FleetPolicy | None = None
) -> NDArray[np.float64]:
    """The teacher's command as a residual on the labels' base, (B, n, k), unclipped.

    The teacher acts once (its states advance one step) on the fleets' true
    observations; so does ``twin``, the copy of the env's base shown the whole
    applied force (``label_base="twin"``), on the same observations, which
    report that force. Without a twin the base is the env's, which acted on
    the present observation when the env took it.
    """
    obs = np.asarray(env.sim.arrays.obs, dtype=np.float64)
    command = np.asarray(teacher.act_batch(obs), dtype=np.float64)
    controller = env.controller
    if twin is None:
        base = controller.base_actions
    else:
        base = np.asarray(twin.act_batch(obs), dtype=np.float64)
    force = (command[..., :3] - base[..., :3]) / _force_reach(env)
    if controller.config.mode == "force":
        return force
    rate_reach = controller.config.scale * float(env.scenario.theta_dot_max)
    rate = (command[..., 3] - base[..., 3]) / rate_reach
    return np.concatenate([force, rate[..., None]], axis=-1)


def _force_reach(env: FleetVecEnv) -> NDArray[np.float64]:
    """The force one unit of residual adds, scale x tau_limit, (n, 3) in N, N, N m."""
    tau_min, tau_max = env.scenario.tau_limits
    return env.controller.config.scale * np.maximum(np.abs(tau_min), np.abs(tau_max))


def _applied_bounds(env: FleetVecEnv) -> NDArray[np.float64]:
    """The residual's bounds of effect on the env's present base, (2, B, n, k): lo, hi.

    Force axes: the residuals whose command reaches the actuator limits,
    (tau_min - tau_base) / reach and (tau_max - tau_base) / reach, clipped to
    [-1, 1]; with ``yield_at_limit``, an axis whose base is at a limit has no
    residual of effect (lo = hi there: a pull back from the limit is dropped,
    a push past it saturates). The rate (``force_and_rate``): [-1, 1].
    """
    tau_min, tau_max = env.scenario.tau_limits
    base, reach = env.controller.base_actions[..., :3], _force_reach(env)
    bounds = np.full((2, *base.shape[:-1], env.controller.action_size), 1.0)
    bounds[0] = -1.0
    low = np.clip((np.asarray(tau_min) - base) / reach, -1.0, 1.0)
    high = np.clip((np.asarray(tau_max) - base) / reach, -1.0, 1.0)
    if env.controller.config.yield_at_limit:
        at_max, at_min = env.controller.base_at_limits()
        low = np.where(at_max, high, low)
        high = np.where(at_min, low, high)
    bounds[0, ..., :3], bounds[1, ..., :3] = low, high
    return bounds


def student_actions(
    network: PolicyNetwork, stats: InputStatistics, inputs: NDArray[np.float32]
) -> NDArray[np.float32]:
    """The student's actions (R, k) on raw inputs (R, d), as ``agents.load_policy`` computes them.

    ``inputs`` are the learner's inputs with the history appended
    (``HistoryVecEnv``), normalized with ``stats`` and run through ``network``
    on the network's device on one torch thread; float32 on the CPU.
    """
    device = next(network.parameters()).device
    rows = torch.from_numpy(stats.apply(inputs)).to(device)
    with one_torch_thread(), torch.no_grad():
        return network(rows).cpu().numpy()


def _rollout(
    groups: list[_Group],
    student: PolicyNetwork | None,
    stats: InputStatistics | None,
    steps: int,
) -> tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.float64]]:
    """Run ``steps`` env steps of every group, continuing the episodes under way.

    Each group's ``obs`` is updated in place.

    Returns:
        The inputs (S, d) the student read, the raw labels (S, k) of the teacher
        and the applied residual's bounds (2, S, k) (``_applied_bounds``).
    """
    inputs, labels, bounds = [], [], []
    size = groups[0].env.controller.action_size
    for _ in range(steps):
        label = np.concatenate(
            [_labels(g.env, g.teacher, g.twin).reshape(-1, size) for g in groups]
        )
        bound = np.concatenate(
            [_applied_bounds(group.env).reshape(2, -1, size) for group in groups], axis=1
        )
        obs = np.concatenate([group.obs for group in groups])
        inputs.append(obs)
        labels.append(label)
        bounds.append(bound)
        if student is None:
            action = np.clip(label, -1.0, 1.0).astype(np.float32)
        else:
            assert stats is not None
            action = student_actions(student, stats, obs)
        start = 0
        for group in groups:
            stop = start + group.view.num_envs
            group.view.step_async(action[start:stop])
            stepped, _, dones, _ = group.view.step_wait()
            group.obs = np.asarray(stepped, dtype=np.float32)
            ended = np.asarray(dones).reshape(-1, group.env.n)[:, 0]
            if ended.any():
                group.teacher.reset_fleets(ended)
                if group.twin is not None:
                    group.twin.reset_fleets(ended)
            start = stop
    return np.concatenate(inputs), np.concatenate(labels), np.concatenate(bounds, axis=1)


def _loss(output: torch.Tensor, targets: torch.Tensor, bounds: torch.Tensor | None) -> torch.Tensor:
    """The mean squared error of ``output`` (R, k) on ``targets`` (R, k).

    With ``bounds`` (2, R, k) (lo, hi; the targets lie within them) it is
    one-sided where a target sits at a bound: an output past the bound counts
    as the bound (``DistillConfig.fit_applied``).
    """
    if bounds is not None:
        low, high = bounds
        output = torch.where(targets >= high, torch.minimum(output, high), output)
        output = torch.where(targets <= low, torch.maximum(output, low), output)
    return torch.mean((output - targets) ** 2)


def _fit(
    network: PolicyNetwork,
    rows: torch.Tensor,
    targets: torch.Tensor,
    bounds: torch.Tensor | None,
    config: DistillConfig,
    generator: torch.Generator,
) -> float:
    """Fit the actor's pre-clip output to ``targets`` (in [-1, 1]); return the final loss.

    ``bounds``: (2, R, k) for the applied-force loss (``_loss``), or None.
    """
    optimizer = torch.optim.Adam(network.parameters(), lr=config.learning_rate)

    for _ in range(config.epochs):
        order = torch.randperm(rows.shape[0], generator=generator).to(rows.device)
        for start in range(0, rows.shape[0], config.batch_size):
            index = order[start : start + config.batch_size]
            batch = None if bounds is None else bounds[:, index]
            loss = _loss(network.unbounded(rows[index]), targets[index], batch)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    with torch.no_grad():
        return float(_loss(network(rows), targets, bounds))


def _learner_residual(config: TrainConfig) -> ResidualConfig:
    """The run's residual with its neighbour slots fixed (all groups' inputs share K)."""
    residual = config.residual
    if residual.neighbour_slots is None:  # one named scenario: its own degree
        residual = dataclasses.replace(residual, neighbour_slots=config.learner_slots()[0])
    return residual


def _training_fleets(config: TrainConfig, settings: DistillConfig) -> ScenarioDistribution:
    """The procedural fleets' distribution: ``settings.distribution``, degrees <= the slots.

    The cap is the learner's neighbour slots, at least 2.
    """
    slots = _learner_residual(config).neighbour_slots
    assert slots is not None
    return ScenarioDistribution(max_degree=max(2, slots), **settings.distribution)


def _group(
    config: TrainConfig,
    settings: DistillConfig,
    scenario: Scenario,
    fleets: int,
    offset: int,
    draw: int | None,
) -> _Group:
    """One group's env (seeded ``config.seed + offset``, reset), the student's view, the teacher.

    With ``label_base="twin"`` also the base's twin (``_Group.twin``): a copy
    of the env's base taken before the env resets it, then reset with the
    seed the env gives it.
    """
    base = None if config.base_policy == "none" else config.base_policy  # mpc: fleet by fleet
    env = FleetVecEnv(
        scenario, num_fleets=fleets, base_policy=base, residual=_learner_residual(config)
    )
    seeds = env.seed(config.seed + offset)
    twin = None
    if settings.label_base == "twin":
        twin = copy.deepcopy(env.controller.base)  # not yet reset: as the env's base is
        twin.reset(seed=seeds[0])  # the seed the env's reset gives its base
    view: FleetVecEnv | HistoryVecEnv = env
    if config.history:
        view = HistoryVecEnv(env, config.history)
    obs = np.asarray(view.reset(), dtype=np.float32)
    teacher = make_policy(settings.teacher, env.sim)
    teacher.reset()
    return _Group(env, view, teacher, twin, obs, draw)


def _groups(config: TrainConfig, settings: DistillConfig) -> list[_Group]:
    """Every group of round 0: the named scenarios, then the procedural draws.

    Fleets are shared by ``split_fleets``; group g's fleet k starts from seed
    ``config.seed + offset_g + k`` (``MixtureVecEnv``'s rule).
    """
    named = [
        scenarios.make_scenario(name, **config.scenario_overrides(name))
        for name in config.scenarios
    ]
    distribution = _training_fleets(config, settings)
    draws = [distribution.sample(seed) for seed in draw_seeds(settings, 0)]
    fleets = split_fleets(config.fleets, len(named) + len(draws))
    offsets = np.cumsum([0, *fleets[:-1]]).tolist()
    seeds: list[int | None] = [None] * len(named) + list(draw_seeds(settings, 0))
    return [
        _group(config, settings, scenario, count, int(offset), seed)
        for scenario, count, offset, seed in zip(
            [*named, *draws], fleets, offsets, seeds, strict=True
        )
    ]


def _redraw(
    groups: list[_Group], config: TrainConfig, settings: DistillConfig, round_: int
) -> list[_Group]:
    """``groups`` with the procedural ones replaced by the draws of ``round_`` (fresh episodes)."""
    distribution = _training_fleets(config, settings)
    seeds = iter(draw_seeds(settings, round_))
    offset, replaced = 0, []
    for group in groups:
        fleets = group.env.num_fleets
        if group.draw is None:
            replaced.append(group)
        else:
            seed = next(seeds)
            scenario = distribution.sample(seed)
            replaced.append(_group(config, settings, scenario, fleets, offset, seed))
        offset += fleets
    return replaced


def input_statistics(config: TrainConfig, inputs: NDArray[np.float32]) -> InputStatistics:
    """The student's input statistics: the mean and variance of ``inputs`` (S, d).

    As ``cpf-train`` normalizes: with ``shared_slot_statistics`` the neighbour
    slots share pooled statistics (``agents.envs.slot_statistics``), and with an
    encoder the slots' weights keep mean 0 and variance 1 (an empty slot stays
    exactly 0, as the encoder's mask needs).
    """
    values = inputs.astype(np.float64)
    mean, var = values.mean(axis=0), values.var(axis=0)
    if config.shared_slot_statistics:
        slots, slot_size = config.learner_slots()
        mean, var = shared_slot_statistics(
            mean, var, slots, slot_size, raw_weights=config.encoder is not None
        )
    return InputStatistics(mean, var)


def _agent_record(
    config: TrainConfig,
    settings: DistillConfig,
    draws: list[list[int]],
    rounds: list[dict[str, float]],
    seconds: float,
) -> dict[str, Any]:
    """The ``config.json`` record of the student after ``rounds`` (none yet: the base)."""
    final = (
        rounds[-1] if rounds else {"samples": 0, "zero_loss": 0.0, "clipped": 0.0, "at_limit": 0.0}
    )
    return {
        "config": config.to_json(),
        "distillation": {
            **dataclasses.asdict(settings),
            "draws": draws,
            "samples": int(final["samples"]),
            "losses": [r["loss"] for r in rounds],
            "zero_loss": final["zero_loss"],
            "clipped": final["clipped"],
            "at_limit": final["at_limit"],
            "seconds": seconds,
        },
        "timesteps_done": int(final["samples"]),
        "interrupted": False,
    }


def distill(
    config: TrainConfig,
    settings: DistillConfig,
    out: str | Path,
    device: str = "cpu",
    evaluate: Evaluator | None = None,
) -> DistillReport:
    """Distill a teacher into a local residual student; write its agent folder.

    With ``evaluate`` (``cpf-distill --eval-num-seeds``: ``cpf-train``'s evaluator
    on the validation seeds) the student is evaluated before round 0
    and after each round (``agents.training.schedule.EvaluationLog``, no ``best/``: the
    student is the last round's). Before round 0 its output is exactly zero
    (``student_actor``), so the first row is the base policy (the folder
    evaluated then holds identity input statistics, which a zero output
    ignores). Each row's ``vessel_steps`` is the labelled vessel-steps so far,
    which are the simulated ones (every vessel-step of the rollouts is
    labelled), ``cpf-train``'s axis; ``wall_clock_seconds`` counts from the
    start, teacher, base, simulator and evaluations included. The evaluation
    runs on its own envs, in a fork of torch's random state, on a copy of the
    student: it changes nothing the training computes.

    Args:
        config: The student's run: scenario (one, or a tuple: a mixture), base,
            residual (``mode`` ``"force"`` or ``"force_and_rate"``, ``scale``),
            ``fleets``, ``seed``, ``net_arch``, ``encoder``, ``history`` (``algo``
            must be ``ppo``, whose actor format the student takes).
        settings: Teacher, procedural draws and budget.
        out: The agent folder to write (replaced whole if it exists).
        device: Where torch fits and runs the student (``agents.training.device.torch_device``:
            ``"cpu"``, ``"cuda"``, ``"cuda:1"``, ``"auto"``); the folder is written
            from the CPU and loads on the CPU.
        evaluate: Agent folder -> mean cost per scenario, or None (no evaluation).

    Raises:
        ValueError: A held-out scenario or seed (``splits.check_training``), a
            residual mode other than ``force`` or ``force_and_rate``, ``sac``, no
            base, ``normalize_observations=False``, fewer fleets than scenarios,
            redrawn seeds beyond the training draws, or a device torch cannot use.
    """
    started = time.perf_counter()
    check_distillation(config, settings)
    where = torch_device(device)
    torch.manual_seed(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    groups = _groups(config, settings)
    size = groups[0].obs.shape[1]
    action_size = groups[0].env.controller.action_size
    network = student_actor(config, size, action_size).to(where)
    stats: InputStatistics | None = None
    data: list[NDArray[np.float32]] = []  # each round's normalized student inputs
    labelled: list[NDArray[np.float64]] = []  # each round's labels, unclipped
    bounded: list[NDArray[np.float64]] = []  # each round's applied bounds (2, S, k)
    rounds: list[dict[str, float]] = []
    draws: list[list[int]] = []
    evaluations = None if evaluate is None else EvaluationLog(evaluate, best=None)

    def clock() -> float:
        return time.perf_counter() - started

    def evaluation(statistics: InputStatistics) -> None:
        """Evaluate a copy of the student as it is now (see above)."""
        if evaluations is None:
            return
        record = _agent_record(config, settings, draws, rounds, clock())
        student = copy.deepcopy(network).cpu()
        samples = int(rounds[-1]["samples"]) if rounds else 0
        write = functools.partial(
            write_agent, record=record, network=student, normalization=statistics
        )
        with torch.random.fork_rng(devices=[]):
            evaluations.run(write, samples, clock)

    evaluation(InputStatistics(np.zeros(size), np.ones(size)))
    for round_ in range(settings.rounds):
        if settings.redraw and round_ > 0:
            groups = _redraw(groups, config, settings, round_)
        draws.append(draw_seeds(settings, round_))
        student = None if round_ == 0 else network
        inputs, new_labels, new_bounds = _rollout(groups, student, stats, settings.steps)
        if stats is None:
            stats = input_statistics(config, inputs)
        data.append(stats.apply(inputs))  # normalized once: the statistics stay round 0's
        labelled.append(new_labels)
        bounded.append(new_bounds)
        labels, bounds = np.concatenate(labelled), np.concatenate(bounded, axis=1)
        rows = torch.from_numpy(np.concatenate(data)).to(where)
        clipped = np.clip(labels, -1.0, 1.0)
        applied = np.clip(labels, bounds[0], bounds[1])
        at_limit = (applied <= bounds[0]) | (applied >= bounds[1])
        if settings.fit_applied:
            targets = torch.from_numpy(applied.astype(np.float32)).to(where)
            limits = torch.from_numpy(bounds.astype(np.float32)).to(where)
            loss = _fit(network, rows, targets, limits, settings, generator)
            zero_loss = float(_loss(torch.zeros_like(targets), targets, limits))
        else:
            targets = torch.from_numpy(clipped.astype(np.float32)).to(where)
            loss = _fit(network, rows, targets, None, settings, generator)
            zero_loss = float(np.mean(clipped**2))
        rounds.append(
            {
                "round": round_,
                "samples": int(labels.shape[0]),
                "loss": loss,
                "zero_loss": zero_loss,
                "clipped": float(np.mean(np.abs(labels) > 1.0)),
                "at_limit": float(np.mean(at_limit[:, :3])),
                "seconds": clock(),
            }
        )
        evaluation(stats)
    final = rounds[-1]
    seconds = clock()
    assert stats is not None
    with atomic.staged_folder(out) as staging:
        write_agent(
            staging, _agent_record(config, settings, draws, rounds, seconds), network.cpu(), stats
        )
    return DistillReport(
        Path(out),
        int(final["samples"]),
        tuple(r["loss"] for r in rounds),
        final["zero_loss"],
        final["clipped"],
        final["at_limit"],
        seconds,
        tuple(rounds),
        tuple(tuple(d) for d in draws),
        str(where),
        () if evaluations is None else tuple(evaluations.rows),
    )
