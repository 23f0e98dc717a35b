"""Run a grid's training jobs as ``python -m tssac_core.train`` processes, a few at a time, resumably.

A job's state is read from its run directory alone:

- *finished*: the checkpoints of the roles it trains (decoy.pt, detect.pt, strike.pt; a transfer run's one role)
  are there; it is not run again;
- *partial*: config.json is there but not every checkpoint (the job was killed, or failed); it is continued
  with ``--out DIR --resume``, which loses at most the epoch that was running;
- *new*: no config.json (nor checkpoints); it is started from the beginning;
- *conflict*: config.json records other settings than the grid asks for (e.g. a run left there by an
  earlier grid), or there are checkpoints without one; it is never touched, and running the grid refuses
  to start until it is moved away.

Each job runs in its own process group (its own session), with stdout and stderr appended to
``train.log`` in its run directory. On SIGINT or SIGTERM the runner stops every job it started (SIGTERM
to the group, SIGKILL after a grace period) before it exits, so no training process outlives it, and
records how long each stopped job's invocation ran (its time counts in the run's wall time:
:mod:`tssac_core.train.wall_time`), also as a line in its train.log.
"""

from __future__ import annotations

import enum
import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Hashable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from types import FrameType
from typing import Any, Protocol, cast

import tssac_core
from tssac_core.common.cli import UsageError, write_json
from tssac_core.common.errors import CheckpointError
from tssac_core.common.sessions import in_new_session
from tssac_core.sim.scenario import ROLES, ScenarioError
from tssac_core.sim.scenario import load as load_scenario
from tssac_core.train.config import TrainConfig, config_record, with_recorded_defaults
from tssac_core.train.jobs.job import Job
from tssac_core.train.legacy import config_from_saved
from tssac_core.train.wall_time import Ended, record_invocation

logger = logging.getLogger(__name__)

LOG_NAME = "train.log"
JOB_CONFIG = "job_config.json"
"""In a job's run directory: the TrainConfig the runner starts a new run with, as config.json records it
(``python -m tssac_core.train --config``); the run's own config.json is written from it."""
GRACE_S = 10.0
"""How long a stopped job gets to exit after SIGTERM before SIGKILL."""
POLL_S = 0.1
IGNORED_SETTINGS = ("threads",)
"""config.json keys that may differ from the grid: they change speed, not the result's meaning."""


class Status(enum.Enum):
    FINISHED = "finished"
    PARTIAL = "partial"
    NEW = "new"
    CONFLICT = "conflict"


@dataclass(frozen=True)
class JobState:
    job: Job
    status: Status
    detail: str = ""
    """For a conflict: which setting differs."""


@dataclass(frozen=True)
class Launch:
    """A job the runner started, and how it ended."""

    job: Job
    command: tuple[str, ...]
    resumed: bool
    returncode: int | None = None


def is_finished(job: Job) -> bool:
    """Every role the job trains has its checkpoint."""
    return all((job.out / f"{role}.pt").is_file() for role in job.roles)


def job_state(job: Job) -> JobState:
    """Status of a job from its run directory (module docstring)."""
    config_path = job.out / "config.json"
    if not config_path.is_file():
        if any((job.out / f"{role.value}.pt").is_file() for role in ROLES):
            return JobState(
                job,
                Status.CONFLICT,
                "role checkpoints without a config.json (not made by tssac_core.train for this grid)",
            )
        return JobState(job, Status.NEW)
    try:
        saved = json.loads(config_path.read_text())
    except (OSError, ValueError) as exc:
        return JobState(job, Status.CONFLICT, f"its config.json is not readable ({exc})")
    try:
        difference = config_difference(saved, job.config, job.out)
    except UsageError as exc:
        return JobState(job, Status.CONFLICT, str(exc))
    if difference:
        return JobState(job, Status.CONFLICT, difference)
    return JobState(job, Status.FINISHED if is_finished(job) else Status.PARTIAL)


def config_difference(saved: dict[str, Any], wanted: TrainConfig, run: Path | None = None) -> str:
    """'' if a run's config.json is the run the grid asks for, else the first differing setting.

    A key missing from an older config.json takes what ``train --resume`` gives it. The scenario is the
    same if it is the same file or a file with the same task (:func:`same_scenario`).
    """
    expected = json.loads(json.dumps(asdict(with_recorded_defaults(wanted))))  # tuples -> lists, as in config.json
    have = json.loads(json.dumps(asdict(config_from_saved(saved))))
    for key, value in expected.items():
        if key in IGNORED_SETTINGS:
            continue
        if key == "scenario":
            same = same_scenario(Path(have[key]), Path(value), run)
        else:
            same = have.get(key) == value
        if not same:
            return f"{key}: {have.get(key)!r} in its config.json, {value!r} in the grid"
    return ""


