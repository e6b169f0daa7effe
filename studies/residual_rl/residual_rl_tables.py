"""Print docs/results.md's two residual-RL tables from the committed evaluation files.

Reads ``runs/residual_rl/<scenario>_training_reward/episodes.csv`` (1.5 M
steps) and ``runs/residual_rl_5m/...`` (5 M steps): 20 evaluation episodes
per trained agent and per analytic policy, on the same seeds. Per agent kind,
each cell is the range over its training seeds (``_s0``, ``_s1``, ``_s2``) of
a mean over the 20 episodes:

- cost / nn_dsc: mean episodic cost (log reward) over nn_dsc's mean, same folder;
- P(cost < nn_dsc): fraction of evaluation seeds on which the agent's cost is lower;
- path error RMS (m), last quarter; coordination error at the end;
- failures: episodes that left the path, summed over the training seeds.

Usage::

    python studies/residual_rl/residual_rl_tables.py [--results results]
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

#: (results folder, policy name without ``_<scenario>_s<seed>``, row label); per scenario.
ROWS = {
    "bench_lossy_links": (
        ("residual_rl", "nn_dsc", "`nn_dsc`"),
        ("residual_rl", "backstepping", "`backstepping`"),
        ("residual_rl", "residual_ppo", "residual PPO, forces, 1.5 M steps"),
        ("residual_rl_5m", "residual_ppo", "residual PPO, forces, 5 M steps"),
        ("residual_rl", "residual_ppo_rate", "residual PPO, forces and path-variable rate, 1.5 M"),
        ("residual_rl", "scratch_ppo", "PPO from scratch, 1.5 M"),
    ),
    "bench_saturation": (
        ("residual_rl", "nn_dsc", "`nn_dsc`"),
        ("residual_rl", "backstepping", "`backstepping`"),
        ("residual_rl", "residual_ppo", "residual PPO, forces, 1.5 M steps"),
        ("residual_rl_5m", "residual_ppo", "residual PPO, forces, 5 M steps"),
        ("residual_rl", "scratch_ppo", "PPO from scratch, 1.5 M"),
    ),
}
HEADER = (
    "| policy | cost / nn_dsc | P(cost < nn_dsc) | path error RMS (m) "
    "| coordination error at the end | failures |\n|---|---|---|---|---|---|"
)


def read_episodes(path: Path) -> dict[str, dict[int, dict[str, float]]]:
    """Episodes by policy, then evaluation seed: cost, path RMS (window), coordination, failed."""
    episodes: dict[str, dict[int, dict[str, float]]] = defaultdict(dict)
    with path.open(newline="") as handle:
        for row in csv.DictReader(handle):
            episodes[row["policy"]][int(row["seed"])] = {
                "cost": float(row["cost"]),
                "path": float(row["path_error_rms_window"]),
                "coordination": float(row["coordination_error_end"]),
                "failed": float(row["terminated"]),
            }
    return episodes


def _span(values: Sequence[float], form: Callable[[float], str]) -> str:
    """``a-b`` over the training seeds, or one number if they print the same."""
    low, high = form(min(values)), form(max(values))
    return low if low == high else f"{low}-{high}"


def row(episodes: dict[str, dict[int, dict[str, float]]], kind: str, scenario: str) -> list[str]:
    """The cells of one table row for a policy kind (an analytic policy or an agent kind)."""
    reference = episodes["nn_dsc"]
    reference_cost = float(np.mean([e["cost"] for e in reference.values()]))
    if kind in ("nn_dsc", "backstepping"):
        runs = [episodes[kind]]
    else:
        prefix = f"{kind}_{scenario}_s"
        names = sorted(n for n in episodes if n.startswith(prefix) and n[len(prefix) :].isdigit())
        runs = [episodes[name] for name in names]
    ratios, beats, paths, coordination, failed, total = [], [], [], [], 0, 0
    for run in runs:
        seeds = sorted(run)
        if seeds != sorted(reference):
            raise ValueError(f"{kind} on {scenario} was not evaluated on nn_dsc's seeds.")
        ratios.append(np.mean([run[s]["cost"] for s in seeds]) / reference_cost)
        beats.append(np.mean([run[s]["cost"] < reference[s]["cost"] for s in seeds]))
        paths.append(np.mean([run[s]["path"] for s in seeds]))
        coordination.append(np.mean([run[s]["coordination"] for s in seeds]))
        failed += int(sum(run[s]["failed"] for s in seeds))
        total += len(seeds)
    if kind == "nn_dsc":
        ratio, beat = f"1 ({reference_cost:.0f})", "-"
    else:
        ratio, beat = _span(ratios, lambda x: f"{x:.2f}"), _span(beats, lambda x: f"{x:.2f}")
    return [
        ratio,
        beat,
        _span(paths, lambda x: f"{x:.3g}"),
        _span(coordination, lambda x: f"{x:.2g}"),
        f"{failed}/{total}",
    ]


def tables(results: Path) -> str:
    """Both tables, markdown, one per scenario."""
    blocks = []
    for scenario, rows in ROWS.items():
        lines = [f"`{scenario}`:", "", HEADER]
        for folder, kind, label in rows:
            episodes = read_episodes(
                results / folder / f"{scenario}_training_reward" / "episodes.csv"
            )
            lines.append(f"| {label} | " + " | ".join(row(episodes, kind, scenario)) + " |")
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks)


def main(argv: Sequence[str] | None = None) -> str:
    """Print the tables; return them."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--results", type=Path, default=Path(__file__).parent.parent / "results")
    text = tables(parser.parse_args(argv).results)
    print(text)
    return text


if __name__ == "__main__":
    main()
