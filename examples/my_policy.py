r"""Template of a policy of your own, for ``cpf-bench`` and ``cpf-run`` (docs/extending.md).

Two ways to hand the commands a policy, both named ``module:NAME``:

* a policy class, called as ``ProportionalPolicy(scenario, **options)``;
* a factory called like ``baselines.make_policy`` without the name:
  ``tuned_backstepping(scenario, **options)`` returns a policy object.

Run from the repository root (the folder of this file on ``PYTHONPATH``)::

    PYTHONPATH=examples cpf-bench --policies nn_dsc my_policy:ProportionalPolicy \\
        my_policy:tuned_backstepping --scenarios bench_mild --num-seeds 3
    PYTHONPATH=examples cpf-run --policy my_policy:ProportionalPolicy --scenario wang2014

Copy this file into your own package and name it there
(``my_package.controllers:MyPolicy``), or register the name in your
package's ``pyproject.toml`` so that ``--policies my_controller`` finds it::

    [project.entry-points."cpf_env.policies"]
    my_controller = "my_package.controllers:MyPolicy"
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from baselines import make_policy
from baselines.cooperative import LocalObservation
from baselines.gains import BacksteppingGains
from baselines.kernel_types import CooperativeOutputs
from baselines.policy import AnalyticPolicy, virtual_control

Array = NDArray[np.float64]


class ProportionalPolicy(AnalyticPolicy):
    """tau0 = -K2 (nu - alpha) - z1: backstepping without the model terms.

    ``baselines.policy.AnalyticPolicy`` gives the cooperative layer (path-variable
    consensus, the distributed speed estimator, the commanded theta rate and
    the message), the per-fleet states, ``act``, ``act_batch``, ``predict``,
    ``reset`` and ``diagnostics``; a subclass gives the force command.
    """

    name = "proportional"
    gains_type = BacksteppingGains  # its fields are the accepted options (K1, K2, k3..k6)
    gains: BacksteppingGains

    def _kinetic_states(self) -> dict[str, tuple[int, ...]]:
        return {}  # name -> shape per vessel of states the force law keeps (reset to 0)

    def _kinetics(
        self,
        obs: LocalObservation,
        cooperation: CooperativeOutputs,
        states: dict[str, Array],
        started: NDArray[np.bool_],
    ) -> tuple[Array, dict[str, Array]]:
        """The force command tau0 (B, n, 3) in N, N, N m, and the diagnostics it adds.

        ``obs`` holds the local observation's parts as (B, n, 3) arrays (z1:
        path error in the body frame (m, m, rad), nu: velocity (m/s, m/s,
        rad/s), t1: J^T eta_d^theta); ``cooperation.vhat`` is the speed
        estimate (m/s).
        """
        del states, started
        k1, k2 = np.array(self.gains.K1), np.array(self.gains.K2)
        alpha = virtual_control(k1, obs.z1, obs.t1, cooperation.vhat)  # desired velocity (m/s)
        tau0 = -k2 * (obs.nu - alpha) - obs.z1
        zeros = np.zeros_like(tau0)
        return tau0, {"nn_output": zeros, "nubar_dot": zeros, "alpha": alpha, "aux_state": zeros}


def tuned_backstepping(scenario: Any, **options: Any) -> AnalyticPolicy:
    """``backstepping`` with other velocity gains K2 (N s/m, N s/m, N m s/rad) unless given."""
    options.setdefault("K2", (80.0, 90.0, 10.0))
    return make_policy("backstepping", scenario, **options)
