"""BenchMARL tasks for ``cpf_env``: ``CpfTask``, its ``CpfTaskClass`` and the task configs.

Each member of ``CpfTask`` is a training scenario: the paper's scenarios
(``cpf_env.scenarios.paper``), the benchmark suite (``suite.SUITE``) and the
hard track (``list_suite("hard")``: residual over each scenario's best
deployable design, whole episodes); the ``_shift`` variants, validation and
evaluation seeds are held out (``cpf_env.scenarios.splits``: the env refuses
them). The env is the native batched ``TorchRLFleetEnv`` (BenchMARL's
``num_envs`` is the number of fleets, no ``SerialEnv``), in the residual form
over a named base policy, with the global state for centralized critics and
frozen input statistics.

The default configuration of each task is ``conf/task/cpf/<task>.yaml`` beside
this module (``CpfTaskConfig`` lists and checks its fields); episodes are 200
control periods (10 s) there, short enough for an on-policy batch to hold
whole episodes, except on the hard track, whose episodes are the scenario's
own (its crossings come after 40 s; a batch then holds parts of episodes).
Importing this module also registers every task as ``cpf/<task>`` in
BenchMARL's registry, so its Hydra loader finds them
(``cpf-marl algorithm=mappo task=cpf/bench_lossy_links``).

Example::

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig
    from agents.marl.tasks import CpfTask

    experiment = Experiment(
        task=CpfTask.BENCH_LOSSY_LINKS.get_from_yaml(),
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=ExperimentConfig.get_from_yaml(),
    )
    experiment.run()
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

from agents.marl.compat import import_benchmarl
from agents.marl.envs import make_env
from cpf_env.envs.residual import ResidualConfig
from cpf_env.envs.torchrl_env import GROUP
from cpf_env.scenarios.splits import check_training

import_benchmarl()

from benchmarl.environments import Task, TaskClass, task_config_registry  # noqa: E402
from benchmarl.utils import _read_yaml_config  # noqa: E402
from torchrl.data import Composite  # noqa: E402
from torchrl.envs import EnvBase  # noqa: E402

__all__ = ["CONF", "ENV_NAME", "CpfTask", "CpfTaskClass", "CpfTaskConfig", "CpfTaskEnum"]

#: BenchMARL's environment name of these tasks (``task=cpf/<task>``).
ENV_NAME = "cpf"
#: The Hydra config folder: ``config.yaml`` and ``task/cpf/<task>.yaml``.
CONF = Path(__file__).parent / "conf"


@dataclasses.dataclass
class CpfTaskConfig:
    """The fields of a task config (``conf/task/cpf/<task>.yaml``).

    Attributes:
        scenario: The registered scenario (a training scenario, not a ``_shift``).
        max_steps: Episode length in control periods (the scenario's ``max_steps``).
        base_policy: Base policy name (``baselines.DEPLOYABLE``), or ``"none"``.
        mode: Residual mode (``RESIDUAL_MODES``).
        scale: Residual range as a fraction of the limits.
        extras: Local extras of the learner's input (``EXTRAS``).
        messages: Message entries the learner writes, end to end (``ResidualConfig``).
        normalize: Scale inputs with statistics of the base policy alone.
        normalization_steps: Control periods those statistics pool.
        shared_slot_statistics: One set of statistics for every neighbour slot, the
            links' weights left raw (``agents.marl.envs.make_env``): the inputs of the
            neighbour-encoder actor (``agents.marl.models``).
        state: Give centralized critics the global state.
        privileged_state: Append what no vessel observes to that state (the true
            lumped force, v0, each vessel's offset from the fleet's mean path
            variable; ``TorchRLFleetEnv``): an asymmetric actor-critic, whose
            critic is told the truth and whose actor stays local. Native route only.
        stagger: Spread the fleets' horizons (``EpisodeCore``; on, as on every
            batched route; one fleet per worker on the PettingZoo route has nothing
            to spread).
        overrides: Other ``Scenario`` field overrides.
    """

    scenario: str
    max_steps: int = 200
    base_policy: str = "nn_dsc"
    mode: str = "force"
    scale: float = 0.2
    extras: list[str] = dataclasses.field(default_factory=list)
    messages: int = 0
    normalize: bool = True
    normalization_steps: int = 200
    shared_slot_statistics: bool = False
    state: bool = True
    privileged_state: bool = False
    stagger: bool = True
    overrides: dict[str, Any] = dataclasses.field(default_factory=dict)

    def residual(self) -> ResidualConfig:
        """The residual composition these fields describe."""
        return ResidualConfig(
            mode=self.mode, scale=self.scale, extras=tuple(self.extras), messages=self.messages
        )


def checked_config(config: dict[str, Any]) -> CpfTaskConfig:
    """A task config dict as ``CpfTaskConfig``; unknown or missing fields are named."""
    fields = {field.name for field in dataclasses.fields(CpfTaskConfig)}
    unknown = sorted(set(config) - fields)
    if unknown:
        raise ValueError(
            f"unknown cpf task config fields {unknown}; the fields are {sorted(fields)}."
        )
    if "scenario" not in config:
        raise ValueError("a cpf task config needs 'scenario' (a registered scenario name).")
    checked = CpfTaskConfig(**config)
    checked.residual()  # checks mode, scale, extras and messages
    if checked.privileged_state and not checked.state:
        raise ValueError(
            "privileged_state: true appends to the global state, which this task config "
            "turns off: set state: true as well, or privileged_state: false."
        )
    return checked


class CpfTaskClass(TaskClass):
    """BenchMARL's task class over ``TorchRLFleetEnv`` (continuous actions, one group)."""

    def training_config(
        self, continuous_actions: bool, seed: int | None, seeds: int
    ) -> tuple[CpfTaskConfig, int]:
        """The checked task config and the first seed of the ``seeds`` training seeds it uses.

        Raises:
            ValueError: Discrete actions, a bad config, a held-out scenario or evaluation seeds.
        """
        if not continuous_actions:
            raise ValueError(
                "cpf tasks have continuous actions only; set prefer_continuous_actions."
            )
        config = checked_config(self.config)
        first = 0 if seed is None else int(seed)
        check_training(config.scenario, range(first, first + seeds))
        return config, first

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
    ) -> Callable[[], EnvBase]:
        """A maker of a residual env of ``num_envs`` fleets, fleet k seeded ``seed + k``.

        Raises:
            ValueError: Discrete actions, a held-out scenario or evaluation seeds.
        """
        config, first = self.training_config(continuous_actions, seed, int(num_envs))

        def make() -> EnvBase:
            return make_env(
                config.scenario,
                num_envs,
                config.base_policy,
                config.residual(),
                config.stagger,
                seed=first,
                device=device,
                normalize=config.normalize,
                normalization_steps=config.normalization_steps,
                shared_slot_statistics=config.shared_slot_statistics,
                state=config.state,
                privileged_state=config.privileged_state,
                max_steps=config.max_steps,
                **config.overrides,
            )

        return make

    def supports_continuous_actions(self) -> bool:
        """True: forces (and rate) are continuous."""
        return True

    def supports_discrete_actions(self) -> bool:
        """False."""
        return False

    def max_steps(self, env: EnvBase) -> int:
        """The episode length of the config."""
        return int(self.config.get("max_steps", CpfTaskConfig.max_steps))

    def has_render(self, env: EnvBase) -> bool:
        """False: evaluation renders nothing (``cpf-run`` draws fleets)."""
        return False

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        """``{"vessel": ["vessel_0", ...]}``."""
        return dict(env.group_map)  # a TransformedEnv forwards it to TorchRLFleetEnv

    def observation_spec(self, env: EnvBase) -> Composite:
        """The vessels' local observations only (no state, no infos), without the batch."""
        spec = env.full_observation_spec_unbatched.clone()
        for key in list(spec[GROUP].keys()):
            if key != "observation":
                del spec[GROUP][key]
        for key in list(spec.keys()):
            if key != GROUP:
                del spec[key]
        return spec

    def info_spec(self, env: EnvBase) -> Composite | None:
        """The vessels' infos, if the env outputs any, without the batch."""
        spec = env.full_observation_spec_unbatched.clone()
        if "info" not in spec[GROUP].keys():
            return None
        del spec[GROUP, "observation"]
        for key in list(spec.keys()):
            if key != GROUP:
                del spec[key]
        return spec

    def state_spec(self, env: EnvBase) -> Composite | None:
        """The global state, if the config asks for it, without the batch."""
        spec = env.full_observation_spec_unbatched
        if "state" not in spec.keys():
            return None
        return Composite({"state": spec["state"].clone()})

    def action_spec(self, env: EnvBase) -> Composite:
        """The residual actions in [-1, 1], without the batch."""
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        """None: every action is allowed."""
        return None

    @staticmethod
    def env_name() -> str:
        """``"cpf"``."""
        return ENV_NAME


