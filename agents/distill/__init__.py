"""Teacher and student: DAgger of a local residual student from a teacher policy (``cpf-distill``).

- ``config``: ``DistillConfig`` (the teacher, the data, the budget) and the report;
- ``dagger``: ``distill``, the rounds of labelling, aggregating and fitting.
"""
