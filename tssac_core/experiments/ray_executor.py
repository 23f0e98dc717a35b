"""``--executor ray``: the grid's training jobs as Ray tasks, one per (algorithm, seed) job.

Each job is a task asking for the job's CPUs (its torch threads). The task runs on whichever node Ray
gives it the same ``python -m tssac_core.train`` process the local executor starts (the same command,
the same ``train.log``), in the driver's working directory, and decides there, from the run directory,
whether to start the run or ``--resume`` it. So the run directory and its resume state are the only
state: the node needs to see it, which on a cluster means a shared filesystem (docs/ray.md).

- A task whose worker process dies (killed, out of memory, its node lost) is retried by Ray
  (:data:`WORKER_RETRIES` times); the training process dies with its worker (``PR_SET_PDEATHSIG``), so
  the retry finds the run partial and resumes it from its last finished epoch.
- Each task reports where it started through a Ray queue; the driver prints it, and each job's end,
  as the local executor does.
- Ctrl-C or SIGTERM: every running task is cancelled (a KeyboardInterrupt inside it): it stops its
  training process as the local executor does (SIGTERM to its group, then SIGKILL) and writes the
  "stopped after" line; queued jobs are dropped. Each run stays resumable.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import socket
import subprocess
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tssac_core.experiments.grid import Job
from tssac_core.experiments.jobs import (
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
from tssac_core.ray_cluster import RayTarget, cluster_cpus, ray_session
from tssac_core.ray_map import cancel, drain, one_line

WORKER_RETRIES = 3
"""Times Ray runs a job again after its worker process died (each run resumes the last)."""
TASK_WAKE_S = 1.0
DRIVER_WAKE_S = 2.0
"""How often a task looks at its training process, and the driver at its tasks and their start reports: rarely,
since on a machine whose CPUs the jobs fill, every wake-up of these (and of the Ray actor they ask) is taken
from the training."""
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


def run_job(job: Job, directory: str, events: Any) -> Outcome:
    """The Ray task: train (or resume) ``job`` in ``directory`` (the driver's working directory) until its
    process ends; a cancel (KeyboardInterrupt) stops it and leaves it resumable."""
    if not Path(directory).is_dir():
        raise RuntimeError(
            f"node {socket.gethostname()} does not see {directory}: running a grid on a Ray cluster needs "
            "the checkout and the results on a filesystem every node mounts at the same path (docs/ray.md)"
        )
    os.chdir(directory)
    state = job_state(job)
    if state.status is Status.FINISHED:  # an earlier attempt finished it before its worker died
        return Outcome(0, (), False)
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
    events.put(Started(job.name, socket.gethostname(), node_id(), os.getpid(), proc.pid, resume))
    try:
        while proc.poll() is None:
            with contextlib.suppress(subprocess.TimeoutExpired):  # wakes once a second: Ray's cancel comes as SIGINT
                proc.wait(timeout=TASK_WAKE_S)
    except KeyboardInterrupt:
        stop(proc)
        log_stopped(job, time.monotonic() - began)
        raise
    return Outcome(proc.returncode, cmd, resume)


def run_jobs_on_ray(
    states: list[JobState],
    parallel: int | None,
    report: Callable[[str], None],
    target: RayTarget,
    may_start: Callable[[Job], bool] = lambda job: True,
) -> list[Launch]:
    """Run every new or partial job as a Ray task, at most ``parallel`` at once (None: as many as the
    cluster's CPUs hold); returns the launches, in start order (a failed task: returncode None).

    :func:`tssac_core.experiments.jobs.schedule` with :class:`RayTasks`: the local executor's contract
    (finished jobs skipped, ``may_start`` asked before each start, every running job stopped on
    KeyboardInterrupt, which is re-raised)."""
    if any(s.status is Status.CONFLICT for s in states):
        raise ValueError("run_jobs_on_ray was given a conflicting job")
    pending = [s for s in states if s.status in (Status.NEW, Status.PARTIAL)]
    if not pending:
        return []
    with ray_session(target) as ray, interrupt_on_sigterm():
        threads = {s.job.name: s.job.config().threads for s in pending}
        slots = parallel or max(1, cluster_cpus(ray) // max(threads.values()))
        report(f"Ray: {cluster_cpus(ray)} CPUs, {slots} jobs at a time, {max(threads.values())} CPU(s) each")
        runner = RayTasks(ray, threads, report)
        try:
            return schedule(pending, slots, runner, report, may_start)
        finally:
            runner.report_started()


class RayTasks:
    """The Ray executor's :class:`tssac_core.experiments.jobs.JobRunner`: each job a Ray task (:func:`run_job`)
    asking for the job's threads as CPUs, run in the driver's working directory."""

    def __init__(self, ray: Any, threads: dict[str, int], report: Callable[[str], None]) -> None:
        from ray.util.queue import Queue

        self.ray = ray
        self.threads = threads
        self.report = report
        self.directory = os.getcwd()
        self.events = Queue(actor_options={"num_cpus": 0})
        self.task = ray.remote(max_retries=WORKER_RETRIES, retry_exceptions=False)(run_job)
        self.starts: dict[str, int] = {}

    def start(self, job: Job, resume: bool) -> Hashable:
        return self.task.options(num_cpus=self.threads[job.name]).remote(job, self.directory, self.events)

    def ended(self, running: dict[Hashable, Launch]) -> list[tuple[Hashable, Launch]]:
        done, _ = self.ray.wait(list(running), num_returns=len(running), timeout=DRIVER_WAKE_S)
        self.report_started()
        return [(ref, finished(self.ray, ref, running[ref], self.report)) for ref in done]

    def stop(self, running: dict[Hashable, Launch]) -> None:
        """Cancel every running task: each stops its training process and writes the stopped line (a task that
        does not end in time is killed, and its training process dies with it)."""
        for launch in running.values():
            self.report(f"stopping {launch.job.name}; it resumes on the next run")
        cancel(self.ray, list(running))

    def report_started(self) -> None:
        """Print the starts the tasks reported since the last call; a second start of a job is Ray's retry."""

        def on_event(event: Started) -> None:
            self.starts[event.name] = self.starts.get(event.name, 0) + 1
            again = " again after its worker died" if self.starts[event.name] > 1 else ""
            self.report(
                f"started {event.name}{again}{' (resume)' if event.resumed else ''}: "
                f"on {event.host} (node {event.node}), Ray worker pid "
                f"{event.worker_pid}, training pid {event.train_pid}"
            )

        drain(self.events, on_event)


def finished(ray: Any, ref: Any, launch: Launch, report: Callable[[str], None]) -> Launch:
    """The launch as its task ended, reported as the local executor reports a job's end."""
    job = launch.job
    try:
        outcome: Outcome = ray.get(ref)
    except Exception as exc:  # the task raised, or its worker died more often than it is retried
        report(f"FAILED {job.name}: {one_line(exc)}; see {job.out / LOG_NAME}")
        return Launch(job, launch.command, launch.resumed, None)
    ended = Launch(job, outcome.command or launch.command, outcome.resumed, outcome.returncode)
    report_end(ended, report)
    return ended