def same_scenario(saved: Path, wanted: Path, run: Path | None) -> bool:
    """Whether a run trained on the task of the scenario file ``wanted``: the same path, or the same task
    (scenario digest) in the file it names, or, if that file is gone (a run directory copied from another
    clone), in its role checkpoints, which record the digest of the task they were trained on."""
    if saved.resolve() == wanted.resolve():
        return True
    try:
        digest = load_scenario(wanted).digest()
        if saved.is_file():
            return load_scenario(saved).digest() == digest
    except ScenarioError:
        return False
    if run is None:
        return False
    for role in ROLES:
        checkpoint = run / f"{role.value}.pt"
        if checkpoint.is_file():
            try:
                from tssac_core.deploy.policy import read_checkpoint  # torch: not for --help or --dry-run

                return read_checkpoint(checkpoint).get("scenario_digest") == digest
            except CheckpointError:
                return False
    return False


def command(job: Job, resume: bool) -> tuple[str, ...]:
    """The job's process: a new run of the TrainConfig in its :data:`JOB_CONFIG` file (:func:`start` writes it),
    or ``--resume`` of the run in its directory (its config.json wins)."""
    head = (sys.executable, "-m", "tssac_core.train")
    board = () if job.tensorboard is None else ("--tensorboard", str(job.tensorboard))
    if resume:
        return (*head, "--out", str(job.out), "--resume", "--no-progress", *board)
    return (*head, "--config", str(job.out / JOB_CONFIG), "--out", str(job.out), "--no-progress", *board)


