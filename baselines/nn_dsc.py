"""The paper's controller: NN-based adaptive dynamic surface control, and its ablations.

Wang, Wang & Peng (2014), docs/model.md section 7, per vessel i:

    alpha_i = -K1 z_i1 + t_i1 vhat_i                                        [15]
    rho nubar_id' + nubar_id = alpha_i,   nubar_id(0) = alpha_i(0)           [18]
    z_i2 = nu_i - nubar_id
    pi_i' = -K_pi pi_i + tau_tilde_i,   tau_tilde_i = tau_i - tau_i0        [21]
    e_i2 = z_i2 - pi_i
    xi_i = [1, nu_i, nubar_id'],   sigma_l(xi) = tanh(v_l^T xi)             [28]
    tau_i0 = -K2 e_i2 - z_i1 + What_i^T sigma(xi_i)                         [29]
    What_i' = -Gamma_W (sigma(xi_i) e_i2^T + k_W What_i),   What_i(0) = 0   [30]
      (option leakage="plain": What_i' = -Gamma_W sigma(xi_i) e_i2^T - k_W What_i)

with the cooperative layer of ``baselines.cooperative`` (eqs. [34]-[35]).

Two readings of [30] are offered (option ``leakage``, ``baselines.gains``):
the default above, and ``"plain"``, the integrating one under which the NN
tracks f (claim 2) but which needs a control step of about 0.01 s. Both adapt
on e_i2 = z_i2 - pi_i, as the command does: our choice (the paper's proof
suggests z_i2). It is what lets the auxiliary system keep an integrating NN
from learning the saturation as model error (``docs/reproduction.md``).

Discrete time, one update per control step k (obs_k is the observation after
step k - 1; every input is held over the step, as the plant holds tau):

1. the auxiliary state is advanced over the step that just ended with the
   tau_tilde it saw, tau applied (from obs_k) minus the vessel's own command
   of step k - 1: pi_k (tau applied arrives in float32, so an unsaturated step
   leaves a rounding residue of ~1e-7 |tau| in tau_tilde);
2. alpha_k, nubar_dot_k = (alpha_k - nubar_k) / rho, z2, e2, sigma, tau0_k are
   computed from obs_k and the states at k;
3. nubar, What (and gamma, vhat in the cooperative layer) are advanced to
   k + 1 with the inputs of step k.

The stiff linear parts are integrated exactly (exponential Euler,
docs/model.md section 7): the DSC filter (rate 1/rho), the auxiliary system (K_pi) and the
sigma-modification leakage of What (Gamma_W k_W, or k_W under
``leakage="plain"``), each with its input held
over the step; so are gamma and vhat. Nothing is integrated by forward Euler.

The NN's fixed input weights v_l (``NNDSCGains.input_weights``) are the same
for every vessel; each vessel adapts its own What_i.

Ablations (thin subclasses): ``dsc`` (no NN term), ``nn_dsc_no_aux``
(no auxiliary system, e2 = z2) and ``nn_dsc_global_v0`` (v0 from the
scenario's schedule instead of the estimator: knowledge outside the local
observation, deliberately).
"""

from __future__ import annotations

from typing import Any, ClassVar, cast

import numpy as np

from baselines.cooperative import exponential_euler
from baselines.gains import NNDSCGains
from baselines.kernel_types import KINETICS_NN_DSC
from baselines.policy import AnalyticPolicy

__all__ = ["DSCPolicy", "GlobalSpeedPolicy", "NNDSCPolicy", "NoAuxPolicy"]


class NNDSCPolicy(AnalyticPolicy):
    """NN-based adaptive DSC with saturation auxiliary system (the paper's controller).

    The equations above run compiled (``baselines.kernels``); this class turns
    the gains into their kernel form.

    Args:
        env: A ParallelEnv, FleetSim, Scenario or scenario name.
        **options: Any field of ``NNDSCGains`` (e.g. ``K2=(30, 30, 5)``, ``hidden=40``).

    Example:
        >>> import numpy as np
        >>> from cpf_env import FleetSim, scenarios
        >>> sim = FleetSim(scenarios.get("wang2014"))
        >>> policy = NNDSCPolicy(sim)
        >>> obs = sim.reset(seeds=[0])
        >>> for _ in range(10):
        ...     obs = sim.step(policy.act_batch(obs))
        >>> policy.diagnostics["nn_output"].shape
        (1, 5, 3)
    """

    name = "nn_dsc"
    gains_type = NNDSCGains
    kinetics = KINETICS_NN_DSC
    #: Include the NN term What^T sigma(xi) in tau0 and adapt What.
    use_nn: ClassVar[bool] = True
    #: Include the saturation auxiliary system (otherwise e2 = z2).
    use_aux: ClassVar[bool] = True

    def _kinetic_constants(self) -> dict[str, Any]:
        """K1, K2, the DSC filter, the auxiliary system and the weight law in kernel form."""
        g = cast(NNDSCGains, self.gains)
        filter_decay, _ = exponential_euler(1.0 / g.rho, self.dt)
        aux_decay, aux_gain = exponential_euler(np.array(g.K_pi), self.dt)
        leak_decay, leak_gain = exponential_euler(g.leakage_rate(), self.dt)
        return {
            "use_nn": self.use_nn,
            "use_aux": self.use_aux,
            "k1": np.array(g.K1),
            "k2": np.array(g.K2),
            "rho": float(g.rho),
            "filter_decay": float(filter_decay),
            "aux_decay": aux_decay,
            "aux_gain": aux_gain,
            "leak_decay": float(leak_decay),
            "adapt_gain": float(g.Gamma_W * leak_gain),
            "input_weights": g.input_weights(),
        }

    def _hidden_units(self) -> int:
        """The NN size l (What has shape (l, 3) per vessel)."""
        return cast(NNDSCGains, self.gains).hidden


class DSCPolicy(NNDSCPolicy):
    """Ablation ``dsc``: the paper's controller without the NN term (What = 0)."""

    name = "dsc"
    use_nn = False


class NoAuxPolicy(NNDSCPolicy):
    """Ablation ``nn_dsc_no_aux``: without the saturation auxiliary system (e2 = z2)."""

    name = "nn_dsc_no_aux"
    use_aux = False


class GlobalSpeedPolicy(NNDSCPolicy):
    """Ablation ``nn_dsc_global_v0``: every vessel knows v0, no speed estimator.

    Each vessel uses vhat_i = v0(t) from the scenario's schedule, t = steps * dt
    on the policy's own clock (counted since its reset). This deliberately uses
    knowledge outside the local observation (vessels with b_i = 0 do not hear v0).
    """

    name = "nn_dsc_global_v0"
    global_speed = True
