"""The cooperative layer shared by every analytic policy, and its numerical helpers.

Vessel i reads from its local observation its own path variable, the
neighbours' path-variable differences and messages (their speed estimates),
and v0 if it hears the leader. From these it computes, per docs/model.md section 8:

- the synchronization error s_i = sum_j a_ij (theta_i - theta_j), with
  theta_j - theta_i taken from the neighbour slots as received;
- the gradient term mu_i = z_i1^T t_i1, t_i1 = J^T eta_di^theta;
- the path-variable correction omega_is = -k3 (s_i - mu_i) - gamma_i and the
  auxiliary state gamma_i' = -k4 gamma_i + (s_i - mu_i)               [34];
- the speed estimate vhat_i' = -k5 sum_j a_ij (vhat_i - vhat_j) - k6 b_i (vhat_i - v0)  [35],
  vhat_j being neighbour j's message;
- the commanded rate theta_i' = vhat_i + omega_is                         [12].

Discrete time (one update per control step dt, the inputs held over the
step): gamma and vhat are linear in themselves, so they are advanced by the
exact exponential-Euler map x+ = e^{-a dt} x + (1 - e^{-a dt}) / a * u
(docs/model.md, section 7). For vhat, a = k5 sum_j a_ij + k6 b_i and
u = k5 sum_j a_ij vhat_j + k6 b_i v0: the update is a convex combination of
the vessel's own estimate and its neighbours' and the leader's, stable for
any dt. The estimate a vessel broadcasts at step k is vhat_i(k + 1), so that
at step k + 1 every vessel combines values of the same instant.

The equations run compiled, once, in ``baselines.kernels`` (``_cooperate``),
their sums as explicit left-to-right loops so that a fleet's numbers do not
depend on how many fleets are in the batch. This module keeps the
Python-facing pieces: the parsed observation (``LocalObservation``) that a
kinetic part written in Python receives (with the layer's output,
``baselines.kernels.CooperativeOutputs``), and the numerical helpers the
policies use to build their coefficients.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpf_env.sim.observation import ObsLayout

__all__ = [
    "LocalObservation",
    "exponential_euler",
]

Array = NDArray[np.float64]


def exponential_euler(rate: ArrayLike, dt: float) -> tuple[Array, Array]:
    """Coefficients of the exact step of x' = -a x + u with u held over dt (docs/model.md s. 7).

    Args:
        rate: Decay rate a >= 0 (1/s), any shape.
        dt: Step (s).

    Returns:
        (e^{-a dt}, (1 - e^{-a dt}) / a), both of the shape of ``rate``; the
        second is dt where a = 0. Then x(t + dt) = first * x + second * u.
    """
    a = np.asarray(rate, dtype=np.float64)
    positive = a > 0.0
    gain = np.where(positive, -np.expm1(-a * dt) / np.where(positive, a, 1.0), dt)
    return np.exp(-a * dt), gain


@dataclass(frozen=True)
class LocalObservation:
    """A batch of local observations as named float64 arrays (shapes for B fleets, n vessels).

    Attributes:
        nu: (B, n, 3) body velocity u, v, r (m/s, m/s, rad/s).
        z1: (B, n, 3) path error in the body frame, eq. [10] (m, m, rad).
        t1: (B, n, 3) J^T eta_d^theta.
        t2: (B, n, 3) J^T eta_d^theta2.
        theta: (B, n) own path variable.
        tau_applied: (B, n, 3) force applied over the last step (N, N, N m).
        leader: (B, n) b_i.
        v0: (B, n) leader speed as heard (m/s; 0 when b_i = 0).
        weight: (B, n, K) a_ij per neighbour slot (0 = empty slot).
        dtheta: (B, n, K) theta_j - theta_i as received.
        message: (B, n, K) first float of neighbour j's last message (zeros if m = 0).
    """

    nu: Array
    z1: Array
    t1: Array
    t2: Array
    theta: Array
    tau_applied: Array
    leader: Array
    v0: Array
    weight: Array
    dtheta: Array
    message: Array

    @classmethod
    def parse(cls, layout: ObsLayout, obs: Array) -> LocalObservation:
        """Split observations (B, n, layout.size) by the layout's named slices."""
        weight = layout.slot_weights(obs)
        messages = layout.slot_messages(obs)
        message = messages[..., 0] if layout.msg_size > 0 else np.zeros(weight.shape)
        return cls(
            nu=obs[..., layout.nu],
            z1=obs[..., layout.z1],
            t1=obs[..., layout.t1],
            t2=obs[..., layout.t2],
            theta=obs[..., layout.theta][..., 0],
            tau_applied=obs[..., layout.tau],
            leader=obs[..., layout.leader][..., 0],
            v0=obs[..., layout.v0][..., 0],
            weight=weight,
            dtheta=layout.slot_theta_differences(obs),
            message=message,
        )
