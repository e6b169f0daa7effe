"""A learned navigation filter: the analytic filter's estimate corrected from the vessel's history.

- ``correction``: ``Correction``, the map from recent fix offsets, applied forces
  and the filter bank to the estimate's error (a matrix and maybe a network, in
  NumPy), and the matrix's least-squares ``fit``;
- ``network``: the network's fit (PyTorch) on what the matrix leaves;
- ``policy``: ``LearnedFilter``, a filtered design acting on the corrected estimate;
- ``fit``: gathering closed-loop data in rounds, fitting and validating
  (``cpf-fit-filter``);
- ``folder``: the data-only folder it writes, which ``agents.load_policy`` reads.
"""
