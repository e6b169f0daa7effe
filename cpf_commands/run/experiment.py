"""Run a policy on a scenario and record what happened.

``run_episode`` steps one fleet (``FleetSim`` with B = 1, the same simulator
as the ParallelEnv) with an analytic policy and returns a ``Trajectory``.
Sample k holds the state at t_k, the action taken then, and the reward that
action earned. Besides the policy's diagnostics it records the true lumped
uncertainty the paper's NN is meant to learn (eq. [26]; docs/model.md, section 7),

    f_i = C(nu) nu + D(nu) nu + Delta(nu) - tau_w(t, nu) + M nubar_d'
        = f_lumped + M nubar_d',

with f_lumped = -M a_free from ``cpf_env.evaluation.privileged.lumped_uncertainty``
(a_free the plant's true acceleration with zero applied force): it covers
current, waves and wind too and uses the simulator's own right-hand side, so
the physics stays written once (the privileged references are told the same
f).

Example:
    >>> from cpf_commands.run.experiment import run_episode
    >>> trajectory = run_episode("wang2014", "nn_dsc", seed=0, max_steps=100)
    >>> trajectory.eta.shape
    (100, 5, 3)
"""

from __future__ import annotations

from typing import Any

import numpy as np
from tqdm.auto import tqdm

from cpf_bench.rollout import StepObserver, rollout
from cpf_commands.common.policies import resolve_policy
from cpf_env.envs.policy import FleetPolicy
from cpf_env.evaluation.metrics import Trajectory
from cpf_env.evaluation.privileged import lumped_uncertainty
from cpf_env.model.paths import encode_paths, evaluate_paths
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.sim.fleet import FleetSim

__all__ = ["run_episode"]


def run_episode(
    scenario: str | Scenario = "wang2014",
    policy: str = "nn_dsc",
    seed: int | None = 0,
    max_steps: int | None = None,
    policy_options: dict[str, Any] | None = None,
    progress: bool = False,
    observer: StepObserver | None = None,
) -> Trajectory:
    """Run one episode of ``policy`` on ``scenario`` and record it.

    Args:
        scenario: Scenario name or object.
        policy: A baseline name or a ``cpf-train --out`` folder (``resolve_policy``).
        seed: Reset seed of the environment and the policy.
        max_steps: Control steps to run (default: the scenario's ``max_steps``);
            the run stops early if the episode terminates.
        policy_options: Gains of a baseline (e.g. ``K2=(30, 30, 5)``).
        progress: Show a progress bar.
        observer: Also sees every step, after the trajectory's recorder (e.g. a
            ``cpf_commands.run.video.VideoRecorder``).

    Returns:
        The recorded trajectory (T = number of steps taken); its
        ``fleet_metrics`` are the benchmark's metrics of this episode
        (``cpf_env.evaluation.fleet_metrics``), from the same rollout ``cpf-bench`` uses.
    """
    resolved = make_scenario(scenario)
    controller = resolve_policy(policy, resolved, **(policy_options or {}))
    recorder = _TrajectoryRecorder(observer)
    horizon = resolved.max_steps if max_steps is None else int(max_steps)
    if horizon < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}.")
    with tqdm(total=horizon, disable=not progress, desc=f"{resolved.name}/{policy}") as bar:
        metrics = rollout(
            controller, resolved, [seed], max_steps, bar, observer=recorder, policy_seed=seed
        )
    stacked = {name: np.stack(values) for name, values in recorder.series.items()}
    theta = stacked["theta"]
    kinds, params = encode_paths(resolved.paths)
    desired = evaluate_paths(
        np.tile(kinds, theta.shape[0]),
        np.tile(params, (theta.shape[0], 1)),
        theta.reshape(-1),
    )[:, 0, :].reshape(theta.shape + (3,))
    tau_min, tau_max = resolved.tau_limits
    return Trajectory(
        eta_desired=desired,
        tau_min=tau_min,
        tau_max=tau_max,
        extras={name: np.stack(values) for name, values in recorder.extras.items() if values},
        fleet_metrics={name: float(values[0]) for name, values in metrics.items()},
        **stacked,
    )


class _TrajectoryRecorder:
    """Records fleet 0 of a rollout as a ``Trajectory``'s series.

    Sample k: the state at t_k and the action taken then, then the reward
    that action earned, plus the policy's diagnostics and the true lumped
    uncertainty (module docstring).
    """

    _BEFORE = ("eta", "nu", "theta", "errors")
    _AFTER = ("theta_dot", "tau_command", "tau_applied", "reward")

    def __init__(self, observer: StepObserver | None = None) -> None:
        self._observer = observer
        names = ("time", "v0", *self._BEFORE, *self._AFTER)
        self.series: dict[str, list[np.ndarray]] = {name: [] for name in names}
        self.extras: dict[str, list[np.ndarray]] = {"lumped_true": []}
        self._mass: np.ndarray | None = None

    def before(self, sim: FleetSim, actions: np.ndarray, policy: FleetPolicy) -> None:
        """Record the state at t_k and the policy's diagnostics."""
        a = sim.arrays
        time = float(sim.time[0])
        self.series["time"].append(np.array(time))
        self.series["v0"].append(np.array(sim.v0_at(time)))
        for name in self._BEFORE:
            self.series[name].append(getattr(a, name)[0].copy())
        for name, value in policy.diagnostics.items():
            self.extras.setdefault(name, []).append(np.array(value[0], dtype=np.float64))
        if "nubar_dot" in policy.diagnostics:
            nubar_dot = policy.diagnostics["nubar_dot"][0]
            if self._mass is None:
                self._mass = sim.mass_matrices()[0]
            told = lumped_uncertainty(sim)[0] + np.einsum("ijk,ik->ij", self._mass, nubar_dot)
            self.extras["lumped_true"].append(told)
        if self._observer is not None:
            self._observer.before(sim, actions, policy)

    def after(self, sim: FleetSim) -> None:
        """Record what the step's action did."""
        for name in self._AFTER:
            self.series[name].append(getattr(sim.arrays, name)[0].copy())
        if self._observer is not None:
            self._observer.after(sim)
