"""Unmodeled dynamics, ocean current, wave and wind processes (docs/model.md, section 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import NO_DISTURBANCES, free_scenario, reference_matrices, rotation_matrix

from cpf_env import scenarios
from cpf_env.model.disturbances import (
    D_CURRENT_MEAN,
    D_CURRENT_STD,
    D_CURRENT_TC,
    D_SCALE,
    D_WAVE_MEAN,
    D_WAVE_STD,
    D_WAVE_TC,
    D_WIND_MEAN,
    D_WIND_STD,
    D_WIND_TC,
    DIST_PARAM_SIZE,
    Disturbances,
    GaussMarkov,
    OceanCurrent,
    paper_disturbance,
    paper_unmodeled,
)
from cpf_env.model.plant import plant_rhs
from cpf_env.model.vessel import CYBERSHIP2, VesselModel
from cpf_env.sim.fleet import FleetSim

PERTURBED = CYBERSHIP2.perturbed(np.random.default_rng(3), 0.3)


def paper_delta(nu: np.ndarray) -> np.ndarray:
    u, v, r = nu
    return np.array([v**3 + 0.03 * u, u * r + 0.02 * u, u * r + 0.2 * r**2])


def paper_tau_w(t: float, nu: np.ndarray) -> np.ndarray:
    u, v, r = nu
    s = 0.001 * math.sin(t)
    return np.array([v**3 + 0.06 * u + s, u * r + 0.1 * u + s, 0.4 * u * r + v**2 + s])


def reference_rhs(
    model: VesselModel,
    scale: float,
    t: float,
    eta: np.ndarray,
    nu: np.ndarray,
    tau: np.ndarray,
    force_earth: np.ndarray,
    current: np.ndarray,
) -> np.ndarray:
    """(eta', nu') of eq. [2]-[3] with current (Fossen 2011, 10.3) and earth-frame forces."""
    J = rotation_matrix(eta[2])
    nu_c = J.T @ np.array([current[0], current[1], 0.0])
    nu_r = nu - nu_c
    mass, coriolis, damping = reference_matrices(model, nu_r)
    force = tau + J.T @ force_earth - coriolis @ nu_r - damping @ nu_r
    force += scale * (paper_tau_w(t, nu_r) - paper_delta(nu_r))
    skew = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    # nu = nu_r + J^T V_c with V_c constant: d/dt (J^T V_c) = -r S J^T V_c.
    nu_dot = np.linalg.solve(mass, force) - nu[2] * skew @ nu_c
    return np.concatenate([J @ nu, nu_dot])


# --- the paper's terms ------------------------------------------------------------------


def test_paper_terms_match_formulas() -> None:
    rng = np.random.default_rng(0)
    for t, nu in zip(rng.uniform(-20, 20, 50), rng.uniform(-2, 2, (50, 3)), strict=True):
        np.testing.assert_allclose(paper_unmodeled(*nu), paper_delta(nu), rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(
            paper_disturbance(t, *nu), paper_tau_w(t, nu), rtol=1e-14, atol=1e-15
        )


@pytest.mark.parametrize("scale", [0.0, 1.0, 0.4])
@pytest.mark.parametrize("model", [CYBERSHIP2, PERTURBED], ids=["cybership2", "perturbed"])
@pytest.mark.parametrize("current", [(0.0, 0.0), (0.15, -0.25)], ids=["still", "current"])
def test_plant_rhs_matches_paper(
    scale: float, model: VesselModel, current: tuple[float, float]
) -> None:
    """Delta on the left, tau_w on the right, scaled; forces rotated; current relative."""
    rng = np.random.default_rng(1)
    params = model.to_params()
    for _ in range(20):
        t = rng.uniform(0, 100)
        eta = rng.uniform(-5, 5, 3)
        nu = rng.uniform(-1, 1, 3)
        tau, force = rng.uniform(-5, 5, 3), rng.uniform(-2, 2, 3)
        got = plant_rhs(params, scale, t, eta[2], *nu, (*tau, *force, *current))
        expected = reference_rhs(model, scale, t, eta, nu, tau, force, np.array(current))
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-13)


def test_first_step_acceleration_includes_every_force() -> None:
    """One tiny control step of FleetSim against the reference right-hand side.

    Checks that the kernel passes the saturated force, the wave + wind states and
    the current to the plant (finite difference over dt = 1e-6 s).
    """
    disturbances = Disturbances(
        current=OceanCurrent(velocity=(0.1, -0.05), std=0.02),
        waves=GaussMarkov(mean=(0.5, -0.2, 0.1), std=(0.3, 0.3, 0.05), time_constant=2.0),
        wind=GaussMarkov(mean=(0.2, 0.4, 0.0), std=(0.1, 0.1, 0.02), time_constant=30.0),
    )
    nu0 = [[0.3, -0.1, 0.2], [0.1, 0.05, -0.1], [-0.2, 0.1, 0.05]]
    scenario = free_scenario(nu0, disturbances=disturbances, dt=1e-6, substeps=1)
    sim = FleetSim(scenario, num_fleets=2)
    sim.reset(seeds=[4, 5])
    a = sim.arrays
    before = {name: getattr(a, name).copy() for name in ("eta", "nu", "waves", "wind", "current")}
    command = np.array([3.0, -6.0, 1.0])  # sway beyond 4.5 N: saturates
    actions = np.zeros((2, 3, sim.act_dim))
    actions[..., :3] = command
    sim.step(actions)
    tau = np.clip(command, -np.array([9.2, 4.5, 3.0]), [9.2, 4.5, 3.0])
    for b in range(2):
        for i in range(3):
            force = before["waves"][b, i] + before["wind"][b, i]
            expected = reference_rhs(
                CYBERSHIP2,
                1.0,
                0.0,
                before["eta"][b, i],
                before["nu"][b, i],
                tau,
                force,
                before["current"][b],
            )
            got = np.concatenate(
                [a.eta[b, i] - before["eta"][b, i], a.nu[b, i] - before["nu"][b, i]]
            )
            np.testing.assert_allclose(got / 1e-6, expected, rtol=1e-5, atol=1e-7)


def test_unmodeled_scale_zero_removes_the_paper_terms() -> None:
    """A vessel at rest with no force stays at rest exactly; with the paper's terms it moves."""
    rest = [[0.0, 0.0, 0.0]] * 2
    results = {}
    for scale in (0.0, 1.0):
        sim = FleetSim(free_scenario(rest, disturbances=Disturbances(unmodeled_scale=scale)))
        sim.reset(seeds=[0])
        eta0 = sim.arrays.eta.copy()
        for _ in range(100):
            sim.step(np.zeros((1, 2, sim.act_dim)))
        results[scale] = (np.abs(sim.arrays.eta - eta0).max(), np.abs(sim.arrays.nu).max())
    assert results[0.0] == (0.0, 0.0)
    assert results[1.0][1] > 1e-5  # 0.001 sin t pushes every axis


