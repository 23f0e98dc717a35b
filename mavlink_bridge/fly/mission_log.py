"""Reading a SITL world's truth log (JSON Lines) into a mission's outcome, tracks and event markers.

The format is :mod:`tssac_core.wire.truth_log_schema` (the bundled SITL writes it; it is read here
without importing the SITL): a
``header`` line (scenario, seed, the layout flown, ...), one ``step`` line per world step (true
states per role: ``x_m``, ``y_m``, ``cost``, ``cost_total``, ``failsafe`` ...), ``event`` lines
(RADAR_ON, IDENT, HIT, HAZARD, FENCE, MSN_END, the vehicles' ARMED / MODE / FAILSAFE changes, and the
STATUSTEXTs the companions sent, with their text: the runtime-assurance monitor's hand-overs)
and a final ``summary`` line (``success``, ``end``, ``steps``, ``sim_time_s``, ``cost`` per role).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mavlink_bridge.companion.shield import ENGAGED_TEXT, RELEASED_TEXT
from tssac_core.sim.scenario import ROLES
from tssac_core.wire.mission_events import EventName
from tssac_core.wire.truth_log_schema import (
    EVENT,
    FLAGS,
    HEADER,
    ROLES_KEY,
    SCHEMA_VERSION,
    STEP,
    SUMMARY,
    VEHICLES_KEY,
    EventLine,
)

TASK_EVENTS = {"decoy": (EventName.RADAR_ON, 1), "detect": (EventName.IDENT, 1), "strike": (EventName.HIT, 1)}
"""The event that completes each role's task (eq. 9)."""
EVENT_LABELS = {
    EventName.RADAR_ON: "radar on",
    EventName.IDENT: "identified",
    EventName.HIT: "hit",
    EventName.HAZARD: "hazard",
    EventName.FENCE: "left area",
}
_EVENT_VEHICLE = {EventName.RADAR_ON: "decoy", EventName.IDENT: "detect", EventName.HIT: "strike"}


class TruthLogError(ValueError):
    """A truth log that cannot be read; ``str()`` is one line."""


