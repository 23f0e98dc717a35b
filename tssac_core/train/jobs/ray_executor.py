"""``--executor ray``: the grid's training jobs as Ray tasks, one per (algorithm, seed) job.

Each job is a task asking for the job's CPUs (its torch threads). The task runs on whichever node Ray
gives it the same ``python -m tssac_core.train`` process the local executor starts (the same command,
the same ``train.log``), in the driver's working directory, and decides there, from the run directory,
whether to start the run or ``--resume`` it. So the run directory and its resume state are the only
state: the node needs to see it, which on a cluster means a shared filesystem (docs/ray.md).

- Each task is a Ray generator: it yields where it started (:class:`Started`) as soon as its training
  process runs, then how that process ended (:class:`Outcome`). Ray streams both to the driver, which prints
  them as the local executor prints a job's start and end; no actor carries them and the driver polls no one.
- A task whose worker process dies (killed, out of memory, its node lost) is submitted again by the driver
  (:data:`WORKER_RETRIES` times), not by Ray, so that the driver knows each start is a retry; the training
  process dies with its worker (``PR_SET_PDEATHSIG``), so the retry finds the run partial and resumes it from
  its last finished epoch. A task that raises is not retried.
- Ctrl-C or SIGTERM: every running task is cancelled (a KeyboardInterrupt inside it): it stops its
  training process as the local executor does (SIGTERM to its group, then SIGKILL) and records the stop
  (``jobs.log_stopped``); queued jobs are dropped. Each run stays resumable.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import socket
import subprocess
import time
from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tssac_core.parallel.ray_cluster import RayTarget, cluster_cpus, ray_session
from tssac_core.parallel.ray_map import TaskError, cancel, next_yield
from tssac_core.train.jobs.job import Job
from tssac_core.train.jobs.runner import (
    LOG_NAME,
    JobState,
    Launch,
    Status,
    interrupt_on_sigterm,
    job_state,
    log_stopped,
    report_end,
    schedule,
    start,
    stop,
)

WORKER_RETRIES = 3
"""Times the driver submits a job again after its worker process died (each run resumes the last)."""
TASK_WAKE_S = 1.0
DRIVER_WAKE_S = 2.0
"""How often a task looks at its training process, and the driver at its tasks: rarely, since on a machine whose
CPUs the jobs fill, every wake-up of these is taken from the training."""
PR_SET_PDEATHSIG = 1


@dataclass(frozen=True)
class Started:
    """What a task reports when it starts its training process."""

    name: str
    host: str
    node: str
    """The Ray node's id (its first 8 hex digits): two nodes on one host differ here."""
    worker_pid: int
    train_pid: int
    resumed: bool


@dataclass(frozen=True)
class Outcome:
    """How a task's training process ended."""

    returncode: int
    command: tuple[str, ...]
    resumed: bool


def die_with_parent() -> None:
    """In the child, before exec: SIGKILL when the process that started it (the Ray worker) dies (Linux)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: a killed worker may leave its training process running
        pass


def node_id() -> str:
    """This worker's Ray node (first 8 hex digits)."""
    import ray

    return str(ray.get_runtime_context().get_node_id())[:8]


def run_job(job: Job, directory: str) -> Iterator[Started | Outcome]:
    """The Ray task: train (or resume) ``job`` in ``directory`` (the driver's working directory) until its
    process ends, yielding its start, then its end; a cancel (KeyboardInterrupt) stops it and leaves it
    resumable."""
    if not Path(directory).is_dir():
        raise RuntimeError(
            f"node {socket.gethostname()} does not see {directory}: running a grid on a Ray cluster needs "
            "the checkout and the results on a filesystem every node mounts at the same path (docs/ray.md)"
        )
    os.chdir(directory)
    state = job_state(job)
    if state.status is Status.FINISHED:  # an earlier attempt finished it before its worker died
        yield Outcome(0, (), False)
        return
    if state.status is Status.CONFLICT:
        raise RuntimeError(f"{job.out}: {state.detail}")
    resume = state.status is Status.PARTIAL
    # Ray cancels a task with SIGINT: a worker whose Ray was started from a background shell (`cmd &` in a
    # script) inherited SIGINT ignored and would train on until the cancel's grace ran out.
    with contextlib.suppress(ValueError):  # not the worker's main thread: leave its signals alone
        signal.signal(signal.SIGINT, signal.default_int_handler)
    proc, cmd = start(
        job, resume, where=f"ray worker pid {os.getpid()} on {socket.gethostname()}", preexec_fn=die_with_parent
    )
    began = time.monotonic()
    try:
        yield Started(job.name, socket.gethostname(), node_id(), os.getpid(), proc.pid, resume)
        while proc.poll() is None:
            with contextlib.suppress(subprocess.TimeoutExpired):  # wakes once a second: Ray's cancel comes as SIGINT
                proc.wait(timeout=TASK_WAKE_S)
    except KeyboardInterrupt:
        stop(proc)
        log_stopped(job, time.monotonic() - began)
        raise
    yield Outcome(proc.returncode, cmd, resume)


