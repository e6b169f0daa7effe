"""``evaluate``: policies x scenarios x paired seeds, the benchmark's one call.

Every policy runs every scenario on the same evaluation seeds ``seed + k``
(k < ``num_seeds``; paired episodes), as Stable-Baselines3's
``evaluate_policy`` runs one model, and each episode is reduced to the
metrics of ``cpf_env.evaluation.fleet_metrics`` (``cpf_bench.episodes.METRICS``).
A scenario in which nothing is random (``cpf_env.scenarios.suite.is_deterministic``)
runs one episode. Locally every policy's seeds of a scenario share one
batched simulator (``cpf_bench.rollout.rollout_group``: the same numbers as
a batch per cell). The cells of the receding-horizon policies given by name
(``cpf_bench.cache.CACHED_POLICIES``) are read from the content-keyed cache
when it holds them, and stored when they ran whole episodes.

A policy is given as:

- a name of ``baselines.ALL_POLICIES`` (built with ``baselines.make_policy``,
  default gains);
- a policy object (``cpf_env.envs.policy.FleetPolicy``), used as it is on
  every scenario;
- a callable ``scenario -> policy``, called once per scenario; a
  ``ValueError`` it raises skips that scenario (``Evaluation.skipped``);
- anything else a ``resolve(spec, scenario)`` given by the caller builds
  (the commands pass their resolver, which also loads agent folders and
  ONNX files).

Example:
    >>> from cpf_bench import evaluate
    >>> result = evaluate(["nn_dsc", "dsc"], ["bench_mild"], num_seeds=2, max_steps=20)
    >>> cell = result.cell("nn_dsc", "bench_mild")
    >>> cell.seeds, cell.metrics["cost"].shape
    ((10000, 10001), (2,))
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from baselines import ALL_POLICIES, make_policy
from cpf_bench import cache
from cpf_bench.episodes import run_episodes
from cpf_bench.report import CellResult
from cpf_bench.rollout import rollout_group
from cpf_env.envs.policy import FleetPolicy
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.scenarios.splits import EVALUATION_SEED, SPLITS, split_scenario
from cpf_env.scenarios.suite import is_deterministic

__all__ = [
    "Evaluation",
    "Job",
    "build_policy",
    "episode_seeds",
    "evaluate",
    "labelled_policies",
    "policy_label",
    "run_cell",
]

#: A policy as ``evaluate`` takes it (module docstring); ``resolve`` may take more.
PolicySpec = Any
#: Builds a policy the caller names in its own way: (spec, scenario) -> policy.
Resolver = Callable[[Any, Scenario], FleetPolicy]
#: One cell to run: policy label, its specification, the scenario, the seeds.
Job = tuple[str, PolicySpec, Scenario, tuple[int, ...]]
#: Runs cells elsewhere (e.g. as Ray tasks), returning them in the order given.
CellRunner = Callable[[Sequence[Job], int | None], list[CellResult]]


@dataclass(frozen=True)
class Evaluation:
    """What ``evaluate`` measured.

    Attributes:
        cells: One ``CellResult`` per (policy, scenario) that ran, policies outermost.
        skipped: (label, scenario name) -> why the policy could not be built there
            (e.g. a trained agent whose observation layout differs).
    """

    cells: list[CellResult]
    skipped: dict[tuple[str, str], str] = field(default_factory=dict)

    def cell(self, label: str, scenario: str) -> CellResult:
        """The cell of policy ``label`` on the scenario named ``scenario``.

        Raises:
            KeyError: No such cell (the message lists the ones there are).
        """
        for cell in self.cells:
            if cell.policy == label and cell.scenario == scenario:
                return cell
        there = sorted({(cell.policy, cell.scenario) for cell in self.cells})
        raise KeyError(f"no cell ({label!r}, {scenario!r}); the cells are {there}.")


def policy_label(spec: PolicySpec) -> str:
    """The name a policy goes by in tables and file names.

    A baseline's name, a trained agent's path as given (without a trailing
    slash), or an object's ``name`` attribute (else its class name).
    """
    if isinstance(spec, Path):
        return str(spec)
    if isinstance(spec, str):
        return spec.rstrip("/") or spec
    return str(getattr(spec, "name", getattr(spec, "__name__", type(spec).__name__)))


def labelled_policies(
    policies: Sequence[PolicySpec] | Mapping[str, PolicySpec],
) -> dict[str, PolicySpec]:
    """Label -> specification, refusing a policy listed twice or two with the same label."""
    if isinstance(policies, Mapping):
        return dict(policies)
    labelled: dict[str, PolicySpec] = {}
    for spec in policies:
        label = policy_label(spec)
        if label in labelled and isinstance(spec, str | Path):
            raise ValueError(
                f"policy {label!r} is listed twice; duplicates are not allowed (every policy "
                "runs on the same seeds, so a second run would repeat the first)."
            )
        if label in labelled:
            raise ValueError(
                f"two policies are labelled {label!r}; give them distinct name attributes "
                "or pass a mapping label -> policy."
            )
        labelled[label] = spec
    return labelled


def build_policy(spec: PolicySpec, task: Scenario, resolve: Resolver | None = None) -> FleetPolicy:
    """The policy ``spec`` stands for on ``task`` (module docstring).

    Raises:
        ValueError: A specification this call cannot build (and no ``resolve``).
    """
    if isinstance(spec, str) and spec in ALL_POLICIES:
        return make_policy(spec, task)
    if resolve is not None:
        return resolve(spec, task)
    if isinstance(spec, FleetPolicy):
        return spec
    if callable(spec):
        return spec(task)
    raise ValueError(
        f"cannot use {spec!r} as a policy: give a name of baselines.ALL_POLICIES "
        f"({', '.join(sorted(ALL_POLICIES))}), a policy object (act_batch, reset, "
        "diagnostics) or a callable scenario -> policy; load a trained agent first "
        "(agents.load_policy)."
    )


def episode_seeds(task: Scenario, num_seeds: int, seed: int) -> tuple[int, ...]:
    """Evaluation seeds of a scenario: ``seed + k``, one episode if nothing in it is random."""
    return tuple(seed + k for k in range(1 if is_deterministic(task) else num_seeds))


def run_cell(
    label: str,
    spec: PolicySpec,
    task: Scenario,
    seeds: tuple[int, ...],
    max_steps: int | None,
    resolve: Resolver | None = None,
) -> CellResult:
    """One (policy, scenario) cell on its own: build the policy, run its episodes, measure them."""
    metrics = run_episodes(build_policy(spec, task, resolve), task, seeds, max_steps=max_steps)
    return CellResult(label, task.name, seeds, is_deterministic(task), metrics)


def evaluate(
    policies: Sequence[PolicySpec] | Mapping[str, PolicySpec],
    scenarios: Sequence[str | Scenario],
    num_seeds: int = 10,
    seed: int = EVALUATION_SEED,
    max_steps: int | None = None,
    split: str = "test",
    progress: bool = False,
    resolve: Resolver | None = None,
    run_cells: CellRunner | None = None,
) -> Evaluation:
    """Run every policy on every scenario for ``num_seeds`` paired seeds and measure each episode.

    Args:
        policies: Policy specifications (module docstring), or a mapping label ->
            specification.
        scenarios: Registered scenario names or ``Scenario`` objects.
        num_seeds: Episodes per (policy, scenario) (one on a deterministic scenario).
        seed: Episode k is reset with seed ``seed + k`` (default: the first
            evaluation seed, ``cpf_env.scenarios.splits.EVALUATION_SEED``).
        max_steps: Horizon override in control steps (default: each scenario's ``max_steps``).
        split: ``"test"`` (the scenarios as named) or ``"shift"`` (each suite
            scenario's ``_shift`` variant, outside its training ranges).
        progress: Show a progress bar over steps (stderr).
        resolve: Builds the specifications that are not baseline names (default:
            objects and callables only).
        run_cells: Runs the cells that are not cached somewhere else (e.g. Ray
            tasks running ``run_cell``); default: here, a batch per scenario.

    Returns:
        The cells that ran and the (policy, scenario) pairs skipped, with why.

    Raises:
        ValueError: No policy or scenario, an unknown scenario or split, fewer
            than one seed, a bad horizon, or a policy that fits none of the scenarios.
    """
    if isinstance(num_seeds, bool) or int(num_seeds) != num_seeds or num_seeds < 1:
        raise ValueError(f"num_seeds must be an integer >= 1, got {num_seeds!r}.")
    if max_steps is not None and int(max_steps) < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}.")
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; choose one of {list(SPLITS)}.")
    if not scenarios:
        raise ValueError("give at least one scenario.")
    if split == "shift":
        scenarios = [_shifted(name) for name in scenarios]
    tasks = [make_scenario(name) for name in scenarios]
    labelled = labelled_policies(policies)
    if not labelled:
        raise ValueError("give at least one policy.")
    built, skipped = _build(labelled, tasks, resolve)
    jobs = [
        (label, labelled[label], task, episode_seeds(task, int(num_seeds), seed))
        for label in labelled
        for task in tasks
        if (label, task.name) in built
    ]
    found = _cached(jobs, max_steps)
    missing = [job for job in jobs if (job[0], job[2].name) not in found]
    if not missing:
        ran = []
    elif run_cells is not None:
        ran = run_cells(missing, max_steps)
    else:
        ran = _run_here(missing, built, max_steps, progress)
    for job, cell in zip(missing, ran, strict=True):
        if _cacheable(job) and max_steps in (None, job[2].max_steps):  # whole episodes only
            cache.store_cell(job[0], job[2], job[3], max_steps, cell.metrics)
        found[(job[0], job[2].name)] = cell
    return Evaluation([found[(label, task.name)] for label, _, task, _ in jobs], skipped)


def _build(
    labelled: dict[str, PolicySpec], tasks: Sequence[Scenario], resolve: Resolver | None
) -> tuple[dict[tuple[str, str], FleetPolicy], dict[tuple[str, str], str]]:
    """Each policy built for each scenario, and the (label, scenario) pairs that did not fit.

    Raises:
        ValueError: A policy that fits none of the scenarios (the first reason).
    """
    built: dict[tuple[str, str], FleetPolicy] = {}
    skipped: dict[tuple[str, str], str] = {}
    for label, spec in labelled.items():
        reasons = []
        for task in tasks:
            try:
                built[(label, task.name)] = build_policy(spec, task, resolve)
            except ValueError as error:
                skipped[(label, task.name)] = str(error)
                reasons.append(str(error))
        if len(reasons) == len(tasks):
            raise ValueError(reasons[0])
    return built, skipped


def _run_here(
    jobs: Sequence[Job],
    built: dict[tuple[str, str], FleetPolicy],
    max_steps: int | None,
    progress: bool,
) -> list[CellResult]:
    """The cells in this process, one batch per scenario, with a progress bar over steps.

    Returns the cells in the order of ``jobs``.
    """
    groups: dict[str, list[Job]] = {}
    for job in jobs:
        groups.setdefault(job[2].name, []).append(job)
    total = sum(
        group[0][2].max_steps if max_steps is None else int(max_steps) for group in groups.values()
    )
    results: dict[tuple[str, str], CellResult] = {}
    with tqdm(total=total, disable=not progress, unit="step", desc="cpf-bench") as bar:
        for name, group in groups.items():
            bar.set_postfix_str(f"{len(group)} policies on {name}")
            task, seeds = group[0][2], group[0][3]
            policies = [built[(label, name)] for label, *_ in group]
            measured = rollout_group(policies, task, seeds, max_steps=max_steps, progress=bar)
            for (label, *_), metrics in zip(group, measured, strict=True):
                results[(label, name)] = CellResult(
                    label, name, seeds, is_deterministic(task), metrics
                )
    return [results[(label, task.name)] for label, _, task, _ in jobs]


def _cacheable(job: Job) -> bool:
    """A cell of a receding-horizon policy given by name (``cpf_bench.cache``)."""
    return isinstance(job[1], str) and job[1] in cache.CACHED_POLICIES and job[0] == job[1]


def _cached(jobs: Sequence[Job], max_steps: int | None) -> dict[tuple[str, str], CellResult]:
    """The cells found in the content-keyed cache, by (label, scenario name)."""
    found = {}
    for label, spec, task, seeds in jobs:
        if not _cacheable((label, spec, task, seeds)):
            continue
        metrics = cache.load_cell(label, task, seeds, max_steps)
        if metrics is not None:
            found[(label, task.name)] = CellResult(
                label, task.name, seeds, is_deterministic(task), metrics
            )
    return found


def _shifted(name: str | Scenario) -> Scenario:
    """The shift split of a suite scenario given by name."""
    if not isinstance(name, str):
        raise ValueError("split='shift' needs suite scenario names, not Scenario objects.")
    return split_scenario(name, "shift")
