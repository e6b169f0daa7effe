"""The commands a user runs, one subpackage per command family.

=====================  ==============================================================
where                  what
=====================  ==============================================================
``run/``               ``cpf-run``: one scenario, the paper's figures and claims
``bench/``             ``cpf-bench``: policies x scenarios x paired seeds, statistics
``sweep/``             ``cpf-sweep``: training grids on Ray Tune
``train``              ``cpf-train``: train a residual or from-scratch agent
``speed``              ``cpf-speed``: throughput of every layer
``precompile``         ``cpf-precompile``: compile every kernel once
``common/``            what they share: argument types, the policy resolver, Ray
=====================  ==============================================================

This package sits above the environment (``cpf_env``), the analytic policies
(``baselines``) and the learned ones (``agents``): it may import all three,
and none of them imports it. argparse lives only here.
"""
