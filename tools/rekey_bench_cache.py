"""Carry the bench cache's cells over a change that moves code without changing a number.

``cpf_bench.cache`` keys each planner cell on the code it comes from, so a
move or rename of that code re-keys every cell and the next ``cpf-bench``
would rerun the planners (hours on 2 cores). When the change leaves every
number as it was, this tool renames each cache file to its new key instead:

1. the key each file was stored under is recomputed by the code of
   ``--from`` (a git revision, checked out in a temporary worktree) and must
   match the key the file holds: a stale file is left alone and reported;
2. its new key is computed by this checkout's code;
3. unless ``--no-check``, one seed of each planner on each of ``--check``'s
   scenarios is run here, without the cache, and must reproduce the stored
   metrics bit for bit: the evidence that the code the key covers gives the
   same numbers;
4. the files are rewritten under their new keys (atomically), the old ones removed.

A metric added to the bench after a file was written is filled in only where
its value is fixed by construction (``fleet_metrics.unmeasured``): on a
scenario without a separation the separation term is exactly zero and the
closest approach is not measured; where a hull has a sway actuator the
course is not measured. The rerun of step 3 checks the filled values with
the stored ones. A file that lacks any other metric is left alone and
reported.

Usage::

    python tools/rekey_bench_cache.py --from 78d33ea
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cpf_bench import cache  # noqa: E402
from cpf_bench.evaluate import run_cell  # noqa: E402
from cpf_env.evaluation.fleet_metrics import METRICS, unmeasured  # noqa: E402
from cpf_env.infra import atomic  # noqa: E402
from cpf_env.scenarios import list_scenarios, make_scenario  # noqa: E402

#: Run by the old tree's interpreter: each file's (policy, scenario, steps) -> key.
_OLD_KEYS = """
import json, sys
sys.path.insert(0, sys.argv[1])
from importlib import import_module
for name in ("cpf_commands.bench.cache", "cpf_bench.cache"):  # where the cache lived, then lives
    try:
        cache = import_module(name)
        break
    except ModuleNotFoundError:
        continue
from cpf_env.scenarios import make_scenario
for module in (cache, make_scenario):
    where = sys.modules[module.__module__ if callable(module) else module.__name__].__file__
    assert where.startswith(sys.argv[1]), f"{where} is not in the old tree"
def key(policy, scenario, steps):
    try:
        task = make_scenario(scenario)
    except ValueError:  # a scenario the old tree does not have
        return None
    return cache.cell_key(policy, task, steps)
cells = json.loads(sys.stdin.read())
print(json.dumps([key(p, s, n) for p, s, n in cells]))
"""


def _cells(directory: Path) -> list[tuple[Path, dict]]:
    """Every cache file and its content."""
    return [(path, json.loads(path.read_text())) for path in sorted(directory.glob("*.json"))]


def _old_keys(revision: str, cells: list[tuple[str, str, int]]) -> list[str | None]:
    """Each cell's key under the code of ``revision`` (a temporary worktree).

    None for a scenario that revision does not register.
    """
    with tempfile.TemporaryDirectory() as scratch:
        tree = Path(scratch) / "tree"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), revision],
            check=True,
            capture_output=True,
        )
        try:
            done = subprocess.run(
                [sys.executable, "-c", _OLD_KEYS, str(tree)],
                input=json.dumps(cells),
                capture_output=True,
                text=True,
                cwd=tree,
            )
            if done.returncode != 0:
                raise SystemExit(f"the keys of {revision} could not be computed:\n{done.stderr}")
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=True
            )
    keys: list[str | None] = json.loads(done.stdout)
    return keys


def main(argv: list[str] | None = None) -> int:
    """Re-key the cache files (module docstring); 1 if a rerun does not reproduce a cell."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="revision", required=True, help="the revision of the keys")
    parser.add_argument(
        "--check",
        nargs="+",
        default=["bench_mild"],
        help="scenarios on which one seed of each planner is rerun (default: bench_mild)",
    )
    parser.add_argument("--no-check", action="store_true", help="skip the rerun")
    parser.add_argument("--dry-run", action="store_true", help="report, write nothing")
    args = parser.parse_args(argv)
    files, registered = [], set(list_scenarios())
    for path, stored in _cells(cache.CACHE_DIRECTORY):
        if stored["scenario"] in registered:
            files.append((path, stored))
        else:  # e.g. a procedural draw: its Scenario is not rebuilt from its name
            print(f"not a registered scenario, its key cannot be recomputed: {path.name}")
    cells = [(s["policy"], s["scenario"], s["steps"]) for _, s in files]
    old = _old_keys(args.revision, cells)
    plan = []
    for (path, stored), before, (policy, name, steps) in zip(files, old, cells, strict=True):
        if before is None:
            print(f"not a scenario of {args.revision}, left alone: {path.name}")
            continue
        if stored["key"] != before:
            print(f"stale (not the key of {args.revision}), left alone: {path.name}")
            continue
        task = make_scenario(name)
        missing = set(METRICS) - set(next(iter(stored["episodes"].values())))
        fixed = unmeasured(task)
        if not missing <= set(fixed):
            print(f"lacks {sorted(missing)}, which only a rerun gives, left alone: {path.name}")
            continue
        for episode in stored["episodes"].values():
            episode.update({metric: fixed[metric] for metric in sorted(missing)})
        after = cache.cell_key(policy, task, steps)
        plan.append((path, stored, after, bool(missing)))
    moved = [item[:3] for item in plan if item[1]["key"] != item[2] or item[3]]
    print(f"{len(files)} files: {len(plan)} keyed by {args.revision}, {len(moved)} re-keyed here")
    if not args.no_check:
        for path, stored, _, _ in plan:
            if stored["scenario"] not in args.check:
                continue
            seed = min(stored["episodes"], key=int)
            task = make_scenario(stored["scenario"])
            steps = stored["steps"] if stored["steps"] != task.max_steps else None
            cell = run_cell(stored["policy"], stored["policy"], task, (int(seed),), steps)
            for metric, value in stored["episodes"][seed].items():
                got = float(cell.metrics[metric][0])
                same = (math.isnan(got) and math.isnan(value)) or (
                    got == value and math.copysign(1.0, got) == math.copysign(1.0, value)
                )
                if not same:
                    print(f"{path.name} seed {seed}: {metric} {got!r} != stored {value!r}")
                    return 1
            print(f"{path.name} seed {seed}: every metric reproduced bit for bit")
    if args.dry_run:
        return 0
    for path, stored, after in moved:
        target = path.with_name(f"{stored['policy']}-{stored['scenario']}-{after[:16]}.json")
        atomic.write_text(target, json.dumps({**stored, "key": after}, indent=1) + "\n")
        if target != path:
            path.unlink()
    print(f"{len(moved)} files rewritten under their new keys (or with filled metrics)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
