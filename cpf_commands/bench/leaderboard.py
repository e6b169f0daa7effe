"""Regenerate the leaderboard: ``python -m cpf_commands.bench.leaderboard [--track hard]``.

Runs cpf-bench's default policies of the track (every deployable baseline
and the headroom bound ``oracle``) and the track's reference agents of
``results/agents/`` (``TRACKS``: on the core suite ``AGENTS``, one per
learning method and the encoder student that runs on fleets of any degree;
on the hard track ``HARD_AGENTS``, one per learning method) on the track's
``test`` split (20 seeds) and ``shift`` split (10 seeds) with
``run_bench``, and writes

* both results folders (``results/bench_test/`` and ``bench_shift/``, or
  ``hard_test/`` and ``hard_shift/``);
* the marl-eval JSON of every episode of both splits (``leaderboard.json``,
  ``leaderboard_hard.json``; ``cpf_commands.bench.marl_eval``; the shift
  split's tasks are the ``*_shift`` scenarios);
* the text between the track's markers in ``docs/results.md``
  (``<!-- bench:begin -->``, ``<!-- hard:begin -->`` and their ends):
  tables built from those runs, the machine's core count and load, and the
  wall time. The hard track's tables judge each agent against the best
  deployable design of each scenario, the target a learner must pass there.

Every file is written atomically.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import shlex
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from statistics import NormalDist

import numpy as np

from cpf_bench.headroom import headroom_rows, headroom_table, room_table
from cpf_bench.report import CellResult, summarize
from cpf_bench.verdict import verdict, verdicts
from cpf_commands.bench.marl_eval import write_marl_eval
from cpf_commands.bench.run import default_policies, run_bench
from cpf_commands.bench.views import display_name, gap_table, markdown_table
from cpf_env.infra import atomic
from cpf_env.scenarios.suite import list_suite

__all__ = [
    "AGENTS",
    "HARD_AGENTS",
    "HARD_METHODS",
    "LEADERBOARD_JSON",
    "PAGE",
    "TRACKS",
    "Track",
    "main",
]

#: The reference agents (folder -> the label the tables give it), one per learning method;
#: results/README.md has the command that trained each.
AGENTS = {
    "results/agents/residual_ppo_s0": "residual PPO, lossy links",
    "results/agents/suite_residual_ppo_s0": "residual PPO, whole suite",
    "results/agents/student_s0": "student distilled from the oracle",
    "results/agents/student_deepsets_s0": "student with a neighbour encoder, any degree",
    "results/agents/mappo_s0": "residual MAPPO, lossy links",
}
#: The hard track's reference agents: one per learning method on ``hard_sensing``, the learned
#: filter (``agents.estimation``) also on the two other sensing scenarios with room, and
#: residual MAPPO on the two crossing scenarios (learned messages on ``hard_crossing``), each
#: with one budget of vessel-steps; results/README.md has the command that trained each.
HARD_AGENTS = {
    "results/agents/hard_sensing_ppo_scratch_s0": "PPO from scratch, hard_sensing",
    "results/agents/hard_sensing_ppo_residual_s0": "residual PPO on mpc_tuned_ekf, hard_sensing",
    "results/agents/hard_sensing_student_s0": "student of the oracle, hard_sensing",
    "results/agents/hard_sensing_mappo_s0": "residual MAPPO on mpc_tuned_ekf, hard_sensing",
    "results/agents/hard_sensing_learned_filter_s0": (
        "learned filter on mpc_tuned_mmae, hard_sensing"
    ),
    "results/agents/hard_sensing_waves_learned_filter_s0": (
        "learned filter on mpc_tuned_mmae, hard_sensing_waves"
    ),
    "results/agents/hard_heterogeneous_learned_filter_s0": (
        "learned filter on mpc_tuned_mmae, hard_heterogeneous"
    ),
    "results/agents/hard_crossing_mappo_messages_s0": (
        "residual MAPPO with learned messages on mpc_tuned, hard_crossing"
    ),
    "results/agents/hard_large_fleet_mappo_s0": (
        "residual MAPPO on mpc_tuned_ekf_safe, hard_large_fleet"
    ),
}
#: Each learning method of the hard track: its reference agents, each with the scenario it
#: was trained on, where the method is scored (one agent per scenario, as a user would run it).
HARD_METHODS = {
    "PPO from scratch": {"results/agents/hard_sensing_ppo_scratch_s0": "hard_sensing"},
    "residual PPO": {"results/agents/hard_sensing_ppo_residual_s0": "hard_sensing"},
    "student of the oracle": {"results/agents/hard_sensing_student_s0": "hard_sensing"},
    "residual MAPPO": {
        "results/agents/hard_sensing_mappo_s0": "hard_sensing",
        "results/agents/hard_crossing_mappo_messages_s0": "hard_crossing",
        "results/agents/hard_large_fleet_mappo_s0": "hard_large_fleet",
    },
    "learned filter": {
        "results/agents/hard_sensing_learned_filter_s0": "hard_sensing",
        "results/agents/hard_sensing_waves_learned_filter_s0": "hard_sensing_waves",
        "results/agents/hard_heterogeneous_learned_filter_s0": "hard_heterogeneous",
    },
}
#: The marl-eval JSON of both splits, under the results folder.
LEADERBOARD_JSON = "leaderboard.json"
#: The page whose section between the markers this module rewrites.
PAGE = "docs/results.md"
BEGIN, END = "<!-- bench:begin -->", "<!-- bench:end -->"
#: Physical columns of the lossy-links table: metric, heading, scale, unit.
PHYSICAL = (
    ("cost", "cost", 1.0, ""),
    ("cross_track_error_rms_window", "cross-track", 1e3, "mm"),
    ("along_track_error_rms_window", "along-track", 1e3, "mm"),
    ("heading_error_rms_window", "heading", 1e3, "mrad"),
    ("formation_error_rms_window", "formation", 1e3, "mm"),
    ("formation_error_end", "formation at end", 1e3, "mm"),
    ("speed_along_path_window", "speed along path", 1.0, "m/s"),
    ("progress", "progress", 1.0, ""),
)


#: Every reference agent's label, both tracks.
LABELS = {**AGENTS, **HARD_AGENTS}


def _label(policy: str) -> str:
    return LABELS[policy] if policy in LABELS else display_name(policy)


def _physical_table(cells: Sequence[CellResult], scenario: str) -> list[str]:
    judged = {v.policy: v.label for v in verdicts(cells, "nn_dsc") if v.scenario == scenario}
    header = ["policy"] + [f"{h} ({u})" if u else h for _, h, _, u in PHYSICAL] + ["verdict"]
    body = []
    for cell in cells:
        if cell.scenario != scenario:
            continue
        values = [f"{scale * float(np.mean(cell.metrics[m])):.3g}" for m, _, scale, _ in PHYSICAL]
        body.append([_label(cell.policy), *values, judged.get(cell.policy, "reference")])
    return markdown_table(header, body)


def _suite_table(cells: Sequence[CellResult]) -> list[str]:
    names = list(dict.fromkeys(cell.scenario for cell in cells))
    policies = list(dict.fromkeys(cell.policy for cell in cells))
    judged = {(v.policy, v.scenario): v for v in verdicts(cells, "nn_dsc")}
    costs = {(c.policy, c.scenario): float(np.mean(c.metrics["cost"])) for c in cells}
    body = []
    for policy in policies:
        row = [_label(policy)]
        for name in names:
            if (policy, name) not in costs:
                row.append("not run")
                continue
            v = judged.get((policy, name))
            row.append(f"{costs[(policy, name)]:.3g}" + (f" {v.label}" if v else ""))
        body.append(row)
    return markdown_table(["policy", *names], body)


def _power_table(cells: Sequence[CellResult], policy: str = "backstepping") -> list[str]:
    """Seeds a paired comparison needs to detect a cost difference (alpha 0.05, power 0.8).

    n = ((z_0.975 + z_0.8) sd / delta)^2, sd the measured standard deviation of
    the per-seed cost differences ``policy - nn_dsc`` and delta a fraction of
    ``nn_dsc``'s mean cost.
    """
    z = NormalDist().inv_cdf(0.975) + NormalDist().inv_cdf(0.8)
    by_key = {(c.policy, c.scenario): c for c in cells}
    body = []
    for name in dict.fromkeys(c.scenario for c in cells):
        pair = by_key.get((policy, name)), by_key.get(("nn_dsc", name))
        if pair[0] is None or pair[1] is None or len(pair[0].seeds) < 2:
            continue
        differences = pair[0].metrics["cost"] - pair[1].metrics["cost"]
        sd = float(np.std(differences, ddof=1))
        scale = float(np.mean(pair[1].metrics["cost"]))
        needed = [max(2, math.ceil((z * sd / (f * scale)) ** 2)) for f in (0.01, 0.02, 0.05)]
        body.append([name, f"{sd:.3g}", *(str(k) for k in needed)])
    header = ["scenario", f"sd of {policy} - nn_dsc cost", "seeds for 1 %", "2 %", "5 %"]
    return markdown_table(header, body)


def _labelled(lines: list[str]) -> list[str]:
    """Table lines with each agent folder replaced by its label."""
    for folder, label in LABELS.items():
        lines = [line.replace(f"| {folder} |", f"| {label} |") for line in lines]
    return lines


def _gap_lines(cells: Sequence[CellResult], metric: str) -> list[str]:
    return _labelled(gap_table(summarize(cells, "nn_dsc"), cells, metric, "nn_dsc"))


def _against_best(cells: Sequence[CellResult], agents: Sequence[str]) -> list[str]:
    """Each agent's mean cost and verdict against the best deployable design of each scenario."""
    best = {row["scenario"]: row["best"] for row in headroom_rows(cells)}
    by_key = {(c.policy, c.scenario): c for c in cells}
    names = [name for name in dict.fromkeys(c.scenario for c in cells) if name in best]
    body = []
    for agent in agents:
        row = [_label(agent)]
        for name in names:
            cell = by_key.get((agent, name))
            if cell is None:
                row.append("not run")
                continue
            base = by_key[(str(best[name]), name)]
            judged = verdict(cell, base).label
            row.append(f"{np.mean(cell.metrics['cost']):.4g} {judged}")
        body.append(row)
    header = ["agent", *(f"{name} (vs {best[name]})" for name in names)]
    return markdown_table(header, body)


