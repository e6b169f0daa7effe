"""Scenario registry, the paper's scenario, the named variants, and validation messages."""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest
from conftest import ROOT, TAU_MAX

import cpf_env
from cpf_env import scenarios
from cpf_env.model.disturbances import Disturbances
from cpf_env.model.graph import Graph, SwitchingTopology
from cpf_env.model.links import LinkImpairments
from cpf_env.model.paths import Sinusoid, StraightLine
from cpf_env.model.vessel import CYBERSHIP2, PARAM_NAMES
from cpf_env.scenarios import InitialState, Scenario, SpeedSchedule, registry
from cpf_env.sim.fleet import FleetSim

SCENARIO_NAMES = scenarios.list_scenarios()
PAPER_OFFSETS = (-8.0, -4.0, 0.0, 4.0, 8.0)


# --- registry ---------------------------------------------------------------------------


def test_registry_lists_and_builds_every_scenario() -> None:
    assert SCENARIO_NAMES[0] == "wang2014"
    assert len(SCENARIO_NAMES) == len(set(SCENARIO_NAMES)) >= 7
    for name in SCENARIO_NAMES:
        scenario = scenarios.get(name)
        assert isinstance(scenario, Scenario)
        assert scenario.name == name and scenario.description
        assert scenarios.get(name) == scenario  # a fresh, equal object per call
        sim = FleetSim(scenario, num_fleets=2)
        sim.reset(seeds=[0, 1])
        sim.step(np.zeros((2, scenario.n, sim.act_dim)))


def test_unknown_name_lists_the_choices() -> None:
    with pytest.raises(ValueError, match=r"unknown scenario 'wang2015'.*'wang2014'"):
        scenarios.get("wang2015")


