"""The paper's comparison: the (algorithm x seed) grid of training jobs, their evaluation, Table 4 and figures 7-12.

``grid`` (the grid file and its jobs) · ``jobs`` (a job's state from its run directory; the local process
runner) · ``executors`` (`execute`: the one entry point that runs jobs) · ``deadline`` (``--finish-by``) ·
``evaluations`` (what every team flies, cached beside it) · ``learning_curves`` (what a run's metrics.csv says) ·
``summary`` (experiments.json as records per algorithm; the transfer figures) · ``table`` (table4.md) · ``figures``
· ``cli`` (``python -m tssac_core.experiments``).
"""
