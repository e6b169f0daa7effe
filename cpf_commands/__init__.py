"""The commands a user runs: ``cpf-run``, ``cpf-speed`` (and the code they share).

This package sits above the environment (``cpf_env``), the analytic policies
(``baselines``) and the learned ones (``agents``): it may import all three,
and none of them imports it. It holds the experiment runner, the figures and
the entry points; argparse lives only here.
"""
