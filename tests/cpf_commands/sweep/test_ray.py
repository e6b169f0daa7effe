"""Sweeps and the benchmark on local Ray (marker ``ray``; needs ``pip install -e ".[ray]"``).

Run with ``python -m pytest -m ray``. Each test starts and stops its own local
Ray instance, as the commands do.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

pytest.importorskip("ray.tune")

from conftest import ROOT

from agents import load_policy
from cpf_commands.bench.run import run_bench
from cpf_commands.sweep.cli import run_sweep, sweep_main
from cpf_commands.sweep.report import EVALUATION_FILE
from cpf_commands.sweep.spec import SweepSpec, trial_name

pytestmark = pytest.mark.ray

#: A tiny training run: 8 fleets, 2 rollouts.
TINY = ["timesteps=2000", "fleets=8", "n_steps=16"]
AGENT = ROOT / "tests" / "fixtures" / "agents" / "residual_ppo_lossy_links"


def test_two_seeds_by_two_scenarios_then_a_resume(tmp_path, capsys) -> None:
    out = tmp_path / "sweep"
    argv = ["--scenarios", "bench_mild", "bench_lossy_links", "--num-seeds", "2"]
    argv += ["--set", *TINY, "--eval-num-seeds", "2", "--eval-max-steps", "50", "--out", str(out)]
    assert sweep_main(argv) == 0  # Tune's status output on
    printed = capsys.readouterr().out
    assert "4/4 trials done" in printed and "| bench_lossy_links | 2/2 |" in printed
    assert "Trial status" in printed  # what --quiet must hide below
    spec = SweepSpec.from_settings(
        ["bench_mild", "bench_lossy_links"], [0, 1], TINY, eval_num_seeds=2, eval_max_steps=50
    )
    models = {}
    evaluation = json.loads(next(out.glob(f"trials/*/{EVALUATION_FILE}")).read_text())
    assert evaluation["episodes"] == 2 and evaluation["eval_seconds"] > 0
    for params in spec.trials():
        folder = out / "trials" / trial_name(params, spec)
        policy = load_policy(folder)  # every trial is a cpf-train folder
        assert policy.scenario.name == params["scenario"]
        models[folder] = (folder / "model.zip").stat().st_mtime_ns
    assert (out / "summary.md").exists() and (out / "summary.csv").exists()
    capsys.readouterr()
    assert sweep_main([*argv, "--quiet"]) == 0  # the same command again: nothing retrained
    assert {folder: (folder / "model.zip").stat().st_mtime_ns for folder in models} == models
    assert capsys.readouterr().out.startswith("# Sweep summary")  # all done: Ray not started
    removed = next(iter(models))
    shutil.rmtree(removed)
    assert sweep_main([*argv, "--quiet"]) == 0  # the removed trial trains again, alone
    printed = capsys.readouterr().out
    assert "Number of trials" not in printed and "Trial status" not in printed  # quiet
    assert (removed / EVALUATION_FILE).exists()
    del models[removed]
    assert {folder: (folder / "model.zip").stat().st_mtime_ns for folder in models} == models


def test_an_interrupted_sweep_resumes_keeping_finished_trials(tmp_path) -> None:
    out = tmp_path / "sweep"
    argv = [sys.executable, "-c", "from cpf_commands.sweep.cli import sweep_main; sweep_main()"]
    argv += ["--scenarios", "bench_mild", "--num-seeds", "3", "--quiet"]
    argv += [
        "--set",
        "timesteps=30000",
        "fleets=8",
        "--eval-num-seeds",
        "1",
        "--eval-max-steps",
        "20",
    ]
    argv += ["--cpus-per-trial", "2", "--out", str(out)]  # one trial at a time
    process = subprocess.Popen(argv, start_new_session=True, stdout=subprocess.DEVNULL)
    first = out / "trials" / "bench_mild-seed0" / EVALUATION_FILE
    deadline = time.monotonic() + 300
    while not first.exists() and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.5)
    assert first.exists(), "the first trial did not finish in time"
    os.killpg(process.pid, signal.SIGINT)  # as Ctrl-C would
    process.wait(timeout=120)
    finished = sorted(path.parent.name for path in out.glob(f"trials/*/{EVALUATION_FILE}"))
    assert len(finished) < 3, "the sweep ended before it could be interrupted"
    kept = {name: (out / "trials" / name / "model.zip").stat().st_mtime_ns for name in finished}
    spec = SweepSpec.from_settings(
        ["bench_mild"],
        [0, 1, 2],
        ["timesteps=30000", "fleets=8"],
        eval_num_seeds=1,
        eval_max_steps=20,
        cpus_per_trial=2,
    )
    rows = run_sweep(spec, out, quiet=True)
    assert [row["status"] for row in rows] == ["done"] * 3
    assert {name: (out / "trials" / name / "model.zip").stat().st_mtime_ns for name in kept} == kept


def test_auto_without_a_cluster_is_a_clear_error(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path / "ray"))  # no cluster of this machine's
    out = tmp_path / "sweep"
    with pytest.raises(SystemExit) as exit_info:
        sweep_main(["--scenarios", "bench_mild", "--out", str(out), "--address", "auto"])
    assert exit_info.value.code == 2
    assert "could not join a Ray cluster at --address auto" in capsys.readouterr().err
    assert not out.exists()


def test_the_benchmark_on_ray_equals_the_local_run(tmp_path) -> None:
    policies = ["nn_dsc", "backstepping", AGENT]
    names = ["bench_lossy_links", "bench_mild"]
    local = run_bench(
        policies, names, num_seeds=2, max_steps=60, out=tmp_path / "local", figures=False
    )
    remote = run_bench(
        policies,
        names,
        num_seeds=2,
        max_steps=60,
        out=tmp_path / "ray",
        figures=False,
        distribute=True,
    )
    assert [(c.policy, c.scenario, c.seeds) for c in remote] == [
        (c.policy, c.scenario, c.seeds) for c in local
    ]
    for name in ("episodes.csv", "summary.csv", "summary.md"):
        assert (tmp_path / "ray" / name).read_bytes() == (tmp_path / "local" / name).read_bytes()


def test_a_trial_trains_exactly_as_train_does(tmp_path) -> None:
    """Trials run cpf-train's function; the second reuses the first's worker process (Tune's
    reuse_actors) and must still give the bits of a fresh in-process run."""
    import torch
    from stable_baselines3 import PPO

    from agents import train

    fixed = {"timesteps": 3000, "fleets": 4, "n_steps": 16}
    spec = SweepSpec(("bench_mild",), (3, 4), fixed=fixed, eval_num_seeds=0, cpus_per_trial=2)
    run_sweep(spec, tmp_path / "sweep", quiet=True)  # one trial at a time
    results = tmp_path.glob("sweep/tune/run1/bench_mild-seed*/result.json")
    pids = {json.loads(path.read_text().splitlines()[-1])["pid"] for path in results}
    assert len(pids) == 1, "the second trial should have reused the first one's process"
    for seed in (3, 4):
        config = spec.config({"scenario": "bench_mild", "seed": seed})
        assert config.torch_threads == 2  # the CPUs each trial reserves
        train(config, tmp_path / f"here{seed}", progress=False)
        # SB3's model.zip is a pickle; both were written by this test's own training runs
        swept = PPO.load(tmp_path / "sweep" / "trials" / f"bench_mild-seed{seed}" / "model.zip")
        here = PPO.load(tmp_path / f"here{seed}" / "model.zip")
        for name, value in here.policy.state_dict().items():
            assert torch.equal(swept.policy.state_dict()[name], value), (seed, name)


_LISTENING_SOCKETS = """
import os, subprocess
from cpf_commands.common.ray_runtime import start_ray
ray = start_ray(None, quiet=True)
assert ray.get(ray.remote(lambda: 1 + 1).remote()) == 2
session = ray._private.worker._global_node.get_session_dir_path()
pids = {str(os.getpid())}
for name in filter(str.isdigit, os.listdir("/proc")):
    try:
        if session in open(f"/proc/{name}/cmdline").read():
            pids.add(name)
    except OSError:
        pass
listing = subprocess.run(["ss", "-ltnpH"], capture_output=True, text=True, check=True).stdout
for line in listing.splitlines():
    if any(f"pid={pid}," in line for pid in pids):
        print(line.split()[3])
ray.shutdown()
"""


def test_the_local_instance_listens_on_loopback_only_and_its_token_is_private(tmp_path) -> None:
    """Every TCP socket the local instance's processes listen on is bound to 127.0.0.1.

    In a fresh process, since Ray reads its token once per process.
    """
    token = tmp_path / "auth_token"
    environment = {**os.environ, "RAY_AUTH_TOKEN_PATH": str(token), "NUMBA_NUM_THREADS": "1"}
    for name in ("RAY_AUTH_TOKEN", "RAY_ADDRESS"):
        environment.pop(name, None)
    run = subprocess.run(
        [sys.executable, "-c", _LISTENING_SOCKETS],
        env=environment,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    addresses = run.stdout.split()
    assert len(addresses) >= 3, addresses  # GCS, raylet, driver at least
    for address in addresses:
        assert address.rsplit(":", 1)[0] in ("127.0.0.1", "[::ffff:127.0.0.1]"), addresses
    assert token.stat().st_mode & 0o777 == 0o600
