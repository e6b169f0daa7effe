"""Record the simulator's every array along fixed runs, or compare two such records bit for bit.

Used to check that a change to the compiled step leaves every trajectory
unchanged: record with the old code, record with the new, compare. Each run
is one registered scenario at B fleets, 300 steps with seeded actions of
two kinds (uniform over 1.5 times the limits, so saturation and clipping
are exercised; and ``nn_dsc`` plus seeded noise, so the states are those of
an episode that follows its paths), fleets 0 and 2 reset half way. Every
array of ``FleetArrays`` is stored after steps 1, 10, 100, 150 (the reset),
151 and 300, with the true accelerations ``FleetSim.accelerations()``.

``--compare`` reports, per array, whether the records are ``np.array_equal``
and equal byte for byte (which also tells 0.0 from -0.0 and NaN payloads)
and exits 1 on any difference, or if an array of the old record is missing
from the new; arrays only the new record has are named, not compared.
Usage (the interpreter decides which checkout is measured)::

    /path/to/old/.venv/bin/python tools/trajectory_fingerprint.py --out /tmp/old.npz
    python tools/trajectory_fingerprint.py --out /tmp/new.npz
    python tools/trajectory_fingerprint.py --compare /tmp/old.npz /tmp/new.npz
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np

from baselines import make_policy
from cpf_env import scenarios
from cpf_env.model.disturbances import GaussMarkov
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import FleetSim

STEPS = 300
RECORDED = (1, 10, 100, 150, 151, 300)
RESET_AT, RESET_FLEETS = 150, (0, 2)


def variants() -> dict[str, Scenario]:
    """Branches no registered scenario takes within 300 steps, on top of them.

    ``tight_team_quadratic``: terminations (failure penalty), the team reward and
    the quadratic form; ``no_unmodeled_mixed_std``: ``unmodeled_scale = 0`` and
    disturbance processes with some zero standard deviations; ``signed_zero``:
    a wave process with mean -0.0, zero spread and a correlation time far below
    dt (the one-step factor underflows to 0).
    """
    wang, waves = scenarios.get("wang2014"), scenarios.get("bench_current_waves")
    reward = dataclasses.replace(wang.reward, team=True, form="quadratic")
    mixed = dataclasses.replace(
        waves.disturbances,
        unmodeled_scale=0.0,
        waves=GaussMarkov(mean=(0.1, 0.0, 0.0), std=(0.5, 0.0, 0.1), time_constant=2.0),
    )
    edge = dataclasses.replace(
        waves.disturbances,
        waves=GaussMarkov(mean=(-0.0, -0.0, 0.2), std=(0.0, 0.0, 0.1), time_constant=1e-6),
    )
    return {
        "tight_team_quadratic": dataclasses.replace(wang, max_path_error=1.5, reward=reward),
        "no_unmodeled_mixed_std": dataclasses.replace(waves, disturbances=mixed),
        "signed_zero": dataclasses.replace(waves, disturbances=edge),
    }


def _action_scale(sim: FleetSim) -> np.ndarray:
    """Per-vessel magnitude of each action component, shape (n, act_dim)."""
    c = sim.constants
    m = sim.act_dim - 4
    rate = np.full((sim.n, 1), c.theta_dot_max)
    message = np.full((sim.n, m), c.message_max)
    return np.concatenate([c.tau_scale, rate, message], axis=1)


def record_run(scenario: Scenario, fleets: int, kind: str, seed: int) -> dict[str, np.ndarray]:
    """Every array after the recorded steps of one run (keys ``step/array``)."""
    sim = FleetSim(scenario, num_fleets=fleets)
    sim.reset(seeds=[seed + b for b in range(fleets)])
    rng = np.random.default_rng(seed)
    scale = _action_scale(sim)
    policy = make_policy("nn_dsc", sim) if kind == "nn_dsc" else None
    if policy is not None:
        policy.reset(seed=seed)
    out: dict[str, np.ndarray] = {}
    for step in range(1, STEPS + 1):
        noise = rng.uniform(-1.5, 1.5, (fleets, sim.n, sim.act_dim)) * scale
        if policy is None:
            actions = noise
        else:
            actions = np.asarray(policy.act_batch(sim.arrays.obs), dtype=np.float64) + 0.1 * noise
        sim.step(actions)
        if step == RESET_AT:
            sim.reset(seeds=[seed + 100 + b for b in RESET_FLEETS], fleets=list(RESET_FLEETS))
            if policy is not None:
                policy.reset_fleets(list(RESET_FLEETS))
        if step in RECORDED:
            for field, value in sim.arrays._asdict().items():
                out[f"{step}/{field}"] = value.copy()
            out[f"{step}/accelerations"] = sim.accelerations()
    return out


def record(path: str, fleet_counts: tuple[int, ...]) -> None:
    """Run every registered scenario and variant at every B and both action kinds; save one npz."""
    arrays: dict[str, np.ndarray] = {}
    runs = {name: scenarios.get(name) for name in scenarios.list_scenarios()} | variants()
    for name, scenario in runs.items():
        for fleets in fleet_counts:
            for kind in ("random", "nn_dsc"):
                run = record_run(scenario, fleets, kind, seed=7)
                for key, value in run.items():
                    arrays[f"{name}/B{fleets}/{kind}/{key}"] = value
        print(f"recorded {name}", flush=True)
    np.savez_compressed(path, allow_pickle=False, **arrays)
    print(f"{len(arrays)} arrays -> {path}")


def compare(old_path: str, new_path: str) -> int:
    """Compare two records; print a summary and every difference. Returns the exit status."""
    old, new = np.load(old_path), np.load(new_path)
    removed = sorted(set(old.files) - set(new.files))
    if removed:
        print(f"{len(removed)} arrays missing from {new_path}: {removed[:10]} ...")
        return 1
    added = sorted({key.rsplit("/", 1)[1] for key in set(new.files) - set(old.files)})
    if added:  # a new state array (e.g. a new mechanism's): compared from the next record on
        print(f"only in {new_path}: the arrays {added} (not compared)")
    different = []
    for key in sorted(old.files):
        a, b = old[key], new[key]
        equal = a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b)
        same_bytes = equal and a.tobytes() == b.tobytes()
        if not same_bytes:
            different.append((key, equal))
    runs = {key.rsplit("/", 2)[0] for key in old.files}
    print(f"{len(old.files)} arrays of {len(runs)} runs compared")
    for key, equal in different:
        print(f"DIFFERENT {key}: array_equal={equal}")
    print("all arrays bit-identical" if not different else f"{len(different)} arrays differ")
    return 1 if different else 0


def main(argv: list[str] | None = None) -> int:
    """Record (``--out``) or compare (``--compare``); returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--out", help="record to this .npz file")
    group.add_argument("--compare", nargs=2, metavar=("OLD", "NEW"), help="compare two records")
    parser.add_argument(
        "--fleets", type=int, nargs="+", default=[3, 17], help="B values (>= 16: threaded kernel)"
    )
    args = parser.parse_args(argv)
    if args.compare:
        return compare(*args.compare)
    if min(args.fleets) < 3:
        parser.error("--fleets must be >= 3 (fleets 0 and 2 are reset half way).")
    record(args.out, tuple(args.fleets))
    return 0


if __name__ == "__main__":
    sys.exit(main())
