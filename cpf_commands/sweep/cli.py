"""``cpf-sweep``: train agents over scenarios x seeds x settings with Ray Tune.

Every trial runs ``cpf-train``'s training function on its own batched
simulator (``--set fleets=...`` fleets per trial, so Ray's per-trial start-up
is spread over many vessels), writes an agent folder that
``agents.load_policy`` loads, and is evaluated against its base policy on
paired seeds. Ray runs on this machine by default (a local instance, nothing to
set up) or on a cluster with ``--address``. Running the same command again
resumes the sweep: finished trials are kept, unfinished and failed ones run
again. The summary (``summary.md``, ``summary.csv``) is printed at the end.

Folder layout::

    OUT/sweep.json              the sweep (grid, fixed fields, evaluation)
    OUT/trials/<trial>/         one agent: model.zip, config.json, evaluation.json, ...
    OUT/tune/run<k>/            Ray Tune's logs of the k-th run of the command
    OUT/summary.md, summary.csv

Example::

    cpf-sweep --scenarios bench_mild bench_saturation --num-seeds 2 --set timesteps=20000 \
        --out sweep
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cpf_commands.common.arguments import add_scenarios_argument, positive_int
from cpf_commands.common.ray_runtime import (
    add_address_argument,
    require_ray,
    resolve_address,
    start_ray,
)
from cpf_env.infra import atomic

if TYPE_CHECKING:  # the learning extra is imported only when a sweep runs
    from cpf_commands.sweep.spec import SweepSpec

__all__ = ["run_sweep", "sweep_main"]

#: Ray's switch between its console output engines (the older one is silent at verbose=0).
_OUTPUT_ENGINE = "RAY_AIR_NEW_OUTPUT"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="cpf-sweep",
        description="Train residual (or from-scratch) agents over scenarios x seeds x settings "
        "with Ray Tune, one batched simulator per trial, and summarize them against their "
        "base policy. Resumes when rerun with the same arguments and --out.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    add_scenarios_argument(parser, "scenarios to train on (registered names)", required=True)
    parser.add_argument(
        "--num-seeds", type=positive_int, default=3, help="training seeds per scenario and setting"
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="first training seed (seeds SEED .. SEED + N - 1)"
    )
    parser.add_argument(
        "--set",
        nargs="+",
        default=[],
        dest="settings",
        metavar="FIELD=VALUES",
        help="TrainConfig fields (cpf-train's options): FIELD=VALUE fixes one, FIELD=V1,V2 "
        "sweeps it, FIELD=[JSON list] for values with commas; e.g. timesteps=200000 "
        "fleets=64 residual.scale=0.1,0.2",
    )
    parser.add_argument("--out", required=True, help="sweep folder (resumed if it exists)")
    add_address_argument(parser)
    parser.add_argument(
        "--cpus-per-trial",
        type=positive_int,
        default=1,
        help="CPUs each trial reserves (torch threads)",
    )
    parser.add_argument(
        "--max-concurrent",
        type=positive_int,
        default=None,
        help="trials at once (None: as many as the CPUs allow)",
    )
    parser.add_argument(
        "--eval-num-seeds",
        type=int,
        default=5,
        help="paired evaluation episodes per trial (0: none)",
    )
    parser.add_argument(
        "--eval-max-steps",
        type=positive_int,
        default=None,
        help="evaluation horizon in control steps (None: the scenario's max_steps)",
    )
    parser.add_argument("--quiet", action="store_true", help="no Ray Tune status tables")
    return parser


def _usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _tuner(
    tune: Any, spec: SweepSpec, folder: Path, max_concurrent: int | None, quiet: bool
) -> Any:
    """A Tune experiment over every trial, logged to ``folder/tune/run<k>`` (the k-th run).

    Resuming is the trials' own business (``run_trial`` reports a finished
    trial again without retraining it), not Tune's restore: a trial whose
    folder was removed, or holds an agent trained with another configuration,
    runs again.
    """
    from cpf_commands.sweep.spec import trial_name
    from cpf_commands.sweep.trial import run_trial

    trainable = tune.with_resources(
        tune.with_parameters(run_trial, spec=spec, out=str(folder)),
        {"cpu": spec.cpus_per_trial},
    )
    runs = folder / "tune"
    numbers = [int(path.name[3:]) for path in runs.glob("run*") if path.name[3:].isdigit()]
    run = 1 + max(numbers, default=0)
    return tune.Tuner(
        trainable,
        param_space=spec.param_space(tune),
        tune_config=tune.TuneConfig(
            max_concurrent_trials=max_concurrent,
            reuse_actors=True,
            trial_name_creator=lambda trial: trial_name(trial.config, spec),
            trial_dirname_creator=lambda trial: trial_name(trial.config, spec),
        ),
        run_config=tune.RunConfig(
            name=f"run{run}", storage_path=str(runs), verbose=0 if quiet else 1
        ),
    )


def _run_trials(
    spec: SweepSpec, folder: Path, address: str, max_concurrent: int | None, quiet: bool
) -> dict[str, str]:
    """Run the sweep's unfinished trials on Ray; trial name -> why it failed."""
    from cpf_commands.sweep.report import EVALUATION_FILE
    from cpf_commands.sweep.spec import trial_name

    if address == "local":  # workers share this machine's kernel cache: fill it once, here
        from cpf_env.sim.precompile import precompile

        if not quiet:
            print(
                "cpf-sweep: loading the simulator's kernels (compiling them takes about a "
                "minute the first time on a machine)...",
                flush=True,
            )
        precompile(spec.scenarios)
    ray = start_ray(address, spec.cpus_per_trial, quiet=quiet)
    output = os.environ.get(_OUTPUT_ENGINE)
    if quiet:  # Tune's newer console output prints its banners even at verbose=0
        os.environ[_OUTPUT_ENGINE] = "0"
    try:
        from ray import tune

        spec.save(folder)
        for name in ("summary.md", "summary.csv"):  # never left behind by an aborted run
            (folder / name).unlink(missing_ok=True)
        grid = _tuner(tune, spec, folder, max_concurrent, quiet).fit()
    except KeyboardInterrupt:  # with Ray Client, Tune's own Ctrl-C handling is on the cluster
        print("cpf-sweep: interrupted; rerun the same command to resume.", file=sys.stderr)
        return {}
    finally:
        ray.shutdown()
        if output is None:
            os.environ.pop(_OUTPUT_ENGINE, None)
        else:
            os.environ[_OUTPUT_ENGINE] = output
    results = {
        trial_name(result.config, spec): result
        for result in (grid[k] for k in range(len(grid)))
        if result.config is not None
    }
    errors = {
        name: (str(result.error).strip().splitlines() or ["unknown error"])[-1]
        for name, result in results.items()
        if result.error is not None
    }
    for name, result in results.items():  # finished on a node, its folder not seen here
        reported = (result.metrics or {}).get("trial") == name  # its final report
        if reported and not (folder / "trials" / name / EVALUATION_FILE).exists():
            errors[name] = (
                f"it finished, but its folder is not (yet) visible at {folder} on this "
                "machine: give --out a path that this machine and every node share (on a "
                "slow network file system, rerun the command to pick it up)"
            )
    return errors


