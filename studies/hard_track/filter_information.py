"""What the learned navigation filter lacks on hulls it does not know: the hull's model.

On ``hard_heterogeneous`` every vessel's true model is drawn +-30 % around
the nominal one at each reset (``VesselModel.perturbed``) and its thrusters
lag; the learned filter (``agents.estimation``) closes half of
``hard_sensing``'s room and a fifth of this one. Two measurements say why,
on training seeds (below the evaluation seeds):

1. **The map, with and without the hull.** On the base's episodes
   (``mpc_tuned_mmae``, zero correction) of the scenario and of its variants
   without the model spread and without the thruster lag, the learned
   filter's inputs (``correction.assemble``) and the bank's error on the true
   state are gathered; a network of the learned filter's size and schedule
   (``agents.estimation.network``) is fitted on ``--num-seeds`` episodes, once
   on those inputs and once with each vessel's true parameter factors
   (log(true / nominal), privileged) added, and the RMS error each leaves on
   ``--held-out`` further episodes is printed: what a first round of the map
   can explain, and how much of it needs the hull.
2. **The bank told the hull.** ``mpc_tuned_mmae`` whose filters predict with
   each vessel's true model (the inner design still plans on the nominal
   one), with its true mass matrices only, and with its true damping only,
   against the bank on the nominal model: mean whole-episode cost on
   ``--cost-seeds`` episodes, one fleet per episode (the filter holds one
   model per vessel).

Usage::

    python studies/hard_track/filter_information.py --num-seeds 24 --held-out 6 --cost-seeds 10
    python studies/hard_track/filter_information.py --scenario hard_sensing --cost-seeds 0
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

from agents.estimation.correction import TARGET_SIZE, Correction, assemble, body_error
from agents.estimation.network import BATCH, EPOCHS, HIDDEN, LEARNING_RATE, WEIGHT_DECAY
from agents.estimation.policy import WINDOW, LearnedFilter, bank_size
from baselines.estimator import MPCTunedAdaptive
from cpf_bench.episodes import run_episodes
from cpf_env.model.actuators import Thrusters
from cpf_env.model.vessel import PARAM_NAMES
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.scenarios.splits import check_training
from cpf_env.sim.fleet import FleetSim

Array = NDArray[np.float64]

BASE = "mpc_tuned_mmae"
#: Printed units of the six errors: x, y (mm), psi (mrad), u, v (mm/s), r (mrad/s).
UNITS = ("x mm", "y mm", "psi mrad", "u mm/s", "v mm/s", "r mrad/s")
#: First training seed of the cost runs (apart from the map's gathering seeds).
COST_SEED = 200


def variants(name: str) -> dict[str, Scenario]:
    """The scenario, and without its model spread and without its thruster lag where it has them."""
    task = make_scenario(name)
    found = {name: task}
    if task.model_spread > 0.0:
        found["without the model spread"] = task.replace(model_spread=0.0)
    if not task.thrusters.instant:
        found["without the thruster lag"] = task.replace(thrusters=Thrusters())
    return found


def gather(task: Scenario, seeds: Sequence[int]) -> tuple[Array, Array, Array]:
    """(inputs (N, D), hull factors (N, P), errors (N, 6)) of the bank's episodes on ``seeds``."""
    check_training(task, seeds)
    policy = LearnedFilter(task, Correction.zero(WINDOW, bank_size(BASE)), base=BASE)
    nominal = np.stack([model.to_params() for model in task.vessel_models])
    magnitude = np.where(nominal == 0.0, 1.0, np.abs(nominal))  # (n, P), a zero stays a zero
    sim = FleetSim(task, num_fleets=len(seeds))
    obs = sim.reset(seeds=list(seeds))
    inputs, factors, errors = [], [], []
    for step in range(task.max_steps):
        actions = policy.act_batch(obs)
        alive = ~sim.arrays.terminated
        if step >= WINDOW and alive.any():
            states = policy.base.state[alive]
            seen = assemble(policy.history_inputs()[alive], states, policy.base.members[alive])
            inputs.append(seen.reshape(-1, seen.shape[-1]))
            ratio = np.abs(sim.arrays.params[alive]) / magnitude
            factors.append(np.log(np.maximum(ratio, 1e-12)).reshape(-1, nominal.shape[-1]))
            truth = body_error(states, sim.arrays.eta[alive], sim.arrays.nu[alive])
            errors.append(truth.reshape(-1, TARGET_SIZE))
        obs = sim.step(actions)
    return np.concatenate(inputs), np.concatenate(factors), np.concatenate(errors)


def held_out_rms(train: tuple[Array, Array], test: tuple[Array, Array], seed: int) -> Array:
    """(6,) RMS error a network (the learned filter's size and schedule) leaves on ``test``."""
    (x, y), (x_test, y_test) = train, test
    mean, scale = x.mean(axis=0), x.std(axis=0) + 1e-12
    offset, spread = y.mean(axis=0), y.std(axis=0) + 1e-12
    torch.manual_seed(seed)
    widths = (x.shape[1], *HIDDEN)
    layers: list[torch.nn.Module] = []
    for k in range(len(HIDDEN)):
        layers += [torch.nn.Linear(widths[k], widths[k + 1]), torch.nn.SiLU()]
    network = torch.nn.Sequential(*layers, torch.nn.Linear(widths[-1], TARGET_SIZE))
    optimizer = torch.optim.Adam(network.parameters(), lr=LEARNING_RATE, weight_decay=WEIGHT_DECAY)
    inputs = torch.tensor((x - mean) / scale, dtype=torch.float32)
    targets = torch.tensor((y - offset) / spread, dtype=torch.float32)
    for _ in range(EPOCHS):
        for rows in torch.randperm(len(inputs)).split(BATCH):
            optimizer.zero_grad()
            torch.nn.functional.mse_loss(network(inputs[rows]), targets[rows]).backward()
            optimizer.step()
    with torch.no_grad():
        shown = torch.tensor((x_test - mean) / scale, dtype=torch.float32)
        predicted = network(shown).numpy().astype(np.float64) * spread + offset
    return np.sqrt(np.mean((y_test - predicted) ** 2, axis=0))


