"""Infrastructure every layer may use: nothing here knows vessels, fleets or policies.

What lives here: files and folders that are never half-written and a lock
that refuses a second writer (``atomic``), and the key of numba's on-disk
cache for every compiled kernel of the package (``kernel_cache``, imported
first by ``cpf_env``, before any kernel module is decorated).

What it may import: nothing of the package. Kept out of the physics layers
(``model``, ``sim``), which hold the task itself.
"""
