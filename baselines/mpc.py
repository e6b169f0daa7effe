"""Receding-horizon control on the benchmark's own stage cost: ``oracle`` and ``mpc``.

One sampling-based model-predictive controller, two members that differ only
in what they are told (``baselines.mpc_kernels`` holds the compiled parts):

==================  ===========================================================
``oracle``          privileged, not deployable (``baselines.PRIVILEGED``):
                    centralized over the fleet; predicts with copies of the
                    simulator's fleets (true model, unmodeled dynamics, the
                    true disturbances of the coming steps, ideal links, true
                    v0, taken up from 0 no faster than the fleet can follow:
                    ``SPEED_RATE``); minimizes the fleet's cost
``mpc``             deployable (``baselines.POLICIES``): per vessel, from its
                    local observation only; predicts with the nominal model
                    plus a disturbance-observer estimate of the residual
                    force, neighbours' path variables as received, advanced by
                    packet age at their communicated speed, and a distributed
                    estimate of v0; minimizes the vessel's own cost
``mpc_privileged``  ``mpc`` told what it lacks (true model and residual, ideal
                    links, true v0), an ablation (``baselines.PRIVILEGED``)
==================  ===========================================================

The plan. Each member tracks its path with a stateless feedback
(``mpc_kernels.tracking_feedback``) and plans offsets on top of it:
piecewise-constant force and path-rate offsets over ``horizon`` seconds in
knots of ``knot`` control steps, followed by ``tail`` seconds of the
feedback alone (a terminal cost: the feedback's cost-to-go). Every
``knot`` steps it samples ``samples`` candidate plans, rolls each out on its
prediction model with the benchmark's stage cost (``cpf_env.sim.reward``:
the same terms and weights), and keeps the cheapest. Two candidates are
always among them: the warm start (the previous plan shifted by one knot)
and the bare feedback (zero offsets). So the kept plan never costs more over
the horizon than either, on the prediction model; for the oracle the
prediction model is the simulator, so that holds for the executed plan too.
Commands are clipped to the force limits and the path-variable rate limit.

Batching: the oracle rolls out all its fleets' candidates (B x samples
copies) in one compiled call; ``mpc`` rolls out all vessels' candidates
(B x n x samples single-vessel models) in one.

Randomness: each fleet draws its samples from its own generator, seeded by
``reset(seed)`` and the fleet's first observation of the episode, so a
fleet's plans depend on its episode alone, not on its row in the batch nor
on the other fleets.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baselines import mpc_kernels as kernels
from baselines.barrier import BARRIER_MARGIN
from baselines.policy import resolve_scenario
from baselines.privileged import fleet_rows, simulator_of
from cpf_env.envs.policy import FleetPolicy, fleet_mask
from cpf_env.evaluation.privileged import ideal_link_observations, true_dynamics
from cpf_env.sim.fleet import FleetSim, observation_layout
from cpf_env.sim.observation import LEADER, NU, SLOT_MSG, SLOT_WEIGHT, SLOTS, TAU, V0

__all__ = [
    "ORACLE_BARRIER_MARGIN",
    "SPEED_RATE",
    "MPCPolicy",
    "MPCPrivileged",
    "OraclePolicy",
    "RecedingHorizon",
    "RecedingHorizonGains",
    "thruster_gain",
]

Array = NDArray[np.float64]

#: How far outside the collision distance the oracle's feedback keeps two vessels (m).
ORACLE_BARRIER_MARGIN = 0.01
#: The reference speed's rate limit of the oracle (and of ``mpc_tuned``'s estimate): a
#: quarter of the nominal surge acceleration at the force limit (``RecedingHorizonGains``).
SPEED_RATE = 0.25


@dataclass(frozen=True)
class RecedingHorizonGains:
    """Horizon, sampling and feedback gains of the receding-horizon policies.

    Attributes:
        horizon: Planned part of the horizon (s).
        tail: Feedback-only continuation scored after it (s), the terminal cost.
        knot: Control steps per knot; the plan is revised every knot.
        samples: Candidate plans per revision (>= 2: warm start and bare feedback).
        force_noise: Std of a sampled force offset, fraction of each axis' limit.
        rate_noise: Std of a sampled path-rate offset (1/s), common to a fleet's
            vessels (plus ``VESSEL_RATE_SHARE`` of it per vessel).
        K1: Kinematic gains (1/s), surge, sway, yaw.
        K2: Velocity-error gains (1/s), each capped at 1 / (2 T) behind thrusters with a
            lag T (``thruster_gain``).
        k_sync: Gain of the synchronization error on the path rate (1/s), capped
            per vessel at 1 / (dt d_i) (d_i its weighted degree) so the consensus is
            stable on any graph.
        k_mu: Gain of the path-error gradient mu on the path rate (1/s).
        observer_time: Time constant of ``mpc``'s residual-force observer (s).
        k5: ``mpc``'s speed-estimator gain on neighbours' estimates (1/s).
        k6: ``mpc``'s speed-estimator gain on the heard v0 (1/s).
        speed_rate: How fast the reference speed may move, a fraction > 0 of the
            nominal surge acceleration at the force limit, tau_max_u / (m - X_udot)
            (``inf``: no limit): ``mpc``'s speed estimate moves at most that much
            per second on each vessel; the oracle takes up v0 at that rate from 0,
            with the fleet's smallest such acceleration (``mpc_kernels.ramped_speed``).
        barrier_margin: Where the scenario has a separation, how far outside its collision
            distance the oracle's feedback keeps every pair of vessels (m, > 0;
            ``baselines.barrier``); ``mpc`` has no barrier (``baselines.safety`` adds one).
        lookahead: Where no hull has a sway force (``Scenario.actuated``),
            the line-of-sight lookahead Delta (m, > 0) of the feedback's heading
            reference: the yaw error becomes psi - pi_p + atan(y_e / Delta), y_e the
            cross-track error, so the hull turns toward its path instead of asking for
            a sway force it does not have (``mpc_kernels.tracking_feedback``). 2 m,
            chosen on training seeds 0-2 of ``hard_underactuated`` (0.5, 1, 2, 5 and
            10 m tried: 632, 502, 474, 506, 509 for the ``oracle``; 509 without it).
    """

    horizon: float = 2.0
    tail: float = 8.0
    knot: int = 10
    samples: int = 12
    force_noise: float = 0.1
    rate_noise: float = 0.3
    vessel_rate_share: float = 0.1
    K1: tuple[float, float, float] = (1.0, 1.0, 1.0)
    K2: tuple[float, float, float] = (6.0, 6.0, 6.0)
    k_sync: float = 6.0
    k_mu: float = 0.0
    observer_time: float = 0.2
    k5: float = 1.0
    k6: float = 1.0
    speed_rate: float = math.inf
    barrier_margin: float = BARRIER_MARGIN
    lookahead: float = 2.0

    def vector(self, ramp: float, lag: float = 0.0, sway: bool = True) -> Array:
        """The feedback's gains in kernel form (``mpc_kernels.GAINS_SIZE``,).

        Args:
            ramp: The oracle's reference-speed ramp (m/s^2).
            lag: The thrusters' time constant T (s, ``cpf_env.model.actuators``); for
                T > 0 each velocity gain is capped at 1 / (2 T) (``thruster_gain``).
            sway: Whether any hull has a sway force; without, the feedback steers by
                line of sight (``lookahead``).
        """
        K2 = [thruster_gain(k, lag) for k in self.K2]
        return np.array(
            [*self.K1, *K2, self.k_sync, self.k_mu, ramp, self.barrier_margin,
             self.lookahead if not sway else 0.0], dtype=np.float64
        )  # fmt: skip


def thruster_gain(gain: float, lag: float) -> float:
    """A velocity-loop gain (1/s) a thruster lag T (s) leaves well damped: min(gain, 1 / (2 T)).

    The velocity error e of the feedback obeys e' = -K2 e when the force acts
    at once. Through a first-order thruster lag the loop is T e'' + e' + K2 e = 0,
    whose damping 1 / (2 sqrt(K2 T)) falls below 1 / sqrt(2) (an overshoot of
    more than 4 %) for K2 > 1 / (2 T); the default K2 = 6 1/s behind a 0.5 s
    lag rings with a damping of 0.29. Capping K2 at 1 / (2 T) keeps the damping
    at 1 / sqrt(2) or more; T = 0 leaves ``gain`` as it is.
    """
    return gain if lag <= 0.0 else min(gain, 1.0 / (2.0 * lag))


def _gains(options: dict[str, Any]) -> RecedingHorizonGains:
    """The gains with ``options`` applied; ValueError naming unknown or bad options."""
    known = {field.name for field in dataclasses.fields(RecedingHorizonGains)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"unknown option(s) {unknown}; choose among {sorted(known)}.")
    gains = dataclasses.replace(RecedingHorizonGains(), **options)
    if gains.horizon <= 0 or gains.tail < 0 or gains.knot < 1 or gains.samples < 2:
        raise ValueError(
            "need horizon > 0, tail >= 0, knot >= 1 and samples >= 2 (warm start and bare "
            f"feedback), got {gains}."
        )
    if not 0.0 <= gains.vessel_rate_share <= 1.0:
        raise ValueError(f"vessel_rate_share must be in [0, 1], got {gains.vessel_rate_share!r}.")
    if not gains.barrier_margin > 0:
        raise ValueError(
            f"barrier_margin must be > 0 (m outside the collision distance), got "
            f"{gains.barrier_margin!r}."
        )
    if not gains.lookahead > 0:
        raise ValueError(f"lookahead must be > 0 (m), got {gains.lookahead!r}.")
    if not gains.speed_rate > 0:
        raise ValueError(
            "speed_rate must be > 0 (a fraction of the nominal surge acceleration at the "
            f"force limit; inf for no limit), got {gains.speed_rate!r}."
        )
    return gains


class RecedingHorizon(FleetPolicy):
    """The sampling planner shared by the members (module docstring).

    Args:
        env: Anything ``baselines.policy.resolve_scenario`` accepts.
        **options: Fields of ``RecedingHorizonGains``; those not given take the member's
            ``DEFAULTS``, then the dataclass's.

    Attributes:
        speed_step: (n,) the most the reference speed moves in one control step (m/s),
            ``speed_rate`` x dt x each vessel's nominal surge acceleration at its limit.
        last_costs: (R, samples) predicted costs of the candidates at the last
            revision, candidate 0 the warm start and 1 the bare feedback; R rows
            (fleets for the oracle, fleet x vessel for ``mpc``).
        last_choice: (R,) the candidate kept at the last revision.
    """

    name: ClassVar[str]
    privileged: ClassVar[bool]
    #: The member's own defaults of ``RecedingHorizonGains`` fields.
    DEFAULTS: ClassVar[dict[str, Any]] = {}
    #: Plan dimensions per vessel: force offsets (3) and path-rate offset.
    DIMS = 4

    def __init__(self, env: object, **options: Any) -> None:
        self.scenario = resolve_scenario(env)
        self.gains = _gains({**self.DEFAULTS, **options})
        s = self.scenario
        self.n = s.n
        self.obs_dim = observation_layout(s).size
        self.act_dim = 4 + s.message_size
        self.message_entries = min(1, s.message_size)
        self.agents = [f"vessel_{i}" for i in range(s.n)]
        self.diagnostics: dict[str, Array] = {}
        self._constants = tuple(FleetSim(s).constants)
        _, tau_max = s.tau_limits
        surge = tau_max[:, 0] / np.array([v.mass - v.X_udot for v in s.vessel_models])
        self.speed_step: Array = self.gains.speed_rate * s.dt * surge
        self._gain_vector = self.gains.vector(
            ramp=self.gains.speed_rate * float(surge.min()),
            lag=s.thrusters.time_constant,
            sway=bool(s.actuated[:, 1].any()),
        )
        self._knots = max(1, round(self.gains.horizon / (s.dt * self.gains.knot)))
        self._tail = round(self.gains.tail / (s.dt * self.gains.knot))
        self._noise_scale = np.array([*(self.gains.force_noise * tau_max.max(axis=0)),
                                      self.gains.rate_noise])  # fmt: skip
        self._seed = 0
        self.last_costs = np.zeros((0, self.gains.samples))
        self.last_choice = np.zeros(0, dtype=np.int64)
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        """Forget every fleet's plan and states; ``seed`` seeds the sampling (default 0)."""
        self._seed = 0 if seed is None else int(seed)
        self._rows = 0
        self._rngs: list[np.random.Generator] = []
        self._fresh = np.zeros(0, dtype=bool)
        self._plans = np.zeros((0, self.n, self._knots, self.DIMS))
        self._steps = np.zeros(0, dtype=np.int64)

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Forget the plans and states of the fleets in a (B,) mask or index list."""
        index = np.flatnonzero(fleet_mask(fleets, self._rows))
        self._fresh[index] = True
        self._plans[index] = 0.0
        self._steps[index] = 0
        self._reset_rows(index)

    def _reset_rows(self, index: NDArray[np.int64]) -> None:
        """Member states of the fleets ``index`` back to their start."""

    def _ensure_rows(self, rows: int) -> None:
        """Size the per-fleet states for ``rows`` fleets (a new batch size restarts them)."""
        if rows == self._rows:
            return
        self._rows = rows
        self._rngs = [np.random.default_rng() for _ in range(rows)]
        self._fresh = np.ones(rows, dtype=bool)
        self._plans = np.zeros((rows, self.n, self._knots, self.DIMS))
        self._steps = np.zeros(rows, dtype=np.int64)
        self._allocate(rows)

    def _allocate(self, rows: int) -> None:
        """Allocate member states for ``rows`` fleets."""

    def _seed_fresh(self, obs: NDArray[Any]) -> None:
        """Seed the generator of each fleet starting an episode from its first observation.

        So a fleet's samples are a function of the policy's seed and of its
        episode alone, whatever its row in the batch.
        """
        for b in np.flatnonzero(self._fresh):
            digest = hashlib.sha256(np.ascontiguousarray(obs[b], dtype=np.float64).tobytes())
            self._rngs[b] = np.random.default_rng((self._seed, int.from_bytes(digest.digest()[:8])))
        self._fresh[:] = False

    def _candidates(self, fleets: NDArray[np.int64]) -> Array:
        """Candidate plans (F, samples, n, knots + tail, DIMS) of the fleets ``fleets``.

        Candidate 0 is the warm start (the plan shifted by a knot), 1 the bare
        feedback (zero offsets); the others perturb the warm start. The tail
        knots are zero (the feedback alone).
        """
        K, knots = self.gains.samples, self._knots
        warm = np.zeros_like(self._plans[fleets])
        warm[:, :, :-1] = self._plans[fleets][:, :, 1:]
        shape = (len(fleets), K, self.n, knots, self.DIMS)
        out = np.zeros((len(fleets), K, self.n, knots + self._tail, self.DIMS))
        out[:, 0, :, :knots] = warm
        for r, b in enumerate(fleets):
            noise = self._rngs[b].standard_normal(shape[1:]) * self._noise_scale
            # the path rate moves the fleet as one (a vessel alone pays the 1 mm sync scale)
            common = self._rngs[b].standard_normal((K, 1, knots)) * self.gains.rate_noise
            noise[..., 3] = self.gains.vessel_rate_share * noise[..., 3] + common
            out[r, 2:, :, :knots] = warm[r][None] + noise[2:]
        return out

    def _keep(self, costs: Array) -> NDArray[np.int64]:
        """The cheapest candidate per row (R, samples) -> (R,); recorded with the costs."""
        choice = np.argmin(costs, axis=1)
        self.last_costs, self.last_choice = costs, choice
        return choice


class _ReadsSimulator(RecedingHorizon):
    """A privileged member: it reads the true state of the simulator it acts in.

    Build it with a ``FleetSim`` (or an env that has one) or call
    ``bind_simulator(sim, fleets)`` before acting, as for the privileged
    references of ``baselines.privileged`` (``cpf_bench.rollout``
    does, with the fleets the policy acts for).
    """

    def __init__(self, env: object, **options: Any) -> None:
        super().__init__(env, **options)
        self._sim: FleetSim | None = None
        self._fleets = np.zeros(0, dtype=np.int64)
        sim = simulator_of(env)
        if sim is not None:
            self.bind_simulator(sim)

    def bind_simulator(self, sim: FleetSim, fleets: ArrayLike | None = None) -> None:
        """Plan for ``sim``'s fleets ``fleets`` (default all); observation row k is ``fleets[k]``.

        Raises:
            ValueError: ``sim`` runs another scenario, or bad fleet indices.
        """
        if sim.scenario != self.scenario:
            raise ValueError(
                f"policy {self.name!r} was built for scenario {self.scenario.name!r} but the "
                f"simulator runs {sim.scenario.name!r}; build it for that scenario."
            )
        self._sim, self._fleets = sim, fleet_rows(sim, fleets)

    def _bound(self) -> FleetSim:
        """The bound simulator; RuntimeError if there is none."""
        if self._sim is None:
            raise RuntimeError(
                f"policy {self.name!r} reads the simulator it acts in: build it with the "
                "FleetSim (or env) or call bind_simulator(sim) first."
            )
        return self._sim


class OraclePolicy(_ReadsSimulator):
    """The headroom bound: centralized, told everything, planning on copies of the simulator.

    Where the scenario has a separation (vessels that pass close), three
    defaults change (docs/hard_track.md, "The bound"), none given explicitly:

    - its rollouts see the whole episode from any step (``tail`` the episode's
      length): with the 10 s of the core suite the cost of a pass always lay
      partly beyond the view, and the planner put it off by stopping, even
      backing, the fleet short of the crossings;
    - its feedback keeps every pair of vessels ``barrier_margin`` (default
      ``ORACLE_BARRIER_MARGIN``, a backstop just outside the collision) apart;
    - its path-rate samples are common to the fleet (``vessel_rate_share`` 0):
      a vessel's own rate offset bought passes by desynchronizing the formation
      at the 1 mm sync scale.
    """

    name = "oracle"
    privileged = True
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "speed_rate": SPEED_RATE,
        "barrier_margin": ORACLE_BARRIER_MARGIN,
    }

    def __init__(self, env: object, **options: Any) -> None:
        scenario = resolve_scenario(env)
        if scenario.separation is not None:
            whole_episode = scenario.max_steps * scenario.dt
            options = {"vessel_rate_share": 0.0, "tail": whole_episode, **options}
        super().__init__(env, **options)

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """Actions (B, n, 4 + m) of the bound fleets; ``obs`` only fixes B (the truth is read).

        Raises:
            RuntimeError: Not bound to a simulator.
            ValueError: ``fleets`` given, or ``obs`` not of the bound fleets' shape.
        """
        sim = self._bound()
        given = np.asarray(obs)
        if fleets is not None or given.shape != (len(self._fleets), self.n, self.obs_dim):
            raise ValueError(
                "policy 'oracle' acts for all the fleets it is bound to, observations of shape "
                f"{(len(self._fleets), self.n, self.obs_dim)}; got {given.shape}"
                + (" and fleets" if fleets is not None else "")
                + ". Bind it to the fleets you want (bind_simulator(sim, fleets))."
            )
        self._ensure_rows(len(self._fleets))
        self._seed_fresh(given)
        steps = sim.arrays.step[self._fleets]
        due = np.flatnonzero(steps % self.gains.knot == 0)
        if due.size:
            self._revise(sim, due)
        actions = np.zeros((len(self._fleets), self.n, self.act_dim))
        offsets = np.ascontiguousarray(self._plans[:, :, 0])
        kernels.oracle_rows(tuple(sim.arrays), self._constants, self._fleets,
                            self._gain_vector, offsets, actions)  # fmt: skip
        return actions

    def _revise(self, sim: FleetSim, due: NDArray[np.int64]) -> None:
        """Sample, roll out on copies of the due fleets and keep each one's cheapest plan."""
        K = self.gains.samples
        candidates = self._candidates(due)
        R = len(due)
        source = self._fleets[due]
        copies = tuple(np.repeat(field[source], K, axis=0) for field in sim.arrays)
        plans = np.ascontiguousarray(
            candidates.transpose(0, 1, 3, 2, 4).reshape(R * K, -1, self.n, self.DIMS)
        )
        costs = np.empty(R * K)
        kernels.fleet_rollouts(copies, self._constants, self._gain_vector, plans,
                               self.gains.knot, costs)  # fmt: skip
        choice = self._keep(costs.reshape(R, K))
        self._plans[due] = candidates[np.arange(R), choice, :, : self._knots]


