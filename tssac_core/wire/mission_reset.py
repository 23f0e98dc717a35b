"""The mission-reset protocol between ``fly`` and the processes it keeps alive across a campaign.

A SITL world (``python -m sim_vehicles --serve``) and a companion (``python -m mavlink_bridge.companion
--serve``) fly the mission their command line names, print their ``end ...`` line, and then, instead of
exiting, read the next mission from standard input: one JSON object per line, the fields of
:class:`NextMission`. The process resets as an autopilot does when it reboots (a new world or a new
companion state, its clocks back at 0, its counters at 0) but keeps its UDP socket, its signing state and
its pid; it prints ``ready ...`` (the world) and flies the mission. ``{"quit": true}`` or the end of the
input ends the process with exit code 0.

On the MAVLink side the reset is a reboot: the world forgets its clients and drains its sockets, so its
vehicles are silent until their companion's first heartbeat of the new mission, exactly as a freshly
started world is; each companion drops whatever its socket still holds of the previous mission before it
sends that heartbeat. Nothing of one mission can reach the next.
"""

from __future__ import annotations

import json
import os
import select
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from pathlib import Path

QUIT = {"quit": True}


class ResetError(Exception):
    """A malformed mission line; ``str()`` is one line."""


@dataclass(frozen=True)
class NextMission:
    """One mission of a campaign, as ``fly`` sends it to a process it keeps alive.

    The world reads ``scenario``, ``seed``, ``truth_log``, ``tlog_dir`` and ``log``; a companion reads
    ``scenario``, ``status_json``, ``tlog`` and ``log``. A path left None is not written this mission."""

    index: int
    scenario: Path
    """The mission's scenario file, with its fixed layout."""
    seed: int = 0
    truth_log: Path | None = None
    tlog_dir: Path | None = None
    status_json: Path | None = None
    tlog: Path | None = None
    log: Path | None = None
    """Where the process's standard error goes from now on (the mission's own log file)."""

    def to_line(self) -> str:
        data = {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(self).items() if v is not None}
        return json.dumps(data, sort_keys=True) + "\n"

    @classmethod
    def from_line(cls, line: str) -> NextMission | None:
        """The mission a line names; None for a quit. Raises ResetError with one line."""
        try:
            data = json.loads(line)
        except json.JSONDecodeError as exc:
            raise ResetError(f"mission line is not JSON ({exc.msg}): {line.strip()[:80]!r}") from None
        if not isinstance(data, dict):
            raise ResetError(f"mission line is not a JSON object: {line.strip()[:80]!r}")
        if data == QUIT:
            return None
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ResetError(f"mission line has unknown fields: {', '.join(unknown)}")
        if not isinstance(data.get("index"), int) or not isinstance(data.get("scenario"), str):
            raise ResetError("mission line needs an integer 'index' and a 'scenario' path")
        if not isinstance(data.get("seed", 0), int):
            raise ResetError("mission line: 'seed' must be an integer")
        paths: dict[str, Path | None] = {}
        for name in ("truth_log", "tlog_dir", "status_json", "tlog", "log"):
            value = data.get(name)
            if value is not None and not isinstance(value, str):
                raise ResetError(f"mission line: {name!r} must be a path")
            paths[name] = None if value is None else Path(value)
        return cls(
            index=data["index"],
            scenario=Path(data["scenario"]),
            seed=data.get("seed", 0),
            truth_log=paths["truth_log"],
            tlog_dir=paths["tlog_dir"],
            status_json=paths["status_json"],
            tlog=paths["tlog"],
            log=paths["log"],
        )


class MissionInput:
    """The mission lines arriving on a file descriptor (standard input: fd 0), read without blocking the process
    for longer than a poll, so that a stop request is seen while it waits."""

    def __init__(self, fd: int = 0) -> None:
        self.fd = fd
        self._buffer = b""
        self._eof = False

    def next(self, stop: Callable[[], bool], poll_s: float = 0.2, timeout_s: float | None = None) -> NextMission | None:
        """Block until the next mission line (None: quit, end of input, a stop request or the timeout).
        Raises ResetError for a malformed line."""
        line = self.line(stop, poll_s, timeout_s)
        return None if line is None else NextMission.from_line(line)

    def line(self, stop: Callable[[], bool], poll_s: float = 0.2, timeout_s: float | None = None) -> str | None:
        """Block until the next line that is not blank (None: end of input, a stop request or the timeout). A
        process fly starts reads its configuration so, before its missions (``--config-json -``)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            line, newline, rest = self._buffer.partition(b"\n")
            if newline or (self._eof and line):
                self._buffer = rest
                if line.strip():
                    return line.decode(errors="replace")
                continue
            if self._eof or stop() or (deadline is not None and time.monotonic() >= deadline):
                return None
            try:
                ready, _, _ = select.select([self.fd], [], [], poll_s)
            except InterruptedError:
                continue
            if ready:
                chunk = os.read(self.fd, 65536)
                self._eof = not chunk
                self._buffer += chunk


def redirect_stderr(path: Path) -> None:
    """From now on the process's standard error (its log) goes to ``path`` (created or truncated): each mission
    of a persistent process has its own log file, as a process started for it would."""
    path.parent.mkdir(parents=True, exist_ok=True)
    sys.stderr.flush()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        os.dup2(fd, 2)
    finally:
        os.close(fd)
