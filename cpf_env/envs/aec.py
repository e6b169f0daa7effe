"""The AEC form of the ParallelEnv: agents act in turn, the fleet steps after the last.

PettingZoo's ``parallel_to_aec`` stores each agent's action and validates
nothing until the last agent's turn, when the whole dict reaches the
ParallelEnv; a bad action given by ``vessel_2`` is then reported at
``vessel_4``'s turn and stays stored, so every later ``step`` raises again.
``CheckedAEC`` checks each action at the turn it is given (the ParallelEnv's
own ``check_action``) and stores nothing when it raises, so the agent can
simply act again.
"""

from __future__ import annotations

from typing import Any

from pettingzoo.utils.conversions import parallel_to_aec_wrapper

from cpf_env.envs.parallel import CooperativePathFollowingEnv

__all__ = ["CheckedAEC"]


class CheckedAEC(parallel_to_aec_wrapper):
    """``parallel_to_aec`` that rejects a bad action at the turn it is given.

    Args:
        parallel_env: The ParallelEnv to wrap.
    """

    def __init__(self, parallel_env: CooperativePathFollowingEnv) -> None:
        super().__init__(parallel_env)
        self._parallel = parallel_env

    def step(self, action: Any) -> None:
        """Take the selected agent's action; the fleet steps after the last live agent.

        Raises:
            ValueError: Bad action (wrong shape, complex, non-finite); nothing is
                stored and the same agent is still to act.
        """
        agent = self.agent_selection
        if action is not None or not (self.terminations[agent] or self.truncations[agent]):
            action = self._parallel.check_action(agent, action)
        super().step(action)
