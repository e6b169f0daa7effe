"""The learners' vector envs over the batched simulator, and what their slots see.

- ``vec_env``: ``FleetVecEnv``, a native Stable-Baselines3 ``VecEnv`` over one ``FleetSim``;
- ``mixture_env``: ``MixtureVecEnv``, fleets of several scenarios in one vector env;
- ``history_env``, ``history``: each slot's own recent inputs and actions;
- ``slot_statistics``: observation normalization shared by every neighbour slot;
- ``fleetwise``: whole-batch bases run fleet by fleet;
- ``resolve``: the learning routes' name resolution (scenario, base policy, residual).
"""