# --- ocean current ----------------------------------------------------------------------


@pytest.mark.parametrize("psi0", [0.7, -2.4])
@pytest.mark.parametrize("velocity", [(0.2, -0.1), (-0.05, 0.3)])
def test_current_carries_a_vessel_at_rest_with_the_water(
    psi0: float, velocity: tuple[float, float]
) -> None:
    """Damping acts on nu_r = nu - J^T V_c, so the unforced vessel ends with nu_r -> 0."""
    disturbances = Disturbances(unmodeled_scale=0.0, current=OceanCurrent(velocity=velocity))
    scenario = free_scenario(
        [[0.0, 0.0, 0.0]], disturbances=disturbances, psi0=psi0, dt=0.5, substeps=10
    )
    sim = FleetSim(scenario)
    sim.reset(seeds=[0])
    actions = np.zeros((1, 1, sim.act_dim))
    for _ in range(600):  # 300 s: surge damping is slow at low speed (m11 / d11 ~ 36 s)
        sim.step(actions)
    eta, nu = sim.arrays.eta[0, 0].copy(), sim.arrays.nu[0, 0].copy()
    earth_velocity = rotation_matrix(eta[2]) @ nu
    np.testing.assert_allclose(earth_velocity[:2], velocity, atol=1e-4)
    assert abs(nu[2]) < 1e-6
    for _ in range(20):  # and it drifts with the water: 10 s -> 10 V_c
        sim.step(actions)
    np.testing.assert_allclose(
        sim.arrays.eta[0, 0, :2] - eta[:2], 10.0 * np.array(velocity), atol=1e-3
    )