@dataclass
class MissionRecord:
    """What one truth log says about a mission."""

    header: dict[str, Any]
    summary: dict[str, Any] | None
    """None if the world was killed before it could write one."""
    tracks_m: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    events: list[EventLine] = field(default_factory=list)
    """The log's ``event`` lines, as written."""
    steps: int = 0
    failsafe_steps: dict[str, int] = field(default_factory=dict)
    last_flags: dict[str, bool] = field(default_factory=dict)
    last_cost: dict[str, float] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        return self.summary is not None

    @property
    def success(self) -> bool:
        return bool(self.summary["success"]) if self.summary is not None else bool(self.last_flags.get("hit", False))

    @property
    def end(self) -> str:
        return str(self.summary["end"]) if self.summary is not None else "incomplete"

    @property
    def sim_time_s(self) -> float:
        if self.summary is not None:
            return float(self.summary["sim_time_s"])
        return self.steps * float(self.header.get("dt_s", 0.1))

    @property
    def cost(self) -> dict[str, float]:
        if self.summary is not None:
            return {k: float(v) for k, v in self.summary["cost"].items()}
        return dict(self.last_cost)

    def task_done(self) -> dict[str, bool]:
        seen = {(e.get("event"), e.get("value")) for e in self.events}
        return {role: ev in seen for role, ev in TASK_EVENTS.items()}

    def event_count(self, name: str) -> dict[str, int]:
        """Per role, how many events ``name`` of a UAV (HAZARD, FENCE: their ``vehicle``) the log holds."""
        out = {r.value: 0 for r in ROLES}
        for e in self.events:
            if e.get("event") == name and e.get("vehicle") in out:
                out[str(e["vehicle"])] += 1
        return out

    def backup_segments_km(self) -> dict[str, list[list[tuple[float, float]]]]:
        """Per role, the stretches of track flown under the runtime-assurance monitor's backup: from each
        "<role>: shield on" STATUSTEXT to the next "shield off" (or the end), as lists of (x_km, y_km)."""
        return {
            role: [self._stretch_km(role, first, last) for first, last in ranges]
            for role, ranges in self.backup_step_ranges().items()
        }

    def backup_step_ranges(self) -> dict[str, list[tuple[int, int]]]:
        """Per role, (first_step, last_step) of each stretch under the backup (``backup_segments_km``'s steps)."""
        out: dict[str, list[tuple[int, int]]] = {}
        start: dict[str, int] = {}
        for e in self.events:
            role, text = str(e.get("vehicle")), str(e.get("text", ""))
            if e.get("event") != "STATUSTEXT" or role not in self.tracks_m:
                continue
            k = int(e.get("step", 0))
            if text.startswith(f"{role}: {ENGAGED_TEXT}") and role not in start:
                start[role] = k
            elif text.startswith(f"{role}: {RELEASED_TEXT}") and role in start:
                out.setdefault(role, []).append((start.pop(role), k))
        for role, k in start.items():
            out.setdefault(role, []).append((k, len(self.tracks_m[role])))
        return out

    def _stretch_km(self, role: str, first_step: int, last_step: int) -> list[tuple[float, float]]:
        track = self.tracks_m[role]
        return [(x / 1000.0, y / 1000.0) for x, y in track[max(first_step - 1, 0) : max(last_step, first_step)]]

    def tracks_km(self) -> dict[str, list[tuple[float, float]]]:
        return {role: [(x / 1000.0, y / 1000.0) for x, y in pts] for role, pts in self.tracks_m.items()}

    def event_markers_km(self) -> list[tuple[str, float, float]]:
        """(label, x_km, y_km) of the mission events, at the position of the vehicle concerned."""
        return [(label, x, y) for _, label, x, y in self.timed_event_markers_km()]

    def timed_event_markers_km(self) -> list[tuple[int, str, float, float]]:
        """(track index, label, x_km, y_km) of the mission events: ``event_markers_km`` with when they happened."""
        out = []
        for e in self.events:
            if e.get("event") not in set(EventName):
                continue
            name = EventName(e["event"])
            if name not in EVENT_LABELS or e.get("value") == 0 and name == EventName.RADAR_ON:
                continue
            role = e.get("vehicle") or _EVENT_VEHICLE.get(name)
            track = self.tracks_m.get(str(role))
            if not track:
                continue
            k = min(max(int(e.get("step", 0)) - 1, 0), len(track) - 1)
            x, y = track[k]
            label = EVENT_LABELS[name] + (f" ({role})" if name in (EventName.HAZARD, EventName.FENCE) else "")
            out.append((k, label, x / 1000.0, y / 1000.0))
        return out


def read_mission(path: Path) -> MissionRecord:
    """Parse a truth log; a missing summary (world killed) is allowed, a missing header is not."""
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise TruthLogError(f"{path}: cannot read truth log ({exc.strerror or exc})") from None
    header: dict[str, Any] | None = None
    record: MissionRecord | None = None
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            if n == len(lines):
                break  # a line cut off by a killed writer
            raise TruthLogError(f"{path}:{n}: not JSON") from None
        kind = row.get("type")
        if header is None:
            if kind != HEADER:
                raise TruthLogError(f"{path}: first line is not a header")
            schema = row.get("schema", 1)  # version 1 logs have no schema key
            if type(schema) is not int or not 1 <= schema <= SCHEMA_VERSION:
                raise TruthLogError(
                    f"{path}: truth log schema {schema!r} is not one this reader knows (1-{SCHEMA_VERSION})"
                )
            header = row
            record = MissionRecord(header=row, summary=None, tracks_m={role: [] for role in row.get(ROLES_KEY, [])})
            continue
        assert record is not None
        if kind == STEP:
            record.steps = int(row["step"])
            record.last_flags = {k: bool(row.get(k, False)) for k in FLAGS}
            for role, v in row[VEHICLES_KEY].items():
                record.tracks_m.setdefault(role, []).append((float(v["x_m"]), float(v["y_m"])))
                record.last_cost[role] = float(v["cost_total"])
                if v.get("failsafe"):
                    record.failsafe_steps[role] = record.failsafe_steps.get(role, 0) + 1
        elif kind == EVENT:
            record.events.append(row)
        elif kind == SUMMARY:
            record.summary = row
    if record is None:
        raise TruthLogError(f"{path}: empty truth log")
    return record
