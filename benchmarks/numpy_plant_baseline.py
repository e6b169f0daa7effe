"""How much faster is the compiled step than plain numpy? ``FleetSim.step`` vs a batched numpy RK4.

A benchmark comparator, not a second simulator: the numpy code below is the
plant of ``cpf_env.model.plant`` (``plant_rhs`` with ``hydrodynamic_forces``
and ``solve_mass`` of ``cpf_env.model.vessel``, the paper's unmodeled
dynamics and disturbance of ``cpf_env.model.disturbances``, the current
acting through the relative velocity), integrated over one control period
with ``substeps`` classical RK4 steps and the load held, the way one would
write it without numba: every quantity an array over all B x n vessels, no
Python loop over vessels. It only integrates the plant; ``FleetSim.step``
also saturates the commands, advances the disturbance processes and the
path variables, exchanges the messages and writes observations, rewards and
errors. Nothing in the package imports this file; the test
``tests/test_numpy_plant_baseline.py`` checks that it integrates the same
plant as the simulator (to 1e-12, relative).

Both are timed in the same run, in alternating blocks (the best block of each,
as ``timeit`` reports, since the machine may be shared): ``FleetSim.step``
with a fixed action (zero by default), and ``numpy_rk4_period`` on the same
B x n vessels, time and load held as in one control period. Prints
vessel-steps/s of both and their ratio. Usage::

    python benchmarks/numpy_plant_baseline.py                       # B = 1,024, wang2014
    python benchmarks/numpy_plant_baseline.py --fleets 16 1024 --seconds 4 --scenario bench_mild
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from cpf_commands.common.arguments import positive_int
from cpf_env import scenarios
from cpf_env.model.disturbances import D_SCALE
from cpf_env.model.vessel import I11, I22, I23, I32, I33, M11, M22, M23, X_U
from cpf_env.sim.fleet import FleetSim

Array = NDArray[np.float64]


class PlantLoad(NamedTuple):
    """The inputs held over a control period, one entry per vessel, each shape (N,).

    The numpy form of the plant load of ``cpf_env.model.plant``: applied force
    (N, N, N m, body frame), earth-frame wave plus wind force (N, N, N m) and
    the earth-frame current (m/s).
    """

    tau_u: Array
    tau_v: Array
    tau_r: Array
    force_x: Array
    force_y: Array
    moment: Array
    current_x: Array
    current_y: Array


def numpy_plant_rhs(
    p: Array, scale: float, t: float, psi: Array, u: Array, v: Array, r: Array, load: PlantLoad
) -> tuple[Array, ...]:
    """The plant's right-hand side for N vessels at once (``cpf_env.model.plant.plant_rhs``).

    Args:
        p: True parameters, one row per entry of ``PARAM_NAMES``, shape (PARAM_SIZE, N).
        scale: Factor on the paper's unmodeled dynamics and disturbance.
        t: Time (s), the same for every vessel (fleets stepped together).
        psi: Heading (rad), shape (N,).
        u: Surge velocity over ground, body frame (m/s), shape (N,).
        v: Sway velocity over ground, body frame (m/s), shape (N,).
        r: Yaw rate (rad/s), shape (N,).
        load: Held inputs.

    Returns:
        (x', y', psi', u', v', r'), each shape (N,).
    """
    c, s = np.cos(psi), np.sin(psi)
    uc = c * load.current_x + s * load.current_y
    vc = -s * load.current_x + c * load.current_y
    ur, vr = u - uc, v - vc
    # C(nu_r) nu_r + D(nu_r) nu_r (cpf_env.model.vessel.hydrodynamic_forces)
    c13 = -p[M22] * vr - p[M23] * r
    c23 = p[M11] * ur
    au, av, ar = np.abs(ur), np.abs(vr), np.abs(r)
    d11 = -p[X_U] - p[X_U + 1] * au - p[X_U + 2] * ur * ur
    d22 = -p[X_U + 3] - p[X_U + 4] * av - p[X_U + 5] * ar
    d23 = -p[X_U + 6] - p[X_U + 7] * av - p[X_U + 8] * ar
    d32 = -p[X_U + 9] - p[X_U + 10] * av - p[X_U + 11] * ar
    d33 = -p[X_U + 12] - p[X_U + 13] * av - p[X_U + 14] * ar
    h0 = c13 * r + d11 * ur
    h1 = c23 * r + d22 * vr + d23 * r
    h2 = -c13 * ur - c23 * vr + d32 * vr + d33 * r
    f0 = load.tau_u + c * load.force_x + s * load.force_y - h0
    f1 = load.tau_v - s * load.force_x + c * load.force_y - h1
    f2 = load.tau_r + load.moment - h2
    if scale != 0.0:
        # The paper's disturbance minus its unmodeled dynamics (cpf_env.model.disturbances).
        wave = 0.001 * np.sin(t)
        cubic = vr * vr * vr
        f0 += scale * ((cubic + 0.06 * ur + wave) - (cubic + 0.03 * ur))
        f1 += scale * ((ur * r + 0.1 * ur + wave) - (ur * r + 0.02 * ur))
        f2 += scale * ((0.4 * ur * r + vr * vr + wave) - (ur * r + 0.2 * r * r))
    # M^{-1} f (cpf_env.model.vessel.solve_mass), then nu' = nu_r' + d/dt (J^T V_c).
    a0 = p[I11] * f0
    a1 = p[I22] * f1 + p[I23] * f2
    a2 = p[I32] * f1 + p[I33] * f2
    return c * u - s * v, s * u + c * v, r, a0 + r * vc, a1 - r * uc, a2


def numpy_rk4_period(
    p: Array,
    scale: float,
    t0: float,
    dt: float,
    substeps: int,
    state: tuple[Array, ...],
    load: PlantLoad,
) -> tuple[Array, ...]:
    """One control period of ``substeps`` RK4 steps for N vessels (``plant.rk4_period``).

    Args:
        p: True parameters, shape (PARAM_SIZE, N).
        scale: Factor on the paper's unmodeled dynamics and disturbance.
        t0: Time at the start of the period (s).
        dt: Control period (s).
        substeps: RK4 steps per period.
        state: (x, y, psi, u, v, r), each shape (N,), at t0.
        load: Held inputs.

    Returns:
        (x, y, psi, u, v, r) at t0 + dt, each shape (N,).
    """
    x, y, psi, u, v, r = state
    h = dt / substeps
    for k in range(substeps):
        t = t0 + k * h
        k1 = numpy_plant_rhs(p, scale, t, psi, u, v, r, load)
        k2 = numpy_plant_rhs(p, scale, t + 0.5 * h, psi + 0.5 * h * k1[2], u + 0.5 * h * k1[3],
                             v + 0.5 * h * k1[4], r + 0.5 * h * k1[5], load)  # fmt: skip
        k3 = numpy_plant_rhs(p, scale, t + 0.5 * h, psi + 0.5 * h * k2[2], u + 0.5 * h * k2[3],
                             v + 0.5 * h * k2[4], r + 0.5 * h * k2[5], load)  # fmt: skip
        k4 = numpy_plant_rhs(p, scale, t + h, psi + h * k3[2], u + h * k3[3], v + h * k3[4],
                             r + h * k3[5], load)  # fmt: skip
        w = h / 6.0
        x = x + w * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
        y = y + w * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
        psi = psi + w * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        u = u + w * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
        v = v + w * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
        r = r + w * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5])
    return x, y, psi, u, v, r


def plant_inputs(sim: FleetSim) -> tuple[Array, tuple[Array, ...], PlantLoad]:
    """The simulator's current plant inputs in numpy form, N = B n vessels.

    Returns:
        Parameters (PARAM_SIZE, N); state (x, y, psi, u, v, r), each (N,); and
        the load the next step holds: the last applied force, wave plus wind
        force and the fleet's current repeated per vessel.
    """
    a = sim.arrays
    vessels = a.eta.shape[0] * a.eta.shape[1]
    params = np.ascontiguousarray(a.params.reshape(vessels, -1).T)
    eta, nu = a.eta.reshape(vessels, 3), a.nu.reshape(vessels, 3)
    state = tuple(np.ascontiguousarray(column) for column in (*eta.T, *nu.T))
    tau = a.tau_applied.reshape(vessels, 3)
    force = (a.waves + a.wind).reshape(vessels, 3)
    current = np.repeat(a.current, a.eta.shape[1], axis=0)
    load = PlantLoad(*(np.ascontiguousarray(column) for column in (*tau.T, *force.T, *current.T)))
    return params, state, load


def best_rate(run_block: Callable[[], int], seconds: float) -> float:
    """Calls per second of ``run_block`` (which returns its number of calls) over ``seconds``."""
    calls, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds:
        calls += run_block()
    return calls / elapsed


def compare(scenario_name: str, fleets: int, seconds: float, blocks: int = 3) -> dict[str, float]:
    """Time ``FleetSim.step`` and the numpy RK4 on B = ``fleets``, alternating blocks.

    Args:
        scenario_name: Registered scenario.
        fleets: B.
        seconds: Wall-clock budget of each of the two, split into ``blocks`` blocks.
        blocks: Timed blocks per contestant; the best of each is reported.

    Returns:
        B, n and vessel-steps/s of both, and the ratio simulator / numpy.
    """
    scenario = scenarios.get(scenario_name)
    sim = FleetSim(scenario, num_fleets=fleets)
    sim.reset(seeds=list(range(fleets)))
    actions = np.zeros((fleets, sim.n, sim.act_dim))
    params, state, load = plant_inputs(sim)
    c = sim.constants
    scale, t0 = float(c.disturbances[D_SCALE]), 0.0

    def simulator_block() -> int:
        for _ in range(10):
            sim.step(actions)
        return 10

    def numpy_block() -> int:
        nonlocal state
        for _ in range(10):  # the state advances; time and load stay those of one period
            state = numpy_rk4_period(params, scale, t0, c.dt, c.substeps, state, load)
        return 10

    simulator_block(), numpy_block()  # warm-up (and the kernels' load from the cache)
    simulator, numpy = 0.0, 0.0
    for _ in range(blocks):
        simulator = max(simulator, best_rate(simulator_block, seconds / blocks))
        numpy = max(numpy, best_rate(numpy_block, seconds / blocks))
    vessels = fleets * sim.n
    return {
        "B": fleets,
        "n": sim.n,
        "simulator": simulator * vessels,
        "numpy": numpy * vessels,
        "ratio": simulator / numpy,
    }


def main(argv: list[str] | None = None) -> list[dict[str, float]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fleets", type=positive_int, nargs="+", default=[1024], help="B values")
    parser.add_argument("--scenario", default="wang2014", help="registered scenario")
    parser.add_argument(
        "--seconds", type=float, default=3.0, help="wall-clock budget of each contestant per B"
    )
    args = parser.parse_args(argv)
    if not args.seconds > 0.0:
        parser.error(f"--seconds must be > 0, got {args.seconds}.")
    print(
        f"{platform.machine()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}, "
        f"NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'unset')}, "
        f"scenario {args.scenario}"
    )
    header = f"{'B':>6} {'n':>3} {'FleetSim.step':>16} {'numpy RK4':>14} {'ratio':>7}"
    print(header + "   vessel-steps/s")
    rows = []
    for fleets in args.fleets:
        row = compare(args.scenario, fleets, args.seconds)
        rows.append(row)
        print(
            f"{row['B']:>6} {row['n']:>3} {row['simulator']:>16,.0f} {row['numpy']:>14,.0f} "
            f"{row['ratio']:>6.2f}x"
        )
    return rows


if __name__ == "__main__":
    main()
