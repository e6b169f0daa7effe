"""``cpf-distill``: DAgger of a local residual student from a teacher (``agents.distill.dagger``).

The run is one TOML file: its top-level keys are ``agents.TrainConfig`` fields
(the student: ``scenario``, a name, a list of names or ``"suite"``; ``base``,
``mode``, ``scale``, ``fleets``, ``net_arch``, ...) and its ``[distill]`` table
holds ``agents.distill.config.DistillConfig`` fields (``teacher``, ``rounds``,
``steps``, ``epochs``, ``batch_size``, ``learning_rate``, ``procedural``,
``redraw``, ``fit_applied``, ``label_base``), with the procedural fleets' ``ScenarioDistribution``
ranges in a ``[distill.distribution]`` table (e.g. ``v0 = [0.05, 0.5]``,
``force_scale = [0.5, 1.0]``). The student may be an MLP over K neighbour slots or, with
``encoder = "deepsets"`` (and ``shared_slot_statistics = true``), a
permutation-invariant encoder that runs on any degree; ``history = H`` gives
it its own last H inputs and actions (``agents.envs.history``).
``--seed`` sets ``TrainConfig.seed`` (the student's weights, the fleets'
seeds and the data order). ``--out`` receives an ordinary agent folder
(``agents.load_policy``, ``cpf-bench --policies DIR``) plus the run files:

- ``run.json``: the configuration, the distillation settings, the package
  versions, the torch device, the wall time, the per-round record and the
  procedural draw seeds of every round (``draws``);
- ``rounds.csv``: per DAgger round, ``round``, ``samples`` (labelled
  vessel-steps so far), ``loss`` (the student's mean squared error on them,
  or its applied-force loss with ``fit_applied``),
  ``zero_loss`` (the base's, a = 0), ``clipped`` (share of label components
  beyond the residual's reach), ``at_limit`` (share of force label components
  at an actuator limit or the residual's reach) and ``seconds`` (since the start);
- with ``--eval-num-seeds N`` (N > 0; default 0, none), ``evaluations.csv`` in
  ``cpf-train``'s columns (``agents.training.schedule.EvaluationLog``, the evaluator
  ``agents.training.evaluation.ValidationEvaluator`` on the training scenarios'
  validation seeds, N seeds each): the student before round 0 (exactly the
  base) and after each round, at the labelled vessel-steps so far, and
  ``run.json``'s ``evaluation`` (the settings, as ``cpf-train`` records
  them), so ``cpf-curves`` reads the run as it reads ``cpf-train``'s.

``--device`` (default ``cpu``; ``auto``, ``cuda``, ``cuda:N``) is where torch
fits the student; it is recorded in ``run.json``, not in the agent's
``TrainConfig`` (the folder loads on the CPU whatever fitted it).
``--log DIR`` writes the run files to DIR instead. An existing ``--out`` (or
``--log``) is refused unless ``--force``; everything is written atomically.

Example::

    cpf-distill --config studies/student/student_mpc.toml --seed 0 --out runs/student_s0
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import io
import json
import platform
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cpf_commands.common.arguments import non_negative_int
from cpf_commands.common.extras import missing_extra
from cpf_commands.hyperparameters import merge_settings, moved_keys, toml_chain
from cpf_env.infra import atomic
from cpf_env.scenarios.suite import SUITE

try:  # the learning extra; on the base install, a message instead of a traceback
    from agents.training.evaluation import ValidationEvaluator
except ModuleNotFoundError as error:
    raise SystemExit(missing_extra("cpf-distill", error)) from None

if TYPE_CHECKING:
    from agents.distill.config import DistillConfig
    from agents.training.config import TrainConfig

__all__ = ["distill_main", "read_distill_config"]

#: The run record and the per-round curve ``--out`` (or ``--log``) receives.
RUN_RECORD, ROUNDS = "run.json", "rounds.csv"
#: Columns of ``rounds.csv``.
ROUND_COLUMNS = ("round", "samples", "loss", "zero_loss", "clipped", "at_limit", "seconds")


def read_distill_config(path: str | Path, seed: int) -> tuple[TrainConfig, DistillConfig]:
    """The student's ``TrainConfig`` and the ``DistillConfig`` of a TOML file.

    Args:
        path: The file: ``TrainConfig`` keys at the top, ``DistillConfig`` keys in ``[distill]``.
        seed: ``TrainConfig.seed`` (a ``seed`` key in the file is refused: give ``--seed``).

    Raises:
        ValueError: Unreadable or invalid TOML, a missing ``[distill]`` table, an unknown
            key (the valid ones are listed), or a value the configurations refuse.
    """
    from agents.distill.config import DistillConfig
    from agents.training.config import TrainConfig

    file = Path(path)
    values: dict[str, Any] = {}
    table: Any = None
    for _, layer in toml_chain(file, "distillation"):  # [distill] merges key by key
        own = layer.pop("distill", None)
        if isinstance(own, dict) and isinstance(table, dict):
            table = {**table, **own}
        elif own is not None:
            table = own
        values = merge_settings(values, layer)
    if not isinstance(table, dict):
        raise ValueError(
            f"{file} needs a [distill] table (DistillConfig: teacher, rounds, steps, ...); "
            "the student's TrainConfig keys go above it."
        )
    if "seed" in values:
        raise ValueError(f"{file} sets seed; give it on the command line (--seed) instead.")
    known = {f.name for f in dataclasses.fields(TrainConfig)} - {"seed"}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(
            f"{file} has unknown keys {unknown}{moved_keys(unknown)}; valid keys: {sorted(known)}."
        )
    settings_known = {f.name for f in dataclasses.fields(DistillConfig)}
    unknown = sorted(set(table) - settings_known)
    if unknown:
        raise ValueError(
            f"{file} [distill] has unknown keys {unknown}; valid keys: {sorted(settings_known)}."
        )
    scenario = values.get("scenario")
    if scenario == "suite":
        values["scenario"] = tuple(SUITE)
    elif isinstance(scenario, list):
        values["scenario"] = tuple(scenario)
    if isinstance(values.get("net_arch"), list):
        values["net_arch"] = tuple(values["net_arch"])
    return TrainConfig(**values, seed=seed), DistillConfig(**table)


def _rounds_csv(rounds: Sequence[dict[str, float]]) -> str:
    """``rounds.csv`` text."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(ROUND_COLUMNS)
    for row in rounds:
        writer.writerow([row[name] for name in ROUND_COLUMNS])
    return buffer.getvalue()


