"""FleetMetrics against hand calculations on a constructed two-fleet trajectory.

Three vessels follow parallel straight lines y = 0, 5, 10 m along +x (so
theta is the x of the path point and |eta_d'| = 1). Every quantity is set by
hand and the expected metrics are written out as arithmetic on those
numbers, independently of the code under test.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from cpf_env.evaluation.fleet_metrics import METRICS, FleetMetrics, path_relative
from cpf_env.model.paths import StraightLine
from cpf_env.scenarios.reward_weights import REWARD_TERMS

DT, T, V0 = 0.1, 8, 0.5
LINES = tuple(StraightLine(y0=5.0 * i) for i in range(3))
ALONG = np.array([0.1, -0.2, 0.3])
CROSS_EARLY, CROSS_LATE = np.array([0.3, 0.0, -0.4]), np.array([0.1, 0.1, 0.1])
HEADING = np.array([0.05, -0.1, 0.02])
OFFSET = np.array([0.0, 0.5, -0.25])  # theta_i - theta_0
PATH_ERROR = np.array([0.2, 0.7, 0.4])
U, V = 1.0, 0.1
FAIL_STEP = 4  # fleet 1 fails on step index 3: it lasts 4 steps
GARBAGE = 1e6


def _state(t: int, fleet: int) -> SimpleNamespace:
    """The simulator's arrays after step t of one fleet, (1, 3, ...)."""
    bad = fleet == 1 and t >= FAIL_STEP
    cross = CROSS_LATE if t >= 6 else CROSS_EARLY
    theta = 0.8 * V0 * (t + 1) * DT + OFFSET
    eta = np.stack(
        [theta + ALONG, 5.0 * np.arange(3) + cross, HEADING + np.array([0, 2 * np.pi, 0])], -1
    )
    errors = np.zeros((3, 4))
    errors[:, 0] = PATH_ERROR
    tau_applied = np.array([[1.0, 0.0, 0.0]] * 3)  # half of tau_scale 2 N on one axis
    tau_command = tau_applied.copy()
    tau_command[0, 1] = 3.0  # vessel 0 saturated on every step
    state = {
        "eta": eta,
        "nu": np.array([[U, V, 0.0]] * 3),
        "theta": theta,
        "theta_dot": np.full(3, V0 + 0.1),
        "errors": errors,
        "reward": np.full(3, -1.0),
        "reward_terms": np.zeros((3, len(REWARD_TERMS))),
        "tau_applied": tau_applied,
        "tau_command": tau_command,
    }
    if bad:
        state = {k: np.full_like(v, GARBAGE) for k, v in state.items()}
    return SimpleNamespace(**state)


def _batch(t: int) -> SimpleNamespace:
    fleets = [_state(t, 0), _state(t, 1)]
    return SimpleNamespace(
        **{k: np.stack([getattr(f, k) for f in fleets]) for k in vars(fleets[0])}
    )


def _measure(sway: bool) -> dict[str, np.ndarray]:
    """The metrics of the two recorded fleets, on hulls with or without a sway actuator."""
    actuated = np.ones((3, 3), dtype=bool)
    actuated[:, 1] = sway
    sim = SimpleNamespace(
        scenario=SimpleNamespace(dt=DT, paths=LINES, separation=None, actuated=actuated),
        constants=SimpleNamespace(tau_scale=np.full((3, 3), 2.0)),
        num_fleets=2,
    )
    meter = FleetMetrics(sim, T)  # type: ignore[arg-type]
    start = _batch(0)
    start.theta = OFFSET[None] + 0.0 * start.theta
    start.eta = start.eta.copy()
    start.eta[..., 0] = OFFSET + ALONG
    meter.start(start)  # type: ignore[arg-type]
    for t in range(T):
        meter.record(t, _batch(t), V0, np.full((2, 3), V0 - 0.05))  # type: ignore[arg-type]
    return meter.reduce(np.array([T, FAIL_STEP]), np.array([False, True]))


@pytest.fixture(scope="module")
def measured() -> dict[str, np.ndarray]:
    return _measure(sway=True)


def test_every_metric_is_returned(measured: dict[str, np.ndarray]) -> None:
    assert tuple(measured) == METRICS
    assert all(v.shape == (2,) for v in measured.values())


def test_path_relative_in_a_rotated_frame() -> None:
    """A line heading 90 deg: along is +y, cross is -x; heading wraps; sog projects."""
    line = (StraightLine(x0=1.0, y0=2.0, heading=math.pi / 2),)
    from cpf_env.model.paths import encode_paths

    kinds, params = encode_paths(line)
    eta = np.array([[[1.0 - 0.3, 2.0 + 4.0 + 0.2, math.pi / 2 + 0.1 - 2 * math.pi]]])
    rel = path_relative(eta, np.array([[[2.0, 0.5, 0.0]]]), np.array([[4.0]]), kinds, params)
    assert rel["along"][0, 0] == pytest.approx(0.2)
    assert rel["cross"][0, 0] == pytest.approx(0.3)
    assert rel["heading"][0, 0] == pytest.approx(0.1)
    assert rel["sog"][0, 0] == pytest.approx(2.0 * math.cos(0.1) - 0.5 * math.sin(0.1))
    assert rel["thetap"][0, 0] == pytest.approx(4.2)
    assert rel["course"][0, 0] == pytest.approx(0.1 + math.atan2(0.5, 2.0))


