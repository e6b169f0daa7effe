"""Common plumbing of the analytic policies: interface, internal states, input layouts.

A policy maps local observations to actions and keeps its own internal states
(filters, NN weights, speed estimates), one set per vessel of each of B
fleets. It reads nothing but the observation and the scenario's known
constants (nominal model, saturation limits, dt, message size) and never
touches a simulator.

Interface (``cpf_env.envs.policy.FleetPolicy``, shared with trained agents):

- ``act_batch(obs (B, n, obs_dim), fleets=None) -> (B, n, 4 + m)``: the core, float64;
- ``act(observations: dict) -> dict`` for the PettingZoo ``ParallelEnv`` (B = 1, float32);
- ``predict(obs, state, episode_start, deterministic)`` in the Stable-Baselines3 style,
  so ``stable_baselines3.common.evaluation.evaluate_policy`` runs it;
- ``reset(seed=None)`` / ``reset_fleets(mask)``: forget all / some fleets' internal states;
- ``diagnostics``: internal signals of the last ``act_batch``, leading axes (B, n).

Action of vessel i: [tau0 (3, N, N, N m, before saturation), theta_dot (1/s),
vhat_i(k + 1) (m/s), 0 ...]: the env saturates tau0 and integrates theta.

The equations run compiled (``baselines.kernels``): a policy here holds the
gains in kernel form (``PolicyConstants``), the internal states of B fleets
(``PolicyStates``) and the bookkeeping around them (validation, partial
fleets, restarts). A subclass either names a compiled kinetic part
(``kinetics``) or writes its own in Python (``_kinetic_states`` and
``_kinetics``, after the compiled cooperative layer; ``docs/extending.md``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baselines.cooperative import LocalObservation, exponential_euler
from baselines.gains import CooperativeGains
from baselines.kernel_types import (
    KINETICS_PYTHON,
    NO_KNOWLEDGE,
    CooperativeOutputs,
    KnownDynamics,
    PolicyConstants,
    PolicyOutputs,
    PolicyStates,
)
from baselines.kernels import act_rows, cooperative_rows
from cpf_env import scenarios
from cpf_env.envs.policy import FleetPolicy, fleet_mask
from cpf_env.model.vessel import PARAM_SIZE
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import observation_layout
from cpf_env.sim.threads import PARALLEL_MIN_FLEETS

__all__ = ["DIAGNOSTICS", "AnalyticPolicy", "resolve_scenario", "virtual_control"]

Array = NDArray[np.float64]

#: Names of ``AnalyticPolicy.diagnostics`` and their trailing shapes after (B, n).
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


class AnalyticPolicy(FleetPolicy):
    """Base class: gains in kernel form, the internal states and their bookkeeping.

    A subclass sets ``kinetics`` to a compiled kinetic part of
    ``baselines.kernels`` and fills its coefficients in ``_kinetic_constants``,
    or leaves ``KINETICS_PYTHON`` and implements ``_kinetic_states`` and
    ``_kinetics`` in numpy (they then run after the compiled cooperative layer).

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
    #: The kinetic part: one of ``baselines.kernels.KINETICS_*``.
    kinetics: ClassVar[int] = KINETICS_PYTHON
    #: True: each neighbour's received theta_j is advanced by its packet age x dt x its
    #: communicated speed estimate (``baselines.delay_compensated``).
    delay_compensation: ClassVar[bool] = False
    #: True: a headroom reference told what no vessel observes (``baselines.privileged``).
    privileged: ClassVar[bool] = False

    def __init__(self, env: object, **options: Any) -> None:
        self.scenario = resolve_scenario(env)
        self.gains = self.gains_type.from_options(options, owner=f"policy {self.name!r}")
        self.layout = observation_layout(self.scenario)
        self.n = self.scenario.n
        self.obs_dim = self.layout.size
        self.act_dim = 4 + self.scenario.message_size
        self.message_entries = min(1, self.scenario.message_size)
        self.dt = float(self.scenario.dt)
        self.agents = [f"vessel_{i}" for i in range(self.n)]
        if self.scenario.message_size < 1 and not self.global_speed:
            raise ValueError(
                f"policy {self.name!r} broadcasts its speed estimate and needs "
                "Scenario.message_size >= 1."
            )
        self.diagnostics: dict[str, Array] = {}
        self._constants = self._build_constants()
        self._states: PolicyStates | None = None
        self._python_states: dict[str, Array] = {}
        self._all_fleets = np.zeros(0, dtype=np.int64)

    # --- the kinetic part, given by subclasses -------------------------------------------

    def _kinetic_constants(self) -> dict[str, Any]:
        """Coefficients of a compiled kinetic part: fields of ``PolicyConstants``."""
        return {}

    def _hidden_units(self) -> int:
        """Number l of NN hidden units whose weights the states hold (0: no NN)."""
        return 0

    def _kinetic_states(self) -> dict[str, tuple[int, ...]]:
        """Python kinetic part: internal states, name -> shape per vessel (all start at 0)."""
        return {}

    def _kinetics(
        self,
        obs: LocalObservation,
        cooperation: CooperativeOutputs,
        states: dict[str, Array],
        started: NDArray[np.bool_],
    ) -> tuple[Array, dict[str, Array]]:
        """Python kinetic part: the force command of step k; advances ``states`` to k + 1.

        Args:
            obs: Local observations at step k.
            cooperation: This step's cooperative signals.
            states: Kinetic states at step k, (B, n, ...); replace entries with step k + 1.
            started: (B,) False for fleets acting for the first time since their reset.

        Returns:
            tau0 (B, n, 3) in N, N, N m, and the diagnostics "nn_output", "nubar_dot",
            "alpha", "aux_state".
        """
        raise NotImplementedError(
            f"policy {type(self).__name__} names no compiled kinetic part (kinetics) and "
            "implements no _kinetics: give one of the two."
        )

    # --- interface ------------------------------------------------------------------------

    def reset(self, seed: int | None = None) -> None:
        """Forget all internal states; they are re-initialized on the next act.

        Args:
            seed: Accepted for interface compatibility; the policies are
                deterministic (the NN input weights are fixed by ``nn_seed``).
        """
        del seed
        self._states = None
        self._python_states = {}
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
        batch = self._validate(self._observations(obs))
        if fleets is None:
            states = self._states_for(batch.shape[0])
            index = self._all_fleets
        else:
            index = self._fleet_index(fleets, batch.shape[0])
            states = self._states_for(self._all_fleets.shape[0])
        rows = batch.shape[0]
        out = self._new_outputs(rows)
        if self.kinetics == KINETICS_PYTHON:
            self._act_in_python(batch, index, states, out)
        else:
            act_rows(
                tuple(self._constants), tuple(states), batch, index,
                tuple(self._knowledge(index)), tuple(out), rows >= PARALLEL_MIN_FLEETS,
            )  # fmt: skip
        self.diagnostics = {name: getattr(out, name) for name in DIAGNOSTICS}
        return out.actions

    def _new_outputs(self, rows: int) -> PolicyOutputs:
        """Fresh output arrays for ``rows`` acting fleets (the diagnostics keep them)."""
        vectors = np.empty((5, rows, self.n, 3))  # one allocation per shape, C-contiguous slices
        scalars = np.empty((3, rows, self.n))
        return PolicyOutputs(
            actions=np.empty((rows, self.n, self.act_dim)),
            nn_output=vectors[0],
            nubar_dot=vectors[1],
            alpha=vectors[2],
            speed_estimate=scalars[0],
            aux_state=vectors[3],
            tau_command=vectors[4],
            omega_s=scalars[1],
            gamma=scalars[2],
        )

    def _observations(self, obs: ArrayLike) -> ArrayLike:
        """The observations the policy acts on: ``obs`` (a privileged reference substitutes)."""
        return obs

    def _knowledge(self, fleets: NDArray[np.int64]) -> KnownDynamics:
        """What the policy is told beyond its observation for the acting ``fleets``: nothing."""
        del fleets
        return NO_KNOWLEDGE

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Restart the internal states of some fleets; the others are untouched.

        Args:
            fleets: (B,) bool mask, or indices, of the fleets to restart. Their
                states are re-initialized on their next act, as after ``reset()``.
        """
        if self._states is None:
            return
        num_fleets = self._all_fleets.shape[0]
        mask = fleet_mask(fleets, num_fleets)
        for array in (*self._states, *self._python_states.values()):
            array[mask] = 0  # started -> False, steps -> 0, every state -> 0

    # --- helpers --------------------------------------------------------------------------

    def _build_constants(self) -> PolicyConstants:
        """The gains and fixed coefficients in kernel form (cooperative part + kinetic part)."""
        g = self.gains
        gamma_decay, gamma_gain = exponential_euler(g.k4, self.dt)
        schedule = self.scenario.v0_schedule
        fields: dict[str, Any] = {
            "kinetics": self.kinetics,
            "use_nn": False,
            "use_aux": False,
            "global_speed": self.global_speed,
            "delay_compensation": self.delay_compensation,
            "privileged": self.privileged,
            "n_slots": self.layout.n_slots,
            "slot_size": self.layout.slot_size,
            "msg_size": self.layout.msg_size,
            "dt": self.dt,
            "k1": np.zeros(3),
            "k2": np.zeros(3),
            "k3": float(g.k3),
            "k5": float(g.k5),
            "k6": float(g.k6),
            "gamma_decay": float(gamma_decay),
            "gamma_gain": float(gamma_gain),
            "rho": 1.0,
            "filter_decay": 0.0,
            "aux_decay": np.zeros(3),
            "aux_gain": np.zeros(3),
            "leak_decay": 0.0,
            "adapt_gain": 0.0,
            "input_weights": np.zeros((0, 7)),
            "mass": np.zeros((self.n, 3, 3)),
            "hydro_params": np.zeros((self.n, PARAM_SIZE)),
            "v0_times": np.array(schedule.times, dtype=np.float64),
            "v0_values": np.array(schedule.values, dtype=np.float64),
        }
        fields.update(self._kinetic_constants())
        return PolicyConstants(**fields)

    def _act_in_python(
        self, batch: Array, index: NDArray[np.int64], states: PolicyStates, out: PolicyOutputs
    ) -> None:
        """The compiled cooperative layer, then the subclass's ``_kinetics`` in numpy."""
        rows = batch.shape[0]
        cooperation = CooperativeOutputs(*(np.empty((rows, self.n)) for _ in range(9)))
        cooperative_rows(self._constants, states, batch, index, cooperation)
        kinetic_states = {key: value[index] for key, value in self._python_states.items()}
        local = LocalObservation.parse(self.layout, batch)
        tau0, kinetic = self._kinetics(
            local,
            cooperation,
            kinetic_states,
            states.started[index].copy(),
        )
        for key, value in kinetic_states.items():
            self._python_states[key][index] = value
        states.vhat[index], states.gamma[index] = cooperation.vhat_next, cooperation.gamma_next
        states.started[index] = True
        states.steps[index] += 1
        out.actions[...] = 0.0
        out.actions[..., :3] = tau0
        out.actions[..., 3] = cooperation.theta_dot
        if self.act_dim > 4:
            out.actions[..., 4] = cooperation.vhat_next
        for name in ("nn_output", "nubar_dot", "alpha", "aux_state"):
            getattr(out, name)[...] = kinetic[name]
        out.speed_estimate[...] = cooperation.vhat
        out.tau_command[...] = tau0
        out.omega_s[...] = cooperation.omega_s
        out.gamma[...] = cooperation.gamma

    def _validate(self, obs: ArrayLike) -> Array:
        """Check (B, n, obs_dim) and finiteness; return a C-contiguous float64 array."""
        batch = np.ascontiguousarray(obs, dtype=np.float64)
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
        num_fleets = self._all_fleets.shape[0] if self._states is not None else 0
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

    def _states_for(self, num_fleets: int) -> PolicyStates:
        """The internal states, allocated (zeros) on first use; a new B needs a reset."""
        if self._states is None:
            shape = (num_fleets, self.n)
            self._states = PolicyStates(
                vhat=np.zeros(shape),
                gamma=np.zeros(shape),
                nubar=np.zeros((*shape, 3)),
                pi=np.zeros((*shape, 3)),
                weights=np.zeros((*shape, self._hidden_units(), 3)),
                tau0=np.zeros((*shape, 3)),
                started=np.zeros(num_fleets, dtype=bool),
                steps=np.zeros(num_fleets, dtype=np.int64),
            )
            self._python_states = {
                key: np.zeros((*shape, *s)) for key, s in self._kinetic_states().items()
            }
            self._all_fleets = np.arange(num_fleets, dtype=np.int64)
        elif self._all_fleets.shape[0] != num_fleets:
            raise ValueError(
                f"this policy holds internal states for B = {self._all_fleets.shape[0]} fleets "
                f"but got B = {num_fleets}; call reset() before changing the number of fleets."
            )
        return self._states
