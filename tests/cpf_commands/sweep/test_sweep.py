"""The sweep's specification, summary and command-line checks, and precompilation: no Ray needed.

The runs on Ray itself are in ``test_ray.py`` (marker ``ray``).
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import pkgutil
import re
import socket
import subprocess
import sys
import types

import numba
import pytest
from numba.core.registry import CPUDispatcher

import cpf_env
from cpf_commands.common import ray_runtime
from cpf_commands.precompile import precompile_main
from cpf_commands.sweep.cli import run_sweep, sweep_main
from cpf_commands.sweep.report import (
    EVALUATION_FILE,
    summary_markdown,
    summary_rows,
    trial_state,
    write_evaluation,
)
from cpf_commands.sweep.spec import SweepSpec, parse_setting, trial_name
from cpf_commands.sweep.trial import run_trial
from cpf_env.infra import atomic
from cpf_env.sim.precompile import KERNEL_MODULES, kernels_of_package, precompile

# --- --set parsing ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("timesteps=20000", ("timesteps", (20000,))),
        ("residual.scale=0.1,0.2", ("residual.scale", (0.1, 0.2))),
        ("residual.mode=force,force_and_rate", ("residual.mode", ("force", "force_and_rate"))),
        ("residual.hide_residual_from_base=false", ("residual.hide_residual_from_base", (False,))),
        ("reward_form=none,log", ("reward_form", (None, "log"))),
        ("torch_threads=2", ("torch_threads", (2,))),
        ('residual.extras=[[],["base_action"]]', ("residual.extras", ((), ("base_action",)))),
        ("net_arch=[[64,64],[128]]", ("net_arch", ((64, 64), (128,)))),
    ],
)  # fmt: skip
def test_settings_are_parsed_to_the_field_types(text: str, expected: tuple) -> None:
    assert parse_setting(text) == expected


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("timesteps", "takes FIELD=VALUE"),
        ("=3", "takes FIELD=VALUE"),
        ("bogus=1", "unknown TrainConfig field 'bogus'.*'timesteps'"),
        ("seed=1,2", "set seed with --seed and --num-seeds"),
        ("scenario=wang2014", "set scenario with --scenarios"),
        ("timesteps=many", "'many' is not a valid int"),
        ("timesteps=1.5", "'1.5' is not a valid int"),
        ("residual.hide_residual_from_base=maybe", "not a valid bool"),
        ("residual.extras=[oops", "is not a JSON list"),
    ],
)
def test_bad_settings_say_what_is_wrong(text: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        parse_setting(text)


# --- the grid --------------------------------------------------------------------------------


def test_every_combination_is_one_trial_with_its_own_folder_name() -> None:
    spec = SweepSpec.from_settings(
        ["bench_mild", "bench_saturation"], [0, 1], ["timesteps=100", "residual.scale=0.1,0.2"]
    )
    trials = list(spec.trials())
    assert len(trials) == 2 * 2 * 2
    names = [trial_name(params, spec) for params in trials]
    assert len(set(names)) == len(names)
    assert names[0] == "bench_mild-seed0-residual.scale0.1"
    assert spec.fixed == {"timesteps": 100} and spec.grid == {"residual.scale": (0.1, 0.2)}
    config = spec.config(trials[-1])
    assert (config.scenario, config.seed, config.residual.scale, config.timesteps) == (
        "bench_saturation",
        1,
        0.2,
        100,
    )


@pytest.mark.parametrize(
    ("scenarios", "seeds", "settings", "match"),
    [
        (["bench_mild"], [0], ["residual.scale=-1"], "scale"),
        (["no_such"], [0], [], "unknown scenario 'no_such'"),
        (["bench_mild"], [0, 0], [], "seeds repeat"),
        (["bench_mild"], [], [], "at least one scenario and one seed"),
        (["bench_mild"], [0], ["residual.scale=0.1", "residual.scale=0.2"], "given twice"),
        (["bench_mild"], [0], ["fleets=0"], "fleets must be an integer >= 1"),
        (
            ["bench_mild"],
            [0],
            ["residual.scale=0.1,0.10"],
            r"scale: values repeat \(\[0.1, 0.1\]\)",
        ),
        (["bench_mild"], [0], ["net_arch=64,64"], r"values repeat.*net_arch=\[\[64,64\]\]"),
        (["bench_mild"], [-1], [], "seed must be an integer in"),
    ],
)
def test_a_bad_sweep_is_refused_before_any_trial_starts(
    scenarios: list, seeds: list, settings: list, match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        SweepSpec.from_settings(scenarios, seeds, settings)


@pytest.mark.parametrize(
    ("arguments", "match"),
    [
        ({"grid": {"no_such": (1, 2)}}, "'no_such' is not a field a sweep can set"),
        ({"fixed": {"seed": 3}}, "'seed' is not a field a sweep can set"),
        ({"cpus_per_trial": 0}, "CPUs per trial must be >= 1"),
        ({"fixed": {"torch_threads": 2}}, "torch_threads 2 is more than the 1 CPU"),
        ({"grid": {"torch_threads": (1, 4)}, "cpus_per_trial": 2}, "torch_threads 4 is more"),
    ],
)
def test_a_sweep_built_in_python_is_checked_too(arguments: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        SweepSpec(("bench_mild",), (0,), **arguments)


def test_a_folder_keeps_its_sweep_and_refuses_another(tmp_path) -> None:
    spec = SweepSpec(("bench_mild",), (0, 1), {"residual.scale": (0.1, 0.2)}, {"timesteps": 100})
    assert spec.check_folder(tmp_path / "new") is False
    assert not (tmp_path / "new").exists()  # checking writes nothing
    spec.save(tmp_path)
    assert json.loads((tmp_path / "sweep.json").read_text())["seeds"] == [0, 1]
    assert spec.check_folder(tmp_path) is True  # the same sweep: a resume
    grid = {"residual.scale": (0.1, 0.2)}
    other = SweepSpec(("bench_mild",), (0, 1, 2), grid, {"timesteps": 100})
    with pytest.raises(ValueError, match=r"differs in seeds \(saved \[0, 1\], now \[0, 1, 2\]\)"):
        other.check_folder(tmp_path)
    threads = SweepSpec(("bench_mild",), (0, 1), spec.grid, spec.fixed, cpus_per_trial=2)
    with pytest.raises(ValueError, match=r"differs in cpus_per_trial.*another --out"):
        threads.check_folder(tmp_path)  # torch threads change the results: no mixing
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="is a file; give a folder"):
        spec.check_folder(tmp_path / "file")
    saved = json.loads((tmp_path / "sweep.json").read_text())
    (tmp_path / "sweep.json").write_text(json.dumps(saved | {"cpf_env_version": "0.0.1"}))
    with pytest.raises(ValueError, match=r"made by cpf_env 0.0.1; this is .*choose another --out"):
        spec.check_folder(tmp_path)  # an upgraded package does not resume an old sweep


def test_the_order_of_set_does_not_change_the_sweep(tmp_path) -> None:
    settings = ["residual.scale=0.1,0.2", "n_epochs=2,4"]
    first = SweepSpec.from_settings(["bench_mild"], [0], settings)
    second = SweepSpec.from_settings(["bench_mild"], [0], settings[::-1])
    names = [trial_name(params, first) for params in first.trials()]
    assert names == [trial_name(params, second) for params in second.trials()]
    assert names[0] == "bench_mild-seed0-n_epochs2-residual.scale0.1"
    first.save(tmp_path)
    assert second.check_folder(tmp_path) is True


# --- the summary -----------------------------------------------------------------------------


def _finished(out, spec: SweepSpec, params: dict, ratio: float, reference="nn_dsc") -> str:
    """Write the files a trial leaves when it finishes (config.json as agents.train writes it)."""
    folder = out / "trials" / trial_name(params, spec)
    folder.mkdir(parents=True)
    config = {"config": json.loads(json.dumps(spec.config(params).to_json()))}
    (folder / "config.json").write_text(json.dumps(config))
    record = {"reference": reference, "seed": 9000, "cost": 1.0, "cost_ratio": ratio,
              "p_beats_reference": 0.6}  # fmt: skip
    write_evaluation(folder, record)
    return folder.name


def test_the_summary_has_every_trial_and_each_setting_over_seeds(tmp_path) -> None:
    spec = SweepSpec(("bench_mild",), (0, 1, 2), {"residual.scale": (0.1, 0.2)}, {"timesteps": 100})
    for seed, scale, ratio in ((0, 0.1, 0.9), (1, 0.1, 1.1), (2, 0.1, 0.8), (0, 0.2, 0.5)):
        params = {"scenario": "bench_mild", "seed": seed, "residual.scale": scale}
        _finished(tmp_path, spec, params, ratio)
    errors = {"bench_mild-seed1-residual.scale0.2": "RuntimeError: diverged"}
    rows = summary_rows(spec, tmp_path, errors)
    status = {row["trial"]: row["status"] for row in rows}
    assert len(rows) == 6
    assert status["bench_mild-seed1-residual.scale0.2"] == "error: RuntimeError: diverged"
    assert status["bench_mild-seed2-residual.scale0.2"] == "not finished"
    assert sum(value == "done" for value in status.values()) == 4
    text = summary_markdown(spec, rows, "cpf-sweep ...")
    assert "| bench_mild | 0.1 | 3/3 | 0.9333 | 0.8000 | 1.1000 | 2/3 |" in text
    assert "| bench_mild | 0.2 | 1/3 | 0.5000 | 0.5000 | 0.5000 | 1/1 |" in text
    assert "trained from scratch (here: nn_dsc)" in text


def test_a_trial_counts_only_if_it_finished_with_this_configuration(tmp_path) -> None:
    spec = SweepSpec(("bench_mild",), (0, 1, 2), fixed={"timesteps": 100})
    params = [{"scenario": "bench_mild", "seed": seed} for seed in (0, 1, 2)]
    done, stale, cut = (_finished(tmp_path, spec, p, 0.9) for p in params)
    other = SweepSpec(("bench_mild",), (1,), fixed={"timesteps": 200})  # what trained seed 1
    config = {"config": json.loads(json.dumps(other.config(params[1]).to_json()))}
    (tmp_path / "trials" / stale / "config.json").write_text(json.dumps(config))
    (tmp_path / "trials" / cut / EVALUATION_FILE).write_text('{"reference": "nn_')  # cut off
    status = {row["trial"]: row["status"] for row in summary_rows(spec, tmp_path, {})}
    assert status[done] == "done"
    assert status[stale].startswith("stale: trained with another configuration")
    # evaluated on the test seeds (recorded before the validation seeds): evaluated again
    record = json.loads((tmp_path / "trials" / done / EVALUATION_FILE).read_text())
    write_evaluation(tmp_path / "trials" / done, {k: v for k, v in record.items() if k != "seed"})
    assert trial_state(tmp_path / "trials" / done, spec.config(params[0]))[0] == "stale"
    assert status[cut] == "not finished"
    assert trial_state(tmp_path / "trials" / cut, spec.config(params[2])) == ("missing", {})


def test_the_summary_names_each_base_and_shows_none_settings(tmp_path) -> None:
    spec = SweepSpec(
        ("bench_mild",),
        (0,),
        {"base_policy": ("nn_dsc", "backstepping"), "reward_form": (None, "log")},
    )
    for base in ("nn_dsc", "backstepping"):
        for form in (None, "log"):
            params = {"scenario": "bench_mild", "seed": 0, "base_policy": base, "reward_form": form}
            _finished(tmp_path, spec, params, 0.5, reference=base)
    text = summary_markdown(spec, summary_rows(spec, tmp_path, {}), "cpf-sweep ...")
    assert "(here: backstepping, nn_dsc)" in text
    assert "| bench_mild | backstepping | none | 1/1 |" in text


# --- the command without Ray -----------------------------------------------------------------


def _closed_port() -> int:
    """A local TCP port nothing listens on."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class _RayThatMustNotStart(types.ModuleType):
    """Stands in for ``ray``: the address check must fail before ``ray.init``."""

    def init(self, *args, **kwargs) -> None:
        raise AssertionError("ray.init was called for an address nobody answers at")


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--num-seeds", "1", "--out", "x"], "--scenarios"),
        (["--scenarios", "bench_mild", "--out", "x", "--set", "bogus=1"], "unknown TrainConfig"),
        (["--scenarios", "bench_mild", "--out", "x", "--cpus-per-trial", "0"], "integer >= 1"),
        (["--scenarios", "nowhere", "--out", "x"], "invalid choice"),
    ],
)
def test_sweep_command_rejects_bad_arguments_before_starting_ray(
    argv, match, monkeypatch, capsys
) -> None:
    monkeypatch.setitem(sys.modules, "ray", _RayThatMustNotStart("ray"))
    with pytest.raises(SystemExit) as exit_info:
        sweep_main(argv)
    assert exit_info.value.code == 2
    assert match in capsys.readouterr().err