def child_environment() -> dict[str, str]:
    """The runner's environment, with this tssac_core first on the path: the jobs run the same code."""
    env = dict(os.environ)
    root = str(Path(tssac_core.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH", "")) if p)
    return env


def start(
    job: Job, resume: bool, where: str = "", preexec_fn: Callable[[], None] | None = None
) -> tuple[subprocess.Popen[bytes], tuple[str, ...]]:
    """Start one job in a new session (its own process group), output appended to its train.log; ``where``:
    a line for the log saying where it runs (the Ray executor's worker); ``preexec_fn``: run in the child
    before the command (the Ray executor binds the job to its worker's life)."""
    job.out.mkdir(parents=True, exist_ok=True)
    if not resume:
        write_json(job.out / JOB_CONFIG, config_record(job.config))
    cmd = command(job, resume)
    with (job.out / LOG_NAME).open("ab") as log:
        log.write(f"\n=== {time.strftime('%Y-%m-%d %H:%M:%S')} runner: {' '.join(cmd)}\n".encode())
        if where:
            log.write(f"=== {where}\n".encode())
        log.flush()
        proc = subprocess.Popen(
            cmd,
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            env=child_environment(),
            start_new_session=True,
            preexec_fn=in_new_session(preexec_fn),
        )
    return proc, cmd


def log_stopped(job: Job, seconds: float) -> None:
    """Record that the runner stopped the job after ``seconds`` of training: in its wall time
    (:mod:`tssac_core.train.wall_time`) and in its train.log."""
    record_invocation(job.out, seconds, Ended.STOPPED)
    with (job.out / LOG_NAME).open("a") as log:
        log.write(
            f"=== {time.strftime('%Y-%m-%d %H:%M:%S')} runner: stopped after {seconds:.0f} s; the next run resumes it\n"
        )


def stop(proc: subprocess.Popen[bytes], grace_s: float = GRACE_S) -> None:
    """Stop a job's whole process group: SIGTERM, then SIGKILL if it has not exited after ``grace_s``."""
    if proc.poll() is not None:
        return
    for sig, wait_s in ((signal.SIGTERM, grace_s), (signal.SIGKILL, None)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=wait_s)
            break
        except subprocess.TimeoutExpired:
            continue


@contextmanager
def interrupt_on_sigterm() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt, as SIGINT does, so that one cleanup path serves both."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class JobRunner(Protocol):
    """Where :func:`schedule` runs jobs: local processes (:class:`LocalProcesses`) or Ray tasks
    (:mod:`tssac_core.train.jobs.ray_executor`). A handle is whatever the runner knows a running job by."""

    def start(self, job: Job, resume: bool) -> Hashable:
        """Start ``job`` (``--resume`` it if ``resume``); its handle."""
        ...

    def ended(self, running: dict[Hashable, Launch]) -> list[tuple[Hashable, Launch]]:
        """Wait a moment for jobs of ``running`` to end; those that did, each with its final launch (exit code
        set, None for a task that failed), each reported."""
        ...

    def stop(self, running: dict[Hashable, Launch]) -> None:
        """Stop every job of ``running`` so that the next run resumes it; say so for each."""
        ...


def schedule(
    states: list[JobState],
    parallel: int,
    runner: JobRunner,
    report: Callable[[str], None] = logger.info,
    may_start: Callable[[Job], bool] = lambda job: True,
) -> list[Launch]:
    """Run every new or partial job with ``runner``, at most ``parallel`` at once; returns the launches, in start
    order.

    Finished jobs are skipped; conflicts must have been refused by the caller. A free slot goes to the first
    pending job that ``may_start`` allows (``--finish-by``: :mod:`tssac_core.experiments.deadline`); one it
    refuses is dropped, and reported, since time only runs on. On KeyboardInterrupt (SIGINT, or SIGTERM via
    :func:`interrupt_on_sigterm`) every running job is stopped, then it re-raises.
    """
    pending = [s for s in states if s.status in (Status.NEW, Status.PARTIAL)]
    if any(s.status is Status.CONFLICT for s in states):
        raise ValueError("schedule was given a conflicting job")
    launches: list[Launch] = []
    running: dict[Hashable, int] = {}  # handle -> launch index

    def running_launches() -> dict[Hashable, Launch]:
        return {handle: launches[index] for handle, index in running.items()}

    try:
        while pending or running:
            while pending and len(running) < parallel:
                state = pending.pop(0)
                if not may_start(state.job):
                    report(f"not started {state.job.name}: it would not finish in the time given")
                    continue
                resume = state.status is Status.PARTIAL
                running[runner.start(state.job, resume)] = len(launches)
                launches.append(Launch(state.job, command(state.job, resume), resume))
            if not running:  # every pending job refused
                break
            for handle, launch in runner.ended(running_launches()):
                launches[running.pop(handle)] = launch
    finally:
        if running:
            runner.stop(running_launches())
    return launches


def report_end(launch: Launch, report: Callable[[str], None]) -> None:
    """Say how a job's process ended: finished, or failed with its exit code (and where its log is)."""
    code = launch.returncode
    ok = code == 0 and is_finished(launch.job)
    report(
        f"{'finished' if ok else f'FAILED (exit code {code})'} {launch.job.name}"
        + ("" if ok else f": see {launch.job.out / LOG_NAME}")
    )


class LocalProcesses:
    """The local executor's :class:`JobRunner`: each job a ``python -m tssac_core.train`` process here."""

    def __init__(self, report: Callable[[str], None]) -> None:
        self.report = report
        self.began: dict[Hashable, float] = {}

    def start(self, job: Job, resume: bool) -> Hashable:
        proc, _ = start(job, resume)
        self.began[proc] = time.monotonic()
        self.report(f"started {job.name}{' (resume)' if resume else ''}: pid {proc.pid}, log {job.out / LOG_NAME}")
        return proc

    def ended(self, running: dict[Hashable, Launch]) -> list[tuple[Hashable, Launch]]:
        out = []
        for handle, launch in running.items():
            code = cast("subprocess.Popen[bytes]", handle).poll()
            if code is not None:
                out.append((handle, Launch(launch.job, launch.command, launch.resumed, code)))
                report_end(out[-1][1], self.report)
        time.sleep(POLL_S)
        return out

    def stop(self, running: dict[Hashable, Launch]) -> None:
        for handle, launch in running.items():
            proc = cast("subprocess.Popen[bytes]", handle)
            self.report(f"stopping {launch.job.name} (pid {proc.pid}); it resumes on the next run")
            stop(proc)
            log_stopped(launch.job, time.monotonic() - self.began[handle])


def run_jobs(
    states: list[JobState],
    parallel: int,
    report: Callable[[str], None] = logger.info,
    may_start: Callable[[Job], bool] = lambda job: True,
) -> list[Launch]:
    """The local executor: :func:`schedule` with :class:`LocalProcesses`, SIGTERM handled as SIGINT."""
    with interrupt_on_sigterm():
        return schedule(states, parallel, LocalProcesses(report), report, may_start)
