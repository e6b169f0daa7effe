"""Break the code on purpose, one change at a time, and report which tests catch each break.

Every entry of ``BREAKS`` is one deliberate bug: a file, a text that must
occur exactly once in it, and its replacement. For each entry this command
copies the repository (with its numba caches, as a developer's checkout has
them) to a temporary folder, applies the edit there, runs the default test
suite in the copy and lists the tests that fail. A break that no test
catches is reported as such, and the command then exits with status 1.

The repository itself is never modified. A new entry is one line.

Usage::

    python tools/breaks.py                    # every break, full default suite each
    python tools/breaks.py --targeted         # each break's listed test files only (fast)
    python tools/breaks.py --only residual-sign --only aux-off
    python tools/breaks.py --list

Run it from a virtualenv with the package installed (``CONTRIBUTING.md``);
the copy comes first on ``PYTHONPATH``, so the tests and the commands they
start import the broken copy. One full-suite run per break: about 3-5 min
each on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Break:
    """One deliberate bug.

    Attributes:
        name: Short identifier (``--only``).
        path: File to edit, relative to the repository root.
        old: Text that must occur exactly once in ``path``.
        new: Its replacement.
        targets: Test files expected to catch it (``--targeted`` runs only these).
        warm_cache: Fill numba's cache in the copy before breaking it, so that a
            stale cached kernel would hide the break.
    """

    name: str
    path: str
    old: str
    new: str
    targets: tuple[str, ...]
    warm_cache: bool = False


REPRODUCE_TESTS = "tests/cpf_commands/run/test_reproduce.py"
CLAIMS_TESTS = "tests/cpf_commands/run/test_claims.py"

# fmt: off
BREAKS: tuple[Break, ...] = (
    Break("bench-path-error-max-doubled", "cpf_env/evaluation/fleet_metrics.py", 'put("path_error_max", path_error.max(axis=2))', 'put("path_error_max", 2.0 * path_error.max(axis=2))', ("tests/cpf_env/evaluation/test_fleet_metrics.py",)),  # noqa: E501
    Break("bench-spread-halved", "cpf_env/evaluation/fleet_metrics.py", 'put("spread", r["theta"].max(axis=2) - r["theta"].min(axis=2))', 'put("spread", 0.5 * (r["theta"].max(axis=2) - r["theta"].min(axis=2)))', ("tests/cpf_env/evaluation/test_fleet_metrics.py",)),  # noqa: E501
    Break("privileged-f-sign", "baselines/kernels.py", "hydrodynamic = known.lumped[r, i, row]", "hydrodynamic = -known.lumped[r, i, row]", ("tests/baselines/test_privileged.py",)),  # noqa: E501
    Break("privileged-stale-links", "cpf_env/evaluation/privileged.py", "out[i, base + SLOT_AGE] = 0.0", "pass", ("tests/baselines/test_privileged.py",)),  # noqa: E501
    Break("equivalence-margin-either-end", "cpf_bench/verdict.py", "if -band < cost[1] and cost[2] < band:", "if -band < cost[1] or cost[2] < band:", ("tests/cpf_bench/test_verdict.py",)),  # noqa: E501
    Break("gap-closed-inverted", "cpf_bench/stats.py", "return float((y.mean() - x.mean()) / gap), low, high", "return float(gap / (y.mean() - x.mean())), low, high", ("tests/cpf_bench/test_stats.py",)),  # noqa: E501
    Break("residual-sign", "cpf_env/envs/residual.py", "shown[..., self.layout.z1] -= offset[index]", "shown[..., self.layout.z1] += offset[index]", ("tests/cpf_env/envs/test_residual.py",)),  # noqa: E501
    Break("observation-views", "cpf_env/envs/parallel.py", "dict(zip(self.possible_agents, inputs[0].copy(),", "dict(zip(self.possible_agents, inputs[0],", ("tests/cpf_env/envs/test_no_aliasing.py",)),  # noqa: E501
    Break("info-views", "cpf_env/envs/core.py", '"eta": a.eta[rows].copy(),', '"eta": a.eta[rows],', ("tests/cpf_env/envs/test_no_aliasing.py", "tests/cpf_env/envs/test_env.py")),  # noqa: E501
    Break("nonfinite-action-stepped", "cpf_env/sim/kernels.py", "if not math.isfinite(actions[b, i, k]):", "if math.isnan(actions[b, i, k]):", ("tests/cpf_env/sim/test_sim.py",)),  # noqa: E501
    Break("vector-env-views", "cpf_env/envs/gym_envs.py", "obs = self.core.inputs.reshape(self.num_envs, -1).copy()", "obs = self.core.inputs.reshape(self.num_envs, -1)", ("tests/cpf_env/envs/test_no_aliasing.py",)),  # noqa: E501
    Break("vec-env-views", "agents/envs/vec_env.py", "return self.core.inputs.reshape(self.num_envs, -1).copy()", "return self.core.inputs.reshape(self.num_envs, -1)", ("tests/agents/test_vec_env.py",)),  # noqa: E501
    Break("critic-terminal-after-reset", "agents/envs/vec_env.py", "terminal = np.concatenate([terminal, unobserved], axis=-1)", "terminal = np.concatenate([terminal, unobserved_state(self.sim, fleets)], axis=-1)", ("tests/agents/test_asymmetric_critic.py",)),  # noqa: E501
    Break("folder-keeps-critic-columns", "agents/training/run_folder.py", "unobserved = list(unobserved_columns(self.model))", "unobserved = []", ("tests/agents/test_asymmetric_critic.py",)),  # noqa: E501
    Break("thresholds-loosened", "cpf_commands/run/reproduce.py", "SPEED_TOLERANCE = 0.01, 0.01, 1e-4", "SPEED_TOLERANCE = 0.1, 1.0, 0.1", (CLAIMS_TESTS, REPRODUCE_TESTS)),  # noqa: E501
    Break("command-bound-loosened", "cpf_commands/run/reproduce.py", "COMMAND_BOUND = 25.0", "COMMAND_BOUND = 2500.0", (CLAIMS_TESTS, REPRODUCE_TESTS)),  # noqa: E501
    Break("claim4-reads-applied", "cpf_commands/run/reproduce.py", "command = np.abs(trajectory.tau_command[:, vessel])", "command = np.abs(trajectory.tau_applied[:, vessel])", (CLAIMS_TESTS, REPRODUCE_TESTS)),  # noqa: E501
    Break("nn-halved", "baselines/kernels.py", "out.nn_output[r, i, q] = total", "out.nn_output[r, i, q] = 0.5 * total", (REPRODUCE_TESTS,)),  # noqa: E501
    Break("aux-off", "baselines/nn_dsc.py", "use_aux: ClassVar[bool] = True", "use_aux: ClassVar[bool] = False", ("tests/baselines/test_nn_dsc.py",)),  # noqa: E501
    Break("reward-scale-not-squared", "cpf_env/sim/reward.py", "error_squared / (scale * scale)", "error_squared / scale", ("tests/cpf_env/sim/test_reward.py", "tests/cpf_env/envs/test_env.py"), warm_cache=True),  # noqa: E501
    Break("cache-stamp-per-file", "cpf_env/infra/kernel_cache.py", 'return ("cpf_env kernel sources", self._stamp)', "return self._inner.get_source_stamp()", ("tests/cpf_env/infra/test_kernel_cache.py",)),  # noqa: E501
    Break("bench-cache-keeps-comments", "cpf_bench/sources.py", "if token.type == tokenize.COMMENT:", "if False:", ("tests/cpf_bench/test_sources.py",)),  # noqa: E501
    Break("bench-cache-misses-local-imports", "cpf_bench/sources.py", "for node in ast.walk(tree):", "for node in tree.body:", ("tests/cpf_bench/test_sources.py",)),  # noqa: E501
    Break("resume-forgets-numpy-random", "agents/training/checkpoint.py", 'np.random.set_state(decode_value(state["numpy_random"], arrays))  # noqa: NPY002', "pass", ("tests/agents/test_resume.py",)),  # noqa: E501
    Break("snapshot-skips-generators", "agents/training/snapshot.py", 'current.bit_generator.state = decode_value(node["generator"], self.arrays)', "pass", ("tests/agents/test_snapshot.py", "tests/agents/test_resume.py")),  # noqa: E501
    Break("closed-loop-never-holds", "baselines/closed_loop.py", "held = hold_ended and ended[b] >= 0", "held = False", ("tests/baselines/test_closed_loop.py", "tests/cpf_bench/test_rollout.py")),  # noqa: E501
    Break("closed-loop-records-gamma", "baselines/closed_loop.py", "record_fleet(a, record, k, b, out.speed_estimate[r])", "record_fleet(a, record, k, b, out.gamma[r])", ("tests/baselines/test_closed_loop.py", "tests/cpf_bench/test_rollout.py")),  # noqa: E501
    Break("distill-applied-loss-two-sided", "agents/distill/dagger.py", "torch.minimum(output, high)", "output", ("tests/agents/test_distill.py",)),  # noqa: E501
    Break("distill-bounds-ignore-base", "agents/distill/dagger.py", "np.clip((np.asarray(tau_max) - base) / reach, -1.0, 1.0)", "np.clip(np.asarray(tau_max) / reach, -1.0, 1.0)", ("tests/agents/test_distill.py",)),  # noqa: E501
    Break("residual-yield-drops-push", "cpf_env/envs/residual.py", "force[(at_max & (force < 0.0)) | (at_min & (force > 0.0))] = 0.0", "force[at_max | at_min] = 0.0", ("tests/cpf_env/envs/test_residual.py",)),  # noqa: E501
    Break("distill-yield-bounds-kept", "agents/distill/dagger.py", "low = np.where(at_max, high, low)", "pass", ("tests/agents/test_distill.py",)),  # noqa: E501
    Break("distill-twin-labels-on-env-base", "agents/distill/dagger.py", "base = np.asarray(twin.act_batch(obs), dtype=np.float64)", "base = controller.base_actions", ("tests/agents/test_distill.py",)),  # noqa: E501
    Break("distill-twin-unseeded", "agents/distill/dagger.py", "twin.reset(seed=seeds[0])", "twin.reset()", ("tests/agents/test_distill.py",)),  # noqa: E501
    Break("distill-twin-not-restarted", "agents/distill/dagger.py", "group.twin.reset_fleets(ended)", "pass", ("tests/agents/test_distill.py",)),  # noqa: E501
    Break("worst-episode-is-the-largest", "cpf_bench/verdict.py", "return float(values[np.argmax(off_target(metric, values))])", "return float(np.max(values))", ("tests/cpf_bench/test_verdict.py",)),  # noqa: E501
    Break("progress-ahead-counts-as-better", "cpf_bench/verdict.py", "return values if target is None else np.abs(values - target)", "return values if target is None else target - values", ("tests/cpf_bench/test_verdict.py",)),  # noqa: E501
    Break("curves-mean-not-iqm", "cpf_commands/curves.py", "iqm(values, axis=1)", "values.mean(axis=1)", ("tests/cpf_commands/test_curves.py",)),  # noqa: E501
    Break("line-of-sight-steers-away", "baselines/mpc_kernels.py", "z1[2] + math.atan(cross / lookahead)", "z1[2] - math.atan(cross / lookahead)", ("tests/baselines/test_mpc.py",)),  # noqa: E501
    Break("shift-gives-the-hull-sway", "cpf_env/scenarios/splits.py", "base = hard.without_sway(base)", "pass", ("tests/cpf_env/scenarios/test_hard.py",)),  # noqa: E501
)
# fmt: on

#: Not copied: the virtualenv, git's data, outputs of earlier runs.
_SKIP = shutil.ignore_patterns(".venv", ".git", "outputs", "runs", ".mypy_cache", ".ruff_cache")


def _environment(copy: Path) -> dict[str, str]:
    """The environment of the runs in ``copy``: its sources first, one numba thread."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(copy), *filter(None, [env.get("PYTHONPATH")])])
    env.setdefault("NUMBA_NUM_THREADS", "1")
    return env