def test_without_ray_the_commands_say_how_to_install_it(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now raises ImportError
    with pytest.raises(ImportError, match=r"needs Ray.*pip install -e \"\.\[ray\]\""):
        ray_runtime.start_ray(None)


def test_without_ray_or_the_learning_extra_cpf_sweep_says_what_to_install(
    tmp_path, monkeypatch, capsys
) -> None:
    argv = ["--scenarios", "bench_mild", "--out", str(tmp_path / "sweep")]
    with monkeypatch.context() as patch:
        patch.setitem(sys.modules, "ray", None)
        with pytest.raises(SystemExit):
            sweep_main(argv)
    assert 'pip install -e ".[ray]"' in capsys.readouterr().err
    cached = [name for name in sys.modules if name == "agents" or name.startswith("agents.")]
    for name in ["cpf_commands.sweep.spec", *cached]:
        monkeypatch.delitem(sys.modules, name)  # imported again, without stable_baselines3
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)
    with pytest.raises(SystemExit):
        sweep_main(argv)
    message = capsys.readouterr().err
    assert "needs stable_baselines3 (not installed)" in message
    assert 'install the learning and Ray extras: pip install -e ".[rl,ray]"' in message
    assert not (tmp_path / "sweep").exists()


def _no_precompile(scenario_names) -> None:
    raise AssertionError("precompile must not run: there is nothing to train")


