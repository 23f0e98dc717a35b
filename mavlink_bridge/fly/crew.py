"""The processes ``fly`` keeps alive across a campaign: one SITL world and one companion per UAV.

They are started with ``--serve`` for the campaign's first mission (standard input and output piped) and are
told each next mission over the mission-reset protocol (:mod:`tssac_core.wire.mission_reset`). fly reads
their ``ready`` and ``end`` lines through :class:`LineReader`; a process that dies or hangs ends the crew, and the
next mission starts a new one.
"""

from __future__ import annotations

import json
import os
import select
import time
from collections import deque
from dataclasses import dataclass, field

from mavlink_bridge.processes.children import Child
from tssac_core.wire.mission_reset import QUIT, NextMission

QUIT_LINE = json.dumps(QUIT) + "\n"
_CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


class CrewError(Exception):
    """A process of the crew cannot be told the next mission (it died); ``str()`` is one line."""

    def __init__(self, message: str, child: Child) -> None:
        super().__init__(message)
        self.child = child


class LineReader:
    """The lines a child prints on its standard output, read without blocking."""

    def __init__(self, child: Child) -> None:
        self.child = child
        self.lines: deque[str] = deque()
        self.eof = False
        self._partial = b""
        out = child.process.stdout
        assert out is not None, f"{child.name}: standard output is not piped"
        self._fd = out.fileno()

    def fileno(self) -> int:
        return self._fd

    def pump(self) -> None:
        """Read what is waiting (call when select says the pipe is readable)."""
        try:
            chunk = os.read(self._fd, 65536)
        except BlockingIOError:
            return
        except OSError:
            chunk = b""
        if not chunk:
            self.eof = True
            if self._partial:
                self.lines.append(self._partial.decode(errors="replace"))
                self._partial = b""
            return
        *complete, self._partial = (self._partial + chunk).split(b"\n")
        self.lines.extend(line.decode(errors="replace") for line in complete)

    def take(self, prefix: str) -> str | None:
        """The first line read so far that starts with ``prefix`` (lines before it are dropped), or None."""
        while self.lines:
            line = self.lines.popleft()
            if line.startswith(prefix):
                return line
        return None

    def printed(self) -> str:
        """What is left unread, for an error message."""
        return " | ".join(self.lines)


def wait_readable(readers: list[LineReader], timeout_s: float) -> None:
    """Pump every reader whose pipe becomes readable within ``timeout_s``."""
    open_ = [r for r in readers if not r.eof]
    if not open_:
        time.sleep(max(0.0, timeout_s))
        return
    try:
        ready, _, _ = select.select(open_, [], [], max(0.0, timeout_s))
    except InterruptedError:
        return
    for r in ready:
        r.pump()


@dataclass
class Crew:
    """A world and its three companions, alive between missions."""

    world: LineReader
    companions: list[LineReader]
    ended: set[str] = field(default_factory=set)
    """Names of the processes that printed this mission's ``end`` line."""

    @property
    def readers(self) -> list[LineReader]:
        return [self.world, *self.companions]

    @property
    def children(self) -> list[Child]:
        return [r.child for r in self.readers]

    def tell(self, reader: LineReader, mission: NextMission | None) -> None:
        """Send the next mission (None: quit) to one process."""
        stdin = reader.child.process.stdin
        line = QUIT_LINE if mission is None else mission.to_line()
        try:
            assert stdin is not None, f"{reader.child.name}: standard input is not piped"
            stdin.write(line.encode())
            stdin.flush()
        except (OSError, ValueError) as exc:  # ValueError: its pipe already closed (a stop in progress)
            raise CrewError(
                f"{reader.child.name} (pid {reader.child.pid}) cannot take the next mission: {exc}", reader.child
            ) from None

    def cpu_s(self) -> float | None:
        """User + system CPU seconds the crew's processes have used so far (None where /proc is not there)."""
        total = 0.0
        for child in self.children:
            used = process_cpu_s(child.pid)
            if used is None:
                return None
            total += used
        return total


def process_cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a running process, from /proc (Linux); None elsewhere or once it is gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            stat = fh.read()
    except OSError:
        return None
    fields = stat[stat.rindex(b")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) / _CLOCK_TICKS
