"""Mission events: what a world step did that the vehicles' clients must hear about.

Each event goes to every vehicle's clients as a STATUSTEXT (human-readable, max 50 characters) and a
NAMED_VALUE_INT (machine-readable; ``time_boot_ms`` = simulated time of the step):

============  ========================================  ===========================================
name          value                                     when
============  ========================================  ===========================================
``RADAR_ON``  1 on, 0 off                               the SAM radar switches (decoy in its ring)
``IDENT``     1                                         the detect UAV identifies the target
``HIT``       1                                         the strike UAV hits the target (success)
``HAZARD``    vehicle index (0 decoy, 1 detect, 2 strike)  a UAV enters a radar's range (cost)
``FENCE``     vehicle index                             a UAV leaves the area (geofence; mission ends)
``MSN_END``   1 success, 2 geofence, 3 episode cap      the mission ended
============  ========================================  ===========================================

The current flags ``RADAR_ON``, ``IDENT`` and ``HIT`` (and ``MSN_END`` once the mission has ended)
are re-sent every second (simulated time), so a client that connects late or lost a packet still
learns them.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from tssac_core.sim.scenario import ROLES
from tssac_core.sim.world import StepResult
from tssac_core.wire.mission_events import (
    HIT_TEXT,
    IDENTIFIED_TEXT,
    RADAR_TEXTS,
    EventName,
    MissionEnd,
    mission_end_text,
)


class EventKind(enum.Enum):
    RADAR = EventName.RADAR_ON
    IDENTIFIED = EventName.IDENT
    HIT = EventName.HIT
    HAZARD = EventName.HAZARD
    GEOFENCE = EventName.FENCE
    MISSION_END = EventName.MSN_END

    @property
    def value_name(self) -> str:
        """The NAMED_VALUE_INT name (at most 10 characters)."""
        return str(self.value)


@dataclass(frozen=True)
class MissionEvent:
    kind: EventKind
    step: int
    """World step after which it happened."""
    time_s: float
    """Simulated time of that step."""
    value: int
    """The NAMED_VALUE_INT value (see the module table)."""

    @property
    def vehicle(self) -> int | None:
        """Index of the UAV concerned (HAZARD, FENCE), else None."""
        return self.value if self.kind in (EventKind.HAZARD, EventKind.GEOFENCE) else None

    def statustext(self) -> tuple[int, str]:
        """(MAV_SEVERITY, text) of the STATUSTEXT announcing it."""
        k, v = self.kind, self.value
        if k is EventKind.RADAR:
            return mavlink2.MAV_SEVERITY_WARNING, RADAR_TEXTS[bool(v)]
        if k is EventKind.IDENTIFIED:
            return mavlink2.MAV_SEVERITY_NOTICE, IDENTIFIED_TEXT
        if k is EventKind.HIT:
            return mavlink2.MAV_SEVERITY_NOTICE, HIT_TEXT
        if k is EventKind.HAZARD:
            return mavlink2.MAV_SEVERITY_WARNING, f"Hazard: {ROLES[v].value} entered radar range"
        if k is EventKind.GEOFENCE:
            return mavlink2.MAV_SEVERITY_CRITICAL, f"Geofence: {ROLES[v].value} left the area"
        return mavlink2.MAV_SEVERITY_NOTICE, mission_end_text(MissionEnd(v))

    def as_dict(self) -> dict[str, object]:
        role = ROLES[self.vehicle].value if self.vehicle is not None else None
        return {
            "type": "event",
            "step": self.step,
            "t_s": round(self.time_s, 6),
            "event": str(self.kind.value),
            "value": self.value,
            "vehicle": role,
        }


@dataclass
class WorldFlags:
    """The mission state every vehicle re-announces at 1 Hz."""

    radar_on: bool = False
    identified: bool = False
    hit: bool = False
    end: MissionEnd | None = None

    def named_values(self) -> list[tuple[str, int]]:
        out = [
            (str(EventName.RADAR_ON), int(self.radar_on)),
            (str(EventName.IDENT), int(self.identified)),
            (str(EventName.HIT), int(self.hit)),
        ]
        if self.end is not None:
            out.append((str(EventName.MSN_END), int(self.end)))
        return out


def events_from_step(result: StepResult, radar_on: bool, step: int, time_s: float) -> list[MissionEvent]:
    """The events of world 0 of one :meth:`tssac_core.sim.world.World.step` (``radar_on`` = the world's new flag)."""
    out: list[MissionEvent] = []

    def add(kind: EventKind, value: int) -> None:
        out.append(MissionEvent(kind, step, time_s, value))

    if result.radar_on_changed[0]:
        add(EventKind.RADAR, int(radar_on))
    if result.identified_now[0]:
        add(EventKind.IDENTIFIED, 1)
    for i, entered in enumerate(result.hazard_entered[0].tolist()):
        if entered:
            add(EventKind.HAZARD, i)
    for i, out_of_area in enumerate(result.out_of_area[0].tolist()):
        if out_of_area:
            add(EventKind.GEOFENCE, i)
    if result.hit_now[0]:
        add(EventKind.HIT, 1)
    if result.terminated[0] or result.truncated[0]:
        if result.hit_now[0]:
            end = MissionEnd.SUCCESS
        elif result.out_of_area[0].any():
            end = MissionEnd.GEOFENCE
        else:
            end = MissionEnd.EPISODE_CAP
        add(EventKind.MISSION_END, int(end))
    return out
