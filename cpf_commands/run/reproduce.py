"""Reproduce the paper's simulation: run, measure the five claims, write figures and metrics.

The claims are those of the paper's section 4 (docs/reproduction.md), each checked over the last
quarter of the episode with the thresholds of the project's acceptance
criteria. They are evaluated only where they apply: on the paper's scenarios
(``PAPER_SCENARIOS``), and each claim only for a policy that has the part it
is about (claim 2 needs an NN, claim 5 a speed estimator). Claim 2 (the NN
tracks the lumped uncertainty) has no threshold in the paper; it is reported
as the relative RMS error of the NN output per axis, judged "tracks" below
``NN_TRACKING_TOLERANCE``, next to the prediction of the steady-state formula
(see ``predicted_nn_error``).

The weight-law reading of ``nn_dsc`` (``NNDSCGains.leakage``) defaults per
scenario (``default_leakage``): the integrating reading ``"plain"`` on the
fine-step scenarios, which exist for it, the policy's own default elsewhere.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from baselines import ALL_POLICIES, NNDSCGains
from cpf_bench.rollout import StepObserver
from cpf_commands.common.outputs import claim_output_folder
from cpf_commands.run.experiment import run_episode
from cpf_commands.run.figures import write_figures
from cpf_env.evaluation.metrics import Trajectory, episode_metrics, final_window
from cpf_env.infra import atomic
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.scenarios.fine import FINE_SCENARIOS
from cpf_env.sim.fleet import FleetSim

__all__ = [
    "COMMAND_BOUND",
    "COORDINATION_TOLERANCE",
    "NN_TRACKING_TOLERANCE",
    "PAPER_SCENARIOS",
    "PATH_TOLERANCE",
    "RUN_FILES",
    "SATURATION_TRANSIENT",
    "SPEED_TOLERANCE",
    "Claim",
    "default_leakage",
    "evaluate_claims",
    "judging_gap",
    "policy_options",
    "predicted_nn_error",
    "reproduce",
    "run_folder",
    "settling_time",
    "warm_up",
]

#: The files of cpf-run's output folder (shell patterns; the figures are fig3_*.png .. fig7_*.png).
RUN_FILES = ("metrics.json", "trajectory.npz", "fig*.png")
#: Disk space of the outputs per vessel and control step (trajectory.npz uncompressed, generous),
#: and of the figures.
OUTPUT_BYTES_PER_VESSEL_STEP, FIGURE_BYTES = 1024, 4 * 2**20

#: Thresholds over the last quarter (m; path-variable units; m/s).
PATH_TOLERANCE, COORDINATION_TOLERANCE, SPEED_TOLERANCE = 0.01, 0.01, 1e-4
#: Relative RMS error below which the NN is said to track f_i.
NN_TRACKING_TOLERANCE = 0.2
#: Claim 4: the paper's forces saturate "only in the first seconds" (Fig. 6), so the
#: command must be inside the limits from this time (s) on; measured: nn_dsc's last
#: saturated command of vessel 3 at 4.85 s (wang2014_fine) and 3.2 s (wang2014), 18.3 s
#: without the auxiliary system on wang2014_fine.
SATURATION_TRANSIENT = 10.0
#: Claim 4: bound on the peak |tau0| / limit of vessel 3 (per axis). The peak is the
#: initial errors' command in the first half second; measured 16.0 (sway, wang2014_fine)
#: and 7.9 (wang2014) for nn_dsc, 54 when the auxiliary system is off (the command winds
#: up), 160 for a policy commanding 10 times nn_dsc's force.
COMMAND_BOUND = 25.0
#: Path error (m) below which every vessel counts as settled (``settling_time``).
SETTLING_TOLERANCE = 0.05
#: The paper's simulation, at the RL control step and at the fine one.
PAPER_SCENARIOS = ("wang2014", "wang2014_fine")


@dataclass(frozen=True)
class Claim:
    """One claim of the paper with its measured value.

    Attributes:
        number: 1..5 as in docs/reproduction.md.
        figure: The paper's figure.
        statement: What the paper claims.
        measured: What this run measured, in words with numbers.
        holds: Whether the measured value meets the stated threshold; None where
            the claim is not judged (``judging_gap``: a run shorter than the paper's).
        values: The measured numbers by name (JSON-ready), e.g. ``relative_error``
            and ``predicted_relative_error`` (surge, sway, yaw) for claim 2.
    """

    number: int
    figure: str
    statement: str
    measured: str
    holds: bool | None
    values: dict[str, Any] = field(default_factory=dict)


def default_leakage(scenario: str) -> str:
    """Weight-law reading ``cpf-run`` uses on ``scenario`` unless told otherwise.

    ``"plain"`` (integrating, the reading under which the NN tracks f) on the
    fine-step scenarios of ``cpf_env.scenarios.fine``; ``"gamma_scaled"`` (the
    policy's default, stable at 0.05 s) on every other scenario.
    """
    return "plain" if scenario in FINE_SCENARIOS else NNDSCGains().leakage


def judging_gap(scenario: Scenario, max_steps: int) -> str | None:
    """Why the paper's claims are not judged on a run of ``max_steps`` (asked for), or None.

    The claims are the paper's statements about its whole simulation (the
    scenario's episode, 150 s): measured over the last quarter of a shorter
    run, they would judge an earlier window, still in the transient on a
    short one, against thresholds meant for the end of the paper's run.
    """
    needed, ran = scenario.max_steps * scenario.dt, max_steps * scenario.dt
    if ran >= needed:
        return None
    return f"the run is shorter than the claim needs ({ran:.4g} s < {needed:.4g} s)"


def settling_time(trajectory: Trajectory, tolerance: float = SETTLING_TOLERANCE) -> float | None:
    """Time (s) from which every vessel's path error stays below ``tolerance`` (m).

    Returns None if the last sample is not settled, 0 if all samples are.
    """
    worst = trajectory.errors[..., 0].max(axis=1)
    unsettled = np.flatnonzero(worst >= tolerance)
    if unsettled.size == 0:
        return 0.0
    if unsettled[-1] + 1 >= worst.shape[0]:
        return None
    return float(trajectory.time[unsettled[-1] + 1])


def _nn_relative_error(trajectory: Trajectory, vessel: int) -> NDArray[np.float64] | None:
    """RMS(nn - f) / RMS(f) per axis over the last quarter, or None without an NN."""
    nn, true = trajectory.extras.get("nn_output"), trajectory.extras.get("lumped_true")
    if nn is None or true is None or not np.any(nn):
        return None
    window = final_window(trajectory)
    error = nn[window, vessel] - true[window, vessel]
    scale = np.sqrt((true[window, vessel] ** 2).mean(axis=0))
    return np.sqrt((error**2).mean(axis=0)) / np.maximum(scale, 1e-12)


def predicted_nn_error(
    trajectory: Trajectory, gains: NNDSCGains, vessel: int
) -> tuple[NDArray[np.float64], float] | None:
    """Relative RMS error of the NN that the steady-state formula predicts, per axis.

    When the weights follow their equilibrium of [30], What = -g sigma e2^T
    (g = ``gains.static_gain()``: 1/k_W, or Gamma_W/k_W under ``leakage="plain"``),
    the NN output is -s e2 with s = g ||sigma(xi)||^2. At steady state the
    command balances f, -K2 e2 - s e2 = f (z1 small), so the NN outputs
    s / (K2 + s) f and misses K2 / (K2 + s) f. This returns
    RMS(K2 / (K2 + s_t) f_t) / RMS(f_t) over the last quarter, per axis.

    Args:
        trajectory: A run with the ``nubar_dot`` and ``lumped_true`` extras.
        gains: The gains of the run's NN.
        vessel: 0-based vessel index.

    Returns:
        ((3,) predicted errors, mean s over the window), or None without the extras.
    """
    nubar_dot, true = trajectory.extras.get("nubar_dot"), trajectory.extras.get("lumped_true")
    if nubar_dot is None or true is None:
        return None
    window = final_window(trajectory)
    nu = trajectory.nu[window, vessel]
    xi = np.concatenate([np.ones((nu.shape[0], 1)), nu, nubar_dot[window, vessel]], axis=-1)
    sigma = np.tanh(xi @ gains.input_weights().T)  # (T, l)
    s = gains.static_gain() * (sigma**2).sum(axis=-1, keepdims=True)  # (T, 1)
    f = true[window, vessel]
    k2 = np.array(gains.K2)
    missed = k2 / (k2 + s) * f
    predicted = np.sqrt((missed**2).mean(axis=0)) / np.maximum(np.sqrt((f**2).mean(axis=0)), 1e-12)
    return predicted, float(s.mean())


def _nn_claim(
    trajectory: Trajectory, vessel: int, gains: NNDSCGains | None
) -> tuple[str, bool, dict[str, Any]] | None:
    """Claim 2's message, verdict and values, or None if the policy has no NN."""
    nn_error = _nn_relative_error(trajectory, vessel)
    if nn_error is None:
        return None
    message = (
        "relative RMS error (surge, sway, yaw) over last quarter "
        + ", ".join(f"{e:.3f}" for e in nn_error)
        + f" (tracks if < {NN_TRACKING_TOLERANCE})"
    )
    values: dict[str, Any] = {"relative_error": nn_error.tolist()}
    prediction = None if gains is None else predicted_nn_error(trajectory, gains, vessel)
    if gains is not None and prediction is not None:
        predicted, s = prediction
        values.update(predicted_relative_error=predicted.tolist(), s_mean=s)
        message += (
            "; steady-state formula K2/(K2+s) predicts "
            + ", ".join(f"{e:.3f}" for e in predicted)
            + f" with s = {gains.static_gain():g} ||sigma||^2 = {s:.3g} (leakage={gains.leakage})"
        )
    return message, bool(np.all(nn_error < NN_TRACKING_TOLERANCE)), values


def _force_claim(trajectory: Trajectory, vessel: int) -> Claim:
    """Claim 4 on what the controller decides: its command tau0, not the clipped force.

    Holds when (a) the command exceeds a limit at some step (saturation is
    active, else the claim says nothing), (b) it is inside the limits from
    ``SATURATION_TRANSIENT`` s on (saturated only in the transient: no windup;
    a run shorter than that cannot show it),
    (c) its peak stays within ``COMMAND_BOUND`` times the limits, and (d) the
    applied force is within the limits, which the plant's clip guarantees
    (structural, reported as such).
    """
    limits = np.maximum(np.abs(trajectory.tau_min[vessel]), np.abs(trajectory.tau_max[vessel]))
    command = np.abs(trajectory.tau_command[:, vessel])  # (T, 3)
    beyond = np.any(command > limits, axis=1)  # (T,)
    saturated_steps = int(beyond.sum())
    last = float(trajectory.time[np.flatnonzero(beyond)[-1]]) if saturated_steps else None
    peak = command.max(axis=0) / limits
    applied = np.abs(trajectory.tau_applied[:, vessel]).max(axis=0)
    within = bool(np.all(applied <= limits + 1e-12))
    # A run that ends inside the transient cannot show that saturation ends with it.
    confined = last is not None and bool(last < SATURATION_TRANSIENT <= trajectory.time[-1])
    bounded = bool(np.all(peak <= COMMAND_BOUND))
    last_text = "never" if last is None else f"last at {last:.3g} s"
    measured = (
        f"command beyond the limits on {saturated_steps} steps, {last_text} "
        f"(must saturate, and only before {SATURATION_TRANSIENT:g} s); peak of |tau0| divided "
        "by the limit (surge, sway, yaw) "
        + ", ".join(f"{p:.3g}" for p in peak)
        + f" (bound {COMMAND_BOUND:g}); applied max |tau| (surge, sway, yaw) "
        + ", ".join(f"{t:.3g}" for t in applied)
        + " vs limits "
        + ", ".join(f"{t:.3g}" for t in limits)
        + " (structural: the plant clips, so this part cannot fail)"
    )
    return Claim(
        4,
        "Fig. 6",
        f"forces of vessel {vessel} (the paper's vessel {vessel + 1}) saturate only in the "
        "transient and stay within the limits",
        measured,
        saturated_steps > 0 and confined and bounded and within,
        {
            "saturated_steps": saturated_steps,
            "last_saturated_time": last,
            "command_peak_over_limit": peak.tolist(),
            "force_max_abs": applied.tolist(),
            "limits": limits.tolist(),
            "applied_within_limits": within,
        },
    )


def evaluate_claims(
    trajectory: Trajectory,
    metrics: dict[str, Any],
    gains: NNDSCGains | None = None,
    estimator: bool = True,
) -> list[Claim]:
    """Check the paper's claims (docs/reproduction.md) that apply to a recorded run.

    Args:
        trajectory: The run.
        metrics: ``episode_metrics(trajectory)``.
        gains: The NN's gains, for claim 2's steady-state prediction (None: no prediction).
        estimator: Whether the policy estimates v0 (claim 5 applies).

    Returns:
        The claims in order, without claim 2 if the policy has no NN (its NN
        output is identically 0) and without claim 5 if it has no estimator.
    """
    n = trajectory.eta.shape[1]
    nn_vessel, force_vessel = min(1, n - 1), min(2, n - 1)
    path = max(metrics["path_error_max"])
    coordination = metrics["coordination_error_max"]
    speed = metrics.get("speed_estimate_error_max") if estimator else None
    nn = _nn_claim(trajectory, nn_vessel, gains)
    claims = [
        Claim(
            1,
            "Fig. 3",
            "every vessel converges to a small neighbourhood of its path",
            f"max path error over last quarter {path:.3g} m (threshold {PATH_TOLERANCE} m)",
            path < PATH_TOLERANCE,
            {"path_error_max": path},
        )
    ]
    if nn is not None:
        claims.append(
            Claim(
                2,
                "Fig. 4",
                f"the NN output tracks the lumped uncertainty f of vessel {nn_vessel} (the "
                f"paper's vessel {nn_vessel + 1})",
                *nn,
            )
        )
    claims += [
        Claim(
            3,
            "Fig. 5",
            "coordination errors theta_i - theta_j converge near 0",
            f"max |theta_i - theta_j| over last quarter {coordination:.3g} "
            f"(threshold {COORDINATION_TOLERANCE})",
            coordination < COORDINATION_TOLERANCE,
            {"coordination_error_max": coordination},
        ),
        _force_claim(trajectory, force_vessel),
    ]
    if speed is not None:
        claims.append(
            Claim(
                5,
                "Fig. 7",
                "every speed estimate converges to v0, also where b_i = 0",
                f"max |vhat_i - v0| over last quarter {max(speed):.3g} m/s "
                f"(threshold {SPEED_TOLERANCE})",
                max(speed) < SPEED_TOLERANCE,
                {"speed_estimate_error_max": max(speed)},
            )
        )
    return claims


def warm_up(scenario: str | Scenario) -> None:
    """Compile (or load from numba's cache) the simulator kernels a run uses."""
    sim = FleetSim(make_scenario(scenario), num_fleets=1)
    sim.reset(seeds=[0])
    sim.accelerations()
    sim.step(np.zeros((1, sim.scenario.n, sim.act_dim)))


def policy_options(policy: str, scenario: str, leakage: str | None) -> dict[str, Any]:
    """Options for ``make_policy``: the weight-law reading, for policies that have one."""
    gains_type = getattr(ALL_POLICIES.get(policy), "gains_type", None)
    if gains_type is None or "leakage" not in gains_type.option_names():
        if leakage is not None:
            raise ValueError(
                f"policy {policy!r} has no NN weight law; leave out the leakage option "
                "(it applies to nn_dsc and its ablations)."
            )
        return {}
    return {"leakage": default_leakage(scenario) if leakage is None else leakage}


def reproduce(
    scenario: str | Scenario = "wang2014_fine",
    policy: str = "nn_dsc",
    seed: int = 0,
    max_steps: int | None = None,
    out: str | Path | None = "outputs",
    figures: bool = True,
    progress: bool = False,
    leakage: str | None = None,
    observer: StepObserver | None = None,
    force: bool = False,
) -> tuple[dict[str, Any], list[Claim]]:
    """Run the reproduction and write ``metrics.json``, ``trajectory.npz`` and figures.

    Args:
        scenario: Scenario name or object.
        policy: A baseline name or a ``cpf-train --out`` folder (``resolve_policy``).
        seed: Seed of environment and policy.
        max_steps: Control steps (default: the scenario's episode length).
        out: Output directory; its subdirectory ``<scenario>_<policy>`` (``run_folder``)
            is checked and locked before the episode runs and written whole at the
            end (``cpf_env.infra.atomic.staged_folder``). None writes nothing.
        figures: Write the PNG figures.
        progress: Show a progress bar (after compiling the kernels, so that its
            time estimate is that of the run).
        leakage: Weight-law reading of nn_dsc and its ablations (default:
            ``default_leakage(scenario)``); must be None for other policies.
        observer: Also sees every step of the episode (``cpf-run --video``).
        force: Replace the results already in the output folder (``cpf-run --force``).

    Returns:
        (metrics, claims); the claims are empty off the paper's scenarios,
        and not judged (``holds`` None, the reason in ``metrics["claims_not_judged"]``)
        on a run shorter than the scenario's episode. ``metrics`` adds ``scenario``,
        ``policy``, ``policy_options``, ``seed``,
        ``settling_time_s``, ``claims`` (each with ``holds``) and, when it
        writes, ``output_directory``.

    Raises:
        ValueError: A bad argument, or an output folder that is a file or a link,
            holds other files, holds results without ``force``, is not writable,
            lacks space, or is being written by another cpf-run.
        OSError: The outputs could not be written (disk full); the folder is as it was.
    """
    resolved = make_scenario(scenario)
    options = policy_options(policy, resolved.name, leakage)
    if out is None:
        return _reproduce(
            resolved, policy, options, seed, max_steps, progress, observer, None, False
        )
    directory = run_folder(out, resolved.name, policy)
    horizon = resolved.max_steps if max_steps is None else max(int(max_steps), 1)
    needed = horizon * resolved.n * OUTPUT_BYTES_PER_VESSEL_STEP + figures * FIGURE_BYTES
    lock = claim_output_folder(directory, RUN_FILES, force, "cpf-run", needed_bytes=needed)
    try:
        return _reproduce(
            resolved, policy, options, seed, max_steps, progress, observer, directory, figures
        )
    finally:
        lock.release()


def run_folder(out: str | Path, scenario: str, policy: str) -> Path:
    """The output folder of a cpf-run: ``out/<scenario>_<policy folder's name>``.

    The ``:`` of a ``package.module:NAME`` policy becomes ``+``
    (``bench_mild_my_policy+ProportionalPolicy``): ``:`` is not allowed in
    Windows file names and is a separator to shells and ``PATH``-like lists,
    and ``+`` is in no Python module or attribute name, so two specs never
    share a folder.
    """
    return Path(out) / f"{scenario}_{Path(policy).name.replace(':', '+')}"


def _reproduce(
    resolved: Scenario,
    policy: str,
    options: dict[str, Any],
    seed: int,
    max_steps: int | None,
    progress: bool,
    observer: StepObserver | None,
    directory: Path | None,
    figures: bool,
) -> tuple[dict[str, Any], list[Claim]]:
    """``reproduce`` once its output folder (if any) is claimed."""
    if progress:
        warm_up(resolved)
    trajectory = run_episode(
        resolved,
        policy,
        seed=seed,
        max_steps=max_steps,
        policy_options=options,
        progress=progress,
        observer=observer,
    )
    metrics = episode_metrics(trajectory)
    policy_type = ALL_POLICIES.get(policy)
    claims: list[Claim] = []
    if resolved.name in PAPER_SCENARIOS:
        gains = NNDSCGains.from_options(options) if "leakage" in options else None
        estimator = not getattr(policy_type, "global_speed", False)
        claims = evaluate_claims(trajectory, metrics, gains, estimator)
        gap = judging_gap(resolved, resolved.max_steps if max_steps is None else max_steps)
        if gap is not None:
            claims = [replace(claim, holds=None) for claim in claims]
            metrics["claims_not_judged"] = gap
    metrics.update(
        scenario=resolved.name,
        policy=policy,
        policy_options=options,
        seed=seed,
        settling_time_s=settling_time(trajectory),
        claims=[asdict(claim) for claim in claims],
    )
    if directory is not None:
        with atomic.staged_folder(directory) as staging:  # all files or none, nothing followed
            atomic.write_text(staging / "metrics.json", json.dumps(metrics, indent=2))
            trajectory.save(str(staging / "trajectory.npz"))
            if figures:
                write_figures(trajectory, staging)
        metrics["output_directory"] = str(directory)
    return metrics, claims
