"""Integral LOS on a straight line in a cross current: the cross-track error over time.

Two vessels on parallel straight lines 3 m apart start 0.5 m off them, in a
5 cm/s current across the lines (v0 = 0.2 m/s, no unmodeled dynamics), and
run ``ilos`` (``baselines.ilos``) for ``--seconds``. For each integral gain
sigma it prints the largest |y_e| (mm) of each window of ``--window`` seconds:
plain LOS (sigma = 0) settles at an offset, sigma > 0 takes the vessels to the
path, and too large a sigma starts a slow oscillation that grows.

Usage::

    python studies/ilos/line_in_current.py --sigmas 0 0.07 0.1
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

import baselines
from cpf_env.model.disturbances import Disturbances, OceanCurrent
from cpf_env.model.graph import Graph
from cpf_env.model.paths import StraightLine
from cpf_env.scenarios import InitialState, Scenario
from cpf_env.sim.fleet import FleetSim


def line_in_a_current(steps: int, current: tuple[float, float] = (0.0, 0.05)) -> Scenario:
    """The two-vessel straight-line task of the module docstring, ``steps`` control steps long."""
    return Scenario(
        name="line_in_a_current",
        paths=tuple(StraightLine(x0=0.0, y0=3.0 * i, heading=0.0) for i in range(2)),
        topology=Graph.from_edges(2, [(0, 1)], leaders=(0,)),
        initial=InitialState(eta=((0.0, 0.5, 0.0), (0.0, 3.5, 0.0))),
        v0=0.2,
        disturbances=Disturbances(unmodeled_scale=0.0, current=OceanCurrent(velocity=current)),
        max_steps=steps + 1,
        max_path_error=50.0,
    )


def window_maxima(sigma: float, seconds: float, window: float) -> list[float]:
    """Largest |y_e| (m) over both vessels in each window, for integral gain ``sigma``."""
    scenario = line_in_a_current(round(seconds / 0.05))
    sim = FleetSim(scenario, num_fleets=1)
    policy = baselines.make_policy("ilos", scenario, sigma=sigma)
    obs = sim.reset(seeds=[0])
    errors = np.empty(scenario.max_steps - 1)
    for k in range(errors.size):
        actions = policy.act_batch(obs)
        errors[k] = np.abs(policy.diagnostics["aux_state"][0, :, 1]).max()
        obs = sim.step(actions)
    per = round(window / scenario.dt)
    return [float(errors[k : k + per].max()) for k in range(0, errors.size, per)]


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 0.07, 0.1])
    parser.add_argument("--seconds", type=float, default=6000.0)
    parser.add_argument("--window", type=float, default=500.0)
    args = parser.parse_args(argv)
    print(f"max |y_e| (mm) per {args.window:g} s window, {args.seconds:g} s")
    for sigma in args.sigmas:
        maxima = window_maxima(sigma, args.seconds, args.window)
        print(f"sigma = {sigma:<5g} " + " ".join(f"{1000 * m:8.2f}" for m in maxima))


if __name__ == "__main__":
    main()