def _evaluated(rows: Sequence[dict[str, float]], log: Path) -> str:
    """The line on the evaluations (none: empty)."""
    if not rows:
        return ""
    costs = ", ".join(f"{row['mean_cost']:.4g}" for row in rows)
    seconds = sum(row["evaluation_seconds"] for row in rows)
    return (
        f"validation cost before round 0 (the base) and after each round: {costs} "
        f"({seconds:.0f} s of evaluation; {log}/{'evaluations.csv'})\n"
    )


def _versions() -> dict[str, str]:
    """Versions of the packages the student depends on."""
    import numpy
    import torch

    import cpf_env

    return {
        "python": platform.python_version(),
        "cpf_env": cpf_env.__version__,
        "torch": torch.__version__,
        "numpy": numpy.__version__,
    }


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="cpf-distill",
        description="DAgger of a local residual student (the agent-folder actor on the "
        "vessel's local input) from a teacher policy of baselines (deployable or privileged), "
        "over one scenario, a mixture or the suite, optionally with procedural fleets. "
        "Writes an agent folder (cpf-bench --policies DIR) with run.json and rounds.csv.",
    )
    parser.add_argument(
        "--config", metavar="FILE.toml", required=True,
        help="TrainConfig keys at the top (scenario may be 'suite'), DistillConfig keys in a "
        "[distill] table",
    )  # fmt: skip
    parser.add_argument(
        "--seed", type=int, required=True, help="training seed (below 9000 minus the fleets)"
    )
    parser.add_argument("--out", required=True, help="the agent folder to write")
    parser.add_argument(
        "--log", metavar="DIR", default=None,
        help="write run.json and rounds.csv to DIR instead of --out",
    )  # fmt: skip
    parser.add_argument(
        "--force", action="store_true", help="replace an existing --out (and --log)"
    )
    parser.add_argument(
        "--eval-num-seeds", type=non_negative_int, default=0,
        help="evaluate the student before round 0 (the base) and after each round on the "
        "training scenarios' validation seeds, this many episodes each, into "
        "evaluations.csv (cpf-train's columns; cpf-curves reads it); 0: none",
    )  # fmt: skip
    parser.add_argument(
        "--device", default="cpu",
        help="torch device that fits the student: cpu (default), auto, cuda or cuda:N; the "
        "agent folder loads on the CPU whatever fitted it",
    )  # fmt: skip
    return parser


