"""The paper's comparison: the (algorithm x seed) grid of training jobs, their evaluation, Table 4 and figures 7-12.

``grid`` (the grid file and its jobs) · ``jobs`` (a job's state from its run directory; the local process
runner) · ``executors`` (`execute`: the one entry point that runs jobs) · ``deadline`` (``--finish-by``) ·
``report`` (evaluation, Table 4, the transfer experiment) · ``figures`` · ``cli``
(``python -m tssac_core.experiments``).
"""
