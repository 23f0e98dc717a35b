"""A run's training wall time: ``wall_time.json`` in its run directory, one record per invocation that spent it.

``python -m tssac_core.train`` appends a ``finished`` record when it has trained every role; the grid runner
appends a ``stopped`` record when it stops a job (SIGINT or SIGTERM to the runner, or a Ray cancel), since the
epoch then running was spent although it is trained again. An invocation killed some other way leaves no
record, and its time is not counted. The seconds are whole (as ``train.log`` prints them). The file::

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


def record_invocation(run: Path, seconds: float, ended: Ended) -> None:
    """Append one invocation's wall time (rounded to whole seconds) to ``run/wall_time.json``."""
    records = [*read_invocations(run), Invocation(round(seconds), ended)]
    write_json(run / WALL_TIME_FILE, {"invocations": [{"seconds": i.seconds, "ended": i.ended.value} for i in records]})


def training_wall_s(run: Path) -> float | None:
    """Wall seconds of a run: the sum over its recorded invocations (None when none is recorded)."""
    invocations = read_invocations(run)
    return float(sum(i.seconds for i in invocations)) if invocations else None
