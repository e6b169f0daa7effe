"""Per-step reward of a vessel: its terms, their form and their weights.

The weights, forms and scales are the scenario's ``RewardWeights``
(``cpf_env.scenarios.reward_weights``); this module computes the reward in
the compiled step. Reward of vessel i for one control step is minus dt times a weighted sum of
costs, one per term (``REWARD_TERMS``):

    r_i = -dt * sum_k w_k c_k

=========  =============================  ======================================
term       error x_k                      cost c_k
=========  =============================  ======================================
position   ||z1_xy|| (m)                  rho(x / position_scale)
heading    wrapped z1_psi (rad)           rho(x / heading_scale)
sync       s_i = sum_j a_ij (theta_i -    rho(x / sync_scale)
           theta_j) on true values
speed      theta_dot_i - v0 (m/s)         rho(x / speed_scale)
effort     ||tau_i / tau_max||            x^2 (always quadratic)
failure    on the step the fleet          (T - t) / dt * w_position *
           terminates only                rho(max_path_error / position_scale)
separation distances d_ij to the other    sum_j (max(0, d_safe - d_ij) /
           vessels (m), with a            (d_safe - d_hard))^2, weight the
           ``Scenario.separation`` only   ``Separation``'s (0 without one)
=========  =============================  ======================================

with z1 the body-frame path error after the step, tau_i the applied
(saturated) force and tau_max the per-axis magnitude limit
max(|tau_min|, |tau_max|). Two forms of rho:

- ``"log"`` (default): rho(y) = log(1 + y^2). Quadratic inside the scale,
  logarithmic outside it: an error of one scale costs log 2, a transient of
  100 scales costs only about 9.2, so the steady state (where the paper's
  claims live) is not drowned by the first seconds, and a learner keeps a
  gradient at millimetre errors. The scales are the task's tolerances.
- ``"quadratic"``: rho(y) = y^2 with every scale 1, i.e. the plain
  ``w_pos ||z1_xy||^2 + w_head z1_psi^2 + ...`` of the first release.

Why ``"log"`` is the default (measured, see ``docs/residual_rl.md``): under
the quadratic form 84 % of ``nn_dsc``'s episodic cost on ``saturation_heavy``
falls in the first 10 s, and in the steady state the effort term is 20 times
the position term, so a 17-fold difference in tail path error between two
controllers changes the cost by 1.6 %; residual PPO trained on it made every
task metric worse.

The failure term charges every vessel of a fleet that leaves its path or
collides (two vessels closer than the separation's hard distance) the
position cost of sitting at the termination distance for the rest of the
episode (T = max_steps * dt). Without it, ending an episode
early is cheaper than finishing it: PPO from scratch learned exactly that
(every evaluation episode failed, at a lower return than ``nn_dsc``'s).

With a team reward every vessel receives the fleet mean. Each term's
contribution -dt w_k c_k is reported separately (``FleetSim.arrays.reward_terms``
and the env's infos), so episode costs can be decomposed.
"""

from __future__ import annotations

import math

import numba
from numpy.typing import NDArray

from cpf_env.scenarios.reward_weights import ENCODED_FAILURE, ENCODED_FORM, ENCODED_SCALES

__all__ = ["failure_penalty", "separation_term", "step_reward"]


@numba.njit(cache=True, inline="always")
def _shaped(params: NDArray, term: int, error_squared: float) -> float:
    """rho(x / scale) of term ``term`` from x^2, in the encoded form."""
    if params[ENCODED_FORM] > 0.0:
        scale = params[ENCODED_SCALES + term]
        return math.log1p(error_squared / (scale * scale))
    return error_squared


@numba.njit(cache=True, inline="always")
def step_reward(
    params: NDArray,
    dt: float,
    z1: tuple[float, float, float],
    sync_error: float,
    speed_error: float,
    tau: NDArray,
    tau_scale: NDArray,
    terms: NDArray,
) -> float:
    """Reward of one vessel for one control step (see module docstring).

    Args:
        params: ``RewardWeights.encode()``, shape (11,).
        dt: Control period (s).
        z1: Body-frame path error after the step (x (m), y (m), psi (rad)).
        sync_error: s_i on true path variables.
        speed_error: theta_dot_i - v0 (m/s).
        tau: Applied force, shape (3,).
        tau_scale: Per-axis normalization max(|tau_min|, |tau_max|), shape (3,).
        terms: Written with each term's contribution -dt w_k c_k, shape (6,); the
            failure term is 0 here (see ``failure_penalty``).

    Returns:
        The reward, the sum of ``terms``.
    """
    effort = 0.0
    for k in range(3):
        effort += (tau[k] / tau_scale[k]) ** 2
    terms[0] = -dt * params[0] * _shaped(params, 0, z1[0] * z1[0] + z1[1] * z1[1])
    terms[1] = -dt * params[1] * _shaped(params, 1, z1[2] * z1[2])
    terms[2] = -dt * params[2] * _shaped(params, 2, sync_error * sync_error)
    terms[3] = -dt * params[3] * _shaped(params, 3, speed_error * speed_error)
    terms[4] = -dt * params[4] * effort
    terms[5] = 0.0
    return terms[0] + terms[1] + terms[2] + terms[3] + terms[4]


@numba.njit(cache=True, inline="always")
def failure_penalty(params: NDArray, remaining: float, max_path_error: float) -> float:
    """Failure term of each vessel of a fleet that terminates (<= 0).

    Args:
        params: ``RewardWeights.encode()``, shape (11,).
        remaining: Time left in the episode (s), (max_steps - step) * dt.
        max_path_error: The termination distance (m).
    """
    at_limit = params[0] * _shaped(params, 0, max_path_error * max_path_error)
    return -params[ENCODED_FAILURE] * remaining * at_limit


@numba.njit(cache=True, inline="always")
def separation_term(
    separation: NDArray, dt: float, positions: NDArray, i: int
) -> tuple[float, bool]:
    """Vessel i's separation term and whether it is closer than the hard distance to another.

    ``cpf_env.model.separation`` defines the cost; the term is -dt weight c_i.

    Args:
        separation: (3,) safe distance (m), hard distance (m), weight (``KernelConstants``).
        dt: Control period (s).
        positions: (n, 3) the fleet's true poses; columns 0 and 1 are x, y (m).
        i: The vessel.

    Returns:
        (term (<= 0), collided).
    """
    safe, hard = separation[0], separation[1]
    cost = 0.0
    collided = False
    for j in range(positions.shape[0]):
        if j == i:
            continue
        d = math.hypot(positions[i, 0] - positions[j, 0], positions[i, 1] - positions[j, 1])
        if d < safe:
            intrusion = (safe - d) / (safe - hard)
            cost += intrusion * intrusion
        collided = collided or d < hard
    return -dt * separation[2] * cost, collided
