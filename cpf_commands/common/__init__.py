"""What every command shares: argument types, the policy resolver, the Ray runtime.

``arguments`` holds the argparse types and checks every command uses;
``policies`` turns a baseline name, an agent folder or a policy object into
a policy (the one resolver of ``cpf-run``, ``cpf-bench``, ``cpf-sweep``);
``ray_runtime`` starts or joins Ray for ``cpf-sweep`` and ``cpf-bench --ray``.

What it may import: ``cpf_env``, ``baselines`` and ``agents``; no other
command family.
"""
