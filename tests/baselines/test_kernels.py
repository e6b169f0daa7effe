"""The compiled policies reproduce the numpy implementation they replaced.

``data/numpy_policies.npz`` holds, for three scenarios (lossy and delayed
links, a switching topology, model spread with random starts), one stream of
40 observations of 2 fleets (``nn_dsc`` in closed loop, fleet 0's policy
restarted at step 20), and the actions and diagnostics that each analytic
policy's former numpy implementation (the delay-compensated ones included)
computed from that stream, recorded
before the compiled kernels replaced it. The policies are replayed on the
same stream here.

Tolerance: the policies without the NN (``dsc``, ``backstepping``) must be
bit-identical. Those with the NN agree to 1e-12 of each signal's scale: the
kernel's ``math.tanh`` (the C library) and numpy's vectorized ``np.tanh``
differ by an ulp on some inputs (measured: at most 3e-14 on forces of about
200 N over the 40 steps), which then propagates through the adapted weights.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import baselines
from cpf_env import FleetSim, scenarios

DATA = np.load(Path(__file__).parent / "data" / "numpy_policies.npz")
CASES = ("lossy_links", "switching_topology", "bench_heterogeneous")
POLICIES = (
    "nn_dsc",
    "dsc",
    "nn_dsc_no_aux",
    "nn_dsc_global_v0",
    "backstepping",
    "nn_dsc_delay_comp",
    "backstepping_delay_comp",
)
SIGNALS = ("actions", "nn_output", "speed_estimate", "aux_state", "nubar_dot")
RESTART = 20
#: Policies without the NN: bit-identical to the numpy implementation.
EXACT = ("dsc", "backstepping", "backstepping_delay_comp")


def _replay(name: str, scenario: str) -> dict[str, np.ndarray]:
    stream = DATA[f"{scenario}/obs"]
    policy = baselines.make_policy(name, scenarios.get(scenario))
    recorded: dict[str, list[np.ndarray]] = {signal: [] for signal in SIGNALS}
    for t in range(stream.shape[0]):
        if t == RESTART:
            policy.reset_fleets(np.array([True, False]))
        recorded["actions"].append(policy.act_batch(stream[t]))
        for signal in SIGNALS[1:]:
            recorded[signal].append(policy.diagnostics[signal])
    return {signal: np.stack(values) for signal, values in recorded.items()}


@pytest.mark.parametrize("scenario", CASES)
@pytest.mark.parametrize("name", POLICIES)
def test_compiled_policy_reproduces_the_numpy_implementation(name: str, scenario: str) -> None:
    replayed = _replay(name, scenario)
    for signal in SIGNALS:
        expected = DATA[f"{scenario}/{name}/{signal}"]
        if name in EXACT:
            np.testing.assert_array_equal(replayed[signal], expected, err_msg=signal)
        else:
            scale = np.abs(expected).max()
            np.testing.assert_allclose(
                replayed[signal], expected, rtol=0.0, atol=1e-12 * scale, err_msg=signal
            )


def test_the_comparison_sees_a_perturbed_input_and_a_missing_restart() -> None:
    """The recorded numbers pin the policy: a 1 mm path error or a skipped restart shows."""
    expected = DATA["lossy_links/nn_dsc/actions"]
    stream = DATA["lossy_links/obs"].copy()
    stream[5, 0, 1, 3] += 1e-3  # vessel 1's surge path error at step 5 (m)
    policy = baselines.make_policy("nn_dsc", scenarios.get("lossy_links"))
    perturbed = np.stack([policy.act_batch(stream[t]) for t in range(10)])
    assert not np.allclose(perturbed[5:], expected[5:10], rtol=0.0, atol=1e-9)
    assert np.array_equal(perturbed[:5, 0], expected[:5, 0]) or np.allclose(
        perturbed[:5], expected[:5], rtol=0.0, atol=1e-12 * np.abs(expected).max()
    )
    policy.reset()
    stream = DATA["lossy_links/obs"]
    unrestarted = np.stack([policy.act_batch(stream[t]) for t in range(stream.shape[0])])
    assert not np.allclose(unrestarted[RESTART:, 0], expected[RESTART:, 0], rtol=1e-6)


@pytest.mark.parametrize("name", ["nn_dsc", "backstepping"])
def test_parallel_kernel_equals_the_serial_one_bit_for_bit(name: str) -> None:
    """B = 32 runs the threaded kernel; the same fleets acted for 8 at a time run serially."""
    task = scenarios.get("bench_mild")
    sim = FleetSim(task, num_fleets=32)
    threaded = baselines.make_policy(name, task)
    serial = baselines.make_policy(name, task)
    obs = sim.reset(seeds=list(range(32)))
    serial.act_batch(obs[:1].repeat(32, axis=0))  # allocate 32 fleets' states
    serial.reset_fleets(np.ones(32, dtype=bool))
    for t in range(300):
        actions = threaded.act_batch(obs)
        assert np.isfinite(actions).all(), t
        for start in range(0, 32, 8):
            fleets = np.arange(start, start + 8)
            np.testing.assert_array_equal(
                serial.act_batch(obs[fleets], fleets=fleets), actions[fleets], err_msg=str(t)
            )
        obs = sim.step(actions)


def test_policy_kernels_are_keyed_on_the_simulator_sources_they_inline(monkeypatch) -> None:
    """An edit to cpf_env's kernel sources (vessel.py, observation.py, ...) or to
    baselines/kernels.py changes the cache stamp of the policy kernels."""
    from baselines import kernels
    from cpf_env.infra import kernel_cache

    source = kernels.__file__
    stamp = kernel_cache._stamp_of(source)
    assert stamp is not None
    locator = kernels.act_rows_serial._cache._impl._locator
    assert locator.get_source_stamp() == ("cpf_env kernel sources", stamp)
    monkeypatch.setattr(kernel_cache, "_digest", lambda: "edited cpf_env sources")
    assert kernel_cache._stamp_of(source) not in (None, stamp)