#: The kernel's parameters (``PARAM_NAMES``) of the mass matrix with added mass and of its
#: inverse; the rest are the damping coefficients.
INERTIA = slice(0, PARAM_NAMES.index("X_u"))
DAMPING = slice(PARAM_NAMES.index("X_u"), None)


class ToldTheHull(MPCTunedAdaptive):
    """``mpc_tuned_mmae`` whose filters predict with the vessels' true models (one fleet)."""

    name = "mpc_tuned_mmae_told_hull"
    #: The parameters taken from the true model; the others stay nominal.
    told = slice(None)

    def __init__(self, env: object, **options: Any) -> None:
        super().__init__(env, **options)
        self._sim: FleetSim | None = None
        self._given = self._nominal.copy()

    def bind_simulator(self, sim: FleetSim, fleets: ArrayLike | None = None) -> None:
        """Read the true models of ``sim``, which must hold one fleet."""
        if sim.num_fleets != 1:
            raise ValueError("the filter holds one model per vessel: run one fleet at a time.")
        del fleets
        self._sim = sim

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """The bank's design, its filters on the fleet's true models."""
        if self._sim is None:
            raise ValueError("bind_simulator first: the true models are read from it.")
        model = self._given.copy()
        model[:, self.told] = self._sim.arrays.params[0][:, self.told]
        self._nominal = model
        return super().act_batch(obs, fleets)


class ToldTheInertia(ToldTheHull):
    """Told the mass matrices only (rigid body and added mass); nominal damping."""

    name = "mpc_tuned_mmae_told_inertia"
    told = INERTIA


class ToldTheDamping(ToldTheHull):
    """Told the damping only; nominal mass matrices."""

    name = "mpc_tuned_mmae_told_damping"
    told = DAMPING


#: The bank, then told the hull, its inertia, its damping.
TOLD = (MPCTunedAdaptive, ToldTheHull, ToldTheInertia, ToldTheDamping)


def told_costs(task: Scenario, seeds: Sequence[int]) -> dict[str, float]:
    """Mean cost of the bank on the nominal model and told each part of the true one (``TOLD``).

    One fleet per episode.
    """
    check_training(task, seeds)
    costs: dict[str, list[float]] = {design.name: [] for design in TOLD}
    for seed in seeds:
        for design in TOLD:
            metrics = run_episodes(design(task), task, [seed])
            costs[design.name].append(float(metrics["cost"][0]))
    return {name: float(np.mean(values)) for name, values in costs.items()}


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Print and return both measurements (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scenario", default="hard_heterogeneous", help="a scenario with sensors (hard track)"
    )
    parser.add_argument("--num-seeds", type=int, default=24, help="episodes the network fits on")
    parser.add_argument("--held-out", type=int, default=6, help="episodes it is measured on")
    parser.add_argument(
        "--cost-seeds", type=int, default=10, help="episodes of each cost (0: no cost runs)"
    )
    parser.add_argument("--max-steps", type=int, default=None, help="shorter episodes")
    args = parser.parse_args(argv)
    if min(args.num_seeds, args.held_out) < 1 or args.cost_seeds < 0:
        parser.error("--num-seeds and --held-out must be >= 1, --cost-seeds >= 0.")
    if args.max_steps is not None and args.max_steps <= WINDOW:
        parser.error(f"--max-steps must exceed the learned filter's window of {WINDOW} steps.")
    train = range(args.num_seeds)
    test = range(args.num_seeds, args.num_seeds + args.held_out)
    scale = np.full(TARGET_SIZE, 1e3)
    print(f"RMS error left on held-out episodes ({args.held_out}; {', '.join(UNITS)}):\n")
    print("| scenario | what | " + " | ".join(UNITS) + " |")
    print("|---|---|" + "---|" * TARGET_SIZE)
    maps: dict[str, dict[str, list[float]]] = {}
    for label, task in variants(args.scenario).items():
        if args.max_steps is not None:
            task = task.replace(max_steps=args.max_steps)
        x, hull, y = gather(task, train)
        x_test, hull_test, y_test = gather(task, test)
        rows = {
            "the bank": np.sqrt(np.mean(y_test**2, axis=0)),
            "the map": held_out_rms((x, y), (x_test, y_test), seed=0),
            "the map, told the hull": held_out_rms(
                (np.hstack([x, hull]), y), (np.hstack([x_test, hull_test]), y_test), seed=0
            ),
        }
        maps[label] = {what: (rms * scale).tolist() for what, rms in rows.items()}
        for what, values in maps[label].items():
            print(f"| {label} | {what} | " + " | ".join(f"{v:.2f}" for v in values) + " |")
    task = make_scenario(args.scenario)
    if args.max_steps is not None:
        task = task.replace(max_steps=args.max_steps)
    if args.cost_seeds == 0:
        return {"maps": maps, "costs": {}}
    costs = told_costs(task, range(COST_SEED, COST_SEED + args.cost_seeds))
    print(f"\nMean cost, {args.cost_seeds} episode(s) from training seed {COST_SEED}:")
    for name, cost in costs.items():
        print(f"  {name}: {cost:.1f}")
    return {"maps": maps, "costs": costs}


if __name__ == "__main__":
    main()