class CpfTaskEnum(Task):
    """What every enum of cpf tasks shares: configs from ``conf/task/cpf/`` beside this module."""

    def get_from_yaml(self, path: str | None = None) -> TaskClass:
        """The task with its config from ``path``, default ``conf/task/cpf/<task>.yaml`` here."""
        default = CONF / "task" / ENV_NAME / f"{self.name.lower()}.yaml"
        config = dict(_read_yaml_config(str(default if path is None else path)))
        config.pop("defaults", None)
        return self.get_task(config=dataclasses.asdict(checked_config(config)))


class CpfTask(CpfTaskEnum):
    """The cpf_env training scenarios as BenchMARL tasks (``get_from_yaml()`` for the default)."""

    WANG2014 = None
    SATURATION_HEAVY = None
    CURRENT_AND_WAVES = None
    LOSSY_LINKS = None
    SWITCHING_TOPOLOGY = None
    HETEROGENEOUS = None
    LARGE_FLEET = None
    BENCH_MILD = None
    BENCH_SATURATION = None
    BENCH_CURRENT_WAVES = None
    BENCH_LOSSY_LINKS = None
    BENCH_SWITCHING = None
    BENCH_HETEROGENEOUS = None
    BENCH_LARGE_FLEET = None
    HARD_SENSING = None
    HARD_SENSING_WAVES = None
    HARD_UNDERACTUATED = None
    HARD_CROSSING = None
    HARD_UNDERACTUATED_SENSING = None
    HARD_HETEROGENEOUS = None
    HARD_LARGE_FLEET = None

    @staticmethod
    def associated_class() -> type[TaskClass]:
        """``CpfTaskClass``."""
        return CpfTaskClass


task_config_registry.update(
    {f"{ENV_NAME}/{name.lower()}": task for name, task in CpfTask.__members__.items()}
)
