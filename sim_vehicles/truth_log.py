"""The truth log: JSON Lines, one object per line, written as the mission runs.

Line types (key ``type``):

``header``  (first line) ``scenario`` name, ``digest`` (Scenario.digest()), ``seed``, ``dt_s``,
            ``clock`` ("realtime" / "lockstep"), ``speedup``, ``roles`` (["decoy", "detect", "strike"]),
            ``sysids``, ``ports``, ``layout`` (the layout flown, in scenario-file form).
``step``    one per world step: ``step`` (1, 2, ...), ``t_s`` (simulated time after the step),
            ``radar_on``, ``identified``, ``hit`` (mission flags after the step) and ``vehicles``:
            {role: {``x_m``, ``y_m`` (east / north of the area's SW corner), ``v_m_s``, ``phi_rad``
            (CCW from east), ``cost`` (eq. 11 cost of this step, 0/1), ``cost_total``,
            ``omega_cmd``, ``u_cmd`` (the action flown, in [-1, 1]), ``armed``, ``mode``
            ("MANUAL"/"GUIDED"), ``failsafe``}} — true states, no sensor noise.
``event``   ``step``, ``t_s``, ``event`` (RADAR_ON, IDENT, HIT, HAZARD, FENCE, MSN_END — see
            :mod:`sim_vehicles.events`), ``value``, ``vehicle`` (role or null).
``summary`` (last line) ``success`` (target hit), ``end`` ("success", "geofence", "episode_cap" or
            "stopped"), ``steps``, ``sim_time_s``, ``cost`` ({role: total eq. 11 cost}),
            ``cost_limit``, ``radar_on``, ``identified``, ``hit``, ``counters`` ({role: link and
            protocol counters}).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VehicleRow:
    """One vehicle's true state after a step (see the module docstring for units)."""

    role: str
    x_m: float
    y_m: float
    v_m_s: float
    phi_rad: float
    cost: float
    cost_total: float
    omega_cmd: float
    u_cmd: float
    armed: bool
    mode: str
    failsafe: bool

    def as_dict(self) -> dict[str, Any]:
        return {
            "x_m": round(self.x_m, 4),
            "y_m": round(self.y_m, 4),
            "v_m_s": round(self.v_m_s, 5),
            "phi_rad": round(self.phi_rad, 7),
            "cost": self.cost,
            "cost_total": self.cost_total,
            "omega_cmd": round(self.omega_cmd, 7),
            "u_cmd": round(self.u_cmd, 7),
            "armed": self.armed,
            "mode": self.mode,
            "failsafe": self.failsafe,
        }


class TruthLog:
    """Writer of one JSON Lines truth log (opened at construction; OSError -> caller)."""

    def __init__(self, path: Path, header: dict[str, Any]) -> None:
        self.path = path
        self._file: IO[str] | None = open(path, "w", encoding="utf-8")
        self._write({"type": "header", **header})

    def step(self, step: int, time_s: float, flags: dict[str, bool], rows: list[VehicleRow]) -> None:
        self._write({"type": "step", "step": step, "t_s": round(time_s, 6), **flags, "vehicles": {r.role: r.as_dict() for r in rows}})

    def event(self, record: dict[str, Any]) -> None:
        self._write(record)

    def summary(self, record: dict[str, Any]) -> None:
        self._write({"type": "summary", **record})

    def close(self) -> None:
        if self._file is not None:
            try:
                self._file.close()
            finally:
                self._file = None

    def _write(self, record: dict[str, Any]) -> None:
        if self._file is None:
            return
        self._file.write(json.dumps(record, separators=(",", ":")) + "\n")


def read_truth_log(path: str | Path) -> list[dict[str, Any]]:
    """All records of a truth log (for tests and analysis)."""
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]