# --- Gauss-Markov processes -------------------------------------------------------------

GM_DISTURBANCES = Disturbances(
    unmodeled_scale=0.0,
    current=OceanCurrent(velocity=(0.1, -0.2), std=0.05, time_constant=3.0),
    waves=GaussMarkov(mean=(0.0, 0.0, 0.0), std=(0.5, 0.3, 0.1), time_constant=2.0),
    wind=GaussMarkov(mean=(0.3, -0.2, 0.05), std=(0.2, 0.1, 0.02), time_constant=5.0),
)


@pytest.fixture(scope="module")
def gauss_markov_run() -> dict[str, np.ndarray]:
    """States of 400 fleets x 5 vessels over 300 control steps (15 s), from reset on."""
    scenario = scenarios.get("wang2014").replace(disturbances=GM_DISTURBANCES)
    sim = FleetSim(scenario, num_fleets=400)
    sim.reset(seeds=list(range(400)))
    actions = np.zeros((400, 5, sim.act_dim))
    records: dict[str, list[np.ndarray]] = {"waves": [], "wind": [], "current": []}
    for _ in range(301):
        for name, values in records.items():
            values.append(getattr(sim.arrays, name).copy())
        sim.step(actions)
    # -> (time, chains, component)
    return {name: np.array(v).reshape(301, -1, v[0].shape[-1]) for name, v in records.items()}


GM_CASES = {
    "waves": (GM_DISTURBANCES.waves.mean, GM_DISTURBANCES.waves.std, 2.0),
    "wind": (GM_DISTURBANCES.wind.mean, GM_DISTURBANCES.wind.std, 5.0),
    "current": ((0.1, -0.2), (0.05, 0.05), 3.0),
}


@pytest.mark.parametrize("process", GM_CASES)
def test_gauss_markov_stationary_statistics(
    gauss_markov_run: dict[str, np.ndarray], process: str
) -> None:
    """Mean, std, lag-1 and lag-T correlation of the stationary process x' = -(x - m)/T + w."""
    mean, std, time_constant = (np.array(x, dtype=float) for x in GM_CASES[process])
    x = gauss_markov_run[process]
    steps, chains, _ = x.shape
    dt = 0.05
    z = (x - mean) / std  # standardized with the specified mean and std
    # Effective independent samples: chains x (run length / 2 T), at least chains.
    n_eff = chains * max(1.0, (steps - 1) * dt / (2.0 * time_constant))
    assert np.all(np.abs(z.mean(axis=(0, 1))) < 5.0 / math.sqrt(n_eff))
    assert np.all(np.abs(z.var(axis=(0, 1)) - 1.0) < 5.0 * math.sqrt(2.0 / n_eff))
    assert np.all(np.abs(z[0].var(axis=0) - 1.0) < 5.0 * math.sqrt(2.0 / chains))  # reset draw
    # Lag-1 regression coefficient: every transition carries a fresh innovation, so its
    # standard error is sqrt((1 - rho^2) / transitions) -- a sharp test of exp(-dt / T).
    rho1 = math.exp(-dt / time_constant)
    lag1 = (z[:-1] * z[1:]).sum(axis=(0, 1)) / (z[:-1] ** 2).sum(axis=(0, 1))
    assert np.all(np.abs(lag1 - rho1) < 5.0 * math.sqrt((1.0 - rho1**2) / ((steps - 1) * chains)))
    lag = round(time_constant / dt)  # one correlation time: e^-1
    correlation = (z[:-lag] * z[lag:]).sum(axis=(0, 1)) / (z[:-lag] ** 2).sum(axis=(0, 1))
    assert np.all(np.abs(correlation - math.exp(-1.0)) < 5.0 / math.sqrt(n_eff))


