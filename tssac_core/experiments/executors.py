"""Where training jobs run: one entry point, `execute`, for every executor.

``local`` runs each job as a ``python -m tssac_core.train`` process on this machine, a few at a time
(:func:`tssac_core.experiments.jobs.run_jobs`). A job's run directory is its only state, so any executor
can resume what another started.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

from tssac_core.experiments.grid import Job
from tssac_core.experiments.jobs import JobState, Launch, run_jobs

logger = logging.getLogger(__name__)

LOCAL = "local"
EXECUTORS = (LOCAL,)


def execute(
    states: Sequence[JobState],
    executor: str = LOCAL,
    parallel: int = 1,
    report: Callable[[str], None] = logger.info,
    may_start: Callable[[Job], bool] = lambda job: True,
) -> list[Launch]:
    """Run every new or partial job of ``states`` (see `tssac_core.experiments.jobs.job_state`) with ``executor``,
    at most ``parallel`` at once; returns the launches in start order. Finished jobs are skipped; conflicts must
    have been refused by the caller (ValueError otherwise)."""
    if executor == LOCAL:
        return run_jobs(list(states), parallel, report, may_start)
    raise ValueError(f"unknown executor {executor!r} (choose from {', '.join(EXECUTORS)})")
