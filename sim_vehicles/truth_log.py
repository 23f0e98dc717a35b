"""The truth log's writer: JSON Lines, one object per line, written as the mission runs.

The format (line types, fields, units) is :mod:`tssac_core.wire.truth_log_schema`.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import IO, Any

from tssac_core.wire.truth_log_schema import EVENT, HEADER, SUMMARY, VehicleRow, encode, encode_step

_log = logging.getLogger(__name__)


class TruthLog:
    """Writer of one JSON Lines truth log (opened at construction; OSError -> caller)."""

    def __init__(self, path: Path, header: dict[str, Any]) -> None:
        self.path = path
        self._file: IO[str] | None = open(path, "w", encoding="utf-8")
        self._write({"type": HEADER, **header})

    def step(self, step: int, time_s: float, flags: dict[str, bool], rows: list[VehicleRow]) -> None:
        if self._file is not None:
            self._file.write(encode_step(step, time_s, flags, rows))

    def event(self, record: dict[str, Any]) -> None:
        self._write(record)

    def vehicle_event(self, step: int, time_s: float, role: str, name: str, value: int, text: str | None) -> None:
        """A vehicle's own event (ARMED, MODE, FAILSAFE, DATALINK) or a client's STATUSTEXT it relayed (``text``)."""
        record: dict[str, Any] = {
            "type": EVENT,
            "step": step,
            "t_s": round(time_s, 6),
            "event": name,
            "value": value,
            "vehicle": role,
        }
        if text is not None:
            record["text"] = text  # a client's STATUSTEXT
        self._write(record)

    def summary(self, record: dict[str, Any]) -> None:
        self._write({"type": SUMMARY, **record})

    def close(self) -> None:
        if self._file is not None:
            try:
                self._file.close()
            finally:
                self._file = None

    def _write(self, record: dict[str, Any]) -> None:
        if self._file is None:
            return
        self._file.write(encode(record))