def test_a_resume_with_every_trial_finished_only_rewrites_the_summary(
    tmp_path, monkeypatch, capsys
) -> None:
    monkeypatch.setitem(sys.modules, "ray", _RayThatMustNotStart("ray"))
    monkeypatch.setattr("cpf_env.sim.precompile.precompile", _no_precompile)
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    spec = SweepSpec(("bench_mild",), (0, 1), fixed={"timesteps": 100})
    spec.save(tmp_path)
    for params in spec.trials():
        _finished(tmp_path, spec, params, 0.9)
    rows = run_sweep(spec, tmp_path, command="cpf-sweep ...")
    assert [row["status"] for row in rows] == ["done", "done"]
    assert f"resuming {tmp_path}: 2 of 2 trials finished, kept" in capsys.readouterr().out
    assert "| bench_mild | 2/2 | 0.9000 |" in (tmp_path / "summary.md").read_text()
    assert not (tmp_path / "tune").exists()


def test_a_second_sweep_on_the_same_out_is_refused_while_one_runs(tmp_path, monkeypatch) -> None:
    ray = types.ModuleType("ray")
    ray.init = ray.shutdown = lambda *args, **kwargs: None  # type: ignore[attr-defined]
    ray.tune = types.ModuleType("ray.tune")  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "ray", ray)
    monkeypatch.setattr("cpf_env.sim.precompile.precompile", lambda scenario_names: None)
    monkeypatch.setattr(  # the stand-in ray has no internals to keep on localhost
        "cpf_commands.common.ray_runtime._loopback_only", contextlib.nullcontext
    )
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    spec = SweepSpec(("bench_mild",), (0,), fixed={"timesteps": 100})
    with atomic.FolderLock(tmp_path):  # as the first cpf-sweep holds it
        with pytest.raises(ValueError, match=f"{tmp_path} is being written by another cpf-sweep"):
            run_sweep(spec, tmp_path)