def _by_method(cells: Sequence[CellResult]) -> list[CellResult]:
    """The designs' cells and, per method, its agents' cells where they trained, as the method's."""
    own = {
        (folder, scenario): method
        for method, trained in HARD_METHODS.items()
        for folder, scenario in trained.items()
    }
    kept = [cell for cell in cells if cell.policy not in HARD_AGENTS]
    kept += [
        replace(cell, policy=own[(cell.policy, cell.scenario)])
        for cell in cells
        if (cell.policy, cell.scenario) in own
    ]
    return kept


def _core_section(test: Sequence[CellResult], shift: Sequence[CellResult], note: str) -> str:
    lines = [
        "",
        note,
        "",
        "`bench_lossy_links`, `test` split (20 evaluation seeds), final-window means "
        "(whole-episode cost and progress); verdict against `nn_dsc` "
        "(`docs/benchmark.md`, section Verdict):",
        "",
        *_physical_table(test, "bench_lossy_links"),
        "",
        "Every suite scenario, `test` split: mean cost and verdict against `nn_dsc` "
        "(`equivalent`: the cost difference's 95 % interval lies within 1 % of `nn_dsc`'s "
        "mean cost):",
        "",
        *_suite_table(test),
        "",
        "Normalized score against the headroom bound `oracle` (receding-horizon control "
        "told the true model, the future disturbances, ideal links and v0; not deployable), "
        "`test` split: (nn_dsc - policy) / (nn_dsc - oracle) of the mean final-window cost, "
        "with its paired 95 % bootstrap interval (0 = `nn_dsc`, 1 = the bound; above 1 "
        "flagged):",
        "",
        *_gap_lines(test, "cost_window"),
        "",
        "The same for the whole-episode cost, which the start-up transient dominates; n/a "
        "where `oracle` is not better than `nn_dsc`:",
        "",
        *_gap_lines(test, "cost"),
        "",
        "`shift` split (conditions outside the training ranges, 10 seeds): mean cost "
        "and verdict against `nn_dsc`:",
        "",
        *_suite_table(shift),
        "",
        "How many paired seeds a cost difference needs (two-sided, 5 % level, 80 % power; "
        "n = ((1.96 + 0.84) sd / delta)^2 from the measured spread of the per-seed "
        "differences between two analytic controllers, `test` split; delta as a fraction "
        "of `nn_dsc`'s mean cost):",
        "",
        *_power_table(test),
        "",
    ]
    return "\n".join(lines)


