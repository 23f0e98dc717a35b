"""Where training jobs run: one entry point, `execute`, for every executor.

``local`` (the default) runs each job as a ``python -m tssac_core.train`` process on this machine, a few at
a time (:func:`tssac_core.train.jobs.runner.run_jobs`). ``ray`` runs each job as a Ray task asking for the
job's threads as CPUs, on a Ray started inside the command or on an existing cluster
(:mod:`tssac_core.train.jobs.ray_executor`, docs/ray.md). Both are runners of one scheduling loop,
:func:`tssac_core.train.jobs.runner.schedule`. A job's run directory is its only state, so any executor can
resume what another started.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

from tssac_core.parallel.ray_cluster import RayTarget
from tssac_core.train.jobs.job import Job
from tssac_core.train.jobs.runner import JobState, Launch, run_jobs

logger = logging.getLogger(__name__)

LOCAL = "local"
RAY = "ray"
EXECUTORS = (LOCAL, RAY)


def execute(
    states: Sequence[JobState],
    executor: str = LOCAL,
    parallel: int | None = 1,
    report: Callable[[str], None] = logger.info,
    may_start: Callable[[Job], bool] = lambda job: True,
    ray_target: RayTarget | None = None,
) -> list[Launch]:
    """Run every new or partial job of ``states`` (see `tssac_core.train.jobs.runner.job_state`) with ``executor``,
    at most ``parallel`` at once (None: ``local`` one, ``ray`` as many as the cluster's CPUs hold); returns the
    launches in start order. Finished jobs are skipped; conflicts must have been refused by the caller
    (ValueError otherwise). ``ray_target``: which Ray (default: one started inside the command)."""
    if executor == LOCAL:
        return run_jobs(list(states), parallel or 1, report, may_start)
    if executor == RAY:
        from tssac_core.train.jobs.ray_executor import run_jobs_on_ray

        return run_jobs_on_ray(list(states), parallel, report, ray_target or RayTarget(), may_start)
    raise ValueError(f"unknown executor {executor!r} (choose from {', '.join(EXECUTORS)})")