class MPCPolicy(RecedingHorizon):
    """Deployable receding-horizon control per vessel, from its local observation only."""

    name = "mpc"
    privileged = False

    def __init__(self, env: object, **options: Any) -> None:
        super().__init__(env, **options)
        self._nominal = np.stack([v.to_params() for v in self.scenario.vessel_models])
        self._params = np.zeros((0, self.n, self._nominal.shape[1]))
        K = observation_layout(self.scenario).n_slots
        self._slot_width = SLOT_MSG + self.scenario.message_size
        self._slots = K
        self._filter = 1.0 - np.exp(-self.scenario.dt / self.gains.observer_time)

    def _allocate(self, rows: int) -> None:
        n = self.n
        self._speed = np.zeros((rows, n))
        self._residual = np.zeros((rows, n, 3))
        self._previous = np.zeros((rows, n, 3))
        self._started = np.zeros(rows, dtype=bool)
        self._params = np.ascontiguousarray(
            np.broadcast_to(self._nominal, (rows, *self._nominal.shape))
        )

    def _reset_rows(self, index: NDArray[np.int64]) -> None:
        self._speed[index] = 0.0
        self._residual[index] = 0.0
        self._started[index] = False

    # What the vessel is told; ``MPCPrivileged`` overrides these three.
    def _local(self, obs: Array) -> Array:
        """The observations the plan starts from (local: as received)."""
        return obs

    def _update_knowledge(self, obs: Array) -> None:
        """Residual-force observer and v0 estimator, one step (local information only)."""
        dt = self.scenario.dt
        nu = np.ascontiguousarray(obs[..., NU : NU + 3])
        tau = np.ascontiguousarray(obs[..., TAU : TAU + 3])
        started = self._started
        if started.any():
            residual = self._residual[started]
            kernels.observe_residual(self._params[started], nu[started], self._previous[started],
                                     tau[started], dt, self._filter, residual)  # fmt: skip
            self._residual[started] = residual
        self._previous[:] = nu
        self._started[:] = True
        g = self.gains
        slots = SLOTS + self._slot_width * np.arange(self._slots)
        weight = obs[..., slots + SLOT_WEIGHT]
        message = obs[..., slots + SLOT_MSG]
        pull = (weight * (self._speed[..., None] - message)).sum(axis=-1)
        heard = obs[..., LEADER] * (self._speed - obs[..., V0])
        step = dt * (g.k5 * pull + g.k6 * heard)
        # a convex combination of the old estimate, the messages and v0 on any graph: the
        # old one's weight 1 - dt (k5 d_i + k6 l_i) is kept >= 0
        step = step / np.maximum(dt * (g.k5 * weight.sum(axis=-1) + g.k6 * obs[..., LEADER]), 1.0)
        self._speed = self._speed - np.clip(step, -self.speed_step, self.speed_step)

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """Actions (B, n, 4 + m) from local observations (B, n, obs_dim).

        Raises:
            ValueError: ``fleets`` given (this policy acts for every row it is given).
        """
        if fleets is not None:
            raise ValueError(
                f"policy {self.name!r} acts for all rows of obs; pass them without fleets."
            )
        given = np.asarray(obs, dtype=np.float64)
        if given.ndim != 3 or given.shape[1:] != (self.n, self.obs_dim):
            raise ValueError(
                f"observations must have shape (B, {self.n}, {self.obs_dim}), got {given.shape}."
            )
        B = given.shape[0]
        self._ensure_rows(B)
        self._seed_fresh(given)
        local = self._local(given)
        self._update_knowledge(local)
        start = np.empty((B, self.n, kernels.LOCAL_STATE))
        neighbours = np.empty((B, self.n, self._slots, 3))
        kernels.local_start(self._constants, np.ascontiguousarray(local), start, neighbours)
        due = np.flatnonzero(self._steps % self.gains.knot == 0)
        if due.size:
            self._revise(due, start, neighbours)
        actions = np.zeros((B, self.n, self.act_dim))
        kernels.local_commands(
            self._constants, start, neighbours, self._speed, self._residual, self._params,
            self._gain_vector, np.ascontiguousarray(self._plans[:, :, 0]), actions,
        )  # fmt: skip
        self._steps += 1
        self.diagnostics = {"speed_estimate": self._speed.copy()}
        return actions

    def _revise(self, due: NDArray[np.int64], start: Array, neighbours: Array) -> None:
        """Sample, roll out every vessel's candidates and keep each vessel's cheapest plan."""
        K, n, R = self.gains.samples, self.n, len(due)
        candidates = self._candidates(due)  # (R, K, n, knots + tail, 4)
        rows = R * n * K
        per_vessel = candidates.transpose(0, 2, 1, 3, 4)  # (R, n, K, ...)
        plans = np.ascontiguousarray(per_vessel.reshape(rows, -1, self.DIMS))
        vessel = np.ascontiguousarray(
            np.broadcast_to(np.arange(n)[None, :, None], (R, n, K)).reshape(-1)
        )

        def repeat(x: Array) -> Array:
            return np.ascontiguousarray(np.repeat(x[due].reshape(R * n, *x.shape[2:]), K, axis=0))

        costs = np.empty(rows)
        kernels.local_rollouts(
            self._constants, vessel, repeat(start), repeat(neighbours), repeat(self._speed),
            repeat(self._residual), repeat(self._params), self._gain_vector, plans, self.gains.knot,
            costs,
        )  # fmt: skip
        choice = self._keep(costs.reshape(R * n, K))
        chosen = per_vessel.reshape(R * n, K, -1, self.DIMS)[np.arange(R * n), choice]
        self._plans[due] = chosen.reshape(R, n, -1, self.DIMS)[:, :, : self._knots]


class MPCPrivileged(_ReadsSimulator, MPCPolicy):
    """``mpc`` told what it lacks: the true model and residual, ideal links and the true v0.

    Not deployable (an ablation that shows what local information costs
    ``mpc``); it reads the simulator as the oracle does.
    """

    name = "mpc_privileged"
    privileged = True

    def _local(self, obs: Array) -> Array:
        ideal = ideal_link_observations(self._bound(), self._fleets).astype(np.float64)
        return ideal

    def _update_knowledge(self, obs: Array) -> None:
        sim = self._bound()
        lumped, mass = true_dynamics(sim, self._fleets)
        del mass
        self._params = np.ascontiguousarray(sim.arrays.params[self._fleets])
        hydro = np.empty_like(lumped)
        kernels.hydrodynamics(self._params, np.ascontiguousarray(obs[..., NU : NU + 3]), hydro)
        self._residual[:] = lumped - hydro
        self._speed[:] = sim.v0_at(float(sim.arrays.step[self._fleets[0]]) * self.scenario.dt)