def test_register_adds_a_factory_and_refuses_duplicates(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    factory = lambda: scenarios.get("wang2014").replace(name="mine", v0=0.3)  # noqa: E731
    scenarios.register("mine", factory)
    assert scenarios.list_scenarios()[-1] == "mine"
    assert scenarios.get("mine").v0 == SpeedSchedule((0.0,), (0.3,))
    assert cpf_env.parallel_env("mine").scenario.name == "mine"
    with pytest.raises(ValueError, match="already registered"):
        scenarios.register("wang2014", factory)


def test_scenarios_are_frozen() -> None:
    scenario = scenarios.get("wang2014")
    with pytest.raises(dataclasses.FrozenInstanceError):
        scenario.dt = 0.1  # type: ignore[misc]


# --- the paper's scenario (docs/model.md, s. 10) ------------------------------------------


def test_wang2014_is_the_papers_simulation() -> None:
    s = scenarios.get("wang2014")
    assert s.n == 5
    assert (s.dt, s.substeps, s.max_steps) == (0.05, 5, 3000)
    assert s.v0 == SpeedSchedule((0.0,), (0.1,))
    assert s.tau_max == ((9.2, 4.5, 3.0),) * 5
    assert s.tau_min == ((-9.2, -4.5, -3.0),) * 5
    assert s.vessels == (CYBERSHIP2,) * 5 and s.model_spread == 0.0
    assert s.disturbances == Disturbances()  # the paper's Delta and tau_w, nothing else
    assert s.links.perfect
    # Chain 1-2-3-4-5 (vessels 0..4 here), B = diag[1, 0, 0, 1, 0], fixed.
    topology = s.switching
    assert len(topology.graphs) == 1
    chain = np.diag(np.ones(4), 1) + np.diag(np.ones(4), -1)
    np.testing.assert_array_equal(topology.graphs[0].adjacency, chain)
    np.testing.assert_array_equal(topology.graphs[0].leader_links, [1, 0, 0, 1, 0])
    # Paths x_d = theta, y_d = y_i + 2 sin(0.2 theta), psi_d = atan2(y_d', 1).
    theta = np.linspace(-5.0, 60.0, 27)
    for path, offset in zip(s.paths, PAPER_OFFSETS, strict=True):
        assert path == Sinusoid(y0=offset, amplitude=2.0, wavenumber=0.2)
        point = path.evaluate(theta)
        np.testing.assert_allclose(point[:, 0, 0], theta, atol=1e-12)
        np.testing.assert_allclose(point[:, 0, 1], offset + 2 * np.sin(0.2 * theta), atol=1e-12)
        np.testing.assert_allclose(point[:, 0, 2], np.arctan(0.4 * np.cos(0.2 * theta)), atol=1e-12)
        tangent = np.hypot(point[:, 1, 0], point[:, 1, 1])
        assert tangent.min() >= 1.0 and tangent.max() <= 1.08
    # Initial poses, at rest, theta = 0, no spread.
    x0, dy = (-1.0, 1.0, -0.5, 0.5, 0.0), (1.0, -1.0, 0.5, -0.5, 1.0)
    expected = tuple((x, y + d, 0.0) for x, y, d in zip(x0, PAPER_OFFSETS, dy, strict=True))
    init = s.initial
    assert init.eta == expected
    assert init.nu == ((0.0, 0.0, 0.0),) * 5 and init.theta == (0.0,) * 5
    assert init.position_std == init.heading_std == init.theta_std == 0.0
    sim = FleetSim(s)
    sim.reset(seeds=[123])
    np.testing.assert_array_equal(sim.arrays.eta[0], expected)
    np.testing.assert_array_equal(sim.arrays.nu[0], 0.0)


# --- the named variants (docs/model.md, s. 10) --------------------------------------

PAPER_TAU_MAX = np.array([9.2, 4.5, 3.0])
VARIANTS = {
    "saturation-heavy": lambda s: (
        np.all(np.array(s.tau_max) <= PAPER_TAU_MAX)
        and np.all(np.array(s.tau_min) >= -PAPER_TAU_MAX)
        and np.any(np.array(s.tau_max) < PAPER_TAU_MAX)
        and np.any(np.array(s.tau_min) > -PAPER_TAU_MAX)  # tighter on both sides
        and max(s.v0.values) > 0.1
    ),
    "current-and-waves": lambda s: (
        any(s.disturbances.current.velocity) and any(s.disturbances.waves.std)
    ),
    "lossy/delayed links": lambda s: s.links.loss_probability > 0.0 and s.links.delay_steps > 0,
    "switching topology": lambda s: len(s.switching.graphs) > 1,
    "heterogeneous fleet": lambda s: s.model_spread > 0.0,
    "n >= 8": lambda s: s.n >= 8,
}


@pytest.mark.parametrize("variant", VARIANTS)
def test_required_variant_is_registered(variant: str) -> None:
    matches = [name for name in SCENARIO_NAMES if VARIANTS[variant](scenarios.get(name))]
    assert matches, f"no registered scenario is a {variant} variant"


def test_saturation_heavy_really_saturates() -> None:
    """Commands of a simple P controller toward the path exceed the limits most of the time."""
    name = next(n for n in SCENARIO_NAMES if VARIANTS["saturation-heavy"](scenarios.get(n)))
    env = cpf_env.parallel_env(name, info_level="full")
    _, infos = env.reset(seed=0)
    saturated = 0
    for _ in range(100):
        actions = {}
        for agent in env.agents:
            z1 = env.layout
            obs = env.sim.arrays.obs[0, env.possible_agents.index(agent)]
            command = -20.0 * obs[z1.z1] - 20.0 * obs[z1.nu]
            actions[agent] = np.array([*command, 0.5, 0.0], dtype=np.float32)
        _, _, _, _, infos = env.step(actions)
        saturated += sum(bool(np.any(info["saturated"])) for info in infos.values())
    assert saturated > 0.5 * 100 * env.scenario.n


def test_heterogeneous_models_differ_per_vessel_and_per_reset() -> None:
    name = next(n for n in SCENARIO_NAMES if VARIANTS["heterogeneous fleet"](scenarios.get(n)))
    scenario = scenarios.get(name)
    spread = scenario.model_spread
    sim = FleetSim(scenario, num_fleets=2)
    sim.reset(seeds=[0, 1])
    params = sim.arrays.params.copy()
    nominal = np.array([v.to_params() for v in scenario.vessels])
    damping = slice(PARAM_NAMES.index("X_u"), None)
    ratio = params[..., damping] / nominal[None, :, damping]
    assert np.all((ratio >= 1.0 - spread) & (ratio <= 1.0 + spread))
    assert not np.array_equal(params[0], params[1])  # per reset seed
    assert len({row.tobytes() for row in params[0]}) == scenario.n  # per vessel
    sim.reset(seeds=[0], fleets=[1])
    np.testing.assert_array_equal(sim.arrays.params[1], params[0])  # reproducible


# --- replace() and validation messages --------------------------------------------------


def test_replace_overrides_and_revalidates() -> None:
    s = scenarios.get("wang2014").replace(v0=0.3, max_steps=10, tau_max=(4.0, 2.0, 1.0))
    assert s.v0 == SpeedSchedule((0.0,), (0.3,)) and s.max_steps == 10
    assert s.tau_min == ((-4.0, -2.0, -1.0),) * 5  # a mirrored tau_min keeps mirroring
    explicit = scenarios.get("wang2014").replace(tau_min=(-1.0, -2.0, -3.0))
    assert explicit.replace(tau_max=(2.0, 2.0, 2.0)).tau_min == ((-1.0, -2.0, -3.0),) * 5
    assert scenarios.get("wang2014").max_steps == 3000  # the registry copy is untouched


def test_replace_can_change_the_fleet_size() -> None:
    three = scenarios.get("wang2014").replace(
        paths=five_lines()[:3],
        topology=Graph.path(3, leaders=(0,)),
        initial=InitialState(eta=((0.0, 0.0, 0.0), (0.0, 4.0, 0.0), (0.0, 8.0, 0.0))),
    )
    assert three.n == 3 and three.tau_max == ((9.2, 4.5, 3.0),) * 3
    assert three.tau_min == ((-9.2, -4.5, -3.0),) * 3 and len(three.vessel_models) == 3


def test_replace_to_a_new_fleet_size_needs_per_vessel_fields_that_differ() -> None:
    mixed = scenarios.get("wang2014").replace(tau_max=TAU_MAX)
    with pytest.raises(ValueError, match=r"pass tau_max=\.\.\. for the new paths too"):
        mixed.replace(
            paths=five_lines()[:3],
            topology=Graph.path(3, leaders=(0,)),
            initial=InitialState(eta=((0.0, 0.0, 0.0), (0.0, 4.0, 0.0), (0.0, 8.0, 0.0))),
        )


def five_lines() -> tuple[StraightLine, ...]:
    return tuple(StraightLine(y0=4.0 * i) for i in range(5))


def scenario_with(**changes: object) -> Scenario:
    fields = {
        "name": "test",
        "paths": five_lines(),
        "topology": Graph.path(5, leaders=(0,)),
        "initial": InitialState(eta=tuple((0.0, 4.0 * i, 0.0) for i in range(5))),
    }
    fields.update(changes)
    return Scenario(**fields)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (
            lambda: scenario_with(topology=Graph.from_edges(5, [(0, 1), (2, 3), (3, 4)])),
            r"disconnected, components .*\(0, 1\), \(2, 3, 4\).*add links",
        ),
        (
            lambda: scenario_with(topology=Graph.path(5, leaders=())),
            r"No vessel hears the virtual leader.*leaders=\(0,\)",
        ),
        (
            lambda: scenario_with(
                topology=SwitchingTopology(
                    (Graph.from_edges(5, [(0, 1)]), Graph.from_edges(5, [(1, 2), (3, 4)])),
                    (0, 100),
                )
            ),
            "jointly connected",
        ),
        (
            lambda: scenario_with(vessels=dataclasses.replace(CYBERSHIP2, x_g=1.0)),
            r"mass matrix M is not positive definite.*check mass, inertia_z, x_g",
        ),
        (lambda: scenario_with(tau_max=(9.2, -4.5, 3.0)), r"tau_min < 0 < tau_max"),
        (lambda: scenario_with(tau_min=(1.0, -4.5, -3.0)), r"tau_min < 0 < tau_max"),
        (lambda: scenario_with(tau_max=((1.0, 1.0, 1.0),) * 4), r"tau_max must have shape"),
        (lambda: scenario_with(tau_max=(9.2, np.nan, 3.0)), r"tau_max has non-finite"),
        (lambda: scenario_with(paths=five_lines()[:4]), r"topology has 5 vessels but 4 paths"),
        (
            lambda: scenario_with(initial=InitialState(eta=((0.0, 0.0, 0.0),) * 4)),
            r"initial state has 4 vessels but 5 paths",
        ),
        (
            lambda: scenario_with(vessels=(CYBERSHIP2,) * 3),
            r"vessels must be one VesselModel or 5 of them, got 3",
        ),
        (lambda: scenario_with(dt=0.0), r"Scenario.dt = 0.0 is invalid.*must be > 0"),
        (lambda: scenario_with(substeps=0), r"Scenario.substeps = 0 is invalid"),
        (lambda: scenario_with(substeps=2.5), r"Scenario.substeps must be an integer, got 2.5"),
        (lambda: scenario_with(max_steps=0), r"Scenario.max_steps = 0 is invalid"),
        (lambda: scenario_with(model_spread=1.0), r"Scenario.model_spread = 1.0 is invalid"),
        (lambda: scenario_with(max_path_error=-1.0), r"max_path_error = -1.0 is invalid"),
        (lambda: scenarios.get("wang2014").replace(bogus=1), r"unknown Scenario field.*'bogus'"),
        (lambda: cpf_env.parallel_env("wang2014", bogus=1), r"unknown Scenario field.*'bogus'"),
        (lambda: LinkImpairments(loss_probability=1.0), r"loss_probability must be in \[0, 1\)"),
        (lambda: LinkImpairments(delay_steps=-1), r"delay_steps must be a whole number"),
        (lambda: SpeedSchedule((1.0,), (0.1,)), r"times must start at 0"),
        (lambda: SpeedSchedule((0.0, 2.0, 1.0), (0.1, 0.2, 0.3)), r"start at 0 and increase"),
        (lambda: SpeedSchedule((0.0, 1.0), (0.1,)), r"as many values as times"),
        (
            lambda: InitialState(eta=((0.0, 0.0, 0.0),) * 2, position_std=-1.0),
            "position_std must be >= 0",
        ),
        (
            lambda: InitialState(eta=((0.0, 0.0, 0.0),) * 2, nu=((0.0, 0.0),) * 2),
            r"InitialState.nu must have shape \(3,\) or \(2, 3\)",
        ),
    ],
)
def test_bad_scenario_fails_at_construction_saying_what_to_fix(build: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        build()  # type: ignore[operator]


def test_speed_schedule_lookup() -> None:
    schedule = SpeedSchedule((0.0, 5.0, 12.5), (0.1, 0.3, 0.2))
    times = [0.0, 4.999, 5.0, 12.0, 12.5, 1e6]
    assert [schedule.at(t) for t in times] == [0.1, 0.1, 0.3, 0.3, 0.2, 0.2]


def test_initial_state_spread_is_seeded() -> None:
    init = InitialState(
        eta=((0.0, 0.0, 0.0),) * 400, position_std=0.5, heading_std=0.2, theta_std=0.1
    )
    eta, nu, theta = init.sample(np.random.default_rng(0))
    np.testing.assert_allclose(eta.std(axis=0), [0.5, 0.5, 0.2], rtol=0.2)
    assert theta.std() == pytest.approx(0.1, rel=0.2) and not np.any(nu)
    again = init.sample(np.random.default_rng(0))
    assert np.array_equal(eta, again[0]) and np.array_equal(theta, again[2])


# --- the user-composed example ----------------------------------------------------------


def test_custom_scenario_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    spec = importlib.util.spec_from_file_location(
        "custom_scenario", ROOT / "examples" / "custom_scenario.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    summary = module.main(steps=20)
    assert summary["steps"] == 20
    assert not summary["terminated"] and not summary["truncated"]
    assert len(set(summary["mean_reward"].values())) == 1  # the example uses a team reward
    assert all(np.isfinite(e) and e < 10.0 for e in summary["final_path_error"].values())
    assert "three_shapes" in capsys.readouterr().out
    scenario = module.build_scenario()
    assert scenario.n == 3 and len({type(p) for p in scenario.paths}) == 3
