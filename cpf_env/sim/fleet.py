"""``FleetSim``: B independent fleets of n vessels, stepped together.

The simulator owns the state arrays (leading axis B) and calls the fused
kernel of ``cpf_env.sim.kernels`` once per control step. It knows nothing about
Gym: the PettingZoo env is ``FleetSim`` with B = 1, and the vector envs use
B > 1. Fleet k of a batched simulator and a single simulator reset with the
same seed produce bit-identical trajectories.

Example:
    >>> import numpy as np
    >>> from cpf_env import scenarios
    >>> sim = FleetSim(scenarios.get("wang2014"), num_fleets=4)
    >>> obs = sim.reset(seeds=[0, 1, 2, 3])
    >>> obs.shape
    (4, 5, 26)
    >>> obs = sim.step(np.zeros((4, 5, sim.act_dim)))
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpf_env.model import graph, vessel
from cpf_env.model.paths import encode_paths
from cpf_env.model.vessel import PARAM_SIZE
from cpf_env.scenarios import Scenario
from cpf_env.scenarios.reward_weights import REWARD_TERMS
from cpf_env.sim import arrays, kernels
from cpf_env.sim.arrays import FleetArrays, KernelConstants
from cpf_env.sim.observation import ObsLayout
from cpf_env.sim.threads import PARALLEL_MIN_FLEETS

__all__ = ["PARALLEL_MIN_FLEETS", "FleetSim", "as_real_actions", "check_seed", "observation_layout"]

#: Names of the integrated state per vessel, as (array, component, what it is).
_STATE_NAMES = (
    ("eta", 0, "x position"),
    ("eta", 1, "y position"),
    ("eta", 2, "heading psi"),
    ("nu", 0, "surge velocity u"),
    ("nu", 1, "sway velocity v"),
    ("nu", 2, "yaw rate r"),
)


def as_real_actions(actions: object, what: str = "actions") -> NDArray[np.float64]:
    """``actions`` as a float64 array, or ValueError if they are not real numbers.

    Complex values are rejected rather than silently losing their imaginary
    part; so are bools (a force of ``True`` is never meant: every route refuses
    them), strings, None and other non-numeric objects.
    """
    array = np.asarray(actions)
    if array.dtype.kind not in "iuf":
        kind = {"b": "bools are not commands", "c": "complex values"}.get(
            array.dtype.kind, "not numbers"
        )
        raise ValueError(f"{what} must be real numbers, got dtype {array.dtype} ({kind}).")
    return array.astype(np.float64)


def observation_layout(scenario: Scenario) -> ObsLayout:
    """The ``ObsLayout`` of a scenario's vessels (K = largest degree of its topology)."""
    slots = graph.neighbour_slots(scenario.switching)
    return ObsLayout(n_slots=slots.shape[1], msg_size=scenario.message_size)


def _floats(value: ArrayLike) -> NDArray[np.float64]:
    """``value`` as a C-contiguous float64 array (one numba type for every scenario)."""
    return np.ascontiguousarray(value, dtype=np.float64)


def check_seed(seed: object, what: str = "seed") -> int | None:
    """``seed`` as a python int (numpy ints welcome) or None; ValueError for anything else.

    Raises:
        ValueError: A bool, a float, a string, a negative integer ...; the message says
            what a seed must be.
    """
    if seed is None:
        return None
    if isinstance(seed, bool | np.bool_) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"{what} must be an integer >= 0 or None, got {seed!r}.")
    return int(seed)


def _seeds(seeds: object, count: int) -> list[int | None]:
    """``count`` reset seeds checked whole: each a Python or numpy integer >= 0, or None.

    Raises:
        ValueError: Not a sequence of ``count`` entries, or an entry that is a bool, a
            float, a string or a negative integer (named by its position).
    """
    if isinstance(seeds, str | bytes) or not isinstance(seeds, Sequence | np.ndarray):
        raise ValueError(
            f"seeds must be a list of one integer >= 0 (or None) per reset fleet, got {seeds!r}."
        )
    checked = list(seeds)
    if len(checked) != count:
        raise ValueError(f"got {len(checked)} seeds for {count} fleets; give one per fleet.")
    return [check_seed(seed, f"seeds[{k}]") for k, seed in enumerate(checked)]