def run_sweep(
    spec: SweepSpec,
    out: str | Path,
    address: str | None = None,
    max_concurrent: int | None = None,
    command: str = "",
    quiet: bool = False,
) -> list[dict[str, Any]]:
    """Run (or resume) a sweep and write its summary.

    A resumed sweep whose trials have all finished writes its summary again
    without starting Ray.

    Args:
        spec: The ``SweepSpec`` (it also says how many CPUs each trial reserves).
        out: The sweep's folder; on a cluster, a path every node and this
            machine see (shared storage).
        address: Ray address; None starts a local Ray instance (or joins the
            cluster ``RAY_ADDRESS`` names).
        max_concurrent: Trials at once (None: as many as the CPUs allow).
        command: The command line recorded in summary.md.
        quiet: No progress lines, no Ray Tune status output.

    Returns:
        The summary rows, one per trial (``status`` "done", "error: ...",
        "stale: ..." or "not finished").

    Raises:
        ValueError: ``out`` is a file, a symbolic link, not writable, holds a
            different sweep or is being written by another cpf-sweep (its lock,
            ``.NAME.lock`` beside it, is held for the whole command); a
            malformed address; more CPUs per trial than this machine has (local Ray).
        ImportError: Ray is not installed.
        ConnectionError: No Ray cluster answers at ``address``.
    """
    atomic.check_writable(out)  # before resolving: never through a link
    folder = Path(out).resolve()
    try:
        lock = atomic.FolderLock(folder, "another cpf-sweep")
        lock.acquire()
    except atomic.FolderLockedError as error:
        raise ValueError(str(error)) from None
    try:
        return _run_sweep(spec, folder, address, max_concurrent, command, quiet)
    finally:
        lock.release()


