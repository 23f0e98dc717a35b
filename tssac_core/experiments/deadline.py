"""``--finish-by``: start only the grid's jobs that are expected to finish before a given time.

A grid takes longer than the machine is there for (a shared machine's slot, a session that ends): a job
still training when the machine goes is lost unless its directory outlives it, so starting a 65-minute
run 20 minutes before the end only wastes the 20 minutes that a shorter job could have used. The
runner asks :func:`deadline_filter` before each start; a job is expected to take what the finished runs
of the same grid entry (and the same transfer role) took on average, by their recorded wall time, or if there
are none, those of the same learner family (the SAC family's variants cost about the same per update, as do
PPO, PPO-Lagrangian and CPO per epoch), times the share of its epochs still to train (a partial run
resumes at its last finished epoch). A job with no finished run to go by is started: nothing says it
would not fit.
"""

from __future__ import annotations

import datetime as dt
import time
from collections.abc import Callable

from tssac_core.common.cli import UsageError
from tssac_core.experiments.grid import learner_family
from tssac_core.experiments.learning_curves import read_metrics
from tssac_core.train.jobs.job import Job
from tssac_core.train.jobs.runner import JobState, Status, job_state
from tssac_core.train.wall_time import training_wall_s


def parse_finish_by(text: str, now: dt.datetime | None = None) -> float:
    """``HH:MM`` (today, local time) or ``YYYY-MM-DD HH:MM`` as a POSIX time; UsageError if malformed or past."""
    now = now or dt.datetime.now()
    try:
        if len(text.strip()) <= 5:
            clock = dt.datetime.strptime(text.strip(), "%H:%M")
            when = now.replace(hour=clock.hour, minute=clock.minute, second=0, microsecond=0)
        else:
            when = dt.datetime.strptime(text.strip(), "%Y-%m-%d %H:%M")
    except ValueError:
        raise UsageError(f"--finish-by: expected HH:MM or 'YYYY-MM-DD HH:MM', got {text!r}") from None
    if when <= now:
        raise UsageError(f"--finish-by {text}: that time has passed (it is {now:%Y-%m-%d %H:%M})")
    return when.timestamp()


def expected_run_s(states: list[JobState]) -> dict[tuple[str, str | None], float]:
    """Mean wall seconds of the finished runs, per (entry name, transfer role) and per (learner family, transfer
    role)."""
    walls: dict[tuple[str, str | None], list[float]] = {}
    for s in states:
        if s.status is Status.FINISHED and (wall := training_wall_s(s.job.out)) is not None:
            walls.setdefault((s.job.entry.name, s.job.role), []).append(wall)
            walls.setdefault((learner_family(s.job.entry.algo), s.job.role), []).append(wall)
    return {key: sum(w) / len(w) for key, w in walls.items()}


def share_left(job: Job) -> float:
    """The share of the job's epochs not yet in its metrics.csv (1 for a new job)."""
    total = len(job.roles) * job.config.epochs
    done = sum(1 for row in read_metrics(job.out) if row.get("role") in job.roles)
    return max(0.0, 1.0 - done / total)


def deadline_filter(
    states: list[JobState], finish_by: float, clock: Callable[[], float] = time.time
) -> Callable[[Job], bool]:
    """Whether a job, started now, is expected to finish by ``finish_by`` (module docstring); ``states``: the
    grid's jobs as the runner found them. Each decision reads again the jobs that were not finished then, so
    that a run finishing during this invocation informs the next start (the first SAC-family run of a grid
    gives the estimate for the rest of its family)."""
    current = list(states)

    def may_start(job: Job) -> bool:
        current[:] = [s if s.status is Status.FINISHED else job_state(s.job) for s in current]
        expected = expected_run_s(current)
        whole = expected.get((job.entry.name, job.role), expected.get((learner_family(job.entry.algo), job.role)))
        return whole is None or clock() + whole * share_left(job) <= finish_by

    return may_start