def _ints(value: ArrayLike) -> NDArray[np.int64]:
    """``value`` as a C-contiguous int64 array (one numba type for every scenario)."""
    return np.ascontiguousarray(value, dtype=np.int64)


def _separation(scenario: Scenario) -> tuple[float, float, float]:
    """The separation constraint in kernel form: safe and hard distance (m), weight; zeros: none."""
    sep = scenario.separation
    if sep is None:
        return (0.0, 0.0, 0.0)
    return (sep.safe_distance, sep.hard_distance, sep.weight)


def _constants(scenario: Scenario) -> arrays.KernelConstants:
    """The scenario in kernel form.

    Every field has the same numba type whatever the scenario and fleet size
    (C-contiguous float64/int64 arrays of fixed ndim, python floats, ints and
    bools), so one compilation of the kernels serves every scenario: a
    strided table (a switching topology's slot weights were one) would make
    numba compile the whole step again.
    """
    topology = scenario.switching
    slots = graph.neighbour_slots(topology)
    switch_steps, period = graph.switch_table(topology)
    kinds, path_params = encode_paths(scenario.paths)
    tau_min, tau_max = scenario.tau_limits
    return arrays.KernelConstants(
        tau_min=_floats(tau_min),
        tau_max=_floats(tau_max),
        tau_scale=_floats(scenario.tau_scale),
        thruster_decay=float(scenario.thrusters.decay(scenario.dt)),
        thruster_slew=_floats(scenario.thrusters.slews(scenario.dt)),
        instant_thrusters=bool(scenario.thrusters.instant),
        ideal_sensors=bool(scenario.sensors.ideal),
        fix_noise=_floats(scenario.sensors.fix_std),
        fix_period=int(scenario.sensors.period),
        fix_dropout=float(scenario.sensors.dropout),
        velocity_measured=bool(scenario.sensors.velocity),
        separation=_floats(_separation(scenario)),
        theta_dot_max=float(scenario.theta_dot_max),
        message_max=float(scenario.message_max),
        path_kinds=_ints(kinds),
        path_params=_floats(path_params),
        disturbances=_floats(scenario.disturbances.encode()),
        slots=_ints(slots),
        slot_weights=_floats(graph.slot_weights(topology, slots)),
        leaders=_floats(graph.leader_schedule(topology)),
        switch_steps=_ints(switch_steps),
        switch_period=int(period),
        loss_probability=float(scenario.links.loss_probability),
        delay=int(scenario.links.delay_steps),
        v0_times=_floats(scenario.v0_schedule.times),
        v0_values=_floats(scenario.v0_schedule.values),
        dt=float(scenario.dt),
        substeps=int(scenario.substeps),
        reward_params=_floats(scenario.reward.encode()),
        team_reward=bool(scenario.reward.team),
        max_path_error=float(scenario.max_path_error),
        max_steps=int(scenario.max_steps),
    )