def _hard_section(test: Sequence[CellResult], shift: Sequence[CellResult], note: str) -> str:
    agents = list(HARD_AGENTS)
    lines = [
        "",
        note,
        "",
        "`test` split (20 evaluation seeds): the room each scenario leaves, 1 - J oracle / "
        "J best, with its 95 % paired interval:",
        "",
        *headroom_table(test),
        "",
        "Each agent against the best deployable design of each scenario, `test` split: mean "
        "cost and verdict (`beats` needs the whole cost interval below zero and no guarded "
        "physical regression; `not run`: the agent cannot act there, its network's inputs "
        "do not fit the fleet or, for a learned filter, the vessels observe their true state; "
        "`summary.md` says why):",
        "",
        *_against_best(test, agents),
        "",
        "The share of each room an agent closes, (J best - J) / (J best - J oracle), "
        "`test` split (0: the best deployable design, 1: the bound):",
        "",
        *_labelled(room_table(test)),
        "",
        "The same per method, each agent on the scenario it was trained on (IQM over "
        "those scenarios' episodes; the method's agents: results/README.md):",
        "",
        *room_table(_by_method(test)),
        "",
        "The same against the best deployable design, `shift` split (10 seeds):",
        "",
        *_against_best(shift, agents),
        "",
        "Every policy, `test` split: mean cost and verdict against `nn_dsc`:",
        "",
        *_suite_table(test),
        "",
        "`shift` split: mean cost and verdict against `nn_dsc`:",
        "",
        *_suite_table(shift),
        "",
    ]
    return "\n".join(lines)