def test_a_trial_to_run_again_starts_from_an_empty_folder(tmp_path, monkeypatch) -> None:
    """A stale trial is retrained from scratch: nothing of the earlier agent survives."""
    reports = []
    tune = types.ModuleType("ray.tune")
    tune.report = reports.append  # type: ignore[attr-defined]
    ray = types.ModuleType("ray")
    ray.tune = tune  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "ray", ray)
    monkeypatch.setitem(sys.modules, "ray.tune", tune)
    fixed = {"timesteps": 64, "fleets": 2, "n_steps": 16, "batch_size": 160}
    fixed["normalize_observations"] = False
    spec = SweepSpec(("bench_mild",), (0,), fixed=fixed, eval_num_seeds=0)
    params = next(spec.trials())
    stale = SweepSpec(("bench_mild",), (0,), fixed={**fixed, "timesteps": 32}, eval_num_seeds=0)
    folder = tmp_path / "trials" / _finished(tmp_path, stale, params, 0.5)
    (folder / "vecnormalize.pkl").write_text("statistics of the earlier agent")
    assert trial_state(folder, spec.config(params))[0] == "stale"
    run_trial(params, spec, str(tmp_path))
    state, record = trial_state(folder, spec.config(params))
    assert state == "done" and reports[-1] == record
    assert not (folder / "vecnormalize.pkl").exists()
    run_trial(params, spec, str(tmp_path))  # finished: reported again, not retrained
    assert reports[-1] == record and len(reports) == 2