class FleetSim:
    """Batched simulator of B fleets x n vessels (no Gym code).

    Args:
        scenario: The task.
        num_fleets: Number of independent fleets B.

    Attributes:
        scenario: The task.
        num_fleets: B.
        n: Vessels per fleet.
        layout: Observation layout (``ObsLayout``).
        obs_dim: Observation length per vessel.
        act_dim: Action length per vessel, 4 + m: (tau0 (3), theta_dot, message (m)).
        arrays: The state and outputs (``arrays.FleetArrays``); read, do not write
            (read-only attribute: the kernels are handed these very arrays).
        constants: The scenario in kernel form (read-only attribute, as ``arrays``).
    """

    def __init__(self, scenario: Scenario, num_fleets: int = 1) -> None:
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a Scenario, got {type(scenario).__name__}.")
        if int(num_fleets) < 1:
            raise ValueError(f"num_fleets must be >= 1, got {num_fleets}.")
        self.scenario = scenario
        self.num_fleets = B = int(num_fleets)
        self.n = n = scenario.n
        self._constants = _constants(scenario)
        m = scenario.message_size
        self.layout = observation_layout(scenario)
        self.obs_dim = self.layout.size
        self.act_dim = 4 + m
        self._action_shape = (B, n, self.act_dim)
        K = self.layout.n_slots
        self._nominal_params = np.stack([v.to_params() for v in scenario.vessel_models])
        self._arrays = arrays.FleetArrays(
            eta=np.zeros((B, n, 3)),
            nu=np.zeros((B, n, 3)),
            theta=np.zeros((B, n)),
            theta_dot=np.zeros((B, n)),
            tau_command=np.zeros((B, n, 3)),
            tau_applied=np.zeros((B, n, 3)),
            fix=np.zeros((B, n, 3)),
            message=np.zeros((B, n, m)),
            waves=np.zeros((B, n, 3)),
            wind=np.zeros((B, n, 3)),
            current=np.zeros((B, 2)),
            step=np.zeros(B, dtype=np.int64),
            key=np.zeros(B, dtype=np.uint64),
            params=np.broadcast_to(self._nominal_params, (B, n, PARAM_SIZE)).copy(),
            recv_theta=np.zeros((B, n, K)),
            recv_message=np.zeros((B, n, K, m)),
            recv_step=np.zeros((B, n, K), dtype=np.int64),
            history=np.zeros((B, scenario.links.delay_steps + 1, n, 1 + m)),
            obs=np.zeros((B, n, self.obs_dim), dtype=np.float32),
            reward=np.zeros((B, n)),
            reward_terms=np.zeros((B, n, len(REWARD_TERMS))),
            errors=np.zeros((B, n, 4)),
            terminated=np.zeros(B, dtype=bool),
            nonfinite=np.zeros(B, dtype=bool),
        )
        # the kernels take plain tuples of the same arrays (cheaper to dispatch, see kernels)
        self._array_fields = tuple(self._arrays)
        self._constant_fields = tuple(self._constants)
        parallel = B >= PARALLEL_MIN_FLEETS
        self._step_kernel = kernels.step_fleets_parallel if parallel else kernels.step_fleets_serial
        self._observe_kernel = (
            kernels.observe_fleets_parallel if parallel else kernels.observe_fleets_serial
        )
        self._rngs = [np.random.default_rng() for _ in range(B)]
        self._needs_reset = True

    @property
    def arrays(self) -> FleetArrays:
        """The state and per-step outputs (leading axis B; see ``arrays.FleetArrays``)."""
        return self._arrays

    @property
    def constants(self) -> KernelConstants:
        """The scenario in kernel form (``arrays.KernelConstants``)."""
        return self._constants

    @property
    def rngs(self) -> list[np.random.Generator]:
        """Per-fleet generators used at reset (initial states, models, RNG keys)."""
        return self._rngs

    @property
    def started(self) -> bool:
        """True once ``reset()`` has been called (the arrays hold an episode)."""
        return not self._needs_reset

    @property
    def time(self) -> NDArray[np.float64]:
        """Simulated time of each fleet (s), shape (B,)."""
        return self.arrays.step * self.scenario.dt

    def v0_at(self, time: float) -> float:
        """Leader speed (m/s) at ``time`` (s)."""
        return self.scenario.v0_schedule.at(time)

    def reset(
        self,
        seeds: Sequence[int | None] | None = None,
        fleets: ArrayLike | None = None,
    ) -> NDArray[np.float32]:
        """Reset some or all fleets and return all observations.

        Args:
            seeds: One seed per reset fleet; None (or a None entry) keeps that
                fleet's generator running, as Gymnasium does on reset without seed.
            fleets: Indices of the fleets to reset (default: all).

        Returns:
            Observations of every fleet, shape (B, n, obs_dim), float32 (a view;
            copy it if you keep it across steps).

        Raises:
            ValueError: Bad fleet indices, or seeds that are not one integer >= 0 (or None)
                per fleet; every seed is checked before any fleet is reset, so a refused
                call leaves the simulator as it was.
        """
        index = np.arange(self.num_fleets) if fleets is None else _ints(fleets)
        if index.ndim != 1 or np.any((index < 0) | (index >= self.num_fleets)):
            raise ValueError(f"fleets must be indices in [0, {self.num_fleets}), got {fleets!r}.")
        seeds = [None] * len(index) if seeds is None else _seeds(seeds, len(index))
        for b, seed in zip(index, seeds, strict=True):
            if seed is not None:
                self._rngs[b] = np.random.default_rng(seed)
            self._reset_fleet(int(b), self._rngs[b])
        self._observe_kernel(self._array_fields, self._constant_fields, index)
        self._needs_reset = False
        return self.arrays.obs

    def _reset_fleet(self, b: int, rng: np.random.Generator) -> None:
        """Draw fleet b's episode: RNG key, true models, initial state, disturbance states."""
        a, s = self.arrays, self.scenario
        a.key[b] = rng.integers(0, 2**63, dtype=np.uint64)
        if s.model_spread > 0.0:
            a.params[b] = [v.perturbed(rng, s.model_spread).to_params() for v in s.vessel_models]
        eta, nu, theta = s.initial.sample(rng)
        a.eta[b], a.nu[b], a.theta[b] = eta, nu, theta
        d = s.disturbances
        for state, process in ((a.waves, d.waves), (a.wind, d.wind)):
            state[b] = np.array(process.mean) + np.array(process.std) * rng.standard_normal(
                (self.n, 3)
            )
        a.current[b] = np.array(d.current.velocity) + d.current.std * rng.standard_normal(2)
        a.theta_dot[b] = 0.0
        a.tau_command[b] = 0.0
        a.tau_applied[b] = 0.0
        a.message[b] = 0.0
        a.step[b] = 0
        slots = self.constants.slots
        a.recv_theta[b] = np.where(slots >= 0, theta[np.maximum(slots, 0)], 0.0)
        a.recv_message[b] = 0.0
        a.recv_step[b] = 0
        a.history[b] = 0.0
        a.terminated[b] = False
        a.nonfinite[b] = False

    def validate_actions(self, actions: ArrayLike) -> NDArray[np.float64]:
        """Check an action batch and return it as float64 (B, n, act_dim).

        Raises:
            ValueError: Wrong shape, bools, complex values or a non-finite entry (naming
                fleet, vessel, component).
        """
        array = as_real_actions(actions)
        expected = self._action_shape
        if array.shape != expected:
            raise ValueError(
                f"actions must have shape (B, n, 4 + m) = {expected}, got {array.shape}."
            )
        if not np.isfinite(array).all():  # the index search only on the error path
            b, i, k = np.argwhere(~np.isfinite(array))[0]
            raise ValueError(
                f"action of fleet {b}, vessel_{i}, component {k} is {array[b, i, k]}: "
                "actions must be finite."
            )
        return np.ascontiguousarray(array)

    def step(self, actions: ArrayLike) -> NDArray[np.float32]:
        """Advance every fleet one control period and return the observations.

        Args:
            actions: Shape (B, n, 4 + m): force command (N, N, N m), path-variable
                rate (1/s) and message per vessel. Commands beyond the limits are
                saturated by the plant; rate and message are clipped.

        Returns:
            Observations (B, n, obs_dim) float32, a view of ``arrays.obs``. Rewards,
            errors and flags are in ``arrays``.

        Raises:
            ValueError: Bad actions (state untouched).
            RuntimeError: Stepping before reset; a fleet that diverged and was not
                reset; or the plant diverged in this step (the message names fleet,
                vessel and quantity and what to change). Fleets that diverged must be
                reset before the simulator steps again.
        """
        if self._needs_reset:
            raise RuntimeError("call reset() before step().")
        array = np.asarray(actions)
        if array.dtype.kind not in "iuf" or array.shape != self._action_shape:
            self._refuse_diverged_fleets()  # raises first, as it always did, if one diverged
            self.validate_actions(array)  # raises: not real numbers, or the wrong shape
        validated = np.array(array, dtype=np.float64, order="C")  # a copy, as validate_actions
        outcome = self._step_kernel(self._array_fields, self._constant_fields, validated)
        if outcome == kernels.DIVERGED_BEFORE:
            self._refuse_diverged_fleets()  # raises
        if outcome == kernels.NONFINITE_ACTION:
            self.validate_actions(validated)  # raises, naming the first non-finite entry
        if outcome == kernels.DIVERGED:
            raise RuntimeError(self.divergence_message())
        return self._arrays.obs

    def _refuse_diverged_fleets(self) -> None:
        """RuntimeError if a fleet diverged and has not been reset since."""
        if self._arrays.nonfinite.any():
            fleets = np.flatnonzero(self._arrays.nonfinite).tolist()
            raise RuntimeError(
                f"fleet(s) {fleets} diverged and have not been reset; reset them "
                "(reset(fleets=...)) before stepping again."
            )

    def divergence_message(self) -> str:
        """Say which fleet, vessel and quantity became non-finite, and what to change.

        For a simulator in which ``arrays.nonfinite`` holds for some fleet.
        """
        a, s = self.arrays, self.scenario
        b = int(np.flatnonzero(a.nonfinite)[0])
        bad = np.argwhere(~np.isfinite(np.concatenate([a.eta[b], a.nu[b]], axis=1)))
        vessel, column = (int(x) for x in bad[0])
        quantity = _STATE_NAMES[column][2]
        others = sorted({int(i) for i in bad[:, 0]} - {vessel})
        return (
            f"the plant diverged in fleet {b}: the {quantity} of vessel_{vessel} became "
            f"non-finite at step {int(a.step[b])} (t = {a.step[b] * s.dt:g} s)"
            + (f", and the state of vessel(s) {others} too" if others else "")
            + f". Either the RK4 sub-step dt / substeps = {s.dt:g} / {s.substeps} s is too "
            "long for the forces at that state (quadratic damping and the paper's cubic "
            f"unmodeled terms, times unmodeled_scale = {s.disturbances.unmodeled_scale:g}, grow "
            "with speed), or the commands drove the vessel to extreme speeds. Use more "
            "substeps or a smaller dt, a smaller unmodeled_scale or milder model parameters, "
            "or check the policy. Reset the fleet to continue."
        )

    def accelerations(self, tau: ArrayLike | None = None) -> NDArray[np.float64]:
        """True accelerations nu' (B, n, 3) at the current state (m/s^2, m/s^2, rad/s^2).

        Args:
            tau: Applied force (B, n, 3) in N, N, N m; default the last applied force.
        """
        force = self.arrays.tau_applied if tau is None else np.asarray(tau, dtype=np.float64)
        out = np.empty_like(self.arrays.nu)
        kernels.plant_accelerations(self.arrays, self.constants, np.ascontiguousarray(force), out)
        return out

    def mass_matrices(self) -> NDArray[np.float64]:
        """True mass matrices M (B, n, 3, 3) of this episode's vessels (kg, kg m, kg m^2)."""
        p = self.arrays.params
        out = np.zeros(p.shape[:2] + (3, 3))
        out[..., 0, 0] = p[..., vessel.M11]
        out[..., 1, 1], out[..., 1, 2] = p[..., vessel.M22], p[..., vessel.M23]
        out[..., 2, 1], out[..., 2, 2] = p[..., vessel.M32], p[..., vessel.M33]
        return out

    @property
    def truncated(self) -> NDArray[np.bool_]:
        """Fleets that reached ``max_steps`` without terminating, shape (B,).

        Termination wins: a fleet that leaves its path on the last step is
        terminated, not truncated.
        """
        return (self.arrays.step >= self.scenario.max_steps) & ~self.arrays.terminated