def _run(command: Sequence[str], copy: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        list(command), cwd=copy, env=_environment(copy), capture_output=True, text=True, check=False
    )


def apply_break(entry: Break, copy: Path) -> None:
    """Edit ``entry.path`` in ``copy``; raise ValueError unless ``old`` occurs exactly once."""
    path = copy / entry.path
    if not path.is_file():
        raise ValueError(
            f"break {entry.name!r}: {entry.path} does not exist; update the entry in "
            "tools/breaks.py to the current code."
        )
    source = path.read_text()
    count = source.count(entry.old)
    if count != 1:
        raise ValueError(
            f"break {entry.name!r}: {entry.old!r} occurs {count} times in {entry.path} "
            "(must be exactly once); update the entry in tools/breaks.py to the current code."
        )
    path.write_text(source.replace(entry.old, entry.new))


def caught_by(entry: Break, targeted: bool) -> tuple[list[str], str]:
    """Apply ``entry`` in a fresh copy, run the tests; return (failing test ids, summary line)."""
    with tempfile.TemporaryDirectory(prefix=f"break-{entry.name}-") as folder:
        copy = Path(folder) / "repo"
        shutil.copytree(ROOT, copy, ignore=_SKIP)
        where = _run([sys.executable, "-c", "import cpf_env; print(cpf_env.__file__)"], copy)
        if not where.stdout.strip().startswith(str(copy)):
            raise RuntimeError(f"the copy does not come first on sys.path: {where.stdout}")
        if entry.warm_cache:
            warm = "from cpf_env.sim.precompile import precompile; precompile(['wang2014'])"
            _run([sys.executable, "-c", warm], copy)
        apply_break(entry, copy)
        command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rf"]
        result = _run([*command, *(entry.targets if targeted else ())], copy)
    failed = sorted(set(re.findall(r"^(?:FAILED|ERROR) (\S+)", result.stdout, re.MULTILINE)))
    lines = [line for line in result.stdout.splitlines() if line.strip()]
    return failed, lines[-1] if lines else result.stderr.strip()[-300:]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the breaks; print, per break, the tests that catch it. Exit 1 if one is not caught."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--targeted", action="store_true", help="run each break's test files only")
    parser.add_argument("--only", action="append", default=[], help="a break name (repeatable)")
    parser.add_argument("--list", action="store_true", help="list the breaks and exit")
    args = parser.parse_args(argv)
    names = {entry.name for entry in BREAKS}
    unknown = sorted(set(args.only) - names)
    if unknown:
        parser.error(f"unknown break {unknown}; choose from {sorted(names)}")
    chosen = [entry for entry in BREAKS if not args.only or entry.name in args.only]
    if args.list:
        for entry in chosen:
            print(f"{entry.name}: {entry.path}: {entry.old!r} -> {entry.new!r}")
        return 0
    missed = []
    for entry in chosen:
        start = time.perf_counter()
        failed, summary = caught_by(entry, args.targeted)
        seconds = time.perf_counter() - start
        verdict = f"caught by {len(failed)} test(s)" if failed else "NOT CAUGHT"
        print(f"{entry.name} ({entry.path}): {verdict}; {summary} [{seconds:.0f} s]", flush=True)
        for test in failed:
            print(f"    {test}", flush=True)
        if not failed:
            missed.append(entry.name)
    scope = "their listed test files" if args.targeted else "the default suite"
    print(f"{len(chosen) - len(missed)} of {len(chosen)} breaks caught by {scope}.")
    return 1 if missed else 0


if __name__ == "__main__":
    raise SystemExit(main())
