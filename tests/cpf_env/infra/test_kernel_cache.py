"""numba's cache is keyed on every source a kernel compiles from (``infra.kernel_cache``)."""

from __future__ import annotations

import ast
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from cpf_env import scenarios
from cpf_env.infra import kernel_cache
from cpf_env.infra.kernel_cache import KERNEL_MODULES, KERNEL_SOURCES, kernel_sources_digest

#: Run in a copy of the package: wang2014's true accelerations under a fixed
#: force at the initial state (``plant_accelerations`` of sim/kernels.py
#: inlines plant.py and vessel.py), with that kernel's cache statistics.
_ACCELERATIONS = """
import json
import numpy as np
from cpf_env import scenarios
from cpf_env.sim import kernels
from cpf_env.sim.fleet import FleetSim

sim = FleetSim(scenarios.get("wang2014"), num_fleets=1)
accelerations = sim.accelerations(np.full((1, 5, 3), 0.5))
stats = kernels.plant_accelerations.stats
print(json.dumps({
    "package": __import__("cpf_env").__file__,
    "value": accelerations.tolist(),
    "hits": sum(stats.cache_hits.values()),
    "misses": sum(stats.cache_misses.values()),
}))
"""

#: Run in a copy of the package: one reset and one zero-force step of wang2014,
#: printing vessel 0's position reward term, its path error z1 and the step
#: kernel's cache statistics.
_REWARD = """
import json
import numpy as np
from cpf_env import scenarios
from cpf_env.sim import kernels
from cpf_env.sim.fleet import FleetSim, observation_layout

scenario = scenarios.get("wang2014")
sim = FleetSim(scenario, num_fleets=1)
sim.reset(seeds=[0])
obs = sim.step(np.zeros((1, scenario.n, sim.act_dim)))
stats = kernels.step_fleets_serial.stats
print(json.dumps({
    "package": __import__("cpf_env").__file__,
    "term": float(sim.arrays.reward_terms[0, 0, 0]),
    "z1": [float(x) for x in obs[0, 0, observation_layout(scenario).z1]],
    "hits": sum(stats.cache_hits.values()),
    "misses": sum(stats.cache_misses.values()),
}))
"""


def _imports_of_cpf_env(path: Path) -> set[str]:
    """Modules of ``cpf_env`` (as ``sub.module``) that a file imports at module scope."""
    found = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("cpf_env."):
            base = node.module.removeprefix("cpf_env.")
            for alias in node.names:
                submodule = f"{base}.{alias.name}"
                is_module = (ROOT / "cpf_env" / Path(*submodule.split("."))).with_suffix(".py")
                found.add(submodule if is_module.exists() else base)
    return found


def test_kernel_sources_are_closed_under_the_kernel_modules_imports() -> None:
    """A constant or helper read from a module outside the list would be frozen unseen."""
    for name in KERNEL_SOURCES:
        path = (ROOT / "cpf_env" / Path(*name.split("."))).with_suffix(".py")
        missing = _imports_of_cpf_env(path) - set(KERNEL_SOURCES)
        assert not missing, f"{name} imports {missing}: add them to KERNEL_SOURCES"
    assert set(KERNEL_MODULES) <= set(KERNEL_SOURCES)


def test_digest_changes_with_any_kernel_source_and_only_with_them(tmp_path: Path) -> None:
    copy = tmp_path / "cpf_env"
    shutil.copytree(ROOT / "cpf_env", copy, ignore=shutil.ignore_patterns("__pycache__"))
    assert kernel_sources_digest(copy) == kernel_sources_digest(ROOT / "cpf_env")
    (copy / "envs" / "render.py").write_text("# not a kernel source\n")
    assert kernel_sources_digest(copy) == kernel_sources_digest(ROOT / "cpf_env")
    reward = copy / "sim" / "reward.py"
    reward.write_text(reward.read_text() + "\n")
    assert kernel_sources_digest(copy) != kernel_sources_digest(ROOT / "cpf_env")


def test_the_locator_wraps_cpf_env_functions_only() -> None:
    def outside() -> None:
        return None

    locator = kernel_cache._KernelSourcesLocator
    assert locator.from_function(outside, __file__) is None
    inside = locator.from_function(scenarios.get, str(ROOT / "cpf_env" / "sim" / "reward.py"))
    assert inside is not None
    assert inside.get_source_stamp() == ("cpf_env kernel sources", kernel_sources_digest())


