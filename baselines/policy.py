"""Common plumbing of the analytic policies: interface, internal states, input layouts.

A policy maps local observations to actions and keeps its own internal states
(filters, NN weights, speed estimates), one set per vessel of each of B
fleets. It reads nothing but the observation and the scenario's known
constants (nominal model, saturation limits, dt, message size) and never
touches a simulator.

Interface (``baselines.interface.PolicyInterface``, shared with trained agents):

- ``act_batch(obs (B, n, obs_dim), fleets=None) -> (B, n, 4 + m)``: the core, float64;
- ``act(observations: dict) -> dict`` for the PettingZoo ``ParallelEnv`` (B = 1, float32);
- ``predict(obs, state, episode_start, deterministic)`` in the Stable-Baselines3 style,
  so ``stable_baselines3.common.evaluation.evaluate_policy`` runs it;
- ``reset(seed=None)`` / ``reset_fleets(mask)``: forget all / some fleets' internal states;
- ``diagnostics``: internal signals of the last ``act_batch``, leading axes (B, n).

Action of vessel i: [tau0 (3, N, N, N m, before saturation), theta_dot (1/s),
vhat_i(k + 1) (m/s), 0 ...]: the env saturates tau0 and integrates theta.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baselines.cooperative import CooperativeLayer, CooperativeStep, LocalObservation
from baselines.gains import CooperativeGains
from baselines.interface import PolicyInterface
from cpf_env import scenarios
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import observation_layout

__all__ = ["DIAGNOSTICS", "Policy", "resolve_scenario", "virtual_control"]

Array = NDArray[np.float64]

#: Names of ``Policy.diagnostics`` and their trailing shapes after (B, n).
DIAGNOSTICS: dict[str, tuple[int, ...]] = {
    "nn_output": (3,),
    "nubar_dot": (3,),
    "alpha": (3,),
    "speed_estimate": (),
    "aux_state": (3,),
    "tau_command": (3,),
    "omega_s": (),
    "gamma": (),
}


def resolve_scenario(env: object) -> Scenario:
    """The scenario of an env, a FleetSim, any object with ``.scenario``, a name or a Scenario.

    Raises:
        TypeError: ``env`` is none of these.
    """
    if isinstance(env, str):
        return scenarios.get(env)
    if isinstance(env, Scenario):
        return env
    for candidate in (env, getattr(env, "unwrapped", None)):
        scenario = getattr(candidate, "scenario", None)
        if isinstance(scenario, Scenario):
            return scenario
    raise TypeError(
        "env must be a CooperativePathFollowingEnv, a FleetSim, an object with a .scenario, "
        f"a Scenario or a scenario name; got {type(env).__name__}."
    )


def virtual_control(k1: Array, z1: Array, t1: Array, vhat: Array) -> Array:
    """Virtual control alpha_i = -K_i1 z_i1 + t_i1 vhat_i, eq. [15].

    Args:
        k1: Diagonal of K_i1, shape (3,) (1/s).
        z1: Path errors, shape (B, n, 3).
        t1: J^T eta_d^theta, shape (B, n, 3).
        vhat: Speed estimates, shape (B, n) (m/s).

    Returns:
        Desired body velocity, shape (B, n, 3) (m/s, m/s, rad/s).
    """
    return -k1 * z1 + t1 * vhat[..., None]


class Policy(PolicyInterface, abc.ABC):
    """Base class: the cooperative layer, state bookkeeping and the input layouts.

    Subclasses give the kinetic part (the force command) through
    ``_kinetic_states`` and ``_kinetics``.

    Args:
        env: Where the scenario comes from (see ``resolve_scenario``).
        **options: Gains, fields of ``gains_type``; unknown names raise ValueError.

    Attributes:
        scenario: The task (only its known constants are used).
        gains: The gains (a frozen dataclass).
        n: Vessels per fleet.
        obs_dim: Observation length per vessel.
        act_dim: Action length per vessel, 4 + m.
        agents: ``vessel_0`` ... ``vessel_{n-1}``.
        diagnostics: Signals of the last ``act_batch``, name -> (B, n, ...) array
            (see ``DIAGNOSTICS``); new arrays on every call, safe to keep.
    """

    #: Registry name (a key of ``baselines.POLICIES``).
    name: ClassVar[str]
    #: Gains dataclass, whose fields are the accepted options.
    gains_type: ClassVar[type[CooperativeGains]] = CooperativeGains
    #: True: every vessel uses v0 from the scenario's schedule instead of estimating it.
    global_speed: ClassVar[bool] = False

    def __init__(self, env: object, **options: Any) -> None:
        self.scenario = resolve_scenario(env)
        self.gains = self.gains_type.from_options(options, owner=f"policy {self.name!r}")
        self.layout = observation_layout(self.scenario)
        self.n = self.scenario.n
        self.obs_dim = self.layout.size
        self.act_dim = 4 + self.scenario.message_size
        self.dt = float(self.scenario.dt)
        self.agents = [f"vessel_{i}" for i in range(self.n)]
        if self.scenario.message_size < 1 and not self.global_speed:
            raise ValueError(
                f"policy {self.name!r} broadcasts its speed estimate and needs "
                "Scenario.message_size >= 1."
            )
        schedule = self.scenario.v0_schedule if self.global_speed else None
        self.cooperation = CooperativeLayer(self.gains, self.dt, schedule)
        self.diagnostics: dict[str, Array] = {}
        self._states: dict[str, Array] | None = None
        self._started = np.zeros(0, dtype=bool)
        self._steps = np.zeros(0, dtype=np.int64)

    # --- the kinetic part, given by subclasses -------------------------------------------

    @abc.abstractmethod
    def _kinetic_states(self) -> dict[str, tuple[int, ...]]:
        """Internal states of the kinetic part: name -> shape per vessel (all start at 0)."""

    @abc.abstractmethod
    def _kinetics(
        self,
        obs: LocalObservation,
        cooperation: CooperativeStep,
        states: dict[str, Array],
        started: NDArray[np.bool_],
    ) -> tuple[Array, dict[str, Array]]:
        """Force command of step k; advances the kinetic states in ``states`` to step k + 1.

        Args:
            obs: Local observations at step k.
            cooperation: This step's cooperative signals.
            states: Kinetic states at step k, (B, n, ...); replace entries with step k + 1.
            started: (B,) False for fleets acting for the first time since their reset.

        Returns:
            tau0 (B, n, 3) in N, N, N m, and the diagnostics "nn_output", "nubar_dot",
            "alpha", "aux_state".
        """

    # --- interface ------------------------------------------------------------------------

    def reset(self, seed: int | None = None) -> None:
        """Forget all internal states; they are re-initialized on the next act.

        Args:
            seed: Accepted for interface compatibility; the policies are
                deterministic (the NN input weights are fixed by ``nn_seed``).
        """
        del seed
        self._states = None
        self._started = np.zeros(0, dtype=bool)
        self._steps = np.zeros(0, dtype=np.int64)
        self.diagnostics = {}

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """Actions of B fleets from their local observations.

        Args:
            obs: (B, n, obs_dim) local observations at step k; with ``fleets``,
                (len(fleets), n, obs_dim), one row per listed fleet.
            fleets: Indices of the fleets to act for (default: all). The other
                fleets' internal states are left untouched, so a vector env can
                restart and act for a few fleets after an auto-reset. Needs
                internal states already allocated for the full batch.

        Returns:
            (B, n, 4 + m) float64 (one row per acting fleet): tau0 (N, N, N m),
            theta_dot (1/s), message [vhat_i(k + 1), 0, ...].

        Raises:
            ValueError: Wrong shape, non-finite entries, a different B than
                the previous call without ``reset()`` in between, or bad indices.
        """
        batch = self._validate(obs)
        if fleets is None:
            return self._act(batch, self._states_for(batch.shape[0]), self._started, self._steps)
        index = self._fleet_index(fleets, batch.shape[0])
        full = self._states_for(self._started.shape[0])
        states = {key: value[index] for key, value in full.items()}
        started, steps = self._started[index], self._steps[index]
        actions = self._act(batch, states, started, steps)
        for key, value in states.items():
            full[key][index] = value
        self._started[index], self._steps[index] = started, steps
        return actions

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Restart the internal states of some fleets; the others are untouched.

        Args:
            fleets: (B,) bool mask, or indices, of the fleets to restart. Their
                states are re-initialized on their next act, as after ``reset()``.
        """
        if self._states is None:
            return
        num_fleets = self._started.shape[0]
        mask = np.asarray(fleets)
        if mask.dtype != bool:
            index = self._fleet_index(mask, mask.shape[0] if mask.ndim == 1 else -1)
            mask = np.zeros(num_fleets, dtype=bool)
            mask[index] = True
        if mask.shape != (num_fleets,):
            raise ValueError(
                f"fleets must be a mask of shape ({num_fleets},) or indices, got {mask.shape}."
            )
        for key, array in self._states.items():  # new arrays: past diagnostics stay intact
            self._states[key] = np.where(mask.reshape(-1, *[1] * (array.ndim - 1)), 0.0, array)
        self._started[mask] = False
        self._steps[mask] = 0

    def _act(
        self,
        batch: Array,
        states: dict[str, Array],
        started: NDArray[np.bool_],
        steps: NDArray[np.int64],
    ) -> Array:
        """One step for the fleets whose states are given; updates them in place."""
        local = self._local(batch)
        cooperation = self.cooperation.step(local, states["vhat"], states["gamma"], steps)
        tau0, kinetic = self._kinetics(local, cooperation, states, started.copy())
        states["vhat"], states["gamma"] = cooperation.vhat_next, cooperation.gamma_next
        started[:] = True
        steps += 1
        actions = np.zeros((*batch.shape[:2], self.act_dim))
        actions[..., :3] = tau0
        actions[..., 3] = cooperation.theta_dot
        if self.act_dim > 4:
            actions[..., 4] = cooperation.vhat_next
        self.diagnostics = {
            **kinetic,
            "speed_estimate": cooperation.vhat,
            "tau_command": tau0,
            "omega_s": cooperation.omega_s,
            "gamma": cooperation.gamma,
        }
        return actions

    # --- helpers --------------------------------------------------------------------------

    def _local(self, batch: Array) -> LocalObservation:
        """The local observations (B, n, obs_dim) parsed into named arrays."""
        return LocalObservation.parse(self.layout, batch)

    def _validate(self, obs: ArrayLike) -> Array:
        """Check (B, n, obs_dim) and finiteness; return a float64 array."""
        batch = np.asarray(obs, dtype=np.float64)
        if batch.ndim != 3 or batch.shape[1:] != (self.n, self.obs_dim) or batch.shape[0] < 1:
            raise ValueError(
                f"observations must have shape (B, n, obs_dim) = (B, {self.n}, {self.obs_dim}) "
                f"with B >= 1 for scenario {self.scenario.name!r}, got {batch.shape}."
            )
        if not np.isfinite(batch).all():
            b, i, k = np.argwhere(~np.isfinite(batch))[0]
            raise ValueError(
                f"observation of fleet {b}, vessel_{i}, entry {k} ({self.layout.names()[k]}) "
                f"is {batch[b, i, k]}: observations must be finite."
            )
        return batch

    def _fleet_index(self, fleets: ArrayLike, rows: int) -> NDArray[np.int64]:
        """Validate fleet indices against the allocated batch and the number of rows."""
        index = np.asarray(fleets)
        num_fleets = self._started.shape[0] if self._states is not None else 0
        if (
            index.ndim != 1
            or index.shape[0] != rows
            or not np.issubdtype(index.dtype, np.integer)
            or np.any((index < 0) | (index >= num_fleets))
            or np.unique(index).shape[0] != index.shape[0]
        ):
            raise ValueError(
                f"fleets must be {rows} distinct integer indices in [0, {num_fleets}) of the "
                f"batch this policy holds states for, got {np.asarray(fleets).tolist()!r}; act "
                "once on the whole batch (fleets=None) to allocate the states first."
            )
        return index.astype(np.int64)

    def _states_for(self, num_fleets: int) -> dict[str, Array]:
        """The internal states, allocated (zeros) on first use; a new B needs a reset."""
        if self._states is None:
            shapes = {"vhat": (), "gamma": (), **self._kinetic_states()}
            self._states = {k: np.zeros((num_fleets, self.n, *s)) for k, s in shapes.items()}
            self._started = np.zeros(num_fleets, dtype=bool)
            self._steps = np.zeros(num_fleets, dtype=np.int64)
        elif self._started.shape[0] != num_fleets:
            raise ValueError(
                f"this policy holds internal states for B = {self._started.shape[0]} fleets but "
                f"got B = {num_fleets}; call reset() before changing the number of fleets."
            )
        return self._states
