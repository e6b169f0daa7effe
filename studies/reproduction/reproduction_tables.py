"""Regenerate the two reproduction tables of docs/reproduction.md (markdown on stdout).

``claims``: the paper's five claims under both readings of the NN weight law,
side by side: ``wang2014`` (0.05 s, ``leakage="gamma_scaled"``, the RL
default), ``wang2014_fine`` with the same law (the step alone changes
nothing), and ``wang2014_fine`` with ``leakage="plain"`` (``cpf-run``'s
default). Claim 2 shows the measurement next to the steady-state formula
K2 / (K2 + s).

``ablation``: per scenario, each part of the design removed in turn (the NN:
``dsc``; the auxiliary system: ``nn_dsc_no_aux``; the estimator:
``nn_dsc_global_v0``, which is given v0 instead), with the metrics that
change: path error over the last quarter, settling time, saturated steps.

Usage::

    python studies/reproduction/reproduction_tables.py claims
    python studies/reproduction/reproduction_tables.py ablation [--max-steps N]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from cpf_commands.run.experiment import run_episode
from cpf_commands.run.reproduce import (
    COMMAND_BOUND,
    SATURATION_TRANSIENT,
    Claim,
    policy_options,
    reproduce,
    settling_time,
)
from cpf_env import scenarios
from cpf_env.evaluation.metrics import episode_metrics

#: (scenario, leakage) columns of the claims table.
READINGS = (
    ("wang2014", "gamma_scaled"),
    ("wang2014_fine", "gamma_scaled"),
    ("wang2014_fine", "plain"),
)
#: Rows of the ablation table: scenario, and the policies that remove one part each.
ABLATION_SCENARIOS = (
    "wang2014",
    "saturation_heavy",
    "wang2014_fine",
    "unknown_force_fine",
    "saturation_fine",
)
ABLATION_POLICIES = ("nn_dsc", "dsc", "nn_dsc_no_aux", "nn_dsc_global_v0")


def _cell(claim: Claim) -> str:
    """A claim's measured numbers and verdict, short, for one table cell."""
    v = claim.values
    if claim.number == 2:
        text = " / ".join(f"{e:.3f}" for e in v["relative_error"])
        if "predicted_relative_error" in v:
            formula = " / ".join(f"{e:.3f}" for e in v["predicted_relative_error"])
            text += f" (formula: {formula}, s = {v['s_mean']:.3g})"
    elif claim.number == 4:
        last = v["last_saturated_time"]
        text = "never saturated" if last is None else f"saturated until {last:.3g} s"
        text += ", peak " + " / ".join(f"{p:.3g}" for p in v["command_peak_over_limit"])
        text += ", applied within limits" if v["applied_within_limits"] else ", applied OUTSIDE"
    else:
        text = f"{next(iter(v.values())):.2g}"
    return f"{text}: **{'holds' if claim.holds else 'not met'}**"


#: Row labels of the claims table: what is measured, over the last quarter.
CLAIM_ROWS = {
    1: "1. max path error (m) < 0.01 (Fig. 3)",
    2: "2. NN tracks f of vessel 2: relative RMS error surge / sway / yaw < 0.2 (Fig. 4)",
    3: "3. max abs(theta_i - theta_j) < 0.01 (Fig. 5)",
    4: f"4. command tau0 of vessel 3 beyond the limits only before {SATURATION_TRANSIENT:g} s, "
    f"peak abs(tau0) / limit surge / sway / yaw <= {COMMAND_BOUND:g}; applied force within "
    "the limits (structural) (Fig. 6)",
    5: "5. max abs(vhat_i - v0) (m/s) < 1e-4 (Fig. 7)",
}