def _probe(script: str, package_parent: Path, cache: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(NUMBA_CACHE_DIR=str(cache), NUMBA_NUM_THREADS="1", PYTHONPATH=str(package_parent))
    result = subprocess.run(
        [sys.executable, "-c", script],
        cwd=package_parent,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


def _position_term(z1: list[float], divide_by_squared_scale: bool) -> float:
    """-dt w_pos log(1 + (z1x^2 + z1y^2) / s^2), or / s for the edited helper (wang2014)."""
    weights = scenarios.get("wang2014").reward
    scale = weights.position_scale
    error_squared = z1[0] ** 2 + z1[1] ** 2
    divisor = scale * scale if divide_by_squared_scale else scale
    return -0.05 * weights.position * math.log1p(error_squared / divisor)


def _copy_package(tmp_path: Path) -> Path:
    """A copy of ``cpf_env`` without any cache; returns the folder it is in."""
    shutil.copytree(
        ROOT / "cpf_env", tmp_path / "cpf_env", ignore=shutil.ignore_patterns("__pycache__")
    )
    return tmp_path


def _edit(path: Path, old: str, new: str) -> None:
    source = path.read_text()
    assert source.count(old) == 1, f"{old!r} is not once in {path}"
    path.write_text(source.replace(old, new))


def test_editing_a_vessel_helper_recompiles_the_kernel_that_inlines_it(tmp_path: Path) -> None:
    """M^-1 doubled in vessel.py: the next process's accelerations double.

    ``plant_accelerations`` lives in sim/kernels.py, which the edit does not
    touch; numba's own stamp (that file's mtime and size) would load the stale kernel.
    """
    parent, cache = _copy_package(tmp_path), tmp_path / "numba-cache"
    cold = _probe(_ACCELERATIONS, parent, cache)
    assert Path(cold["package"]).parent == parent / "cpf_env"  # the copy ran, not ROOT
    assert cold["misses"] > 0 and cold["hits"] == 0
    assert np.all(np.abs(cold["value"]) > 1e-3)
    warm = _probe(_ACCELERATIONS, parent, cache)
    assert warm["hits"] > 0 and warm["misses"] == 0  # the cache works: unchanged code loads
    assert warm["value"] == cold["value"]
    _edit(
        parent / "cpf_env" / "model" / "vessel.py",
        "return p[I11] * f0, p[I22] * f1 + p[I23] * f2, p[I32] * f1 + p[I33] * f2",
        "return 2 * p[I11] * f0, 2 * (p[I22] * f1 + p[I23] * f2), 2 * (p[I32] * f1 + p[I33] * f2)",
    )
    edited = _probe(_ACCELERATIONS, parent, cache)
    assert edited["misses"] > 0 and edited["hits"] == 0
    np.testing.assert_allclose(edited["value"], 2 * np.array(cold["value"]), rtol=1e-12)


@pytest.mark.slow
def test_editing_the_reward_helper_changes_the_next_runs_rewards(tmp_path: Path) -> None:
    """The log reward's scale edited in reward.py: the next process runs the edit.

    The step kernel lives in sim/kernels.py, which the edit does not touch.
    Slow: the step kernel compiles twice (about 60 s on 2 busy cores).
    """
    parent, cache = _copy_package(tmp_path), tmp_path / "numba-cache"
    cold = _probe(_REWARD, parent, cache)
    assert cold["misses"] > 0 and cold["hits"] == 0
    assert cold["term"] == pytest.approx(_position_term(cold["z1"], True), rel=1e-5)
    warm = _probe(_REWARD, parent, cache)
    assert warm["hits"] > 0 and warm["misses"] == 0
    assert warm["term"] == cold["term"]
    assert list(cache.rglob("*.nbi"))  # NUMBA_CACHE_DIR is where the cache lives
    assert not list((parent / "cpf_env").rglob("*.nbi"))

    reward = parent / "cpf_env" / "sim" / "reward.py"
    _edit(reward, "error_squared / (scale * scale)", "error_squared / scale")
    edited = _probe(_REWARD, parent, cache)
    assert edited["misses"] > 0 and edited["hits"] == 0
    assert edited["term"] == pytest.approx(_position_term(edited["z1"], False), rel=1e-5)
    # The two formulas are far apart at this error, so the check above can tell them apart.
    assert edited["term"] != pytest.approx(_position_term(edited["z1"], True), rel=0.1)