@dataclass(frozen=True)
class Track:
    """What the leaderboard of one track runs and writes.

    Attributes:
        agents: The reference agents (folder -> label).
        prefix: The results folders' prefix (``<prefix>_test``, ``<prefix>_shift``).
        json: The marl-eval JSON's file name, under the results folder.
        markers: The page's begin and end markers of the track's section.
        section: Builds the section's text from the test cells, the shift cells and the note.
    """

    agents: dict[str, str]
    prefix: str
    json: str
    markers: tuple[str, str]
    section: Callable[[Sequence[CellResult], Sequence[CellResult], str], str]


#: The tracks: the core suite and the hard track.
TRACKS = {
    "core": Track(AGENTS, "bench", LEADERBOARD_JSON, (BEGIN, END), _core_section),
    "hard": Track(
        HARD_AGENTS,
        "hard",
        "leaderboard_hard.json",
        ("<!-- hard:begin -->", "<!-- hard:end -->"),
        _hard_section,
    ),
}


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main(argv: Sequence[str] | None = None) -> int:
    """Run both splits, write their folders and the page's benchmark section."""
    parser = argparse.ArgumentParser(prog="python -m cpf_commands.bench.leaderboard")
    parser.add_argument("--page", default=PAGE, help=f"the page to rewrite (default: {PAGE})")
    parser.add_argument("--results", default="results")
    parser.add_argument(
        "--track", choices=sorted(TRACKS), default="core", help="the track (default: core)"
    )
    args = parser.parse_args(argv)
    track = TRACKS[args.track]
    begin, end = track.markers
    page = Path(args.page)
    text = page.read_text()
    if text.count(begin) != 1 or text.count(end) != 1:
        parser.error(f"{page} needs exactly one {begin} and one {end} marker.")
    policies = [*default_policies(args.track), *track.agents]
    results = Path(args.results)
    load_before, start = _load(), time.perf_counter()
    runs = {}
    for split, seeds in (("test", 20), ("shift", 10)):
        command = shlex.join(
            ["cpf-bench", "--policies", *policies, "--track", args.track, "--split", split,
             "--num-seeds", str(seeds)]
        )  # fmt: skip
        runs[split] = run_bench(
            policies,
            list_suite(args.track),
            num_seeds=seeds,
            out=results / f"{track.prefix}_{split}",
            command=command,
            split=split,
        )
    elapsed = time.perf_counter() - start
    flag = "" if args.track == "core" else f" --track {args.track}"
    folders = f"`{results}/{track.prefix}_test/`, `{results}/{track.prefix}_shift/`"
    note = (
        f"Regenerated by `python -m cpf_commands.bench.leaderboard{flag}` (both splits, results "
        f"in {folders} and `{results}/{track.json}`) "
        f"in {elapsed / 60:.1f} min on "
        f"{os.cpu_count()} cores ({platform.machine()}, {platform.python_implementation()} "
        f"{platform.python_version()}), load average (1, 5, 15 min) {load_before} before "
        f"and {_load()} after: the machine was shared."
    )
    text = page.read_text()  # as it is now: the page may have been edited during the run
    if text.count(begin) != 1 or text.count(end) != 1:
        raise SystemExit(f"{page} lost its {begin} or {end} marker during the run; put it back.")
    head, rest = text.split(begin)
    _, tail = rest.split(end)
    write_marl_eval([*runs["test"], *runs["shift"]], results / track.json)
    section = track.section(runs["test"], runs["shift"], note)
    atomic.write_text(page, head + begin + "\n" + section + "\n" + end + tail)
    print(f"wrote {page}, {folders.replace('`', '')}, {results}/{track.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