def test_gauss_markov_draws_are_independent(gauss_markov_run: dict[str, np.ndarray]) -> None:
    """No shared noise between vessels, components, fleets, or wave and wind streams."""
    waves = (gauss_markov_run["waves"] - 0.0) / np.array(GM_DISTURBANCES.waves.std)
    wind = (gauss_markov_run["wind"] - np.array(GM_DISTURBANCES.wind.mean)) / np.array(
        GM_DISTURBANCES.wind.std
    )
    increments = {"waves": np.diff(waves, axis=0), "wind": np.diff(wind, axis=0)}
    w = increments["waves"]  # (time, chains = fleet * 5 + vessel, 3)
    pairs = {
        "vessel 0 vs 1": (w[:, 0::5, 0], w[:, 1::5, 0]),
        "fleet b vs b+1": (w[:, 0:-5:5, 0], w[:, 5::5, 0]),
        "x vs y": (w[..., 0], w[..., 1]),
        "waves vs wind": (w[..., 0], increments["wind"][..., 0]),
    }
    for name, (first, second) in pairs.items():
        correlation = np.corrcoef(first.ravel(), second.ravel())[0, 1]
        assert abs(correlation) < 5.0 / math.sqrt(first.size), name


# --- configuration ----------------------------------------------------------------------


def test_encode_layout_matches_kernel_indices() -> None:
    encoded = GM_DISTURBANCES.encode()
    assert encoded.shape == (DIST_PARAM_SIZE,)
    assert encoded[D_SCALE] == 0.0
    np.testing.assert_array_equal(encoded[D_CURRENT_MEAN : D_CURRENT_MEAN + 2], [0.1, -0.2])
    assert (encoded[D_CURRENT_STD], encoded[D_CURRENT_TC]) == (0.05, 3.0)
    np.testing.assert_array_equal(encoded[D_WAVE_STD : D_WAVE_STD + 3], [0.5, 0.3, 0.1])
    np.testing.assert_array_equal(encoded[D_WAVE_MEAN : D_WAVE_MEAN + 3], [0.0, 0.0, 0.0])
    assert encoded[D_WAVE_TC] == 2.0
    np.testing.assert_array_equal(encoded[D_WIND_MEAN : D_WIND_MEAN + 3], [0.3, -0.2, 0.05])
    np.testing.assert_array_equal(encoded[D_WIND_STD : D_WIND_STD + 3], [0.2, 0.1, 0.02])
    assert encoded[D_WIND_TC] == 5.0


def test_default_disturbances_are_the_paper_only() -> None:
    d = Disturbances()
    assert d.unmodeled_scale == 1.0
    assert d.current.velocity == (0.0, 0.0) and d.current.std == 0.0
    for process in (d.waves, d.wind):
        assert process.mean == (0.0, 0.0, 0.0) and process.std == (0.0, 0.0, 0.0)
    assert NO_DISTURBANCES.unmodeled_scale == 0.0


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: Disturbances(unmodeled_scale=-1.0), "unmodeled_scale"),
        (lambda: Disturbances(unmodeled_scale=float("nan")), "unmodeled_scale"),
        (lambda: GaussMarkov(std=(1.0, -0.1, 0.0)), "std must be >= 0"),
        (lambda: GaussMarkov(mean=(1.0, 2.0)), "mean must be 3 finite numbers"),
        (lambda: GaussMarkov(time_constant=0.0), "time_constant must be > 0"),
        (lambda: OceanCurrent(velocity=(0.1, float("inf"))), "velocity must be 2 finite"),
        (lambda: OceanCurrent(std=-0.01), "std must be >= 0"),
        (lambda: OceanCurrent(time_constant=-5.0), "time_constant must be > 0"),
    ],
)
def test_bad_disturbances_are_rejected(build: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        build()  # type: ignore[operator]


def test_a_process_without_spread_skips_only_draws_that_cannot_matter() -> None:
    """The kernel skips the normal draw when ``gauss_markov_needs_noise`` says so: the
    update must then equal the drift bit for bit, whatever the draw's sign."""
    from cpf_env.model.disturbances import gauss_markov_needs_noise, gauss_markov_update

    for drift in (1.5, -2.0e-300, 0.0, -0.0, 5e-324):
        for spread in (0.0, 0.3):
            results = [gauss_markov_update(drift, spread, noise) for noise in (1.2, -0.7)]
            independent = all(r == drift and np.signbit(r) == np.signbit(drift) for r in results)
            assert gauss_markov_needs_noise(drift, spread) == (not independent), (drift, spread)
