"""``run_bench``: the benchmark as the commands run it, and its output folder.

``run_bench`` resolves every policy the commands accept (a baseline name, a
``cpf-train --out`` folder, an ``.onnx`` file, ``package.module:NAME``, a
registered name or an object: ``cpf_commands.common.policies.resolve_policy``),
runs them with ``cpf_bench.evaluate`` (here, or one (policy, scenario) cell per
Ray task: the same numbers), and ``write_outputs`` fills the output folder with
``episodes.csv``, ``summary.csv``, ``summary.md``, the figures and
``report.html`` (the ranked tables and the figures in one page);
``cpf_commands.bench.cli`` is the command around it.

Example:
    >>> from cpf_commands.bench.run import run_bench
    >>> cells = run_bench(["nn_dsc"], ["bench_mild"], num_seeds=2, max_steps=20, out=None)
    >>> cells[0].seeds, cells[0].metrics["cost"].shape
    ((10000, 10001), (2,))
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path

from tqdm.auto import tqdm

from cpf_bench.evaluate import Job, evaluate, labelled_policies, run_cell
from cpf_bench.report import HEADLINE, CellResult, episodes_csv, summarize, summary_csv
from cpf_bench.verdict import COST_MARGIN, check_margin
from cpf_commands.bench import profiles, ranking, views
from cpf_commands.common.outputs import foreign_files
from cpf_commands.common.policies import PolicySpec, policy_label, refers_to_file, resolve_policy
from cpf_commands.common.ray_runtime import start_ray
from cpf_env.infra import atomic
from cpf_env.scenarios import Scenario
from cpf_env.scenarios.splits import EVALUATION_SEED

__all__ = [
    "BASE_SEED",
    "DEFAULT_REFERENCE",
    "OUTPUT_FILES",
    "default_policies",
    "reference_label",
    "run_bench",
    "write_outputs",
]

#: The rliable-style figures (``cpf_commands.bench.profiles``).
PROFILE_FIGURES = ("performance_profile.png", "probability_of_improvement.png")
#: The files cpf-bench writes to --out (nothing else may be there: it is replaced whole).
OUTPUT_FILES = frozenset(
    (
        "episodes.csv",
        "summary.csv",
        "summary.md",
        "report.html",
        *(f"{metric}.png" for metric, _ in HEADLINE),
        *PROFILE_FIGURES,
    )
)
#: First evaluation seed (training refuses seeds from here on: ``cpf_env.scenarios.splits``).
BASE_SEED = EVALUATION_SEED
#: The reference policy when none is given and it runs.
DEFAULT_REFERENCE = "nn_dsc"


def default_policies(track: str = "core") -> list[str]:
    """``cpf-bench``'s default policy set: every deployable baseline and the headroom bound.

    The headroom bound (``baselines.HEADROOM_REFERENCE``, ``oracle``, privileged,
    not deployable) is what the normalized score is measured against. On the
    hard track the designs for hulls without sway (``baselines.UNDERACTUATED``),
    under the navigation filter (``baselines.FILTERED``) and under the
    separation's safety filter (``baselines.SAFE``, which run where the
    messages carry its broadcast) join: they are the analytic answer to its
    hulls, its sensors and its crossings.
    """
    from baselines import FILTERED, HEADROOM_REFERENCE, POLICIES, SAFE, UNDERACTUATED

    hard = [*UNDERACTUATED, *FILTERED, *SAFE] if track == "hard" else []
    return [*POLICIES, *hard, HEADROOM_REFERENCE]


def write_outputs(
    cells: Sequence[CellResult],
    out: str | Path,
    command: str,
    reference: str = "nn_dsc",
    skipped: Mapping[tuple[str, str], str] | None = None,
    figures: bool = True,
    cost_margin: float = COST_MARGIN,
) -> list[dict[str, object]]:
    """Write episodes.csv, summary.csv, summary.md, report.html and the PNG figures to ``out``.

    report.html holds the ranked tables (``ranking``) and every figure inline.

    The folder is built beside ``out`` and replaces it whole (``cpf_env.infra.atomic``):
    a run killed while writing leaves the previous results.

    Args:
        cells: The results.
        out: Output folder (created or replaced; it must hold only cpf-bench outputs).
        command: The command line recorded in summary.md.
        reference: The policy scores are relative to.
        skipped: (policy, scenario) -> why it was not run, listed in summary.md.
        figures: Write the PNG figures (and put them in report.html).
        cost_margin: The verdict's practical-equivalence margin of the cost, a
            fraction of the reference's mean cost.

    Returns:
        The summary rows.
    """
    directory = Path(out)
    others = foreign_files(directory, OUTPUT_FILES)
    if others:
        raise ValueError(f"{directory} holds files cpf-bench did not write: {others[:5]}.")
    rows = summarize(cells, reference)
    pictures = _figures(rows, cells, reference) if figures else {}
    page = ranking.html_report(
        ranking.ranked_tables(rows, cells, reference, cost_margin),
        ranking.legend(reference, cost_margin),
        command,
        views.regression_lines(cells, reference, cost_margin),
        pictures,
    )
    with atomic.staged_folder(directory) as staging:  # all files or none, no stale figure
        atomic.write_text(staging / "episodes.csv", episodes_csv(cells))
        atomic.write_text(staging / "summary.csv", summary_csv(rows))
        text = views.markdown(rows, cells, command, reference, skipped or {}, cost_margin)
        atomic.write_text(staging / "summary.md", text)
        atomic.write_text(staging / "report.html", page)
        for name, data in pictures.items():
            atomic.write_bytes(staging / name, data)
    return rows


def _figures(
    rows: list[dict[str, object]], cells: Sequence[CellResult], reference: str
) -> dict[str, bytes]:
    """File name -> PNG bytes of every figure (no time stamp: the same rows, the same bytes)."""
    drawings = {
        f"{metric}.png": views.figure(rows, cells, metric, title) for metric, title in HEADLINE
    }
    scores = profiles.normalized_scores(cells, reference)
    if len(scores) > 1:  # the reference and at least one other policy on every scenario
        drawings["performance_profile.png"] = profiles.profile_figure(scores, reference)
        drawings["probability_of_improvement.png"] = profiles.improvement_figure(scores, reference)
    pictures = {}
    for name, drawing in drawings.items():
        buffer = io.BytesIO()
        drawing.savefig(buffer, format="png", dpi=100, metadata={"Software": None})
        pictures[name] = buffer.getvalue()
    return pictures


def _absolute(spec: PolicySpec) -> PolicySpec:
    """An agent folder given by a relative path made absolute (Ray workers run elsewhere)."""
    if refers_to_file(spec):
        return Path(spec).resolve()  # type: ignore[arg-type]
    return spec


def _run_on_ray(
    jobs: Sequence[Job], max_steps: int | None, address: str | None, progress: bool
) -> list[CellResult]:
    """The cells as Ray tasks (one CPU each), on local Ray or the cluster at ``address``.

    Each task builds its policy from the specification and runs the same
    ``run_cell`` as a local run, so the results are identical. A trained
    agent's folder is passed as an absolute path (relative to this process's
    working directory) and must be readable at that path on every node.
    """
    ray = start_ray(address, cpus_per_task=1, quiet=not progress)
    try:
        remote = ray.remote(num_cpus=1)(run_cell)
        futures = [
            remote.remote(label, _absolute(spec), task, seeds, max_steps, resolve_policy)
            for label, spec, task, seeds in jobs
        ]
        pending = list(futures)
        with tqdm(total=len(futures), disable=not progress, unit="cell", desc="cpf-bench") as bar:
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                bar.update(len(ready))
        try:
            return list(ray.get(futures))
        except ray.exceptions.RayTaskError as error:  # a worker's own error, not Ray's wrapper
            if isinstance(error.cause, ValueError | FileNotFoundError):
                raise error.cause from None
            raise
    finally:
        ray.shutdown()


def run_bench(
    policies: Sequence[PolicySpec] | Mapping[str, PolicySpec],
    scenarios: Sequence[str | Scenario],
    num_seeds: int = 10,
    seed: int = BASE_SEED,
    max_steps: int | None = None,
    out: str | Path | None = None,
    command: str = "",
    progress: bool = False,
    figures: bool = True,
    distribute: bool = False,
    address: str | None = None,
    reference: str | None = None,
    split: str = "test",
    cost_margin: float = COST_MARGIN,
) -> list[CellResult]:
    """Run every policy on every scenario for ``num_seeds`` paired seeds, and write the outputs.

    Args:
        policies: Policy specifications (see ``resolve_policy``), or a mapping
            label -> specification.
        scenarios: Registered scenario names or ``Scenario`` objects.
        num_seeds: Episodes per (policy, scenario) (one on a deterministic scenario).
        seed: Episode k is reset with seed ``seed + k``.
        max_steps: Horizon override (default: each scenario's ``max_steps``).
        out: Output folder; None writes nothing.
        command: The command line recorded in summary.md.
        progress: Show a progress bar (stderr).
        figures: Write the PNG figures.
        distribute: Run the (policy, scenario) cells as Ray tasks (needs the
            ``ray`` extra); the results are identical to a local run.
        address: Ray address for ``distribute`` (None: a local Ray instance).
        reference: Label of the policy every other is compared with (paired
            differences, P(beats), verdicts), one of ``policies``; None: ``nn_dsc``
            if it runs, else the first policy.
        split: ``test`` (the scenarios as named, on the evaluation seeds) or
            ``shift`` (each suite scenario's ``_shift`` variant, outside its
            training ranges; ``cpf_env.scenarios.splits``).
        cost_margin: The verdict's practical-equivalence margin of the cost, a
            fraction >= 0 of the reference's mean cost (``verdict.COST_MARGIN``).

    Returns:
        One ``CellResult`` per (policy, scenario), policies outermost. A policy
        that cannot be built for a scenario (a trained agent whose observation
        layout differs) skips it; summary.md lists what was skipped and why.

    Raises:
        ValueError: Unknown scenario or policy, a policy that fits none of the
            scenarios, fewer than one seed, a bad horizon, or ``out`` is a file.
    """
    if out is not None and Path(out).exists() and not Path(out).is_dir():
        raise ValueError(f"--out {out} is a file; give a folder (it is created if needed).")
    check_margin(cost_margin)
    labelled = labelled_policies(policies)
    reference = reference_label(reference, labelled) if labelled else ""
    if labelled and reference not in labelled:
        raise ValueError(
            f"--reference {reference} is not among the policies {sorted(labelled)}; add it to "
            "--policies or choose one of them."
        )
    evaluation = evaluate(
        labelled,
        scenarios,
        num_seeds=num_seeds,
        seed=seed,
        max_steps=max_steps,
        split=split,
        progress=progress,
        resolve=resolve_policy,
        run_cells=(lambda jobs, max_steps: _run_on_ray(jobs, max_steps, address, progress))
        if distribute
        else None,
    )
    cells, skipped = evaluation.cells, evaluation.skipped
    if out is not None:
        write_outputs(
            cells,
            out,
            command,
            reference=reference,
            skipped=skipped,
            figures=figures,
            cost_margin=cost_margin,
        )
    return cells


def reference_label(reference: str | None, labelled: Mapping[str, PolicySpec]) -> str:
    """The reference's label: as given, else nn_dsc if it runs, else the first policy."""
    if reference is not None:
        return policy_label(reference)
    return DEFAULT_REFERENCE if DEFAULT_REFERENCE in labelled else next(iter(labelled))
