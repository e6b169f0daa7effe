"""``cpf_bench.evaluate``: the benchmark's one call, the same numbers as ``cpf-bench``."""

from __future__ import annotations

import numpy as np
import pytest

from baselines import make_policy
from cpf_bench import evaluate
from cpf_commands.bench.run import run_bench
from cpf_env import scenarios


def test_evaluate_gives_the_bench_its_numbers_for_names_objects_and_factories() -> None:
    mild = scenarios.get("bench_mild")
    policies = {
        "nn_dsc": "nn_dsc",
        "object": make_policy("dsc", mild),
        "factory": lambda task: make_policy("backstepping", task),
    }
    result = evaluate(policies, ["bench_mild"], num_seeds=3, max_steps=200)
    cells = run_bench(["nn_dsc", "dsc", "backstepping"], ["bench_mild"], num_seeds=3, max_steps=200)
    for label, cell in zip(policies, cells, strict=True):
        mine = result.cell(label, "bench_mild")
        assert mine.seeds == (10000, 10001, 10002) == cell.seeds
        for name, values in cell.metrics.items():
            np.testing.assert_array_equal(mine.metrics[name], values, err_msg=f"{label} {name}")
    assert result.cell("nn_dsc", "bench_mild").metrics["cost"].min() > 0


def test_seeds_split_and_skips() -> None:
    result = evaluate(["nn_dsc"], ["bench_mild"], num_seeds=2, seed=5, max_steps=5, split="shift")
    (cell,) = result.cells
    assert cell.seeds == (5, 6) and cell.scenario == "bench_mild_shift"
    assert evaluate(["nn_dsc"], ["wang2014"], num_seeds=4, max_steps=5).cells[0].seeds == (10000,)

    def picky(task):
        if task.name == "bench_switching":
            raise ValueError("not this one")
        return make_policy("nn_dsc", task)

    result = evaluate({"picky": picky}, ["bench_mild", "bench_switching"], num_seeds=1, max_steps=2)
    assert [c.scenario for c in result.cells] == ["bench_mild"]
    assert result.skipped == {("picky", "bench_switching"): "not this one"}
    with pytest.raises(KeyError, match="no cell"):
        result.cell("picky", "bench_switching")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"num_seeds": 0}, "num_seeds must be an integer >= 1"),
        ({"num_seeds": 2.5}, "num_seeds must be an integer >= 1"),
        ({"max_steps": 0}, "max_steps must be >= 1"),
        ({"split": "train"}, "unknown split 'train'"),
        ({"scenarios": []}, "at least one scenario"),
        ({"policies": []}, "at least one policy"),
        ({"policies": ["runs/ppo"]}, "load a trained agent first"),
    ],
)
def test_bad_arguments_say_what_to_change(kwargs: dict, message: str) -> None:
    arguments = {"policies": ["nn_dsc"], "scenarios": ["bench_mild"], "max_steps": 2, **kwargs}
    with pytest.raises(ValueError, match=message):
        evaluate(**arguments)
