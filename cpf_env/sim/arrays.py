"""The simulator's arrays: the fleet state the compiled step mutates, and its constants.

``FleetArrays`` holds everything that changes (leading axis B fleets, then n
vessels); ``KernelConstants`` holds a scenario in the plain-array form the
compiled step (``cpf_env.sim.kernels``) reads. ``cpf_env.sim.fleet`` builds
both; the column indices of ``FleetArrays.errors`` are named here.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "ERROR_KEYS",
    "ERR_HEADING",
    "ERR_PATH",
    "ERR_SPEED",
    "ERR_SYNC",
    "FleetArrays",
    "KernelConstants",
]

# Columns of FleetArrays.errors.
ERR_PATH, ERR_HEADING, ERR_SYNC, ERR_SPEED = 0, 1, 2, 3


#: The per-vessel errors as the envs report them: (info key, column of ``FleetArrays.errors``).
ERROR_KEYS = (
    ("path_error", ERR_PATH),
    ("heading_error", ERR_HEADING),
    ("sync_error", ERR_SYNC),
    ("speed_error", ERR_SPEED),
)


class FleetArrays(NamedTuple):
    """Mutable simulator state and per-step outputs; leading axis B (fleets), then n (vessels)."""

    eta: np.ndarray  # (B, n, 3) pose x, y (m), psi (rad), earth frame
    nu: np.ndarray  # (B, n, 3) velocity u, v (m/s), r (rad/s), body frame
    theta: np.ndarray  # (B, n) path variables
    theta_dot: np.ndarray  # (B, n) last commanded (clipped) path-variable rate
    tau_command: np.ndarray  # (B, n, 3) last force command (N, N, N m)
    tau_applied: np.ndarray  # (B, n, 3) force applied over the last step (the thrusters' state)
    fix: np.ndarray  # (B, n, 3) last pose fix x, y (m), psi (rad) of the sensors (eta if ideal)
    message: np.ndarray  # (B, n, m) last message sent (clipped)
    waves: np.ndarray  # (B, n, 3) wave force, earth frame (N, N, N m)
    wind: np.ndarray  # (B, n, 3) wind force, earth frame
    current: np.ndarray  # (B, 2) ocean current, earth frame (m/s)
    step: np.ndarray  # (B,) int64 control steps since reset
    key: np.ndarray  # (B,) uint64 counter-RNG key of the episode
    params: np.ndarray  # (B, n, PARAM_SIZE) true vessel parameters
    recv_theta: np.ndarray  # (B, n, K) last theta_j received in slot k
    recv_message: np.ndarray  # (B, n, K, m) last message received in slot k
    recv_step: np.ndarray  # (B, n, K) int64 step at which the held value was sent
    history: np.ndarray  # (B, delay + 1, n, 1 + m) packets sent, ring buffer by step
    obs: np.ndarray  # (B, n, obs_dim) float32 observations
    reward: np.ndarray  # (B, n) reward of the last step
    reward_terms: np.ndarray  # (B, n, 7) each term's part of the vessel's own reward
    errors: np.ndarray  # (B, n, 4) path, heading, sync, speed error after the last step
    terminated: np.ndarray  # (B,) bool: a vessel left its path (latched until reset)
    nonfinite: np.ndarray  # (B,) bool: the state became NaN/inf (the plant diverged)


class KernelConstants(NamedTuple):
    """Scenario constants in kernel form (see ``Scenario`` for meaning and units)."""

    tau_min: np.ndarray  # (n, 3)
    tau_max: np.ndarray  # (n, 3)
    tau_scale: np.ndarray  # (n, 3) Scenario.tau_scale: max(|tau_min|, |tau_max|), 1 if both 0
    thruster_decay: float  # exp(-dt / T) of the thrusters' lag, 0 for instant thrusters
    thruster_slew: np.ndarray  # (3,) largest change of the applied force per step, inf: none
    instant_thrusters: bool  # the applied force is the saturated command
    ideal_sensors: bool  # observe the true pose and velocity every step (Sensors.ideal)
    fix_noise: np.ndarray  # (3,) standard deviations of a fix: x, y (m), psi (rad)
    fix_period: int  # control steps between fixes
    fix_dropout: float  # probability that a scheduled fix is lost
    velocity_measured: bool  # False: the observation's nu reads 0
    separation: np.ndarray  # (3,) safe distance (m), hard distance (m), weight; 0, 0, 0: none
    theta_dot_max: float
    message_max: float
    path_kinds: np.ndarray  # (n,) int64
    path_params: np.ndarray  # (n, PATH_PARAM_SIZE)
    disturbances: np.ndarray  # (DIST_PARAM_SIZE,)
    slots: np.ndarray  # (n, K) int64 neighbour index per slot, -1 if unused
    slot_weights: np.ndarray  # (T, n, K) a_ij per topology member
    leaders: np.ndarray  # (T, n) b_i per topology member
    switch_steps: np.ndarray  # (T,) int64
    switch_period: int  # 0 = no repetition
    loss_probability: float
    delay: int
    v0_times: np.ndarray  # (S,) s
    v0_values: np.ndarray  # (S,) m/s
    dt: float
    substeps: int
    reward_params: np.ndarray  # (11,) RewardWeights.encode()
    team_reward: bool
    max_path_error: float
    max_steps: int
