"""A learned navigation filter: the analytic filter's estimate corrected from the vessel's history.

- ``correction``: ``Correction``, the linear map from recent fix offsets and
  applied forces to the estimate's error, and its least-squares ``fit``;
- ``policy``: ``LearnedFilter``, a filtered design acting on the corrected estimate;
- ``fit``: gathering closed-loop data, fitting and validating (``cpf-fit-filter``);
- ``folder``: the data-only folder it writes, which ``agents.load_policy`` reads.
"""
