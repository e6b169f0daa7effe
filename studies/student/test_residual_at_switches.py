"""``studies/student/residual_at_switches.py``: its switch steps and its heading error."""

from __future__ import annotations

import re
import runpy
import sys

import pytest
from conftest import ROOT

from agents import load_policy
from cpf_bench.rollout import rollout
from cpf_env.scenarios import make_scenario

STUDENT = ROOT / "results/agents/student_s0"


def test_the_yaw_residual_jumps_on_the_switch_steps_and_the_heading_is_the_rollouts(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("torch")
    script = ROOT / "studies/student/residual_at_switches.py"
    argv = [str(script), str(STUDENT), "--max-steps", "400", "--num-seeds", "1"]
    monkeypatch.setattr(sys, "argv", argv)
    runpy.run_path(str(script), run_name="__main__")
    out = capsys.readouterr().out
    on_switch, between = (
        float(value) for value in re.findall(r"([0-9.]+) N m (?:on a|between)", out)
    )
    # the graph switches every 100 steps: the student's yaw residual moves there
    # (a mask off by one step would read two ordinary steps)
    assert on_switch > 10 * between > 0
    heading = float(re.search(r"heading error \(final-window RMS, rad\): ([0-9.e+-]+)", out)[1])  # type: ignore[index]
    scenario = make_scenario("bench_switching_shift", max_steps=400)
    alone = rollout(load_policy(STUDENT, scenario=scenario), scenario, [10000])
    expected = float(alone["heading_error_rms_window"][0])
    assert heading == pytest.approx(expected, rel=1e-2)  # printed to 3 significant digits
