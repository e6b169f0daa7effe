"""``LearnedFilter``: a design on its navigation filter's estimate, corrected by a learned map.

Each step, per fleet: the base design's filter (``baselines.Filtered``, by
default ``mpc_tuned_mmae``'s bank) takes the observation; the vessel's
recent history of fix offsets and applied forces and the bank's filters
(``agents.estimation.correction``) predict the estimate's error; the
corrected estimate is rebuilt into the observation (``Filtered.observe``)
and the base's inner design acts on it. It reads nothing but the vessel's
own observation, as the filter does: it is as deployable as its base.

Example (with a folder written by ``cpf-fit-filter --out runs/filter``)::

    from agents import load_policy
    policy = load_policy("runs/filter", scenario="hard_sensing")
    actions = policy.act_batch(obs)  # (B, n, obs_dim) -> (B, n, 4 + m)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.estimation.correction import STEP_SIZE, Correction, correct, step_inputs
from baselines import DEPLOYABLE, make_policy
from baselines.estimator import Filtered
from cpf_env.envs.policy import FleetPolicy, fleet_mask
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.sim.observation import TAU

__all__ = ["WINDOW", "LearnedFilter", "bank_size"]

#: Control steps of history the correction reads (10 fixes at the hard track's 5 Hz).
WINDOW = 40

Array = NDArray[np.float64]


def bank_size(base: str) -> int:
    """M, the filters of the bank of ``base``, a deployable design on the navigation filter.

    Raises:
        ValueError: ``base`` is not such a design.
    """
    filtered = {name: cls for name, cls in DEPLOYABLE.items() if issubclass(cls, Filtered)}
    if base not in filtered:
        raise ValueError(
            f"a learned filter corrects a navigation filter's estimate: base must be one "
            f"of {sorted(filtered)}, got {base!r}."
        )
    return len(filtered[base].noise_scales)


class LearnedFilter(FleetPolicy):
    """A design on the navigation filter's estimate plus a learned ``Correction`` (module doc).

    Args:
        scenario: The scenario it acts on (a name or a ``Scenario``); it must have
            sensors (``Scenario.sensors`` not ideal): on the true state there is
            nothing to correct.
        correction: The fitted map (``Correction.zero``: the base alone, bit for bit).
        base: A deployable design on the navigation filter (``baselines.FILTERED``, or
            ``mpc_tuned_ekf_safe``, the safety filter on it).
        name: The policy's label.

    Raises:
        ValueError: ``base`` is not a filtered design, the scenario has ideal sensors, or
            the correction reads another number of filters than the base's bank holds.
    """

    def __init__(
        self,
        scenario: str | Scenario,
        correction: Correction,
        base: str = "mpc_tuned_mmae",
        name: str = "learned_filter",
    ) -> None:
        task = make_scenario(scenario)
        members = bank_size(base)
        if task.sensors.ideal:
            raise ValueError(
                f"{task.name!r} has ideal sensors: its vessels observe their true state, so "
                "there is no estimate to correct. Run the learned filter on a scenario with "
                "Scenario.sensors set (the hard track's sensing scenarios)."
            )
        policy = make_policy(base, task)
        assert isinstance(policy, Filtered)
        if correction.members != members:
            raise ValueError(
                f"the correction reads a bank of {correction.members} filters, and {base!r} "
                f"runs {members}: give the base it was fitted on."
            )
        self.scenario = task
        self.base: Filtered = policy
        self.correction = correction
        self.base_name = base
        self.name = name
        self.n, self.obs_dim, self.act_dim = policy.n, policy.obs_dim, policy.act_dim
        self.agents = policy.agents
        self.message_entries = policy.message_entries
        tau_min, tau_max = task.tau_limits
        scale = np.maximum(np.abs(np.asarray(tau_min)), np.abs(np.asarray(tau_max)))
        self._force_scale = np.maximum(scale.reshape(self.n, 3), 1e-9)
        self._history = np.zeros((0, self.n, correction.window, STEP_SIZE))
        self.diagnostics: dict[str, Array] = {}

    def reset(self, seed: int | None = None) -> None:
        """Forget every fleet's estimate and history."""
        self.base.reset(seed)
        self._history = np.zeros((0, self.n, self.correction.window, STEP_SIZE))

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Forget some fleets' estimates and histories ((F,) bool mask, or indices)."""
        self.base.reset_fleets(fleets)
        self._history[fleet_mask(fleets, self._history.shape[0])] = 0.0

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """The inner design's actions (B, n, act_dim) on the corrected estimates.

        ``diagnostics`` holds the base's, its filter's ``estimate`` (F, n, 9), the
        ``corrected`` estimate of the rows acted for (B, n, 9) and the predicted
        ``error`` (B, n, 6).
        """
        batch = np.ascontiguousarray(obs, dtype=np.float32)
        self.base.estimate(batch, fleets)
        rows = np.arange(batch.shape[0]) if fleets is None else np.asarray(fleets, np.int64)
        if fleets is None and self._history.shape[0] != batch.shape[0]:
            shape = (batch.shape[0], self.n, self.correction.window, STEP_SIZE)
            self._history = np.zeros(shape)
        states = self.base.state[rows]
        step = step_inputs(
            states,
            self.base.last_fix[rows],
            batch[..., TAU : TAU + 3].astype(np.float64),
            self._force_scale,
        )
        history = self._history[rows]
        history[:, :, 1:] = history[:, :, :-1]
        history[:, :, 0] = step
        self._history[rows] = history
        errors = self.correction.predict(history, states, self.base.members[rows])
        corrected = correct(states, errors)
        actions = self.base.policy.act_batch(self.base.observe(batch, corrected), fleets)
        self.diagnostics = {
            **self.base.policy.diagnostics,
            "estimate": self.base.state.copy(),
            "corrected": corrected,
            "error": errors,
        }
        return actions

    def history_inputs(self) -> Array:
        """(F, n, window, ``STEP_SIZE``) a copy of every fleet's history, newest first."""
        return self._history.copy()
