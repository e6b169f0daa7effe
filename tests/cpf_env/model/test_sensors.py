"""Navigation sensors (``cpf_env.model.sensors``): noise, fix rate, dropouts, no velocity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpf_env import scenarios
from cpf_env.model.sensors import Sensors
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.observation import NU, T1, Z1

BASE = scenarios.get("bench_mild")


def _run(sensors: Sensors, fleets: int, steps: int, seeds=None) -> dict[str, np.ndarray]:
    """Fixes, true poses, observations and errors of ``steps`` steps under a fixed command."""
    sim = FleetSim(BASE.replace(sensors=sensors), num_fleets=fleets)
    sim.reset(seeds=list(range(fleets)) if seeds is None else seeds)
    action = np.zeros((fleets, BASE.n, 4 + BASE.message_size))
    action[..., 0], action[..., 2], action[..., 3] = 3.0, 0.2, 0.1  # surge, yaw, path rate
    out: dict[str, list] = {"fix": [], "eta": [], "obs": [], "errors": [], "reward": []}
    for _ in range(steps):
        sim.step(action)
        a = sim.arrays
        for name, value in (("fix", a.fix), ("eta", a.eta), ("obs", a.obs),
                            ("errors", a.errors), ("reward", a.reward)):  # fmt: skip
            out[name].append(value.copy())
    return {name: np.array(values) for name, values in out.items()}


def test_the_default_observes_the_true_state_every_step() -> None:
    assert Sensors().ideal and BASE.sensors == Sensors()
    run = _run(Sensors(), fleets=2, steps=20)
    assert np.array_equal(run["fix"], run["eta"])


def test_fix_noise_has_the_given_standard_deviations_and_is_independent() -> None:
    """64 fleets x 5 vessels x 200 fixes: the sample spread within 3 % of the setting."""
    run = _run(Sensors(position_std=0.02, heading_std=math.radians(1.0)), fleets=64, steps=200)
    noise = (run["fix"] - run["eta"]).reshape(-1, 3)
    np.testing.assert_allclose(noise.std(axis=0), [0.02, 0.02, math.radians(1.0)], rtol=0.03)
    assert np.all(np.abs(noise.mean(axis=0)) < 0.05 * noise.std(axis=0))
    correlation = np.corrcoef(noise.T)
    assert np.all(np.abs(correlation[np.triu_indices(3, 1)]) < 0.02)


def test_a_fix_every_period_steps_held_in_between() -> None:
    """No noise, a fix every 4 steps: the fix is the true pose at steps 4, 8, ... and held."""
    run = _run(Sensors(period=4), fleets=2, steps=40)
    for row in range(40):  # row r is after step r + 1
        step = row + 1
        last_fix_row = step - step % 4 - 1
        expected = run["eta"][last_fix_row] if last_fix_row >= 0 else None
        if expected is not None:
            assert np.array_equal(run["fix"][row], expected), step
    assert not np.array_equal(run["fix"][1], run["eta"][1])  # the hull moved, the fix did not


def test_dropouts_lose_the_given_share_of_fixes() -> None:
    """32 fleets x 5 vessels x 300 scheduled fixes, 30 % lost: 0.30 within 0.01."""
    run = _run(Sensors(dropout=0.3), fleets=32, steps=300)
    fresh = np.all(run["fix"] == run["eta"], axis=-1)  # no noise: a new fix is the true pose
    assert abs(1.0 - fresh.mean() - 0.3) < 0.01
    held = ~fresh[1:] & np.all(run["fix"][1:] == run["fix"][:-1], axis=-1)
    assert held.sum() == (~fresh[1:]).sum()  # a lost fix keeps the last one exactly


def test_without_velocity_the_observation_reads_zero_and_the_cost_stays_true() -> None:
    blind = _run(Sensors(position_std=0.05, velocity=False), fleets=3, steps=50)
    ideal = _run(Sensors(), fleets=3, steps=50)
    assert np.all(blind["obs"][..., NU : NU + 3] == 0.0)
    assert np.any(ideal["obs"][..., NU : NU + 3] != 0.0)
    # Same commands, same plant: the true state, its errors and its cost are those of the ideal run.
    assert np.array_equal(blind["eta"], ideal["eta"])
    assert np.array_equal(blind["errors"], ideal["errors"])
    assert np.array_equal(blind["reward"], ideal["reward"])
    assert not np.array_equal(blind["obs"][..., Z1 : Z1 + 3], ideal["obs"][..., Z1 : Z1 + 3])


def test_the_observation_is_the_fixs_path_frame() -> None:
    """With heading noise only, the observed tangent t1 is turned by exactly the noise."""
    run = _run(Sensors(heading_std=0.05), fleets=2, steps=30)
    ideal = _run(Sensors(), fleets=2, steps=30)
    seen = np.arctan2(run["obs"][..., T1 + 1], run["obs"][..., T1])
    true = np.arctan2(ideal["obs"][..., T1 + 1], ideal["obs"][..., T1])
    turned = np.angle(np.exp(1j * (true - seen)))
    np.testing.assert_allclose(turned, run["fix"][..., 2] - run["eta"][..., 2], atol=1e-6)


def test_a_fleet_sees_the_same_noise_at_any_batch_size() -> None:
    sensors = Sensors(position_std=0.03, heading_std=0.01, period=2, dropout=0.2, velocity=False)
    alone = _run(sensors, fleets=1, steps=60, seeds=[7])
    batch = _run(sensors, fleets=3, steps=60, seeds=[5, 7, 9])
    assert np.array_equal(alone["obs"][:, 0], batch["obs"][:, 1])


@pytest.mark.parametrize(
    ("options", "message"),
    [({"period": 0}, "integer number of control steps >= 1"),
     ({"period": 0.5}, "a faster sensor is read at the control rate"),
     ({"position_std": -0.01}, "position_std must be a finite number >= 0"),
     ({"heading_std": math.nan}, "heading_std must be a finite number"),
     ({"dropout": 1.0}, "dropout must be below 1"),
     ({"velocity": "no"}, "velocity must be True or False")],
)  # fmt: skip
def test_bad_sensor_settings_are_refused_saying_what_to_change(options, message) -> None:
    with pytest.raises(ValueError, match=message):
        Sensors(**options)
