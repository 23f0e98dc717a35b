"""A run's training wall time: ``wall_time.json`` in its run directory, one record per invocation that spent it.

``python -m tssac_core.train`` opens a ``running`` record when it starts and brings its seconds up to date after every
epoch, so a kill costs at most the epoch then running. When it has trained every role the record becomes
``finished``; the grid runner makes it ``stopped`` when it stops a job (SIGINT or SIGTERM to the runner, or a Ray
cancel), with the runner's own count of the seconds, since the epoch then running was spent although it is trained
again. An invocation that finds a ``running`` record before its own was killed some other way: that record becomes
``killed`` and keeps the seconds to its last epoch. The seconds are whole (as ``train.log`` prints them). The file::

    {"invocations": [{"seconds": 412, "ended": "stopped"}, {"seconds": 88, "ended": "finished"}]}
"""

from __future__ import annotations

import enum
import json
from dataclasses import dataclass
from pathlib import Path

from tssac_core.common.cli import write_json

WALL_TIME_FILE = "wall_time.json"


class Ended(enum.Enum):
    """How an invocation that recorded its wall time ended."""

    FINISHED = "finished"
    """``tssac_core.train`` trained every role of the run."""
    STOPPED = "stopped"
    """The grid runner stopped it; the next run resumes it."""
    RUNNING = "running"
    """Training now (its seconds: to its last finished epoch), or killed if another invocation came after it."""
    KILLED = "killed"
    """Killed without a record of its end (found ``running`` by the next invocation); its seconds to its last epoch."""


@dataclass(frozen=True)
class Invocation:
    seconds: int
    ended: Ended


def read_invocations(run: Path) -> list[Invocation]:
    """The invocations recorded in ``run/wall_time.json`` (none if there is no such file)."""
    path = run / WALL_TIME_FILE
    if not path.is_file():
        return []
    data = json.loads(path.read_text())
    return [Invocation(int(i["seconds"]), Ended(i["ended"])) for i in data["invocations"]]


def _write(run: Path, records: list[Invocation]) -> None:
    write_json(run / WALL_TIME_FILE, {"invocations": [{"seconds": i.seconds, "ended": i.ended.value} for i in records]})


def begin_invocation(run: Path) -> None:
    """Open this invocation's ``running`` record; a ``running`` record left by an earlier one becomes ``killed``."""
    records = [Invocation(i.seconds, Ended.KILLED) if i.ended is Ended.RUNNING else i for i in read_invocations(run)]
    _write(run, [*records, Invocation(0, Ended.RUNNING)])


def record_invocation(run: Path, seconds: float, ended: Ended) -> None:
    """This invocation's wall time (rounded to whole seconds), ``ended`` as given: it replaces the invocation's
    ``running`` record if it has one (the last), or is appended."""
    records = read_invocations(run)
    if records and records[-1].ended is Ended.RUNNING:
        records.pop()
    _write(run, [*records, Invocation(round(seconds), ended)])


def training_wall_s(run: Path) -> float | None:
    """Wall seconds of a run: the sum over its recorded invocations (None when none is recorded)."""
    invocations = read_invocations(run)
    return float(sum(i.seconds for i in invocations)) if invocations else None
