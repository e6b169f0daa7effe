"""Shared helpers for the simulator and env tests.

Reference formulas here are written from docs/model.md directly (model attributes,
not the kernel's parameter vector), so tests compare the code against an
independent transcription of the equations.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path as FilePath

import numpy as np
import pytest

from cpf_env import scenarios
from cpf_env.model.disturbances import Disturbances
from cpf_env.model.graph import Graph, SwitchingTopology
from cpf_env.model.paths import StraightLine
from cpf_env.model.vessel import CYBERSHIP2, VesselModel
from cpf_env.scenarios import InitialState, Scenario
from cpf_env.sim.fleet import FleetSim

ROOT = FilePath(__file__).resolve().parents[1]

NO_DISTURBANCES = Disturbances(unmodeled_scale=0.0)

#: A cpf-distill config file small enough for a test (two 10-step rounds on bench_mild).
STUDENT_TOML = """
scenario = "bench_mild"
fleets = 2
net_arch = [16]

[residual]
mode = "force_and_rate"
scale = 1.0

[distill]
teacher = "nn_dsc_privileged"
rounds = 2
steps = 10
epochs = 2
"""

#: Per-vessel, asymmetric saturation limits for the five vessels of wang2014 (N, N, N m).
TAU_MAX = ((9.2, 4.5, 3.0), (5.0, 2.0, 1.0), (12.0, 6.0, 4.0), (1.0, 1.0, 1.0), (3.0, 8.0, 0.5))
TAU_MIN = (
    (-4.0, -4.5, -1.0),
    (-9.0, -1.0, -3.0),
    (-0.5, -6.0, -4.0),
    (-2.0, -3.0, -0.2),
    (-3.0, -1.0, -2.0),
)


def reference_matrices(
    model: VesselModel, nu: Sequence[float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, C(nu), D(nu) of docs/model.md section 1, transcribed from the model's attributes."""
    u, v, r = (float(x) for x in nu)
    m, xg = model.mass, model.x_g
    mass = np.array(
        [
            [m - model.X_udot, 0.0, 0.0],
            [0.0, m - model.Y_vdot, m * xg - model.Y_rdot],
            [0.0, m * xg - model.N_vdot, model.inertia_z - model.N_rdot],
        ]
    )
    m11, m22, m23 = mass[0, 0], mass[1, 1], mass[1, 2]
    coriolis = np.array(
        [
            [0.0, 0.0, -m22 * v - m23 * r],
            [0.0, 0.0, m11 * u],
            [m22 * v + m23 * r, -m11 * u, 0.0],
        ]
    )
    d11 = -model.X_u - model.X_uu * abs(u) - model.X_uuu * u * u
    d22 = -model.Y_v - model.Y_vv * abs(v) - model.Y_rv * abs(r)
    d23 = -model.Y_r - model.Y_vr * abs(v) - model.Y_rr * abs(r)
    d32 = -model.N_v - model.N_vv * abs(v) - model.N_rv * abs(r)
    d33 = -model.N_r - model.N_vr * abs(v) - model.N_rr * abs(r)
    damping = np.array([[d11, 0.0, 0.0], [0.0, d22, d23], [0.0, d32, d33]])
    return mass, coriolis, damping


def rotation_matrix(psi: float) -> np.ndarray:
    """J(psi) of eq. [4] (docs/model.md section 1)."""
    c, s = np.cos(psi), np.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def free_scenario(
    nu0: Sequence[Sequence[float]],
    vessels: VesselModel | tuple[VesselModel, ...] = CYBERSHIP2,
    disturbances: Disturbances = NO_DISTURBANCES,
    psi0: float = 0.3,
    **overrides: object,
) -> Scenario:
    """n vessels (one per row of nu0) on parallel straight lines, no disturbances by default."""
    n = len(nu0)
    topology = Graph.path(n, leaders=(0,)) if n > 1 else Graph.from_edges(1, [], leaders=(0,))
    scenario = Scenario(
        name="free",
        paths=tuple(StraightLine(y0=5.0 * i) for i in range(n)),
        topology=topology,
        initial=InitialState(
            eta=tuple((0.0, 5.0 * i, psi0) for i in range(n)),
            nu=tuple(tuple(float(x) for x in row) for row in nu0),
        ),
        vessels=vessels,
        disturbances=disturbances,
        max_path_error=1e9,
    )
    return scenario.replace(**overrides) if overrides else scenario


def fast_switching(**changes: object) -> Scenario:
    """The switching_topology scenario with its chain, ring and star switching every
    20 steps (period 60) instead of 200, so short runs see several switches."""
    base = scenarios.get("switching_topology")
    topology = SwitchingTopology(base.switching.graphs, (0, 20, 40), period=60)
    return base.replace(topology=topology, **changes)


def fast_member(step: int) -> int:
    """Index of the graph of ``fast_switching()`` active at control step ``step``."""
    return (step % 60) // 20


def snapshot(sim: FleetSim) -> dict[str, np.ndarray]:
    """Copies of every array of the simulator state."""
    return {name: np.array(value, copy=True) for name, value in sim.arrays._asdict().items()}


def assert_unchanged(before: dict[str, np.ndarray], sim: FleetSim) -> None:
    """Every simulator array equals its snapshot, bit for bit."""
    for name, value in sim.arrays._asdict().items():
        assert np.array_equal(before[name], value, equal_nan=True), f"arrays.{name} changed"


def random_actions(
    rng: np.random.Generator, sim: FleetSim, overdrive: float = 1.5, rate: float = 0.1
) -> np.ndarray:
    """Random (B, n, act_dim) batch: forces up to ``overdrive`` x limits, rates about ``rate``."""
    s = sim.scenario
    shape = (sim.num_fleets, sim.n)
    low, high = np.array(s.tau_min), np.array(s.tau_max)
    actions = np.empty((*shape, sim.act_dim))
    actions[..., :3] = overdrive * rng.uniform(low, high, size=(*shape, 3))
    actions[..., 3] = rate + 0.05 * rng.standard_normal(shape)
    actions[..., 4:] = rng.uniform(-2.0, 2.0, size=(*shape, sim.act_dim - 4))
    return actions


# --- shared runs of the reproduction tests (tests/cpf_commands/run/), once per session -----


@pytest.fixture(scope="session")
def short_run():
    """6 s of wang2014 with nn_dsc."""
    from cpf_commands.run.experiment import run_episode

    return run_episode("wang2014", "nn_dsc", seed=0, max_steps=120)


@pytest.fixture(scope="session")
def fine_run():
    """60 s of the reproduction configuration (wang2014_fine, leakage=plain)."""
    from cpf_commands.run.experiment import run_episode

    return run_episode(
        "wang2014_fine", "nn_dsc", max_steps=6000, policy_options={"leakage": "plain"}
    )