def run_jobs_on_ray(
    states: list[JobState],
    parallel: int | None,
    report: Callable[[str], None],
    target: RayTarget,
    may_start: Callable[[Job], bool] = lambda job: True,
) -> list[Launch]:
    """Run every new or partial job as a Ray task, at most ``parallel`` at once (None: as many as the
    cluster's CPUs hold); returns the launches, in start order (a failed task: returncode None).

    :func:`tssac_core.train.jobs.runner.schedule` with :class:`RayTasks`: the local executor's contract
    (finished jobs skipped, ``may_start`` asked before each start, every running job stopped on
    KeyboardInterrupt, which is re-raised)."""
    if any(s.status is Status.CONFLICT for s in states):
        raise ValueError("run_jobs_on_ray was given a conflicting job")
    pending = [s for s in states if s.status in (Status.NEW, Status.PARTIAL)]
    if not pending:
        return []
    with ray_session(target) as ray, interrupt_on_sigterm():
        threads = {s.job.name: s.job.config.threads for s in pending}
        slots = parallel or max(1, cluster_cpus(ray) // max(threads.values()))
        report(f"Ray: {cluster_cpus(ray)} CPUs, {slots} jobs at a time, {max(threads.values())} CPU(s) each")
        return schedule(pending, slots, RayTasks(ray, threads, report), report, may_start)


class RayTasks:
    """The Ray executor's :class:`tssac_core.train.jobs.runner.JobRunner`: each job a Ray generator task
    (:func:`run_job`) asking for the job's threads as CPUs, run in the driver's working directory; a job's handle
    is its name, which stays while the driver submits it again after its worker died."""

    def __init__(self, ray: Any, threads: dict[str, int], report: Callable[[str], None]) -> None:
        self.ray = ray
        self.threads = threads
        self.report = report
        self.directory = os.getcwd()
        self.task = ray.remote(max_retries=0)(run_job)
        self.tasks: dict[str, Any] = {}
        """A running job's name -> its task's ObjectRefGenerator."""
        self.attempts: dict[str, int] = {}

    def start(self, job: Job, resume: bool) -> Hashable:
        self._submit(job)
        return job.name

    def _submit(self, job: Job) -> None:
        self.attempts[job.name] = self.attempts.get(job.name, 0) + 1
        self.tasks[job.name] = self.task.options(num_cpus=self.threads[job.name]).remote(job, self.directory)

    def ended(self, running: dict[Hashable, Launch]) -> list[tuple[Hashable, Launch]]:
        tasks = [self.tasks[str(name)] for name in running]
        ready, _ = self.ray.wait(tasks, num_returns=len(tasks), timeout=DRIVER_WAKE_S)
        names = {id(task): name for name, task in self.tasks.items()}
        ended: list[tuple[Hashable, Launch]] = []
        for task in ready:
            name = names[id(task)]
            if (launch := self._next_report(task, running[name])) is not None:
                del self.tasks[name]
                ended.append((name, launch))
        return ended

    def _next_report(self, task: Any, launch: Launch) -> Launch | None:
        """Read what ``task`` yielded next: print a start (None), or the job's end (its final launch); a worker
        that died submits the job again (None) until WORKER_RETRIES are spent."""
        job = launch.job
        try:
            report: Started | Outcome = next_yield(self.ray, task)
        except TaskError as exc:  # raised (another attempt would too), ended without its Outcome, or its worker died
            if not exc.worker_died or self.attempts[job.name] > WORKER_RETRIES:
                return self._failed(launch, str(exc))
            self._submit(job)
            return None
        if isinstance(report, Started):
            self._report_start(report)
            return None
        ended = Launch(job, report.command or launch.command, report.resumed, report.returncode)
        report_end(ended, self.report)
        return ended

    def _failed(self, launch: Launch, why: str) -> Launch:
        """Report a job whose task failed (``why``: one line); its final launch (no exit code)."""
        self.report(f"FAILED {launch.job.name}: {why}; see {launch.job.out / LOG_NAME}")
        return Launch(launch.job, launch.command, launch.resumed, None)

    def _report_start(self, event: Started) -> None:
        """A start of a job's second or later submission is a retry after its worker died."""
        again = " again after its worker died" if self.attempts[event.name] > 1 else ""
        self.report(
            f"started {event.name}{again}{' (resume)' if event.resumed else ''}: "
            f"on {event.host} (node {event.node}), Ray worker pid "
            f"{event.worker_pid}, training pid {event.train_pid}"
        )

    def stop(self, running: dict[Hashable, Launch]) -> None:
        """Cancel every running task: each stops its training process and writes the stopped line (a task that
        does not end in time is killed, and its training process dies with it)."""
        for launch in running.values():
            self.report(f"stopping {launch.job.name}; it resumes on the next run")
        cancel(self.ray, [self.tasks[str(name)] for name in running])