def test_an_out_that_is_a_file_is_refused(tmp_path, capsys) -> None:
    taken = tmp_path / "taken"
    taken.write_text("")
    with pytest.raises(SystemExit) as exit_info:
        sweep_main(["--scenarios", "bench_mild", "--out", str(taken)])
    assert exit_info.value.code == 2
    assert "is a file; give a folder" in capsys.readouterr().err


def test_more_cpus_per_trial_than_this_machine_has_is_refused_not_left_pending(
    tmp_path, monkeypatch, capsys
) -> None:
    monkeypatch.setitem(sys.modules, "ray", _RayThatMustNotStart("ray"))
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    too_many = str(len(os.sched_getaffinity(0)) + 1)
    out = tmp_path / "sweep"
    with pytest.raises(SystemExit) as exit_info:
        sweep_main(["--scenarios", "bench_mild", "--out", str(out), "--cpus-per-trial", too_many])
    assert exit_info.value.code == 2
    message = capsys.readouterr().err
    assert f"--cpus-per-trial {too_many} is more than the {int(too_many) - 1} CPUs" in message
    assert not out.exists()


@pytest.mark.parametrize("address", ["localhost", "ray://headnode", "10.0.0.1:port"])
def test_an_address_without_a_port_says_how_to_write_one(address, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", _RayThatMustNotStart("ray"))
    with pytest.raises(
        ValueError, match=rf"Ray address '{address}' has no (valid )?port; use HOST:"
    ):
        ray_runtime.start_ray(address)


def test_an_address_nobody_answers_at_is_an_error_not_a_hang(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", _RayThatMustNotStart("ray"))
    address = f"127.0.0.1:{_closed_port()}"
    for spelled in (address, f"ray://{address}"):
        expected = rf"no Ray cluster answers at --address {spelled}"
        with pytest.raises(ConnectionError, match=expected):
            ray_runtime.start_ray(spelled)
    out = tmp_path / "sweep"
    with pytest.raises(SystemExit) as exit_info:
        sweep_main(["--scenarios", "bench_mild", "--out", str(out), "--address", address])
    assert exit_info.value.code == 2
    assert "ray start --head" in capsys.readouterr().err
    assert not out.exists()  # nothing written for a sweep that never started
    with pytest.raises(ValueError, match="no valid port"):
        ray_runtime.start_ray("head-node:http")


def test_workers_get_the_kernel_cache_and_one_numba_thread_per_cpu(monkeypatch) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", "/shared/numba")
    assert ray_runtime.worker_environment(2) == {
        "NUMBA_NUM_THREADS": "2",
        "NUMBA_CACHE_DIR": "/shared/numba",
    }
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert ray_runtime.worker_environment(1) == {"NUMBA_NUM_THREADS": "1"}


# --- precompilation --------------------------------------------------------------------------

ENTRY_KERNELS = (
    "cpf_env.sim.kernels.step_fleets_serial",
    "cpf_env.sim.kernels.step_fleets_parallel",
    "cpf_env.sim.kernels.observe_fleets_serial",
    "cpf_env.sim.kernels.observe_fleets_parallel",
    "cpf_env.sim.kernels.plant_accelerations",
    "cpf_env.model.paths.evaluate_paths",
)


def _counts(output: str) -> tuple[int, int]:
    """(compiled, loaded) from cpf-precompile's report line."""
    found = re.search(
        r": (\d+) signatures compiled and cached, (\d+) loaded from the cache", output
    )
    assert found, output
    return int(found[1]), int(found[2])


def test_every_module_with_kernels_is_precompiled() -> None:
    optional = {"envs.torchrl_env", "envs.torchrl_specs"}  # need TorchRL; no kernels of their own
    with_kernels = set()
    for info in pkgutil.walk_packages(cpf_env.__path__, prefix="cpf_env."):
        name = info.name.removeprefix("cpf_env.")
        if info.ispkg or name in optional:
            continue
        module = importlib.import_module(info.name)
        defined = (
            value
            for value in vars(module).values()
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == module.__name__
        )
        if any(True for _ in defined):
            with_kernels.add(name)
    assert with_kernels == set(KERNEL_MODULES)


def test_precompile_readies_every_entry_kernel(capsys) -> None:
    report = precompile(["wang2014"])
    kernels = kernels_of_package()
    for name in ENTRY_KERNELS:
        assert kernels[name].signatures, name
    assert report.scenarios == ("wang2014",)
    assert precompile_main(["--scenarios", "lossy_links"]) == 0
    compiled, loaded = _counts(capsys.readouterr().out)
    assert compiled == 0 and loaded == 0  # this process already holds every kernel
    with pytest.raises(ValueError, match="unknown scenario"):
        precompile(["nowhere"])


def test_an_unwritable_kernel_cache_is_reported(monkeypatch, capsys) -> None:
    monkeypatch.setattr(numba.config, "CACHE_DIR", "/proc/no-such-cache")
    with pytest.raises(ValueError, match="NUMBA_CACHE_DIR=/proc/no-such-cache is not a directory"):
        precompile(["wang2014"])
    with pytest.raises(SystemExit) as exit_info:
        precompile_main(["--scenarios", "wang2014"])
    assert exit_info.value.code == 2
    assert "point it at a writable directory" in capsys.readouterr().err


@pytest.mark.slow
def test_a_precompiled_cache_is_loaded_not_compiled(tmp_path) -> None:
    environment = {"NUMBA_CACHE_DIR": str(tmp_path)}
    command = [sys.executable, "-m", "cpf_commands.precompile", "--scenarios", "wang2014"]
    first, second = (
        subprocess.run(
            command, env={**os.environ, **environment}, capture_output=True, text=True, check=True
        ).stdout
        for _ in range(2)
    )
    compiled, loaded = _counts(first)
    assert compiled >= len(ENTRY_KERNELS) and loaded == 0
    assert _counts(second) == (0, len(ENTRY_KERNELS))


@pytest.mark.parametrize("seeds", [-1, 1001])
def test_trial_evaluations_stay_on_the_validation_seeds(seeds: int) -> None:
    with pytest.raises(ValueError, match="eval seeds must be from 0 to the 1000 validation seeds"):
        SweepSpec(("bench_mild",), (0,), eval_num_seeds=seeds)
