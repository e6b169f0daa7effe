"""The physical parts of the task, each a small module of pure, batched functions.

What lives here: the vessel model and its hydrodynamics (``vessel``), the
plant's right-hand side and RK4 integration (``plant``), ocean disturbances
and unknown dynamics (``disturbances``), the desired paths (``paths``), the
communication graph (``graph``) and its link impairments (``links``), and the
counter-based random numbers the compiled step draws from (``counter_rng``).

What it may import: ``cpf_env.infra`` and nothing else of ``cpf_env`` outside
this folder. Everything
else (scenarios, the simulator, the environments) is built on these parts.
"""
