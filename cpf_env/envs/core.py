"""The episode core: B fleets' episodes over one ``FleetSim``, under every library route.

Every route (the PettingZoo ``ParallelEnv`` and its AEC form, the Gymnasium
views, the SB3 ``FleetVecEnv`` and its mixture, ``TorchRLFleetEnv``, the
BenchMARL tasks, the RLlib glue) is an adapter over one ``EpisodeCore``; the
rules below live here once, so "the same scenario" gives the same episodes
whichever library steps it:

- **Seeding**: ``reset(seeds=s)`` (or ``reseed(s)``) gives fleet k the
  generator ``default_rng(s + k)``; a reset without seed continues each
  fleet's generator. Seeds are checked whole (integers >= 0, not bool)
  before any fleet is touched.
- **Horizons and stagger**: a fleet's episode is truncated after
  ``horizon[k]`` control steps (``max_steps``). With ``stagger`` (the
  default), every reset of all fleets sets ``horizon[k] = max_steps - k *
  max_steps // B``, so fleets do not end in lockstep and a batch of steps
  sees every phase of an episode; a fleet reset alone runs ``max_steps``.
  With one fleet, stagger changes nothing.
- **Per-fleet resets**: ``reset(fleets=...)`` restarts the listed fleets, their
  base policy's states and their horizons; the others go on.
- **Residual composition**: with a base policy (or a ``ResidualConfig``), the
  action is the learner's correction and the observation its input
  (``cpf_env.envs.residual``); without either, the action is the raw command.
- **Terminal observations**: ``reset_ended()`` returns the last inputs of the
  fleets that ended, then resets them (SB3's same-step convention); routes
  with another convention reset through ``reset(fleets=...)``.
- **Infos as arrays**: ``info_arrays(level)``, (B, n, ...) per quantity, at one
  of ``INFO_LEVELS``; each adapter converts them to its library's form.
- **Refusals**: seeds and actions are validated whole before anything is
  written, so a refused call leaves the state bit-identical.

Example:
    >>> import numpy as np
    >>> from cpf_env import scenarios
    >>> core = EpisodeCore(scenarios.get("wang2014").replace(max_steps=40), num_fleets=4)
    >>> core.reset(seeds=0).shape  # fleet k seeded 0 + k
    (4, 5, 26)
    >>> core.horizon.tolist()  # staggered: max_steps - k * max_steps // B
    [40, 30, 20, 10]
    >>> core.step(np.zeros((4, 5, core.action_size)))
    >>> core.ended.tolist()
    [False, False, False, False]
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig, ResidualController, learner_config
from cpf_env.scenarios import Scenario
from cpf_env.sim import arrays
from cpf_env.sim.fleet import FleetSim, check_seed

__all__ = [
    "DEFAULT_INFO_LEVEL",
    "INFO_LEVELS",
    "EpisodeCore",
    "action_bounds",
    "check_flag",
    "check_info_level",
    "check_num_fleets",
    "checked_actions",
]

#: Detail levels of the infos, least to most: nothing, the four errors, every diagnostic.
#: Every route takes the same names and the same default: the hot path (``"none"``); the
#: arrays stay readable from ``EpisodeCore.info_arrays`` (and ``core.sim.arrays``).
INFO_LEVELS = ("none", "minimal", "full")
DEFAULT_INFO_LEVEL = "none"


def check_info_level(info_level: object) -> str:
    """``info_level`` if it is one of ``INFO_LEVELS``, else ValueError."""
    if info_level not in INFO_LEVELS:
        raise ValueError(
            f"info_level must be one of {INFO_LEVELS}, got {info_level!r}: 'none' (the "
            "default) for empty infos, 'minimal' for the four errors, 'full' for every "
            "diagnostic."
        )
    return str(info_level)


def check_num_fleets(num_fleets: object, what: str = "num_fleets") -> int:
    """``num_fleets`` as an int >= 1, else ValueError."""
    if (
        isinstance(num_fleets, bool | np.bool_)
        or not isinstance(num_fleets, int | np.integer)
        or num_fleets < 1
    ):
        raise ValueError(f"{what} must be an integer >= 1, got {num_fleets!r}.")
    return int(num_fleets)


def check_flag(value: object, name: str) -> bool:
    """``value`` as a bool if it is one (numpy bools welcome), else ValueError."""
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"{name} must be True or False, got {value!r}.")
    return bool(value)


def action_bounds(scenario: Scenario) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Per-vessel bounds of the raw command, those of the ParallelEnv's ``action_space``.

    Returns:
        (low, high), each float32 of shape (n, 4 + m): the force limits (N, N, N m),
        +-theta_dot_max (1/s) and +-message_max. Forces beyond the limits are legal
        (the plant saturates them); rate and message are clipped. An axis without an
        actuator (limits 0, an underactuated hull) is given +-1 N, its ``tau_scale``:
        every command there applies nothing, and a Box whose bounds are equal breaks
        samplers and Gymnasium's environment checker.
    """
    tau_min, tau_max = scenario.tau_limits
    actuated = scenario.actuated
    tau_min, tau_max = np.where(actuated, tau_min, -1.0), np.where(actuated, tau_max, 1.0)
    n, m = scenario.n, scenario.message_size
    rate = np.full((n, 1), scenario.theta_dot_max)
    message = np.full((n, m), scenario.message_max)
    low = np.concatenate([tau_min, -rate, -message], axis=1).astype(np.float32)
    high = np.concatenate([tau_max, rate, message], axis=1).astype(np.float32)
    return low, high


