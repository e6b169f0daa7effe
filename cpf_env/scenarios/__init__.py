"""Scenarios: the task catalog.

What lives here: the ``Scenario`` type (``scenario``), the registry of named
scenarios (``registry``), the paper's simulation and its variants
(``paper``), the fine-step scenarios of the reproduction (``fine``), the
benchmark suite and its tracks (``suite``; the hard track: ``hard``), the reward's weights and forms
(``reward_weights``) and the value checks that scenario fields go through
(``checks``). Importing this package registers every catalog scenario.

What it may import: ``cpf_env.model`` only. The simulator (``cpf_env.sim``)
and the environments (``cpf_env.envs``) consume scenarios; scenarios never
import them.

    >>> from cpf_env import scenarios
    >>> scenarios.get("wang2014").n
    5
    >>> "bench_mild" in scenarios.list_scenarios()
    True
"""

from cpf_env.scenarios import fine, hard, paper, splits, suite
from cpf_env.scenarios.registry import get, list_scenarios, make_scenario, register
from cpf_env.scenarios.scenario import InitialState, Scenario, SpeedSchedule

__all__ = [
    "InitialState",
    "Scenario",
    "SpeedSchedule",
    "fine",
    "get",
    "hard",
    "list_scenarios",
    "make_scenario",
    "paper",
    "register",
    "splits",
    "suite",
]