def test_a_crabbing_hull_is_on_course_and_off_heading() -> None:
    """Sliding sideways at v = -0.05 m/s while surging at 0.5 m/s, the hull holds its line
    only with its bow turned into the drift by beta = atan(0.1): heading error beta, course 0."""
    (line,) = LINES[:1]
    from cpf_env.model.paths import encode_paths

    kinds, params = encode_paths((line,))
    beta = math.atan2(0.05, 0.5)
    eta = np.array([[[3.0, 0.0, beta]]])
    rel = path_relative(eta, np.array([[[0.5, -0.05, 0.0]]]), np.array([[3.0]]), kinds, params)
    assert rel["heading"][0, 0] == pytest.approx(beta)
    assert rel["course"][0, 0] == pytest.approx(0.0, abs=1e-15)
    assert rel["sog"][0, 0] == pytest.approx(math.hypot(0.5, 0.05))


def test_course_is_measured_only_where_no_hull_has_a_sway_actuator(
    measured: dict[str, np.ndarray],
) -> None:
    for name in ("course_error_rms", "course_error_max", "course_error_rms_window"):
        assert np.isnan(measured[name]).all()
    swayless = _measure(sway=False)
    course = np.array([h + math.atan2(V, U) for h in HEADING])
    assert swayless["course_error_rms"][0] == pytest.approx(math.sqrt(np.mean(course**2)))
    assert swayless["course_error_max"][0] == pytest.approx(np.abs(course).max())
    assert all(
        np.array_equal(swayless[name], measured[name], equal_nan=True)
        for name in METRICS
        if not name.startswith("course_")
    )


def test_path_errors(measured: dict[str, np.ndarray]) -> None:
    early = (0.3**2 + 0.0 + 0.4**2) / 3
    assert measured["cross_track_error_rms"][0] == pytest.approx(
        math.sqrt((6 * early + 2 * 0.01) / 8)
    )
    assert measured["cross_track_error_rms_window"][0] == pytest.approx(0.1)
    assert measured["cross_track_error_max"][0] == pytest.approx(0.4)
    assert measured["cross_track_error_max_window"][0] == pytest.approx(0.1)
    along = math.sqrt((0.01 + 0.04 + 0.09) / 3)
    assert measured["along_track_error_rms"][0] == pytest.approx(along)
    assert measured["path_error_max"][0] == pytest.approx(0.7)
    assert measured["path_error_rms"][0] == pytest.approx(math.sqrt((0.04 + 0.49 + 0.16) / 3))


def test_heading_wraps_and_speed_over_ground(measured: dict[str, np.ndarray]) -> None:
    heading = math.sqrt((0.05**2 + 0.1**2 + 0.02**2) / 3)
    assert measured["heading_error_rms"][0] == pytest.approx(heading)
    assert measured["heading_error_max"][0] == pytest.approx(0.1)
    sog = np.mean([U * math.cos(h) - V * math.sin(h) for h in HEADING])
    assert measured["speed_along_path"][0] == pytest.approx(sog)
    sog_error = math.sqrt(np.mean([(U * math.cos(h) - V * math.sin(h) - V0) ** 2 for h in HEADING]))
    assert measured["speed_along_path_error_rms"][0] == pytest.approx(sog_error)


def test_formation_is_physical_and_theta_spread_is_not(measured: dict[str, np.ndarray]) -> None:
    # projected positions theta_i + along_i: 0.1, 0.3, 0.05 -> spread 0.25 m;
    # path variables 0, 0.5, -0.25 -> spread 0.75
    for name in ("formation_error_rms", "formation_error_max", "formation_error_end"):
        assert measured[name][0] == pytest.approx(0.25)
    assert measured["theta_spread_rms"][0] == pytest.approx(0.75)
    assert measured["theta_spread_end"][0] == pytest.approx(0.75)


def test_progress_rates_and_effort(measured: dict[str, np.ndarray]) -> None:
    # the fleet advances 0.8 v0 dt per step: progress 0.8 over the episode and the window
    assert measured["progress"][0] == pytest.approx(0.8)
    assert measured["progress_window"][0] == pytest.approx(0.8)
    assert measured["theta_rate_error_rms"][0] == pytest.approx(0.1)
    assert measured["speed_estimate_error_rms"][0] == pytest.approx(0.05)
    assert measured["control_energy"][0] == pytest.approx(T * DT * 0.25)
    assert measured["saturated_fraction"][0] == pytest.approx(1 / 3)
    assert measured["cost"][0] == pytest.approx(T)
    assert measured["return"][0] == pytest.approx(-T)


def test_a_failed_fleet_counts_up_to_its_failure(measured: dict[str, np.ndarray]) -> None:
    assert measured["terminated"].tolist() == [0.0, 1.0]
    assert measured["steps"].tolist() == [T, FAIL_STEP]
    early = math.sqrt((0.3**2 + 0.4**2) / 3)
    assert measured["cross_track_error_rms"][1] == pytest.approx(early)
    assert measured["cross_track_error_rms_window"][1] == pytest.approx(early)
    assert measured["cost"][1] == pytest.approx(FAIL_STEP)
    assert measured["formation_error_end"][1] == pytest.approx(0.25)
    assert measured["progress"][1] == pytest.approx(0.8)
    assert measured["path_error_max_window"][1] == pytest.approx(0.7)