def checked_actions(
    actions: ArrayLike,
    expected: tuple[int, ...],
    form: str,
    axes: tuple[str, ...],
    finite: bool = True,
) -> NDArray[Any]:
    """``actions`` as an array of shape ``expected`` (not copied), checked whole.

    Args:
        actions: The actions as given.
        expected: The required shape.
        form: How the message writes the shape, e.g. ``"(B, n, k)"``.
        axes: How the message names an index along each axis, e.g. ``"fleet {}"``.
        finite: Also check that every entry is finite.

    Raises:
        ValueError: Wrong shape, not real numbers (bools, complex, strings), or a
            non-finite entry (named along ``axes``).
    """
    array = np.asarray(actions)
    if array.dtype.kind not in "iuf":
        kind = {"b": "bools are not commands", "c": "complex values"}.get(
            array.dtype.kind, "not numbers"
        )
        raise ValueError(f"actions must be real numbers, got dtype {array.dtype} ({kind}).")
    if array.shape != expected:
        raise ValueError(f"actions must have shape {form} = {expected}, got {array.shape}.")
    if finite and not np.isfinite(array).all():
        where = np.argwhere(~np.isfinite(array))[0]
        place = ", ".join(name.format(k) for name, k in zip(axes, where, strict=True))
        raise ValueError(f"action of {place} is {array[tuple(where)]}: actions must be finite.")
    return array