def _run_sweep(
    spec: SweepSpec,
    folder: Path,
    address: str | None,
    max_concurrent: int | None,
    command: str,
    quiet: bool,
) -> list[dict[str, Any]]:
    """``run_sweep`` in its locked folder."""
    from cpf_commands.sweep.report import summary_csv, summary_markdown, summary_rows

    errors: dict[str, str] = {}
    total, done = len(list(spec.trials())), 0
    if spec.check_folder(folder):
        done = sum(row["status"] == "done" for row in summary_rows(spec, folder, errors))
        if not quiet:
            print(f"cpf-sweep: resuming {folder}: {done} of {total} trials finished, kept")
    if done < total:
        require_ray()  # before a minute of compiling, not after
        address = resolve_address(address)
        cpus = _usable_cpus()
        if address == "local" and spec.cpus_per_trial > cpus:
            raise ValueError(
                f"--cpus-per-trial {spec.cpus_per_trial} is more than the {cpus} CPUs this "
                f"process may use: no trial could start. Lower it to at most {cpus}, or run "
                "on a cluster with larger nodes (--address)."
            )
        errors = _run_trials(spec, folder, address, max_concurrent, quiet)
    rows = summary_rows(spec, folder, errors)
    atomic.write_text(folder / "summary.md", summary_markdown(spec, rows, command))
    atomic.write_text(folder / "summary.csv", summary_csv(rows))
    return rows


def sweep_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-sweep``: see ``cpf-sweep --help``."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:  # the trials train with Stable-Baselines3; Ray itself is checked after the arguments
        import stable_baselines3  # noqa: F401

        from cpf_commands.sweep.spec import SweepSpec
    except ImportError as error:
        parser.error(
            f"cpf-sweep trains agents, which needs {error.name} (not installed); install "
            'the learning and Ray extras: pip install -e ".[rl,ray]".'
        )
    try:
        spec = SweepSpec.from_settings(
            args.scenarios,
            range(args.seed, args.seed + args.num_seeds),
            args.settings,
            eval_num_seeds=args.eval_num_seeds,
            eval_max_steps=args.eval_max_steps,
            cpus_per_trial=args.cpus_per_trial,
        )
    except ValueError as error:
        parser.error(str(error))
    command = shlex.join(["cpf-sweep", *(sys.argv[1:] if argv is None else argv)])
    try:
        rows = run_sweep(
            spec,
            args.out,
            address=args.address,
            max_concurrent=args.max_concurrent,
            command=command,
            quiet=args.quiet,
        )
    except (ValueError, ImportError, ConnectionError) as error:
        parser.error(str(error))
    print((Path(args.out) / "summary.md").read_text())
    failed = sum(1 for row in rows if row["status"] != "done")
    print(f"cpf-sweep: {len(rows) - failed}/{len(rows)} trials done; results in {args.out}/")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(sweep_main())