def distill_main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cpf-distill``."""
    parser = _parser()
    args = parser.parse_args(argv)
    out = Path(args.out)
    log = out if args.log is None else Path(args.log)
    for folder in {out, log}:
        if folder.exists() and not args.force:
            parser.error(f"{folder} exists; pass --force to replace it, or choose another --out.")
    try:
        config, settings = read_distill_config(args.config, args.seed)
        from agents.distill.config import check_distillation
        from agents.training.device import torch_device

        check_distillation(config, settings)
        torch_device(args.device)
    except ValueError as error:
        parser.error(str(error))
    import torch

    from agents.distill.dagger import distill

    if config.torch_threads is not None:
        torch.set_num_threads(config.torch_threads)
    from agents.training.schedule import EVALUATIONS, evaluations_csv

    evaluate = (
        None
        if args.eval_num_seeds == 0
        else ValidationEvaluator(config.scenarios, args.eval_num_seeds)
    )
    started = time.perf_counter()
    report = distill(config, settings, out, device=args.device, evaluate=evaluate)
    record = {
        "config": config.to_json(),
        "distill": dataclasses.asdict(settings),
        "evaluation": None if evaluate is None else evaluate.settings,
        "command": ["cpf-distill", *(sys.argv[1:] if argv is None else argv)],
        "versions": _versions(),
        "device": report.device,
        "wall_clock_seconds": round(time.perf_counter() - started, 1),
        "samples": report.samples,
        "clipped": report.clipped,
        "at_limit": report.at_limit,
        "rounds": list(report.rounds),
        "draws": [list(seeds) for seeds in report.draws],
    }
    files = {RUN_RECORD: json.dumps(record, indent=2) + "\n", ROUNDS: _rounds_csv(report.rounds)}
    if report.evaluations:
        files[EVALUATIONS] = evaluations_csv(list(report.evaluations))
    if log == out:
        for name, text in files.items():
            atomic.write_text(out / name, text)
    else:
        with atomic.staged_folder(log) as staging:
            for name, text in files.items():
                atomic.write_text(staging / name, text)
    print(
        f"distilled {settings.teacher} into a {config.residual.mode} residual on "
        f"{config.base_policy} over "
        f"{' + '.join(config.scenarios)}"
        f"{f' + {settings.procedural} procedural fleets' if settings.procedural else ''}"
        f"{' (redrawn every round)' if settings.redraw else ''}: "
        f"{report.samples:,} samples, loss {report.losses[-1]:.4g} (base {report.zero_loss:.4g}), "
        f"{report.clipped:.1%} of label components clipped, {report.at_limit:.1%} of force "
        f"labels at a limit, {record['wall_clock_seconds']} s; "
        f"saved to {out}/\n"
        f"{_evaluated(report.evaluations, log)}"
        f"evaluate: cpf-bench --policies {config.base_policy} {settings.teacher} {out} "
        "--split test"
    )
    return 0


if __name__ == "__main__":
    sys.exit(distill_main())
