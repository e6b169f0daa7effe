"""Residual control, batched: a base policy's command plus a learner's bounded correction.

The learner outputs, per vessel, an action a in [-1, 1]^k. Where it acts is
the ``mode``:

==================  ==  ==============================================================
mode                k   applied command of vessel i
==================  ==  ==============================================================
``force``           3   tau0 = tau_base + scale * tau_limit * a        (default)
``force_and_rate``  4   as ``force``, and theta_dot = theta_dot_base + scale *
                        theta_dot_max * a_3
``kinematic``       3   the base tracks a point moved by d = kinematic_scale * a in
                        its own body frame: it is shown z1 - d instead of z1, which
                        shifts its desired velocity alpha = -K1 z1 + ... by K1 d
==================  ==  ==============================================================

Everything is composed in physical units before the plant's saturation, which
stays the only clip; messages (and theta_dot except in ``force_and_rate``)
are the base's. tau_limit is the per-axis magnitude max(|tau_min|, |tau_max|).
With a = 0 the base policy's actions pass through unchanged, bit for bit.

Learned messages (``messages``, default 0). With ``messages = L`` the
learner's action grows by L entries, a_k .. a_{k+L-1}, which vessel i
broadcasts as its message's last L entries (m - L .. m - 1), the values as
they are (in [-1, 1], no unit: what they mean is learned end to end). Its
neighbours read them in their slots, delayed and lost as the links deliver
every packet. The base keeps its own entries: the base policy declares how
many leading entries it writes (``message_entries``; the analytic designs
write one, their speed estimate, the safety filters six), and the learner
may have only the entries after them. A base that declares nothing is taken
to write all m, so a learned message never overwrites a base's silently.
With ``L = 0`` the messages are the base's, as above.

Yielding at a limit (``yield_at_limit``, default False). Where the base
commands an actuator limit on a force axis (within ``LIMIT_TOLERANCE`` of it,
or past it), a residual that pulls the command back from that limit is
dropped on that axis: tau0 = tau_base there. A base at its limit asks for all
the force there is, because its feedback finds the vessel far from where it
must be; a residual that takes force away then fights a saturated loop
that cannot push back, and a small steady bias of the learner becomes a
steady drift (a vessel that falls behind its fleet for good). A residual
that adds force in the limit's direction is cut by the plant's saturation
as before, so on such an axis the residual has no effect at all. Where the
base is inside its limits nothing changes. The rule reads only the
vessel's own base command and limits, so it is as local as the learner.

What the base policy is told (``hide_residual_from_base``, default True): the
observation's last applied force minus the last force residual. A saturation
auxiliary system (the reference's pi, PAPER eq. [21] in ``docs/model.md``)
compares the applied force with its own command; told the raw applied force,
it would take every residual for saturation and push back (its state settles
at residual / K_pi). Told the applied force minus the residual, it sees only
what the actuators failed to deliver: no residual when nothing saturates.

The learner's input is the vessel's local observation, optionally followed by
extras that are local by construction (``EXTRAS``):

=====================  ==  ==========================================================
extra                  #   content
=====================  ==  ==========================================================
``base_action``        4   the base's tau0 / tau_limit and theta_dot / theta_dot_max
``base_signals``       7   the base's own states: speed estimate (m/s), DSC filter
                           derivative nubar_dot (3), auxiliary state pi (3)
``multiscale_errors``  9   tanh(z1 / s) for s = 0.01, 0.1, 1 (m, m, rad): the path
                           error resolved from millimetres to metres
=====================  ==  ==========================================================

``base_action`` is not available in ``kinematic`` mode (the base acts only
once the correction is known). ``base_signals`` needs a base policy that
reports ``diagnostics`` (the analytic policies do).

Example:
    >>> import numpy as np
    >>> from cpf_env import FleetSim, scenarios
    >>> from baselines import make_policy
    >>> sim = FleetSim(scenarios.get("wang2014"), num_fleets=2)
    >>> loop = ResidualController(sim.scenario, make_policy("nn_dsc", sim), num_fleets=2)
    >>> inputs = loop.observe(sim.reset(seeds=[0, 1]))
    >>> inputs.shape, loop.action_size
    ((2, 5, 26), 3)
    >>> obs = sim.step(loop.compose(np.zeros((2, 5, 3))))
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpf_env.envs.policy import FleetPolicy
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import observation_layout
from cpf_env.sim.observation import SLOT_MSG, ObsLayout

__all__ = [
    "EXTRAS",
    "LIMIT_TOLERANCE",
    "RESIDUAL_MODES",
    "ResidualConfig",
    "ResidualController",
    "ZeroPolicy",
    "check_messages",
    "learner_config",
]

Array = NDArray[np.float64]

#: Where the correction acts, and its action size k.
RESIDUAL_MODES = {"force": 3, "force_and_rate": 4, "kinematic": 3}
#: Optional local inputs for the learner, and their sizes.
EXTRAS = {"base_action": 4, "base_signals": 7, "multiscale_errors": 9}
#: Scales (m, m, rad) of the squashed path errors of ``multiscale_errors``.
MULTISCALE = (0.01, 0.1, 1.0)
#: A base command within this fraction of tau_limit of an actuator limit is at the
#: limit for ``yield_at_limit`` (planners stop at the limit up to rounding).
LIMIT_TOLERANCE = 1e-3


@dataclass(frozen=True)
class ResidualConfig:
    """How the learner's correction enters (see the module docstring).

    Attributes:
        mode: ``"force"``, ``"force_and_rate"`` or ``"kinematic"``.
        scale: Fraction of the force limit (and of theta_dot_max) per unit of
            action, in (0, 10]; 0.2 means a full action moves the command by
            20 % of the limit.
        kinematic_scale: Offset (m, m, rad) per unit of action in ``kinematic`` mode.
        extras: Names from ``EXTRAS`` appended to the learner's input, in this order.
        hide_residual_from_base: Show the base the applied force minus the
            residual (its auxiliary system then reacts to saturation only).
        neighbour_slots: Neighbour slots of the learner's input, or None for the
            scenario's own K. A learner trained with K' slots runs on every
            scenario with K <= K': the vessel's K slots are followed by K' - K
            empty ones (all zero, ``a_ij = 0``), as a vessel with fewer
            neighbours sees them. The base policy always sees the scenario's
            own observation.
        yield_at_limit: Drop a force residual that pulls the command back from an
            actuator limit the base commands (see the module docstring); force
            modes only.
        messages: Message entries the learner writes (the last ``messages`` of the
            scenario's m; see the module docstring), 0: none.
    """

    mode: str = "force"
    scale: float = 0.2
    kinematic_scale: tuple[float, float, float] = (0.05, 0.05, 0.05)
    extras: tuple[str, ...] = ()
    hide_residual_from_base: bool = True
    neighbour_slots: int | None = None
    yield_at_limit: bool = False
    messages: int = 0

    def __post_init__(self) -> None:
        if self.mode not in RESIDUAL_MODES:
            raise ValueError(
                f"residual mode must be one of {sorted(RESIDUAL_MODES)}, got {self.mode!r}."
            )
        if not (isinstance(self.scale, int | float) and 0.0 < float(self.scale) <= 10.0):
            raise ValueError(
                f"residual scale must be a number in (0, 10] (a fraction of the limits), "
                f"got {self.scale!r}."
            )
        kinematic = np.asarray(self.kinematic_scale, dtype=np.float64)
        if kinematic.shape != (3,) or not np.all(np.isfinite(kinematic) & (kinematic > 0.0)):
            raise ValueError(
                "kinematic_scale must be three positive offsets (m, m, rad), "
                f"got {self.kinematic_scale!r}."
            )
        object.__setattr__(self, "kinematic_scale", tuple(float(x) for x in kinematic))
        extras = (self.extras,) if isinstance(self.extras, str) else tuple(self.extras)
        unknown = [name for name in extras if name not in EXTRAS]
        if unknown or len(set(extras)) != len(extras):
            raise ValueError(
                f"extras must be distinct names from {sorted(EXTRAS)}, got {list(extras)}."
            )
        if self.mode == "kinematic" and "base_action" in extras:
            raise ValueError(
                "extra 'base_action' is not available in 'kinematic' mode: the base acts only "
                "after the correction is known. Drop it, or use mode='force'."
            )
        object.__setattr__(self, "extras", extras)
        if not isinstance(self.yield_at_limit, bool):
            raise ValueError(f"yield_at_limit must be true or false, got {self.yield_at_limit!r}.")
        if self.yield_at_limit and self.mode == "kinematic":
            raise ValueError(
                "yield_at_limit acts on a force residual; 'kinematic' mode has none. Drop it, "
                "or use mode='force'."
            )
        messages = self.messages
        if isinstance(messages, bool) or not isinstance(messages, int | np.integer) or messages < 0:
            raise ValueError(
                f"messages must be an integer >= 0 (learned message entries), got {messages!r}."
            )
        object.__setattr__(self, "messages", int(messages))
        slots = self.neighbour_slots
        if slots is not None and (
            isinstance(slots, bool) or not isinstance(slots, int | np.integer) or slots < 1
        ):
            raise ValueError(
                f"neighbour_slots must be an integer >= 1 or None (the scenario's own), "
                f"got {slots!r}."
            )

    @property
    def action_size(self) -> int:
        """The learner's action length per vessel: the mode's k plus the learned messages."""
        return RESIDUAL_MODES[self.mode] + self.messages

    def learner_layout(self, layout: ObsLayout) -> ObsLayout:
        """The layout of the observation part of the learner's input.

        Raises:
            ValueError: The scenario's vessels have more neighbour slots than
                ``neighbour_slots`` (the limit is named).
        """
        if self.neighbour_slots is None:
            return layout
        if layout.n_slots > self.neighbour_slots:
            raise ValueError(
                f"this learner takes at most {self.neighbour_slots} neighbours per vessel, and "
                f"the scenario gives a vessel {layout.n_slots}: use a graph of degree <= "
                f"{self.neighbour_slots}, or train with more neighbour slots "
                "(cpf-train --set neighbour_slots=K)."
            )
        return ObsLayout(n_slots=self.neighbour_slots, msg_size=layout.msg_size)

    def message_inputs(self, layout: ObsLayout) -> list[int]:
        """Columns of the learner's input that hold the neighbours' learned messages.

        Args:
            layout: The scenario's observation layout.

        Returns:
            The last ``messages`` message entries of every neighbour slot of the
            learner's layout, slot by slot (empty without learned messages).
        """
        learner = self.learner_layout(layout)
        first = SLOT_MSG + learner.msg_size - self.messages
        return [
            learner.slot(k).start + first + j
            for k in range(learner.n_slots)
            for j in range(self.messages)
        ]

    def input_size(self, layout: ObsLayout) -> int:
        """The learner's input length per vessel: observation (padded) plus extras."""
        return self.learner_layout(layout).size + sum(EXTRAS[name] for name in self.extras)


def check_messages(scenario: Scenario, base_policy: FleetPolicy, learned: int) -> None:
    """Refuse learned messages that do not fit after the base's ``message_entries``.

    Args:
        scenario: The task (its ``message_size`` m).
        base_policy: The base (``ZeroPolicy`` for a learner without one); one without
            ``message_entries`` is taken to write all m.
        learned: ``ResidualConfig.messages``.

    Raises:
        ValueError: The base's entries and the learned ones exceed m (the numbers named).
    """
    size = scenario.message_size
    if learned == 0:
        return
    written = int(getattr(base_policy, "message_entries", size))
    if written + learned <= size:
        return
    name = getattr(base_policy, "name", type(base_policy).__name__)
    raise ValueError(
        f"the learner is to write {learned} message entries, and the base policy {name!r} "
        f"writes {written} of {scenario.name!r}'s {size} (message_size): ask for at "
        f"most {max(size - written, 0)} learned messages, or give the scenario "
        f"message_size >= {written + learned} (a scenario override)."
    )


def learner_config(
    base_policy: FleetPolicy | None, residual: ResidualConfig | None = None
) -> ResidualConfig:
    """The learner's composition: the one place of the rule for a learner without a base.

    Args:
        base_policy: The policy acting underneath, or None.
        residual: The composition asked for, or None (the default ``ResidualConfig()``).

    Returns:
        ``residual`` over a base policy; with no base policy,
        ``ResidualConfig(mode="force_and_rate", scale=1.0)``: the learner commands
        forces and path-variable rate as fractions of their limits, keeping the given
        ``neighbour_slots`` and ``messages`` (the messages it does not learn are zero).
    """
    asked = ResidualConfig() if residual is None else residual
    if base_policy is None:
        return ResidualConfig(
            mode="force_and_rate",
            scale=1.0,
            neighbour_slots=asked.neighbour_slots,
            messages=asked.messages,
        )
    return asked


class ZeroPolicy(FleetPolicy):
    """The base of a learner that commands everything itself: all-zero actions.

    Args:
        act_dim: Action length per vessel, 4 + m.
    """

    #: Leading message entries written: none.
    message_entries = 0

    def __init__(self, act_dim: int) -> None:
        self.act_dim = act_dim
        self.diagnostics: dict[str, Array] = {}

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """Zeros of shape (rows, n, 4 + m)."""
        del fleets
        shape = np.shape(obs)
        return np.zeros((shape[0], shape[1], self.act_dim))

    def reset(self, seed: int | None = None) -> None:
        """Nothing to forget."""
        del seed

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Nothing to forget."""
        del fleets


class ResidualController:
    """A base policy plus a learner's correction for B fleets (no Gym code).

    Call ``observe(obs)`` with every new observation batch (after reset and
    after each step), then ``compose(a)`` with the learner's action to get the
    command for ``FleetSim.step``.

    Args:
        scenario: The task (limits, dt, layout).
        base_policy: Any ``FleetPolicy``; None commands nothing (a learner from
            scratch, with ``mode="force_and_rate"`` and ``scale=1``).
        num_fleets: B.
        config: ``ResidualConfig`` (default: force residual, scale 0.2, no extras).

    Attributes:
        layout: The observation layout.
        input_size: Length of the learner's input per vessel, obs_dim + extras.
        action_size: The learner's action length, k + ``messages``.
        base_actions: (B, n, 4 + m) the base's last actions (float64).
        residual: (B, n, k) the last correction in physical units (N, N, N m
            [, 1/s]; m, m, rad in ``kinematic`` mode), learned messages aside.

    Raises:
        ValueError: The learned messages do not fit beside the base's (their
            numbers are named).
    """

    def __init__(
        self,
        scenario: Scenario,
        base_policy: FleetPolicy | None,
        num_fleets: int,
        config: ResidualConfig | None = None,
    ) -> None:
        self.scenario = scenario
        self.config = config = ResidualConfig() if config is None else config
        self.layout: ObsLayout = observation_layout(scenario)
        self.n, self.num_fleets = scenario.n, int(num_fleets)
        self.act_dim = 4 + scenario.message_size
        self.base = ZeroPolicy(self.act_dim) if base_policy is None else base_policy
        check_messages(scenario, self.base, config.messages)
        if "base_signals" in config.extras and not hasattr(self.base, "diagnostics"):
            raise ValueError(
                f"extra 'base_signals' reads the base policy's diagnostics, and "
                f"{type(self.base).__name__} has none; drop the extra or use an analytic policy."
            )
        tau_min, tau_max = scenario.tau_limits
        self._tau_scale = scenario.tau_scale  # (n, 3); 1 on an axis without an actuator
        self._near_max = tau_max - LIMIT_TOLERANCE * self._tau_scale
        self._near_min = tau_min + LIMIT_TOLERANCE * self._tau_scale
        self._theta_dot_max = float(scenario.theta_dot_max)
        self.action_size = config.action_size
        self.input_size = config.input_size(self.layout)
        self._padding = config.learner_layout(self.layout).size - self.layout.size
        shape = (self.num_fleets, self.n)
        self.base_actions = np.zeros((*shape, self.act_dim))
        self._k = RESIDUAL_MODES[config.mode]
        self.residual = np.zeros((*shape, self._k))
        self._force_residual = np.zeros((*shape, 3))
        self._obs = np.zeros((*shape, self.layout.size))
        self._signals = np.zeros((*shape, EXTRAS["base_signals"]))

    # --- the loop -------------------------------------------------------------------------

    def reset(self, seed: int | None = None) -> None:
        """Forget the base's states and the last correction of every fleet."""
        self.base.reset(seed=seed)
        self.residual[:] = 0.0
        self._force_residual[:] = 0.0

    def reset_fleets(self, fleets: NDArray[np.bool_]) -> None:
        """Forget the base's states and the last correction of the fleets in the (B,) mask."""
        reset_fleets = getattr(self.base, "reset_fleets", None)
        if reset_fleets is None:
            raise TypeError(
                f"{type(self.base).__name__} has no reset_fleets(mask): a batched env cannot "
                "restart single fleets of it. Give the base policy that method."
            )
        reset_fleets(fleets)
        self.residual[fleets] = 0.0
        self._force_residual[fleets] = 0.0
        self._signals[fleets] = 0.0

    def observe(
        self, obs: ArrayLike, fleets: Sequence[int] | NDArray[np.int64] | None = None
    ) -> Array:
        """Take new observations; return the learner's input.

        Outside ``kinematic`` mode the base acts here, on the observation it is
        shown (its internal states advance one step).

        Args:
            obs: (B, n, obs_dim) observations; with ``fleets``, one row per listed fleet.
            fleets: Indices of the fleets observed (default: all), e.g. the fleets
                just reset by a vector env.

        Returns:
            (rows, n, input_size) float64: observation and extras.
        """
        index = slice(None) if fleets is None else np.asarray(fleets, dtype=np.int64)
        batch = np.asarray(obs, dtype=np.float64)
        self._obs[index] = batch
        if self.config.mode != "kinematic":
            shown = self._shown(batch, index, offset=None)
            if fleets is None:
                self.base_actions[:] = self.base.act_batch(shown)
            else:
                listed = np.asarray(fleets, dtype=np.int64)
                self.base_actions[listed] = self.base.act_batch(shown, fleets=listed)
            self._record_signals(index)
        return self._inputs(batch, index)

    def compose(self, action: ArrayLike) -> Array:
        """The command for the plant from the learner's action.

        Args:
            action: (B, n, k + messages) in [-1, 1] (values outside are clipped to it).

        Returns:
            (B, n, 4 + m) float64: force command (N, N, N m), theta_dot (1/s), message
            (its last ``messages`` entries the learner's).
        """
        a = np.minimum(np.maximum(np.asarray(action, dtype=np.float64), -1.0), 1.0)  # np.clip
        expected = (self.num_fleets, self.n, self.action_size)
        if a.shape != expected:
            raise ValueError(
                f"residual actions must have shape (B, n, k + messages) = {expected}, got "
                f"{a.shape}."
            )
        if not np.isfinite(a).all():
            raise ValueError("residual actions must be finite.")
        a, messages = a[..., : self._k], a[..., self._k :]
        scale = self.config.scale
        if self.config.mode == "kinematic":
            self.residual = np.asarray(self.config.kinematic_scale) * a
            shown = self._shown(self._obs, slice(None), offset=self.residual)
            self.base_actions = self.base.act_batch(shown)
            self._record_signals(slice(None))
            return self._with_messages(self.base_actions.copy(), messages)
        command = self.base_actions.copy()
        force = scale * self._tau_scale * a[..., :3]
        if self.config.yield_at_limit:
            at_max, at_min = self.base_at_limits()
            force[(at_max & (force < 0.0)) | (at_min & (force > 0.0))] = 0.0
        command[..., :3] += force
        self._force_residual = force
        if self.config.mode == "force_and_rate":
            rate = scale * self._theta_dot_max * a[..., 3]
            command[..., 3] += rate
            self.residual = np.concatenate([force, rate[..., None]], axis=-1)
        else:
            self.residual = force
        return self._with_messages(command, messages)

    def base_at_limits(self) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """Where the base's last force command is at (or past) tau_max and tau_min.

        Returns:
            Two (B, n, 3) masks, within ``LIMIT_TOLERANCE`` x tau_limit of the limit.
        """
        base = self.base_actions[..., :3]
        return base >= self._near_max, base <= self._near_min

    # --- helpers --------------------------------------------------------------------------

    def _with_messages(self, command: Array, messages: Array) -> Array:
        """``command`` with the learned messages in its last message entries."""
        if messages.shape[-1]:
            command[..., command.shape[-1] - messages.shape[-1] :] = messages
        return command

    def _shown(self, obs: Array, index: slice | NDArray[np.int64], offset: Array | None) -> Array:
        """The observation the base policy is shown (see the module docstring)."""
        shown = obs
        if self.config.hide_residual_from_base:
            shown = obs.copy()
            shown[..., self.layout.tau] -= self._force_residual[index]
        if offset is not None:
            shown = shown.copy() if shown is obs else shown
            shown[..., self.layout.z1] -= offset[index]
        return shown

    def _inputs(self, obs: Array, index: slice | NDArray[np.int64]) -> Array:
        """Observation, empty slots up to ``neighbour_slots``, extras: (rows, n, input_size)."""
        parts = [obs]
        if self._padding:
            parts.append(np.zeros((*obs.shape[:-1], self._padding)))
        for name in self.config.extras:
            if name == "base_action":
                base = self.base_actions[index]
                parts.append(base[..., :3] / self._tau_scale)
                parts.append(base[..., 3:4] / self._theta_dot_max)
            elif name == "base_signals":
                parts.append(self._signals[index])
            else:
                z1 = obs[..., self.layout.z1]
                parts.extend(np.tanh(z1 / s) for s in MULTISCALE)
        return np.concatenate(parts, axis=-1) if len(parts) > 1 else obs.copy()

    def _record_signals(self, index: slice | NDArray[np.int64]) -> None:
        """Keep the speed estimate, nubar_dot and pi of the base's last act (``base_signals``)."""
        if "base_signals" not in self.config.extras:
            return
        diagnostics: dict[str, Any] = getattr(self.base, "diagnostics", {})
        columns = {
            "speed_estimate": slice(0, 1),
            "nubar_dot": slice(1, 4),
            "aux_state": slice(4, 7),
        }
        for name, column in columns.items():
            if name in diagnostics:
                value = np.asarray(diagnostics[name], dtype=np.float64)
                self._signals[index, :, column] = value.reshape(*value.shape[:2], -1)