def claims_table(max_steps: int | None = None) -> str:
    """Markdown table: one row per claim, one column per (scenario, leakage) reading."""
    columns = []
    for scenario, leakage in READINGS:
        _metrics, claims = reproduce(
            scenario, "nn_dsc", max_steps=max_steps, out=None, leakage=leakage
        )
        columns.append({claim.number: claim for claim in claims})
    header = " | ".join(f"`{s}`, `leakage={law}`" for s, law in READINGS)
    lines = [f"| claim (last quarter) | {header} |", "|---" * (len(READINGS) + 1) + "|"]
    for number, label in CLAIM_ROWS.items():
        lines.append(f"| {label} | " + " | ".join(_cell(c[number]) for c in columns) + " |")
    return "\n".join(lines)


def ablation_rows(max_steps: int | None = None) -> list[tuple[object, ...]]:
    """(scenario, leakage, policy, path error max, path error integral, settling, saturated).

    ``nn_dsc`` comes first for each scenario; saturated is the fraction of
    steps with any axis saturated, averaged over the vessels.
    """
    rows: list[tuple[object, ...]] = []
    for scenario in ABLATION_SCENARIOS:
        for policy in ABLATION_POLICIES:
            options = policy_options(policy, scenario, None)
            trajectory = run_episode(scenario, policy, max_steps=max_steps, policy_options=options)
            metrics = episode_metrics(trajectory)
            dt = scenarios.get(scenario).dt
            integral = float(trajectory.errors[..., 0].mean(axis=1).sum() * dt)
            rows.append((
                scenario,
                options["leakage"],
                policy,
                max(metrics["path_error_max"]),
                integral,
                settling_time(trajectory),
                float(np.mean(metrics["saturated_fraction"])),
            ))  # fmt: skip
    return rows


#: What each ablation removes, by policy name.
REMOVED = {"dsc": "NN", "nn_dsc_no_aux": "auxiliary system", "nn_dsc_global_v0": "estimator"}


def _settle(value: object) -> str:
    return "never" if value is None else f"{value:.1f} s"


def ablation_table(max_steps: int | None = None) -> str:
    """Markdown: a summary (what removing each part changes, per scenario), then every run."""
    rows = ablation_rows(max_steps)
    summary = [
        "| scenario (leakage) | part removed | path error max, last quarter | "
        "settled < 5 cm from | steps saturated |",
        "|---|---|---|---|---|",
    ]
    full = [
        "| scenario (leakage) | policy | path error max, last quarter (m) | "
        "integral of mean path error (m s) | settled < 5 cm from | steps saturated |",
        "|---|---|---|---|---|---|",
    ]
    reference: tuple[object, ...] = ()
    for scenario, leakage, policy, path, integral, settled, saturated in rows:
        full.append(
            f"| `{scenario}` ({leakage}) | `{policy}` | {path:.2e} | {integral:.3f} | "
            f"{_settle(settled)} | {100 * saturated:.1f} % |"  # type: ignore[operator]
        )
        if policy == "nn_dsc":
            reference = (path, settled, saturated)
            continue
        ref_path, ref_settled, ref_saturated = reference
        summary.append(
            f"| `{scenario}` ({leakage}) | {REMOVED[policy]} (`{policy}`) | "
            f"{ref_path:.2e} -> {path:.2e} m (x{path / ref_path:.2g}) | "  # type: ignore[operator]
            f"{_settle(ref_settled)} -> {_settle(settled)} | "
            f"{100 * ref_saturated:.1f} -> {100 * saturated:.1f} % |"  # type: ignore[operator]
        )
    return "\n".join(summary) + "\n\n" + "\n".join(full)


def main(argv: Sequence[str] | None = None) -> str:
    """Print the requested table and return it."""
    parser = argparse.ArgumentParser(prog="reproduction_tables.py", description=__doc__)
    parser.add_argument("table", choices=("claims", "ablation"))
    parser.add_argument("--max-steps", type=int, default=None, help="steps per run (default: full)")
    args = parser.parse_args(argv)
    table = (
        claims_table(args.max_steps) if args.table == "claims" else ablation_table(args.max_steps)
    )
    print(table)
    return table


if __name__ == "__main__":
    main()
