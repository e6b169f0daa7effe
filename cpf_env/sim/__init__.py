"""The simulator: B fleets x n vessels as arrays, advanced by one compiled step.

What lives here: the observation layout and its compiled pieces
(``observation``), the compiled reward (``reward``), the arrays the step
mutates (``arrays``), the fused step itself (``kernels``), ``FleetSim``
(``fleet``: the batched simulator, no Gym code) and the one-off compilation
of every kernel (``precompile``). What is measured on top of it lives in
``cpf_env.evaluation``.

What it may import: ``cpf_env.infra``, ``cpf_env.model`` and ``cpf_env.scenarios`` (a simulator
is built from a ``Scenario``). Never ``cpf_env.envs``: the environments are
views of this layer.
"""