class EpisodeCore:
    """The episodes of B fleets: seeding, horizons, stagger, resets, residual, infos.

    Args:
        scenario: The task (resolve names with ``cpf_env.scenarios.make_scenario``).
        num_fleets: B.
        base_policy: A ``FleetPolicy`` acting underneath (residual form), or None.
        residual: The composition (``ResidualConfig``); with no base policy, the
            learner commands forces and rate itself (``learner_config``).
            Neither given: the raw form, actions are the whole command.
        stagger: Spread the horizons over the fleets at every reset of all fleets.

    Attributes:
        scenario: The task.
        sim: The ``FleetSim`` (its ``arrays`` hold every state and output).
        controller: The ``ResidualController``, or None in the raw form.
        num_fleets: B.
        n: Vessels per fleet.
        horizon: (B,) int, the step at which each fleet's episode is truncated.
        last_base_actions: (B, n, 4 + m) the base's commands of the last step
            (residual form).
        last_residual: (B, n, k) the last correction in physical units, learned messages
            aside (residual form).
    """

    def __init__(
        self,
        scenario: Scenario,
        num_fleets: int = 1,
        base_policy: FleetPolicy | None = None,
        residual: ResidualConfig | None = None,
        stagger: bool = True,
    ) -> None:
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario must be a Scenario, got {type(scenario).__name__}.")
        self.scenario = scenario
        self.num_fleets = B = check_num_fleets(num_fleets)
        self.n = scenario.n
        self.stagger = check_flag(stagger, "stagger")
        if isinstance(base_policy, str):
            raise TypeError(
                f"base_policy={base_policy!r} is a name, and the environment layer takes "
                "policy objects: build one with baselines.make_policy(name, scenario), or "
                "use a learning route of the agents package (agents.envs.vec_env.FleetVecEnv, "
                "agents.marl.envs.make_env), which resolves names."
            )
        if base_policy is not None and not isinstance(base_policy, FleetPolicy):
            raise TypeError(
                "base_policy must be a policy object (act_batch, reset, reset_fleets, "
                f"diagnostics), got {type(base_policy).__name__}."
            )
        self.sim = FleetSim(scenario, num_fleets=B)
        raw = base_policy is None and residual is None
        config = None if raw else learner_config(base_policy, residual)
        self.controller = (
            None if config is None else ResidualController(scenario, base_policy, B, config)
        )
        self.horizon = np.full(B, scenario.max_steps, dtype=np.int64)
        self._inputs = np.zeros((B, self.n, self.input_size), dtype=np.float32)
        self.last_base_actions = np.zeros((B, self.n, self.sim.act_dim))
        width = self.action_size if self.controller is None else self.controller.residual.shape[-1]
        self.last_residual = np.zeros((B, self.n, width))

    @property
    def inputs(self) -> NDArray[np.float32]:
        """(B, n, input_size) float32: the last observations or learner inputs.

        In the raw form, the simulator's own observation array. Copy what you keep
        across steps.
        """
        return self.sim.arrays.obs if self.controller is None else self._inputs

    @property
    def input_size(self) -> int:
        """d, each vessel's observation (raw) or learner input (residual) length."""
        return self.sim.obs_dim if self.controller is None else self.controller.input_size

    @property
    def action_size(self) -> int:
        """a, each vessel's action length: 4 + m raw, k + learned messages residual."""
        return self.sim.act_dim if self.controller is None else self.controller.action_size

    def action_bounds(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """(low, high) of each vessel's action, (n, a) float32: raw bounds, or +-1 residual."""
        if self.controller is None:
            return action_bounds(self.scenario)
        ones = np.ones((self.n, self.action_size), dtype=np.float32)
        return -ones, ones

    # --- seeding and resets ---------------------------------------------------------------

    def fleet_seeds(
        self, seeds: int | Sequence[int | None] | None, fleets: NDArray[np.int64]
    ) -> list[int | None]:
        """One checked seed per fleet in ``fleets``: an int s gives fleet k the seed s + k.

        Raises:
            ValueError: A bad seed, or a sequence of the wrong length (nothing changed).
        """
        if seeds is None:
            return [None] * len(fleets)
        if isinstance(seeds, int | np.integer) and not isinstance(seeds, bool | np.bool_):
            first = check_seed(seeds)
            assert first is not None
            return [first + int(k) for k in fleets]
        if isinstance(seeds, str) or not isinstance(seeds, Sequence | np.ndarray):
            raise ValueError(
                f"seed must be an integer >= 0, None, or one per fleet reset, got {seeds!r}."
            )
        listed = list(seeds)
        if len(listed) != len(fleets):
            raise ValueError(
                f"got {len(listed)} seeds for {len(fleets)} fleets; give one per fleet."
            )
        return [
            check_seed(seed, f"seed of fleet {k}") for seed, k in zip(listed, fleets, strict=True)
        ]

    def reseed(self, seed: int | None) -> None:
        """Fleet k draws its next episodes from ``default_rng(seed + k)``; None: fresh entropy.

        Raises:
            ValueError: ``seed`` is not an integer >= 0 or None (nothing is reseeded).
        """
        checked = check_seed(seed)
        if checked is None:
            checked = int(np.random.default_rng().integers(np.iinfo(np.uint32).max))
        for k in range(self.num_fleets):
            self.sim.rngs[k] = np.random.default_rng(checked + k)

    def reset(
        self,
        seeds: int | Sequence[int | None] | None = None,
        fleets: ArrayLike | None = None,
    ) -> NDArray[np.float32]:
        """Reset all fleets, or the listed ones, with their base policy's states and horizons.

        Args:
            seeds: None (each fleet's generator continues), an int s (fleet k gets
                s + k) or one seed (or None) per reset fleet.
            fleets: Indices of the fleets to reset (default: all, then staggered).

        Returns:
            ``inputs`` (B, n, input_size) float32 (the array itself; copy to keep it).

        Raises:
            ValueError: A bad seed or fleet index; nothing is changed.
        """
        every = fleets is None
        index = np.arange(self.num_fleets) if fleets is None else self._fleet_index(fleets)
        seed_list = self.fleet_seeds(seeds, index)
        obs = self.sim.reset(seeds=seed_list, fleets=None if every else index)
        self.horizon[index] = self.scenario.max_steps
        self.last_base_actions[index] = 0.0
        self.last_residual[index] = 0.0
        if every:
            if self.stagger:
                self.horizon -= (
                    np.arange(self.num_fleets) * self.scenario.max_steps // self.num_fleets
                )
            if self.controller is not None:
                self.controller.reset(seed=seed_list[0])
            self._observe(obs, None)
        else:
            if self.controller is not None:
                mask = np.zeros(self.num_fleets, dtype=bool)
                mask[index] = True
                self.controller.reset_fleets(mask)
            self._observe(obs, index)
        return self.inputs

    def reset_ended(self) -> tuple[NDArray[np.int64], NDArray[np.float32]]:
        """Reset the fleets that ended on the last step; return them and their last inputs.

        Returns:
            (fleets (E,), terminal inputs (E, n, input_size) float32).
        """
        ended = self.ended
        if not ended.any():
            return np.zeros(0, dtype=np.int64), self.inputs[:0].copy()
        fleets = np.flatnonzero(ended)
        terminal = self.inputs[fleets].copy()
        self.reset(fleets=fleets)
        return fleets, terminal

    def _fleet_index(self, fleets: ArrayLike) -> NDArray[np.int64]:
        """Checked fleet indices (ValueError naming the range otherwise)."""
        index = np.asarray(fleets)
        if (
            index.dtype.kind not in "iu"
            or index.ndim != 1
            or np.any((index < 0) | (index >= self.num_fleets))
        ):
            raise ValueError(f"fleets must be indices in [0, {self.num_fleets}), got {fleets!r}.")
        return index.astype(np.int64)

    # --- stepping -------------------------------------------------------------------------

    def check_actions(self, actions: ArrayLike, finite: bool = True) -> NDArray[Any]:
        """The action batch (B, n, action_size) as an array, checked whole; changes nothing.

        Raises:
            ValueError: Wrong shape, not real numbers (bools, complex, strings), or (with
                ``finite``) a non-finite entry (named by fleet, vessel, component).
        """
        form = "(B, n, 4 + m)" if self.controller is None else "(B, n, k)"
        expected = (self.num_fleets, self.n, self.action_size)
        axes = ("fleet {}", "vessel_{}", "component {}")
        return checked_actions(actions, expected, form, axes, finite)

    def step(self, actions: ArrayLike, checked: bool = False) -> None:
        """Advance every fleet one control period ``dt`` with checked actions.

        Args:
            actions: (B, n, 4 + m) raw commands, or (B, n, k) corrections in [-1, 1]
                (clipped to it) in the residual form.
            checked: The actions are what ``check_actions`` returned (an adapter that
                checks them before its own bookkeeping); they are not checked again.

        Raises:
            ValueError: Bad actions; nothing is changed. Shape and type are checked
                here; finiteness where the values enter, before anything is written:
                ``FleetSim.step``'s kernel (raw) or ``ResidualController.compose``.
            RuntimeError: Stepping before reset, or the plant diverged
                (``FleetSim.step``).
        """
        batch = np.asarray(actions) if checked else self.check_actions(actions, finite=False)
        if self.controller is None:
            obs = self.sim.step(batch)
        else:
            command = self.controller.compose(batch)
            self.last_base_actions = self.controller.base_actions.copy()
            self.last_residual = self.controller.residual.copy()
            obs = self.sim.step(command)
        self._observe(obs, None)

    @property
    def terminated(self) -> NDArray[np.bool_]:
        """(B,) fleets whose vessel left its path (latched until reset)."""
        return self.sim.arrays.terminated.copy()

    @property
    def truncated(self) -> NDArray[np.bool_]:
        """(B,) fleets that reached their horizon without terminating."""
        a = self.sim.arrays
        return (a.step >= self.horizon) & ~a.terminated

    @property
    def ended(self) -> NDArray[np.bool_]:
        """(B,) fleets whose episode is over (terminated or truncated)."""
        a = self.sim.arrays
        return a.terminated | (a.step >= self.horizon)

    @property
    def reward(self) -> NDArray[np.float64]:
        """(B, n) each vessel's reward of the last step."""
        return self.sim.arrays.reward

    # --- infos ----------------------------------------------------------------------------

    def info_arrays(self, level: str, fleet: int | None = None) -> dict[str, NDArray[Any]]:
        """The infos of ``level`` as new (B, n, ...) arrays, one per quantity.

        ``"none"``: nothing; ``"minimal"``: ``path_error``, ``heading_error``,
        ``sync_error``, ``speed_error`` (m, rad, ~m, m/s); ``"full"``: also
        ``tau_command``, ``tau_applied`` (N, N, N m), ``saturated`` (per axis),
        ``eta``, ``nu``, ``theta``, ``reward_terms`` and, in the residual form,
        ``base_command`` and ``residual`` of the last step. With ``fleet``, that
        fleet's (n, ...) arrays only.
        """
        if level == "none":
            return {}
        errors, others = self._info_parts(level, slice(None) if fleet is None else fleet)
        return {name: errors[..., k].copy() for name, k in arrays.ERROR_KEYS} | others

    def vessel_infos(self, level: str, fleet: int | None = None) -> list[dict[str, Any]]:
        """``info_arrays`` as one dict per vessel (B n of them, or n of ``fleet``).

        Per-vessel scalars are python floats; vectors are rows of new arrays, so no
        later step writes to them. For the routes whose library wants a dict per
        agent (PettingZoo) or per slot (SB3).
        """
        count = self.n if fleet is not None else self.num_fleets * self.n
        if level == "none":
            return [{} for _ in range(count)]
        errors, others = self._info_parts(level, slice(None) if fleet is None else fleet)
        rows = errors.reshape(count, -1).tolist()
        infos = [{name: row[k] for name, k in arrays.ERROR_KEYS} for row in rows]
        if not others:
            return infos
        if fleet is None:  # (B, n, ...) -> (B n, ...)
            others = {key: value.reshape(count, *value.shape[2:]) for key, value in others.items()}
        tau_command, tau_applied = others["tau_command"], others["tau_applied"]
        saturated, eta, nu = others["saturated"], others["eta"], others["nu"]
        reward_terms, theta = others["reward_terms"], others["theta"].tolist()
        for i, info in enumerate(infos):  # a dict display: the fastest way to add them
            info |= {
                "tau_command": tau_command[i],
                "tau_applied": tau_applied[i],
                "saturated": saturated[i],
                "eta": eta[i],
                "nu": nu[i],
                "theta": theta[i],
                "reward_terms": reward_terms[i],
            }
        if self.controller is not None:
            base, residual = others["base_command"], others["residual"]
            for i, info in enumerate(infos):
                info |= {"base_command": base[i], "residual": residual[i]}
        return infos

    def _info_parts(
        self, level: str, rows: int | slice
    ) -> tuple[NDArray[np.float64], dict[str, NDArray[Any]]]:
        """The errors (..., 4) (a view: copy or convert them) and new arrays of the others."""
        a = self.sim.arrays
        errors = a.errors[rows]
        if level == "minimal":
            return errors, {}
        tau_command, tau_applied = a.tau_command[rows].copy(), a.tau_applied[rows].copy()
        others = {
            "tau_command": tau_command,
            "tau_applied": tau_applied,
            "saturated": tau_command != tau_applied,
            "eta": a.eta[rows].copy(),
            "nu": a.nu[rows].copy(),
            "theta": a.theta[rows].copy(),
            "reward_terms": a.reward_terms[rows].copy(),
        }
        if self.controller is not None:
            others["base_command"] = self.last_base_actions[rows].copy()
            others["residual"] = self.last_residual[rows].copy()
        return errors, others

    def state(self) -> NDArray[np.float32]:
        """Global state (B, 10 n) float32: per vessel eta (3), nu (3), theta, tau_applied (3)."""
        a = self.sim.arrays
        per_vessel = np.concatenate([a.eta, a.nu, a.theta[..., None], a.tau_applied], axis=-1)
        return per_vessel.reshape(self.num_fleets, -1).astype(np.float32)

    # --- helpers --------------------------------------------------------------------------

    def _observe(self, obs: NDArray[np.float32], fleets: NDArray[np.int64] | None) -> None:
        """Keep the learner inputs of all fleets, or of the listed (just reset) ones."""
        if self.controller is None:
            return  # the raw form's inputs are the simulator's observations
        if fleets is None:
            self._inputs[:] = self.controller.observe(obs)
        else:
            self._inputs[fleets] = self.controller.observe(obs[fleets], fleets=fleets)
